"""Crown cover of each species, as issue 40 defines it: the fraction of the
crown's silhouette that is opaque, from the front (looking along +Y) and
the side (looking along -X), orthographic, with the materials' alpha (the
leaf textures' cutout, not the card quads). The crown is the silhouette
above 35 % of the tree's height; cover = covered pixels / pixels inside the
crown's convex hull; a species' figure is the lower of the two views.

    python bench/crown_cover.py [SPECIES ...] [--pixels 1200] [--json FILE] [--png DIR]

Measured on what the exporter writes: each species is grown as a scene
grows it (default quality, its grammar's seed), standing still at rest,
exported to a .glb by treebake's own exporter (textures on), and that file
is read back here (positions, UVs, indices, materials, embedded PNGs) and
rasterised in numpy: a pixel is covered when its centre falls in a
triangle whose material is opaque, or whose texture's alpha at the
interpolated UV (nearest texel of the full-resolution image, as a
magnified cutout samples it) reaches the material's alphaCutoff. No
renderer, no mipmaps: the silhouette the geometry and its alpha define.

`--pixels` is the image height per tree height (pixel = height / pixels,
metres); `--check` also measures at half that and prints the difference
(the figure is stable to 0.01 when it is below 0.01). Writes
out/bench/crown_cover.json.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# the glb read back with treebake's own reader (every length checked)
from treebake.exchange.gltf_read import _accessor, _load as _read_glb  # noqa: E402

CROWN_FROM = 0.35  # the crown: the silhouette above this fraction of the height
SPECIES = ("oak", "spruce", "willow", "sapling", "forest/broadleaf", "forest/birch",
           "forest/conifer")
TARGETS = {"spruce": 0.75, "forest/conifer": 0.75}  # conifers; broadleaf species 0.70
BROADLEAF_TARGET = 0.70
VIEWS = {"front": (0, 2), "side": (1, 2)}  # Z-up world axes: (right, up) of each view


# ---------------------------------------------------------------------------
# the exporter's file


def export_rest_glb(grammar: str, folder: Path, seed: int | None = None) -> Path:
    """The species grown and rigged as a bake does it, at rest (one static
    frame), written by treebake's glTF exporter as folder/<name>/<name>.glb."""
    from treebake.bake import Bake, segment_transforms, tree_bake_from_model
    from treebake.export import ExportOptions, export_bake
    from treebake.species import grown_rig

    rig = grown_rig(_grammar_path(grammar), seed)
    pos, rot = segment_transforms(rig, None, None)
    tree = tree_bake_from_model(rig.model, pos, rot, {"grammar": grammar,
                                                      "seed": rig.model.source.get("seed")})
    name = grammar.replace("/", "_")
    bake = Bake(np.zeros(1), [tree], {"scene": name, "fps": 24.0})
    export_bake(bake, folder, name, ExportOptions(formats=("glb",)))
    return folder / name / f"{name}.glb"


def _grammar_path(grammar: str) -> Path:
    path = Path(grammar)
    if path.suffix == ".lsys":
        return path
    from treebake.library import grammar_path

    return grammar_path(grammar)


def _alpha_of(doc: dict, blob: bytes, material: dict) -> tuple[np.ndarray | None, float]:
    """The material's alpha image (H, W) 0..1 (None: opaque) and cutoff."""
    mode = material.get("alphaMode", "OPAQUE")
    if mode == "OPAQUE":
        return None, 0.0
    pbr = material.get("pbrMetallicRoughness", {})
    factor = float(pbr.get("baseColorFactor", [1, 1, 1, 1])[3])
    cutoff = float(material.get("alphaCutoff", 0.5)) if mode == "MASK" else 0.5
    tex = pbr.get("baseColorTexture")
    if tex is None:
        return np.full((1, 1), factor), cutoff
    image = doc["images"][doc["textures"][tex["index"]]["source"]]
    view = doc["bufferViews"][image["bufferView"]]
    start = view.get("byteOffset", 0)
    png = Image.open(io.BytesIO(blob[start:start + view["byteLength"]])).convert("RGBA")
    return np.asarray(png)[..., 3].astype(np.float64) / 255.0 * factor, cutoff


def glb_triangles(path: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray | None, float,
                                            str]]:
    """Per primitive: triangle corners (T, 3, 3) in the Z-up world (m), their
    UVs (T, 3, 2) (glTF's: v down the image), alpha image, cutoff, material.
    Mesh nodes of static trees carry no transform (treebake writes none);
    skinned meshes are at their bind pose, which is the rest pose."""
    doc, blob = _read_glb(path)
    out = []
    for node in doc["nodes"]:
        if "mesh" not in node:
            continue
        if any(k in node for k in ("matrix", "translation", "rotation", "scale")):
            raise SystemExit(f"{path}: a mesh node with a transform (not read here)")
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            a = prim["attributes"]
            pos = _accessor(doc, blob, a["POSITION"]).astype(np.float64)
            pos = np.stack([pos[:, 0], -pos[:, 2], pos[:, 1]], 1)  # Y up -> Z up
            uv = _accessor(doc, blob, a["TEXCOORD_0"]).astype(np.float64) \
                if "TEXCOORD_0" in a else np.zeros((len(pos), 2))
            idx = _accessor(doc, blob, prim["indices"]).astype(np.int64).reshape(-1, 3)
            mat = doc["materials"][prim["material"]] if "material" in prim else {}
            alpha, cutoff = _alpha_of(doc, blob, mat)
            out.append((pos[idx], uv[idx], alpha, cutoff, mat.get("name", "")))
    return out


# ---------------------------------------------------------------------------
# rasterising


def rasterise(corners: np.ndarray, uvs: np.ndarray, alpha: np.ndarray | None, cutoff: float,
              mask: np.ndarray, budget: int = 1 << 22) -> None:
    """OR into `mask` (H, W) bool the pixels whose centre lies in a triangle
    (corners (T, 3, 2) in pixel units, x right, y down) where the material
    covers: opaque, or alpha at the interpolated UV >= cutoff."""
    h, w = mask.shape
    lo = np.floor(corners.min(1) - 0.5).astype(np.int64)
    hi = np.ceil(corners.max(1) - 0.5).astype(np.int64)
    ext = np.maximum(hi - lo + 1, 1)
    area = ((corners[:, 1, 0] - corners[:, 0, 0]) * (corners[:, 2, 1] - corners[:, 0, 1])
            - (corners[:, 2, 0] - corners[:, 0, 0]) * (corners[:, 1, 1] - corners[:, 0, 1]))
    keep = np.abs(area) > 1e-12  # edge-on triangles cover no pixel centre
    size = np.maximum(ext[:, 0], ext[:, 1])
    bucket = np.where(keep, 1 << np.ceil(np.log2(np.maximum(size, 1))).astype(np.int64), 0)
    for b in np.unique(bucket[bucket > 0]):
        tri = np.nonzero(bucket == b)[0]
        per = max(1, budget // int(b * b))
        grid = np.arange(b)
        for k in range(0, len(tri), per):
            t = tri[k:k + per]
            c = corners[t]
            px = lo[t, 0, None, None] + grid[None, None, :]  # (n, 1, b)
            py = lo[t, 1, None, None] + grid[None, :, None]  # (n, b, 1)
            x, y = px + 0.5, py + 0.5
            x0, y0 = c[:, 0, 0, None, None], c[:, 0, 1, None, None]
            x1, y1 = c[:, 1, 0, None, None], c[:, 1, 1, None, None]
            x2, y2 = c[:, 2, 0, None, None], c[:, 2, 1, None, None]
            a = area[t][:, None, None]
            l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / a
            l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / a
            l0 = 1.0 - l1 - l2
            inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
            inside &= (px >= 0) & (px < w) & (py >= 0) & (py < h)
            if alpha is not None:
                uv = uvs[t]
                u = l0 * uv[:, 0, 0, None, None] + l1 * uv[:, 1, 0, None, None] + \
                    l2 * uv[:, 2, 0, None, None]
                v = l0 * uv[:, 0, 1, None, None] + l1 * uv[:, 1, 1, None, None] + \
                    l2 * uv[:, 2, 1, None, None]
                ah, aw = alpha.shape
                col = np.clip(np.floor(u * aw).astype(np.int64), 0, aw - 1)
                row = np.clip(np.floor(v * ah).astype(np.int64), 0, ah - 1)
                inside &= alpha[row, col] >= cutoff
            n, yy, xx = np.nonzero(inside)
            mask[py[n, yy, 0], px[n, 0, xx]] = True


def silhouette(prims, view: tuple[int, int], pixel: float, lo: np.ndarray,
               hi: np.ndarray) -> np.ndarray:
    """The covered pixels (H, W) of one orthographic view; row 0 is the top
    (hi[2]), pixel edge `pixel` m; lo/hi: the geometry's box (m)."""
    a, b = view
    w = int(np.ceil((hi[a] - lo[a]) / pixel)) + 2
    h = int(np.ceil((hi[b] - lo[b]) / pixel)) + 2
    mask = np.zeros((h, w), bool)
    for corners, uvs, alpha, cutoff, _ in prims:
        xy = np.stack([(corners[..., a] - lo[a]) / pixel + 1.0,
                       (hi[b] - corners[..., b]) / pixel + 1.0], -1)
        rasterise(xy, uvs, alpha, cutoff, mask)
    return mask


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (Andrew's monotone chain) of (N, 2) points, counter-clockwise."""
    pts = np.unique(points, axis=0)
    if len(pts) < 3:
        return pts

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) -
                                     (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts.tolist()), half(pts[::-1].tolist())
    return np.array(lower[:-1] + upper[:-1], dtype=np.float64)


def crown_cover(mask: np.ndarray, pixel: float, top_z: float) -> dict:
    """Cover of the crown in one view's silhouette `mask` (row 0 at height
    top_z + pixel): the covered pixels above CROWN_FROM of the height over
    the pixels whose centre lies in the convex hull of those pixels' squares."""
    h, w = mask.shape
    z = top_z + pixel - (np.arange(h) + 0.5) * pixel  # m, each row's centre height
    covered_rows = np.nonzero(mask.any(1))[0]
    height = float(z[covered_rows[0]] + 0.5 * pixel)  # the silhouette's top, m (ground at 0)
    crown = mask & (z >= CROWN_FROM * height)[:, None]
    rows = np.nonzero(crown.any(1))[0]
    if len(rows) == 0:
        return {"cover": 0.0, "crown_px": 0, "hull_px": 0, "height_m": height}
    left = np.argmax(crown[rows], axis=1)
    right = w - 1 - np.argmax(crown[rows, ::-1], axis=1)
    # each extreme pixel's two outer corners (x right, y down, pixel units)
    pts = np.concatenate([np.stack([left, rows], 1), np.stack([left, rows + 1], 1),
                          np.stack([right + 1, rows], 1), np.stack([right + 1, rows + 1], 1)])
    hull = _hull(pts.astype(np.float64))
    # per row centre, the hull's x extent (convex: one interval)
    yc = np.arange(h) + 0.5
    p, q = hull, np.roll(hull, -1, axis=0)
    dy = q[:, 1] - p[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (yc[:, None] - p[None, :, 1]) / dy[None, :]
        x = p[None, :, 0] + t * (q[None, :, 0] - p[None, :, 0])
    hit = (dy[None, :] != 0) & (t >= 0) & (t <= 1)
    xl = np.where(hit, x, np.inf).min(1)
    xr = np.where(hit, x, -np.inf).max(1)
    xc = np.arange(w) + 0.5
    inside = (xc[None, :] >= xl[:, None]) & (xc[None, :] <= xr[:, None])
    inside &= (z >= CROWN_FROM * height)[:, None]
    n_crown = int(crown.sum())
    n_hull = int((inside | crown).sum())
    return {"cover": n_crown / n_hull, "crown_px": n_crown, "hull_px": n_hull,
            "height_m": height}


def measure(glb: Path, pixels: int, png: Path | None = None) -> dict:
    """Front and side crown cover of the trees in `glb`, `pixels` image rows
    per tree height."""
    prims = glb_triangles(glb)
    pts = np.concatenate([c.reshape(-1, 3) for c, *_ in prims])
    lo, hi = pts.min(0), pts.max(0)
    lo[2] = min(lo[2], 0.0)
    pixel = (hi[2] - lo[2]) / pixels
    out = {"pixel_m": pixel, "triangles": int(sum(len(c) for c, *_ in prims))}
    for view, axes in VIEWS.items():
        mask = silhouette(prims, axes, pixel, lo, hi)
        out[view] = crown_cover(mask, pixel, hi[2])
        if png is not None:
            png.parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(np.where(mask, 0, 255).astype(np.uint8)).save(
                png.with_name(f"{png.stem}_{view}.png"))
    out["cover"] = min(out["front"]["cover"], out["side"]["cover"])
    return out


def target(species: str) -> float:
    return TARGETS.get(species, BROADLEAF_TARGET)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("species", nargs="*", help=f"bundled names or .lsys files "
                    f"(default: {' '.join(SPECIES)})")
    ap.add_argument("--pixels", type=int, default=1200,
                    help="image rows per tree height (default 1200)")
    ap.add_argument("--check", action="store_true",
                    help="also measure at half the pixels and print the difference")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "crown_cover.json"))
    ap.add_argument("--png", default=None, help="folder for the silhouettes (PNG)")
    args = ap.parse_args()
    if args.pixels < 50:
        ap.error("--pixels must be >= 50")
    names = args.species or list(SPECIES)
    rows = []
    head = f"{'species':<18} {'front':>6} {'side':>6} {'cover':>6} {'target':>6} {'ok':>3}"
    if args.check:
        head += f" {'half-res diff':>13}"
    print(head + f" {'triangles':>9} {'pixel mm':>8}")
    t0 = time.perf_counter()
    from treebake.errors import TreebakeError

    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            try:
                glb = export_rest_glb(name, Path(tmp))
            except TreebakeError as exc:
                print(f"crown_cover: {exc}", file=sys.stderr)
                return 2
            png = Path(args.png) / f"{Path(name).stem}" if args.png else None
            r = measure(glb, args.pixels, png)
            row = {"species": name, "front": round(r["front"]["cover"], 4),
                   "side": round(r["side"]["cover"], 4), "cover": round(r["cover"], 4),
                   "target": target(name), "passes": r["cover"] >= target(name),
                   "triangles": r["triangles"], "pixel_m": r["pixel_m"],
                   "glb_bytes": glb.stat().st_size, "views": {v: r[v] for v in VIEWS}}
            line = (f"{name:<18} {r['front']['cover']:>6.3f} {r['side']['cover']:>6.3f} "
                    f"{r['cover']:>6.3f} {target(name):>6.2f} "
                    f"{'yes' if row['passes'] else 'NO':>3}")
            if args.check:
                half = measure(glb, args.pixels // 2)
                row["half_res_cover"] = round(half["cover"], 4)
                line += f" {half['cover'] - r['cover']:>+13.4f}"
            print(line + f" {r['triangles']:>9} {r['pixel_m'] * 1000:>8.1f}")
            rows.append(row)
    print(f"crown: silhouette above {CROWN_FROM:.0%} of the height; cover: covered / convex "
          f"hull pixels, the lower of front and side ({time.perf_counter() - t0:.0f} s)")
    from treebake.fileio import write_text

    write_text(args.json, json.dumps({"crown_from": CROWN_FROM, "pixels": args.pixels,
                                      "species": rows}, indent=2) + "\n")
    print(f"written {args.json}")
    return 0 if all(r["passes"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

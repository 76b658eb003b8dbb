"""Issue 40 item 4: the species sheet. Bakes each bundled species alone
(a short bake at rest: frame 1), exports it as glb at default detail with
treebake's own writer, and renders it with Blender (Cycles, CPU) the way
tests/tools/blender_render.py does: a front view (from -Y), a side view
(from +X), both framing the whole tree, and a close-up of the trunk's
bark at about 1.5 m (of the crown's outer foliage where foliage hides the
bark: a spruce's skirt). Species not rendered in a run keep their images
on disk, and the sheet shows them. Writes docs/renders/<species>_{front,side,close}.jpg
and the sheet docs/renders/species.jpg (one row per species; README).

    python bench/species_sheet.py [SPECIES ...] [--out docs/renders] [--samples 16]
        [--size 640x360] [--blender PATH/TO/BLENDER/PYTHON]

Blender: tests/tools/blender.py's bpy (installed on first use into
tests/tools/.blender) unless --blender names its Python. About 40 s of
one core per view at 640x360 and 16 samples.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tests" / "tools"
SPECIES = ["oak", "spruce", "willow", "palm", "bamboo", "sapling", "forest/broadleaf",
           "forest/birch", "forest/conifer"]
VIEWS = ("front", "side", "close")


def views(bake_path: Path) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
    """Camera (target, from) per view, m, Z up, from the tree at rest."""
    from treebake.bake_file import load_bake

    tree = load_bake(bake_path).trees[0]
    pts = tree.points.astype(np.float64)
    base = pts[tree.seg_start[0]]
    height = float(pts[:, 2].max() - base[2])
    width = float(np.ptp(pts[:, :2], axis=0).max())
    # 35 mm lens, 16:9: about 32 degrees vertically; the whole tree with a margin
    d = 2.0 * max(height, 0.56 * width)
    mid = (base[0], base[1], base[2] + 0.47 * height)
    look = (base[0], base[1], base[2] + 0.45 * height)
    z = base[2] + min(1.5, 0.3 * height)
    close = max(1.0, 8.0 * float(tree.width[0]))
    return {"front": (mid, (look[0] + 0.1 * d, look[1] - d, look[2])),
            "side": (mid, (look[0] + d, look[1] + 0.1 * d, look[2])),
            "close": _close_up(tree, base, z, close)}


def _close_up(tree, base, z: float, distance: float):
    """The bark at height z from `distance` m, unless foliage hides it (a
    spruce's skirt reaching the ground): then the crown's outer foliage at
    a third of its height, from 3 m outside it."""
    tw = tree.twigs
    leafy = np.concatenate([tree.points[tree.seg_end[tree.leaf > 0]], tw.end[tw.leaf > 0]])
    leafy = leafy.astype(np.float64)
    bark = ((base[0], base[1], z), (base[0] + 0.2 * distance, base[1] - distance, z - 0.1))
    if not len(leafy):
        return bark
    r = np.linalg.norm(leafy[:, :2] - base[:2], axis=1)
    hides = (r < distance) & (leafy[:, 2] < z + 1.0)
    if not hides.any():
        return bark
    top = float(leafy[:, 2].max())
    band = np.abs(leafy[:, 2] - (base[2] + 0.35 * (top - base[2]))) < 0.1 * (top - base[2])
    cand = np.nonzero(band & (leafy[:, 1] < base[1]))[0]  # the camera's (-Y) side
    k = cand[np.argmax(r[cand])] if len(cand) else int(np.argmax(r))
    target = leafy[k]
    out = target[:2] - base[:2]
    out = out / max(float(np.linalg.norm(out)), 1e-9)
    eye = (target[0] + 3.0 * out[0], target[1] + 3.0 * out[1], target[2] + 0.5)
    return tuple(float(v) for v in target), eye


def render(python: Path, glb: Path, out: Path, target, eye, size: str, samples: int) -> None:
    cmd = [str(python), str(TOOLS / "blender_render.py"), str(glb), str(out), "1",
           "--engine", "cycles", "--samples", str(samples), "--size", size,
           "--target", ",".join(f"{v:.3f}" for v in target),
           "--from", ",".join(f"{v:.3f}" for v in eye)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, check=False)
    if proc.returncode != 0 or not out.is_file():
        raise SystemExit(f"render failed: {' '.join(cmd)}\n{proc.stderr[-2000:]}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("species", nargs="*", default=SPECIES)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "renders")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--blender", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.blender is None:
        sys.path.insert(0, str(TOOLS))
        import blender

        args.blender = blender.blender_python()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.species:
            stem = name.replace("/", "_")
            job = Path(tmp) / stem
            subprocess.run([sys.executable, "-m", "treebake.cli", "bake", name, "--duration",
                            "0.2", "--format", "glb", "--out", str(job), "--name", stem, "-q"],
                           check=True)
            glb, npz = job / stem / f"{stem}.glb", job / stem / f"{stem}.npz"
            row = []
            for view, (target, eye) in views(npz).items():
                png = job / f"{view}.png"
                render(args.blender, glb, png, target, eye, args.size, args.samples)
                image = Image.open(png).convert("RGB")
                image.save(args.out / f"{stem}_{view}.jpg", quality=85)
                row.append(image)
                print(f"{name} {view}", flush=True)
            rows.append(row)
    # the sheet: every species, those not rendered now from their images on disk
    done = {name: row for name, row in zip(args.species, rows)}
    rows = []
    for name in SPECIES:
        stem = name.replace("/", "_")
        files = [args.out / f"{stem}_{view}.jpg" for view in VIEWS]
        if name in done:
            rows.append(done[name])
        elif all(f.is_file() for f in files):
            rows.append([Image.open(f).convert("RGB") for f in files])
    w, h = rows[0][0].size
    half = (w // 2, h // 2)
    sheet = Image.new("RGB", (half[0] * len(VIEWS), half[1] * len(rows)), (255, 255, 255))
    for j, row in enumerate(rows):
        for i, image in enumerate(row):
            sheet.paste(image.resize(half, Image.Resampling.BOX), (i * half[0], j * half[1]))
    sheet.save(args.out / "species.jpg", quality=85)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

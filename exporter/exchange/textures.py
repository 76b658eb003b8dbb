"""Generated textures for the film look: bark (tileable colour, ridges
along the limb) and leaf cards (a cluster of leaves, a spray of needles or
palm leaflets on a transparent background, alpha 0 or 255 for cutout
rendering), as PNG bytes. Pillow and numpy only.

Deterministic: fixed seeds, integer noise (no FFT or transcendental numpy
functions, whose last bits vary by CPU), Pillow's non-antialiased drawing
reduced 2x by box averaging; PNG written without timestamps. The same
versions give the same bytes.

Orientation matches the meshes' UVs (mesh.py): bark u runs around the
limb, v along it (one repeat per `bark_tile` m); a leaf card's stem is at
v = 0, the bottom of the image.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from functools import cache

import numpy as np
from PIL import Image, ImageDraw

from .foliage import ATLAS
from .mesh import BARK_COLOUR, leaf_colour

BARK_SIZE = (256, 512)  # px: u (around) x v (along)
CARD_SIZE = 512  # px, square leaf cards
SEED = 20260415  # fixed: the look is part of the product, not of a scene

# leaf type -> card style (mesh.LEAF_COLOURS gives the colour)
STYLES = {1: "broadleaf", 2: "needles", 3: "leaflets", 4: "broadleaf"}


@dataclass(frozen=True)
class Texture:
    """A texture: file name (`bark.png`), PNG bytes, whether it repeats
    (bark) or is clamped (cards), whether its alpha is a cutout mask,
    whether its pixels are linear data (a normal map) rather than sRGB
    colour, and its tangent-space normal map (bark), if any."""

    name: str
    png: bytes
    repeat: bool
    cutout: bool
    linear: bool = False
    normal: Texture | None = None


@dataclass(frozen=True)
class TextureMap:
    """What a file-based format (OBJ's .mtl, USD) references for a
    material: the colour PNG's path relative to the file, whether its alpha
    is a cutout, and the normal map's path (None: no normal map)."""

    path: str
    cutout: bool
    normal: str | None = None


def normal_map(height: np.ndarray, depth: float, scale: float) -> np.ndarray:
    """(h, w, 3) uint8 tangent-space normals of a periodic height field
    (0..65535 = `depth` default texels of relief; rows = v up; `scale`
    texels per default texel): central differences that wrap, so the map
    tiles."""
    z = height.astype(np.float64) * (depth / 65535.0)
    du = (np.roll(z, -1, axis=1) - np.roll(z, 1, axis=1)) * (0.5 * scale)
    dv = (np.roll(z, -1, axis=0) - np.roll(z, 1, axis=0)) * (0.5 * scale)
    n = np.stack([-du, -dv, np.ones_like(z)], axis=-1)
    n = n / np.sqrt((n * n).sum(-1, keepdims=True))
    return np.floor((n + 1.0) * 127.5 + 0.5).astype(np.uint8)


def srgb8(linear) -> np.ndarray:
    """Linear RGB 0..1 -> 8-bit sRGB (texture pixels are sRGB in every format)."""
    c = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(255 * s).astype(np.int64)


def _png(image: Image.Image) -> bytes:
    """The image as PNG bytes (the same bytes for the same image). zlib
    level 6, not 9: a quarter of the time for 2 % more bytes (the forest's
    18 textures: 0.41 against 1.66 CPU s, 1.66 against 1.63 MB)."""
    buf = io.BytesIO()
    image.save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


# ---------------------------------------------------------------------------
# integer value noise (periodic, platform-independent)


def _value_noise(rng: np.random.Generator, h: int, w: int, cells_y: int,
                 cells_x: int) -> np.ndarray:
    """(h, w) int64 in 0..65535: a periodic lattice of random values
    (cells_y x cells_x cells) smoothly interpolated in fixed point."""
    lattice = rng.integers(0, 65536, size=(cells_y, cells_x), dtype=np.int64)
    cy, cx = h // cells_y, w // cells_x
    y, x = np.arange(h), np.arange(w)
    iy, ix = y // cy, x // cx
    # smoothstep 3t^2 - 2t^3 in 1/4096 units
    ty = ((y % cy) * 4096) // cy
    tx = ((x % cx) * 4096) // cx
    sy = (ty * ty * (3 * 4096 - 2 * ty)) // (4096 * 4096)
    sx = (tx * tx * (3 * 4096 - 2 * tx)) // (4096 * 4096)
    a = lattice[iy[:, None], ix[None, :]]
    b = lattice[iy[:, None], ((ix + 1) % cells_x)[None, :]]
    c = lattice[((iy + 1) % cells_y)[:, None], ix[None, :]]
    d = lattice[((iy + 1) % cells_y)[:, None], ((ix + 1) % cells_x)[None, :]]
    top = a * (4096 - sx) + b * sx
    bottom = c * (4096 - sx) + d * sx
    return (top * (4096 - sy[:, None]) + bottom * sy[:, None]) // (4096 * 4096)


def _fractal(rng, h, w, octaves) -> np.ndarray:
    """Sum of value-noise octaves ((cells_y, cells_x, weight), ...) -> 0..65535."""
    total = sum(wt for _, _, wt in octaves)
    acc = sum(wt * _value_noise(rng, h, w, cy, cx) for cy, cx, wt in octaves)
    return acc // total


# ---------------------------------------------------------------------------
# bark


@cache
def bark_texture() -> Texture:
    """Furrowed bark: plates along the limb separated by dark fissures,
    tileable both ways, mean colour near mesh.BARK_COLOUR."""
    w, h = BARK_SIZE
    rng = np.random.default_rng(SEED)
    # long in v (image rows), narrow in u: ridges run along the limb
    ridges = _fractal(rng, h, w, ((4, 16, 6), (8, 32, 3), (16, 64, 1)))
    fine = _fractal(rng, h, w, ((64, 64, 2), (128, 128, 1)))
    # fissures where the ridge field is near its middle value
    dist = np.abs(ridges - 32768)  # 0 at a fissure
    plate = np.minimum(dist * 3, 65535)  # 0..65535, flat on plates
    shade = (plate * 3 + fine) // 4  # 0..65535
    base = srgb8(np.asarray(BARK_COLOUR) * 0.8)
    dark = srgb8(np.asarray(BARK_COLOUR) * 0.12)
    light = srgb8(np.minimum(np.asarray(BARK_COLOUR) * 1.4, 1.0))
    mid = 32768
    lo = dark[None, None, :] + ((base - dark)[None, None, :] * np.minimum(shade, mid)[..., None]
                                ) // mid
    hi = base[None, None, :] + ((light - base)[None, None, :] *
                                np.maximum(shade - mid, 0)[..., None]) // mid
    rgb = np.where(shade[..., None] < mid, lo, hi)
    image = Image.fromarray(np.flipud(rgb).astype(np.uint8), "RGB")  # v = 0 at the bottom
    # the relief: the plates' shade, 6 texels deep (rows = v up, like rgb)
    normal = Texture("bark_normal.png", _png(Image.fromarray(np.flipud(normal_map(shade, 6.0, 1.0)),
                                                             "RGB")),
                     repeat=True, cutout=False, linear=True)
    return Texture("bark.png", _png(image), repeat=True, cutout=False, normal=normal)


# ---------------------------------------------------------------------------
# leaf cards


def _shade(rgb: np.ndarray, k: float) -> tuple[int, int, int, int]:
    """The colour `rgb` (sRGB 0..255, float) scaled by k, rounded (half to
    even, as numpy rounds) and clipped: an opaque RGBA fill. Plain Python:
    it is called per leaf and needle, where numpy's per-call cost is most
    of the time."""
    r, g, b = (min(max(round(float(v) * k), 0), 255) for v in rgb)
    return r, g, b, 255


def _leaf_outline(x, y, length, width, angle, n=18) -> list[tuple[int, int]]:
    """An ovate leaf from its base (x, y) along `angle` (radians, image
    coordinates, y down), as a polygon."""
    ca, sa = math.cos(angle), math.sin(angle)
    side = []
    for i in range(n + 1):
        t = i / n
        half = width * math.sin(math.pi * t) * (1.0 - 0.35 * t)  # widest below the middle
        side.append((t * length, half))
    pts = [(u, v) for u, v in side] + [(u, -v) for u, v in reversed(side)]
    return [(round(x + u * ca - v * sa), round(y + u * sa + v * ca)) for u, v in pts]


def _twig(draw, rng, x0, y0, length, angle, width, colour):
    """A twig from (x0, y0): returns points along it (for leaves to hang on)."""
    pts = []
    bend = rng.uniform(-0.25, 0.25)
    x, y = x0, y0
    steps = 12
    for i in range(steps + 1):
        a = angle + bend * i / steps
        pts.append((x, y, a))
        nx, ny = x + math.cos(a) * length / steps, y + math.sin(a) * length / steps
        draw.line([(round(x), round(y)), (round(nx), round(ny))], fill=colour,
                  width=max(1, round(width * (1 - 0.6 * i / steps))))
        x, y = nx, ny
    return pts


# per atlas cell (foliage.ATLAS^2 of them): a tint (linear RGB multipliers: hue)
# and a value; a card picks its cell by the tree's seed (foliage.py)
VARIANTS = ((1.00, 1.00, 1.00, 1.00),  # the species' colour
            (1.22, 1.04, 0.70, 1.08),  # yellower, lighter (sunlit, young leaves)
            (0.80, 0.97, 1.15, 0.86),  # bluer, darker (shade leaves)
            (1.08, 0.94, 0.86, 0.78))  # browner, darker (older leaves)


def _card(kind: int, variant: int = 0) -> Image.Image:
    """One card of leaf type `kind` in colour `variant` (VARIANTS), CARD_SIZE
    px square: leaves where alpha is 255, the leaves' mean colour at alpha 0."""
    s = 2 * CARD_SIZE  # drawn at 2x, box-reduced: softer edges, still a crisp mask
    image = Image.new("RGBA", (s, s), (0, 0, 0, 0))
    draw = ImageDraw.Draw(image)
    rng = np.random.default_rng([SEED, kind, variant])
    tint = VARIANTS[variant % len(VARIANTS)]
    colour = srgb8(np.asarray(leaf_colour(kind)) * np.asarray(tint[:3]) * tint[3]
                   ).astype(np.float64)
    stem = _shade(srgb8(np.asarray(BARK_COLOUR) * 0.8), 1.0)
    style = STYLES.get(kind, "broadleaf")
    up = -math.pi / 2  # image y points down; the stem rises from the bottom edge
    main = _twig(draw, rng, s / 2, s - 1, 0.86 * s, up, 0.012 * s, stem)
    if style == "needles":
        # a spray: side shoots from every node of the leader, both sides, and
        # needles all along every shoot, dense enough to keep its cover in the
        # smaller mipmaps of an alpha-cutout material
        sprigs = [main] + [_twig(draw, rng, x, y, rng.uniform(0.3, 0.46) * s * (1.1 - 0.5 * i / 11),
                                 a + side * rng.uniform(0.7, 1.0), 0.006 * s, stem)
                           for i, (x, y, a) in enumerate(main[1:12]) for side in (-1, 1)]
        for twig in sprigs:
            for x, y, a in twig[1:]:
                for side in (-1, 1):
                    for _ in range(7):
                        na = a + side * rng.uniform(0.5, 1.2)
                        ln = rng.uniform(0.05, 0.08) * s
                        x0, y0 = x + rng.uniform(-10, 10), y + rng.uniform(-10, 10)
                        c = _shade(colour, rng.uniform(0.75, 1.2))
                        draw.line([(round(x0), round(y0)),
                                   (round(x0 + math.cos(na) * ln), round(y0 + math.sin(na) * ln))],
                                  fill=c, width=max(2, round(0.01 * s)))
    elif style == "leaflets":
        for x, y, a in main[1:]:
            for side in (-1, 1):
                na = a + side * rng.uniform(1.0, 1.25)
                ln = rng.uniform(0.28, 0.4) * s * (1.1 - 0.5 * (s - y) / s)
                draw.polygon(_leaf_outline(x, y, ln, 0.034 * s, na, 10),
                             fill=_shade(colour, rng.uniform(0.8, 1.2)))
    else:  # broadleaf: a cluster, alternate ovate leaves on a twig and its side shoots
        twigs = [main[:-1]] + [_twig(draw, rng, x, y, rng.uniform(0.3, 0.45) * s * (1.1 - i / 12),
                                     a + (-1, 1)[i % 2] * rng.uniform(0.55, 0.9), 0.007 * s,
                                     stem)
                               for i, (x, y, a) in enumerate(main[2:11])]
        for twig in twigs:
            for i, (x, y, a) in enumerate(twig[2:]):
                side = -1 if i % 2 else 1
                na = a + side * rng.uniform(0.45, 0.95)
                ln = rng.uniform(0.12, 0.17) * s
                draw.polygon(_leaf_outline(x, y, ln, ln * 0.32, na),
                             fill=_shade(colour, rng.uniform(0.8, 1.15)))
                draw.line([(round(x), round(y)), (round(x + math.cos(na) * ln * 0.85),
                                                  round(y + math.sin(na) * ln * 0.85))],
                          fill=_shade(colour, 0.8), width=max(2, round(0.003 * s)))
            x, y, a = twig[-1]
            draw.polygon(_leaf_outline(x, y, 0.15 * s, 0.05 * s, a), fill=_shade(colour, 1.05))
    small = image.reduce(2)
    alpha = np.asarray(small)[..., 3]
    rgba = np.asarray(small).copy()
    rgba[..., 3] = np.where(alpha >= 128, 255, 0)  # a clean cutout mask
    # a clear frame but for the stem's bottom edge: no leaf touches the next atlas cell
    rgba[:2, :, 3] = rgba[:, :2, 3] = rgba[:, -2:, 3] = 0
    # transparent texels carry the leaves' mean colour, not black: mipmaps and
    # filtering at the cutout's edge then blend toward green, not a dark fringe
    solid = rgba[..., 3] > 0
    mean = rgba[solid][:, :3].astype(np.int64).sum(axis=0) // max(int(solid.sum()), 1)
    rgba[~solid, :3] = mean
    return Image.fromarray(rgba, "RGBA")


def _atlas(kind: int) -> Image.Image:
    """foliage.ATLAS x foliage.ATLAS cards of leaf type `kind`, one colour
    variant each: cell (i, j) (column i, row j from the bottom: UV v up) is
    variant j * ATLAS + i."""
    n = ATLAS
    atlas = Image.new("RGBA", (n * CARD_SIZE, n * CARD_SIZE))
    for j in range(n):
        for i in range(n):
            atlas.paste(_card(kind, j * n + i), (i * CARD_SIZE, (n - 1 - j) * CARD_SIZE))
    return atlas


@cache
def leaf_texture(kind: int, detail: str = "default") -> Texture:
    """Leaf cards of leaf type `kind` (1 broadleaf, 2 conifer needles, 3 palm
    leaflets, 4 autumn broadleaf), an atlas of ATLAS x ATLAS colour
    variants (_atlas): colour where the leaves are, alpha 0 elsewhere.
    detail "far": the same atlas box-reduced to half the texels, its
    alpha cut at 128 again (a clean mask)."""
    name = "leaf.png" if kind == 1 else f"leaf{kind}.png"
    atlas = _atlas(kind)
    if detail == "far":
        rgba = np.asarray(atlas.reduce(2)).copy()
        rgba[..., 3] = np.where(rgba[..., 3] >= 128, 255, 0)
        atlas = Image.fromarray(rgba, "RGBA")
    return Texture(name, _png(atlas), repeat=False, cutout=True)

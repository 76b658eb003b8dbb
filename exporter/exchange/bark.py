"""Bark per species: a tileable colour texture and its tangent-space
normal map, generated from one relief (height) field per species, as PNG
bytes. Pillow and numpy only, deterministic like textures.py: integer
value noise, then float64 arithmetic with + - * / and sqrt only (IEEE
correctly rounded, the same bits on every machine), PNG without
timestamps.

A bark texture covers `MeshOptions.bark_tile` m (1 m) of limb along v
(image rows, v = 0 at the bottom) and the limb's circumference around u
(columns); it repeats both ways. The relief is in units of the default
texture's texel (1/512 m along the limb); the normal map encodes
n = (-dh/du, -dh/dv, 1) / |..| (x right = +u, y up = +v: glTF's and USD's
tangent-space convention, OpenGL's "Y+") as round(255 (n + 1) / 2).

Species (by the grammar's file name, `species_of`): oak (deep furrows
between long ridges), spruce and the forest
conifer (thin scales), birch (white with dark horizontal lenticels and
dark patches), palm (rings of leaf scars), willow (a network of deep
interlacing furrows), bamboo (a smooth green culm with raised nodes),
sapling (smooth young bark with lenticels), the forest broadleaf
(shallower oak-like ridges); anything else gets the generic `bark`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import PurePosixPath

import numpy as np
from PIL import Image

from .textures import BARK_SIZE, SEED, Texture, _fractal, _png, normal_map, srgb8

# detail level -> texels per default texel (bark textures: 128x256, 256x512, 512x1024)
SCALE = {"far": 0.5, "default": 1.0, "hero": 2.0}


@dataclass(frozen=True)
class BarkStyle:
    """A species' bark: pattern (a generator below), its albedo (linear
    RGB) in the fissures / on average / on the ridges, and its relief
    depth (default texels of height at the field's full range)."""

    pattern: str
    dark: tuple[float, float, float]
    base: tuple[float, float, float]
    light: tuple[float, float, float]
    depth: float


# albedos (linear RGB): oak, willow and spruce barks reflect 0.1-0.3 (grey-brown),
# birch's periderm 0.5-0.7 (white), a young green culm 0.2-0.4 in green
STYLES = {
    "oak": BarkStyle("ridges", (0.035, 0.028, 0.022), (0.20, 0.17, 0.13), (0.34, 0.30, 0.25), 9.0),
    "willow": BarkStyle("network", (0.04, 0.032, 0.025), (0.22, 0.19, 0.15),
                        (0.33, 0.30, 0.26), 8.0),
    "spruce": BarkStyle("scales", (0.06, 0.03, 0.02), (0.20, 0.11, 0.07), (0.32, 0.20, 0.13), 4.0),
    "conifer": BarkStyle("scales", (0.06, 0.03, 0.02), (0.20, 0.11, 0.07), (0.32, 0.20, 0.13),
                         4.0),
    "birch": BarkStyle("lenticels", (0.03, 0.03, 0.03), (0.62, 0.60, 0.55), (0.78, 0.77, 0.72),
                       2.5),
    "palm": BarkStyle("rings", (0.07, 0.06, 0.045), (0.25, 0.22, 0.17), (0.38, 0.35, 0.29), 6.0),
    "bamboo": BarkStyle("nodes", (0.10, 0.14, 0.04), (0.22, 0.32, 0.09), (0.34, 0.42, 0.14), 3.0),
    "sapling": BarkStyle("smooth", (0.08, 0.06, 0.045), (0.24, 0.17, 0.11), (0.32, 0.25, 0.17),
                         1.5),
    "broadleaf": BarkStyle("ridges", (0.045, 0.035, 0.028), (0.22, 0.18, 0.14),
                           (0.34, 0.30, 0.25), 5.0),
}
ALIASES = {"forest-birch": "birch", "forest-broadleaf": "broadleaf", "forest-conifer": "conifer"}


def species_of(grammar: str | None) -> str | None:
    """The bark species of a tree grown from `grammar` (its path as the bake
    records it: `grammars/oak.lsys`, `../forest/birch.lsys`), by the file's
    name; None for a grammar of no known species."""
    if not grammar:
        return None
    stem = PurePosixPath(str(grammar).replace("\\", "/")).stem.lower()
    stem = ALIASES.get(stem, stem)
    return stem if stem in STYLES else None


def bark_material(grammar: str | None) -> str:
    """The bark material of a tree: `bark_<species>`, or `bark` (generic)."""
    species = species_of(grammar)
    return "bark" if species is None else f"bark_{species}"


def bark_colour(material: str) -> tuple[float, float, float]:
    """A bark material's plain colour (linear RGB), for --no-textures."""
    from .mesh import BARK_COLOUR

    style = STYLES.get(material.removeprefix("bark_"))
    return BARK_COLOUR if style is None else style.base


# ---------------------------------------------------------------------------
# relief patterns: (height, shade) 0..65535 int64 arrays (h, w), rows = v up


def _bands(h: int, period: int, width: int) -> np.ndarray:
    """(h,) 0..65535: a triangular bump `width` rows wide every `period` rows."""
    d = np.abs((np.arange(h) % period) - period // 2)  # distance to the band's centre
    return np.maximum(width - d, 0) * 65535 // max(width, 1)


def _pattern(style: BarkStyle, h: int, w: int, rng: np.random.Generator):
    p = style.pattern
    k = h // 512 if h >= 512 else 1  # rows per default texel (>= 1)
    if p in ("ridges", "network"):
        # long ridges along the limb, fissures where the field crosses its middle
        cells = ((4, 16, 6), (8, 32, 3), (16, 64, 1)) if p == "ridges" else \
            ((8, 16, 5), (16, 32, 3), (32, 64, 1))
        ridges = _fractal(rng, h, w, cells)
        fine = _fractal(rng, h, w, ((64, 64, 2), (128, 128, 1)))
        plate = np.minimum(np.abs(ridges - 32768) * (3 if p == "ridges" else 4), 65535)
        height = (plate * 3 + fine) // 4
        return height, height
    if p == "scales":
        # thin plates: a cell pattern whose cells tilt (brighter, higher at one end)
        coarse = _fractal(rng, h, w, ((32, 16, 3), (64, 32, 1)))
        fine = _fractal(rng, h, w, ((128, 64, 1),))
        edge = np.minimum(np.abs(coarse - 32768) * 6, 65535)  # 0 on a plate's rim
        # each plate ramps up along v (0..65535 every 64 default texels), its
        # phase shifted by the cell field so plates overlap like scales
        tilt = ((np.arange(h)[:, None] * 16 // k + coarse // 64) % 1024) * 64
        height = (edge * 2 + tilt + fine) // 4
        return height, (edge * 3 + fine) // 4
    if p == "lenticels":
        # white periderm; dark horizontal dashes (lenticels) and dark patches
        patches = _fractal(rng, h, w, ((4, 4, 2), (8, 8, 1)))
        dash = _fractal(rng, h, w, ((128, 8, 1),))  # narrow in v, long around u
        lent = np.where(dash > 47000, 0, 65535)
        dark = np.where(patches > 44000, (65535 - patches) * 3, 65535)
        shade = np.minimum(np.minimum(lent, dark), 65535)
        fine = _fractal(rng, h, w, ((64, 32, 1),))
        height = (shade * 3 + fine) // 4
        return height, (shade * 7 + fine) // 8
    if p in ("rings", "nodes"):
        period = 64 * k if p == "rings" else 128 * k  # 12.5 cm leaf scars; 25 cm internodes
        width = 14 * k if p == "rings" else 6 * k
        band = _bands(h, period, width)[:, None]
        fine = _fractal(rng, h, w, ((64, 32, 2), (128, 64, 1)))
        wobble = _fractal(rng, h, w, ((8, 4, 1),))
        if p == "rings":
            height = np.maximum(65535 - band, 0) * 3 // 4 + fine // 4
            shade = np.maximum(65535 - band, 0) * 2 // 3 + (fine + wobble) // 6
        else:
            height = band * 3 // 4 + fine // 16 + 8192
            shade = np.maximum(40000 - band // 2, 0) + wobble // 3
        return np.minimum(height, 65535), np.minimum(shade, 65535)
    # smooth: faint streaks along the limb and small lenticels
    streak = _fractal(rng, h, w, ((2, 32, 2), (4, 64, 1)))
    dash = _fractal(rng, h, w, ((128, 32, 1),))
    lent = np.where(dash > 50000, 20000, 0)
    shade = np.maximum(streak // 2 + 24576 - lent, 0)
    return shade, shade


def _relief(species: str, h: int, w: int):
    """(height, shade) of a species at h x w texels (rows = v up)."""
    rng = np.random.default_rng([SEED, 41, sorted(STYLES).index(species)])
    return _pattern(STYLES[species], h, w, rng)


def _colour(shade: np.ndarray, dark, base, light) -> np.ndarray:
    """(h, w, 3) sRGB 8-bit: dark -> base over shade 0..32768, base -> light above."""
    d, b, li = srgb8(dark), srgb8(base), srgb8(light)
    mid = 32768
    lo = d + ((b - d) * np.minimum(shade, mid)[..., None]) // mid
    hi = b + ((li - b) * np.maximum(shade - mid, 0)[..., None]) // mid
    return np.where(shade[..., None] < mid, lo, hi)


@cache
def species_bark(species: str, detail: str = "default") -> Texture:
    """`bark_<species>.png` (sRGB colour) with its normal map
    `bark_<species>_normal.png` (linear), at the detail level's size."""
    w, h = BARK_SIZE
    s = SCALE[detail]
    hw, hh = int(w * s), int(h * s)
    style = STYLES[species]
    full = max(s, 1.0)  # far: generated at the default size, then box-reduced
    height, shade = _relief(species, int(h * full), int(w * full))
    if s < 1.0:  # 2x2 box average: the same bark, half the texels
        height = height.reshape(hh, 2, hw, 2).sum((1, 3)) // 4
        shade = shade.reshape(hh, 2, hw, 2).sum((1, 3)) // 4
    rgb = _colour(shade, style.dark, style.base, style.light)
    nrm = normal_map(height, style.depth, s)
    name = f"bark_{species}"
    normal = Texture(f"{name}_normal.png", _png(Image.fromarray(np.flipud(nrm), "RGB")),
                     repeat=True, cutout=False, linear=True)
    colour = Image.fromarray(np.flipud(rgb).astype(np.uint8), "RGB")  # v = 0 at the bottom
    return Texture(f"{name}.png", _png(colour), repeat=True, cutout=False, normal=normal)

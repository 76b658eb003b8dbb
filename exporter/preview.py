"""Orthographic preview pictures drawn with Pillow (no GPU): the tree from the
front (looking along +Y) and from the side (looking along -X)."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

BARK = (92, 64, 40)
LEAF = (70, 140, 60)
BACKGROUND = (250, 250, 245)


def draw_views(starts: np.ndarray, ends: np.ndarray, widths: np.ndarray,
               leafy: np.ndarray | None = None, size: int = 512,
               bounds: tuple[np.ndarray, np.ndarray] | None = None,
               title: str = "") -> Image.Image:
    """Front and side views side by side. starts/ends: (S, 3) m, widths: (S,)
    m. `bounds` fixes the framing (for animation frames); default: fit."""
    if bounds is None:
        pts = np.concatenate([starts, ends])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    else:
        lo, hi = bounds
    views = [(0, 2), (1, 2)]  # front: x right, z up; side: y right, z up
    span = max(float(np.max(hi - lo)), 1e-6) * 1.1
    image = Image.new("RGB", (2 * size, size + 24), BACKGROUND)
    draw = ImageDraw.Draw(image)
    scale = (size - 16) / span
    order = np.argsort(-widths)  # thick first, twigs on top
    for k, (a, b) in enumerate(views):
        cx = 0.5 * (lo[a] + hi[a])
        ox, oy = k * size + size / 2, size - 8
        base = lo[2] - 0.05 * span

        def to_px(p, a=a, b=b, cx=cx, ox=ox, oy=oy, base=base):
            return np.stack([ox + (p[:, a] - cx) * scale, oy - (p[:, b] - base) * scale], axis=1)

        p0, p1 = to_px(starts[order]), to_px(ends[order])
        px_w = np.clip(widths[order] * scale, 1, 40).astype(int)
        for (x0, y0), (x1, y1), w in zip(p0.tolist(), p1.tolist(), px_w.tolist()):
            draw.line((x0, y0, x1, y1), fill=BARK, width=w)
        if leafy is not None and leafy.any():
            tips = to_px(ends[leafy])
            for x, y in tips.tolist():
                draw.ellipse((x - 2, y - 2, x + 2, y + 2), fill=LEAF)
        draw.line((k * size, oy, (k + 1) * size, oy), fill=(160, 160, 150))
    label = f"{title}  front | side  ({span / 1.1:.2f} m across)"
    draw.text((6, size + 6), label, fill=(40, 40, 40))
    return image


def model_preview(model, size: int = 512) -> Image.Image:
    """Preview of a TreeModel at rest."""
    starts = model.points[model.seg_start]
    ends = model.points[model.seg_end]
    return draw_views(starts, ends, model.width, model.leaf > 0, size, title=model.name)

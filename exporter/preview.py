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
    """Preview of a TreeModel at rest, its twigs (`@twig`) drawn too."""
    tw = model.twigs
    starts = np.concatenate([model.points[model.seg_start], tw.start])
    ends = np.concatenate([model.points[model.seg_end], tw.end])
    return draw_views(starts, ends, np.concatenate([model.width, tw.width]),
                      np.concatenate([model.leaf, tw.leaf]) > 0, size, title=model.name)


# ---------------------------------------------------------------------------
# bakes: contact sheet and animated GIF


def posed_segments(bake, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Segment (and twig) starts and ends (S, 3) m, widths (S,) m and leafy
    flags of every tree at bake frame f; projectiles as short thick
    upright strokes."""
    from .rotations import apply, matrices_from_quaternions

    starts, ends, widths, leafy = [], [], [], []
    for t in bake.trees:
        k = bake.frame(t, f)
        rest = (t.points[t.seg_end] - t.points[t.seg_start]).astype(np.float64)
        r = matrices_from_quaternions(t.rotations[k].astype(np.float64))
        p = t.positions[k].astype(np.float64)
        starts.append(p)
        ends.append(p + apply(r, rest))
        widths.append(t.width.astype(np.float64))
        leafy.append(t.leaf > 0)
        tw = t.twigs
        if len(tw):  # rigid on their segments
            s, base = tw.segment, t.points[t.seg_start[tw.segment]].astype(np.float64)
            for end, out in ((tw.start, starts), (tw.end, ends)):
                out.append(p[s] + apply(r[s], end.astype(np.float64) - base))
            widths.append(tw.width.astype(np.float64))
            leafy.append(tw.leaf > 0)
    if bake.objects is not None and len(bake.objects.sizes):
        o = bake.objects
        c = o.positions[f].astype(np.float64)
        half = np.zeros_like(c)
        half[:, 2] = 0.5 * o.sizes
        starts.append(c - half)
        ends.append(c + half)
        widths.append(np.asarray(o.sizes, np.float64))
        leafy.append(np.zeros(len(c), bool))
    return (np.concatenate(starts), np.concatenate(ends), np.concatenate(widths),
            np.concatenate(leafy))


def bake_bounds(bake) -> tuple[np.ndarray, np.ndarray]:
    """Framing for every frame: the rest bounds, grown to include the motion
    but never more than one tree height beyond them (far debris is cut)."""
    rest = np.concatenate([p for t in bake.trees for p in (t.points, t.twigs.start,
                                                            t.twigs.end)])
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    reach = max(t.height for t in bake.trees) if bake.trees else 1.0
    moving = [t.positions.reshape(-1, 3) for t in bake.trees if not t.static]
    if moving:
        pts = np.concatenate(moving)
        lo = np.maximum(np.minimum(lo, pts.min(axis=0)), lo - reach)
        hi = np.minimum(np.maximum(hi, pts.max(axis=0)), hi + reach)
    lo = lo.copy()
    lo[2] = min(lo[2], 0.0)
    return lo, hi


def frame_view(bake, f: int, size: int, bounds) -> Image.Image:
    s, e, w, leafy = posed_segments(bake, f)
    title = f"{bake.meta.get('scene', '')}  frame {f + 1}  t = {float(bake.times[f]):.2f} s"
    return draw_views(s, e, w, leafy, size, bounds=bounds, title=title)


def contact_sheet(bake, columns: int = 4, rows: int = 3, size: int = 256,
                  progress=None) -> Image.Image:
    """columns x rows frames, evenly spaced from first to last, each front
    and side, on one image with the same framing."""
    n = len(bake.times)
    cells = min(columns * rows, n)
    frames = np.unique(np.round(np.linspace(0, n - 1, cells)).astype(int))
    bounds = bake_bounds(bake)
    first = frame_view(bake, int(frames[0]), size, bounds)
    cw, ch = first.size
    cols = min(columns, len(frames))
    sheet = Image.new("RGB", (cols * cw, int(np.ceil(len(frames) / cols)) * ch), BACKGROUND)
    for k, f in enumerate(frames):
        img = first if k == 0 else frame_view(bake, int(f), size, bounds)
        sheet.paste(img, ((k % cols) * cw, (k // cols) * ch))
        if progress is not None:
            progress(k + 1, len(frames))
    return sheet


def animated_gif(bake, size: int = 256, max_frames: int = 120, progress=None) -> bytes:
    """The bake as a looping GIF (front and side), every stride-th frame so
    at most `max_frames` are drawn; played at the bake's speed."""
    import io

    n = len(bake.times)
    stride = max(1, int(np.ceil(n / max_frames)))
    frames = list(range(0, n, stride))
    bounds = bake_bounds(bake)
    images = []
    for k, f in enumerate(frames):
        images.append(frame_view(bake, f, size, bounds).quantize(colors=64, method=2, dither=0))
        if progress is not None:
            progress(k + 1, len(frames))
    buf = io.BytesIO()
    delay = max(20, round(1000.0 * stride / bake.fps / 10.0) * 10)  # GIF ticks are 10 ms
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=delay,
                   loop=0, optimize=False)
    return buf.getvalue()

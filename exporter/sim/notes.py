"""The planar LOD's runs, summed: one record of counts per engine, and the
bake's notes in words — each kind once, with the counts of every run."""

from __future__ import annotations

from .common import cap_note
from .handoff import Engine, TierReport
from .linear import BLAST_SPLIT, ERROR_TOLERANCE
from .rules import MAX_SPIN, broken_note

SMALLEST = ("step", "substep", "force_interval", "stability")  # per run: the finest


def merge_stats(stats: list[dict]) -> dict:
    """Several runs' counts as one: numbers add up, `max_*` and `dofs` take
    the largest, SMALLEST the smallest, lists join, `first_limit` and
    `closest_to_breaking` keep the earliest and the closest, dicts of counts
    add up key by key."""
    out: dict = {}
    for st in stats:
        for key, value in st.items():
            if key not in out:
                out[key] = dict(value) if isinstance(value, dict) else \
                    list(value) if isinstance(value, list) else value
            elif key == "first_limit":
                if value is not None and (out[key] is None or value[2] < out[key][2]):
                    out[key] = value
            elif key == "closest_to_breaking":
                out[key] = max(out[key], value, key=lambda c: c["fraction"])
            elif isinstance(value, dict):
                for k, v in value.items():
                    out[key][k] = out[key].get(k, 0) + v
            elif isinstance(value, list):
                out[key] += value
            elif key.startswith("max_") or key == "dofs":
                out[key] = max(out[key], value)
            elif key in SMALLEST:
                out[key] = min(out[key], value)
            else:
                out[key] += value
    return out


def lod_notes(stats: dict[str, dict], reports: list[TierReport], returned: int) -> list[str]:
    """What the LOD's engines adapted, clamped or broke, in words (never
    silently): `stats` per engine (merge_stats of its runs), the runs'
    own notes once each, and how many trees came back to the linear tier."""
    lin, pym, ref = (stats.get(e.value) for e in Engine)
    notes = []
    limited = [s for s in (lin, pym, ref) if s and s["limited"]]
    if limited:
        first = min((s["first_limit"] for s in limited), key=lambda f: f[2])
        notes.append(cap_note(sum(s["limited"] for s in limited), first))
    if lin:
        notes += linear_notes(lin)
    if pym:
        notes += pymunk_notes(pym)
    notes += list(dict.fromkeys(n for r in reports for n in r.notes))
    if ref:
        from .reference.solver import count_notes

        notes += count_notes(ref)
    broke = broken_note({"reference": ref["broken"] if ref else 0,
                         "pymunk tier": pym["broken"] if pym else 0})
    if broke:
        notes.append(broke)
    if returned:
        notes.append(f"trees came back to the linear tier {returned} time"
                     f"{'s' if returned > 1 else ''}, back in its range")
    return notes


def linear_notes(st: dict) -> list[str]:
    """The linear tier's split steps (blasts, accuracy)."""
    notes = []
    if st["split"]:
        notes.append(f"linear tier: {st['split']} steps split in {BLAST_SPLIT} while a blast "
                     "pushed")
    if st["refined"]:
        t, tree, path, error = min(st["refined"])
        notes.append(f"linear tier: steps split in up to {st['max_parts']} for accuracy from "
                     f"t = {t:.3f} s (the step's error estimate at {tree} {path}: {error:.2%} "
                     f"of its height, past {ERROR_TOLERANCE:.2%})")
    return notes


def pymunk_notes(st: dict) -> list[str]:
    """The pymunk tier's stability floor, split steps and debris spin clamp."""
    notes = []
    if st["inertia_floored"]:
        notes.append(f"pymunk tier: {st['inertia_floored']} of {st['bodies']} bodies made "
                     f"harder to turn (rotary inertia up to {st['max_inertia_ratio']:.1f}x) to "
                     f"stay stable at {st['substep'] * 1e3:.3f} ms steps (omega*h <= "
                     f"{st['stability']:g}; docs/physics.md, \"Stability\")")
    if st["refined"]:
        causes = " or ".join(st["refined_by"]) or "an impulsive load"
        notes.append(f"pymunk tier: {st['refined']} substeps split into up to "
                     f"{st['max_refine']} steps while {causes} acted (pivots drift with the "
                     "square of the step)")
    if st["debris_clamped"]:
        notes.append(f"pymunk tier: debris spin clamped at {MAX_SPIN:.0f} rad/s on "
                     f"{st['debris_clamped']} body substeps")
    return notes

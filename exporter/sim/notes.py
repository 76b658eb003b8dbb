"""The planar LOD's runs, summed into its result: each tree's motion and
engines, one record of counts per engine, the timings, and the bake's notes
in words — each kind once, with the counts of every run."""

from __future__ import annotations

import numpy as np

from ..quality import Quality
from ..scene import Scene
from .common import SimTree, cap_note
from .handoff import Engine, Reason, TierReport, spans_text
from .linear import BLAST_SPLIT, ERROR_TOLERANCE
from .rules import MAX_SPIN, broken_note
from .solver import SolveResult, frame_timing

SMALLEST = ("step", "substep", "force_interval", "stability")  # per run: the finest


# the reference's description of its model, the same on every bake that uses
# it (reference/solver.engine_notes' first two): the bake's notes keep it, its
# log does not repeat it
DESCRIPTIONS = ("reference: MuJoCo ", "reference: joints are two perpendicular hinges")


def log_lines(notes: list[str]) -> list[str]:
    """The notes a bake's log shows: all but the model's description."""
    return [n for n in notes if not n.startswith(DESCRIPTIONS)]


def solve_result(trees: list[SimTree], plan: list[tuple[Quality, list[int]]], results: list,
                 scene: Scene) -> SolveResult:
    """The planar LOD's SolveResult from its chunks' results (scheduler.
    ChunkResult, in `plan`'s order; a motion already taken is None)."""
    motions, tiers = {}, {}
    for (_, members), res in zip(plan, results):
        for i, motion, spans in zip(members, res.motions, res.spans):
            if motion is not None:
                motions[trees[i].name] = motion
            tiers[trees[i].name] = spans_text(spans)
    reports = [r for res in results for r in res.reports]
    returned = sum(s.reason is Reason.BACK for res in results for spans in res.spans
                   for s in spans)
    meta, notes = summarise(reports, returned)
    meta["chunks"] = len(plan)
    objects = next((res.objects for res in results if res.objects is not None), None)
    return SolveResult(motions, objects, meta, notes, tiers, timing_of(reports, scene))


def summarise(reports: list[TierReport], returned: int) -> tuple[dict, list[str]]:
    """The bake's meta (each engine's counts summed over its runs; breaks,
    debris and returns over all) and its notes."""
    by_engine = {e: [r for r in reports if r.engine is e] for e in Engine}
    stats = {e.value: merge_stats([r.stats for r in rs]) for e, rs in by_engine.items() if rs}
    lin, pym, ref = (stats.get(e.value) for e in Engine)
    meta: dict = {"runs": {e.value: len(rs) for e, rs in by_engine.items() if rs}}
    if lin:
        meta["linear_step"] = lin["step"]
    if pym:
        meta["substep"], meta["force_interval"] = pym["substep"], pym["force_interval"]
    if ref:
        meta["reference_step"] = ref["step"]
    meta["stats"] = {"broken": (ref["broken"] if ref else 0) + (pym["broken"] if pym else 0),
                     "debris": (ref["parts"] if ref else 0) + (pym["debris"] if pym else 0),
                     "returned": returned, **stats}
    if ref and "closest_to_breaking" in ref:
        meta["stats"]["closest_to_breaking"] = ref["closest_to_breaking"]
    return meta, lod_notes(stats, reports, returned)


def timing_of(reports: list[TierReport], scene: Scene) -> dict:
    """Seconds spent stepping and updating (loads, checks, events) over all
    runs, per-frame costs of the linear and pymunk tiers, and the simulated
    segment-steps."""
    step = sum(r.timing.get("step_seconds", 0.0) for r in reports)
    update = sum(r.timing.get("update_seconds", 0.0) + r.timing.get("compile_seconds", 0.0)
                 for r in reports)
    frame_seconds = np.zeros(scene.frame_count - 1)
    for r in reports:
        f = r.timing.get("frame_seconds")
        if f is not None and len(f):  # a tier started late covers the last frames
            f = np.asarray(f[-len(frame_seconds):])
            frame_seconds[len(frame_seconds) - len(f):] += f
    engines = {e.value: {"cpu_seconds": round(sum(r.timing["cpu_seconds"] for r in rs), 3),
                         "segment_frames": sum(r.timing["segment_frames"] for r in rs)}
               for e in Engine if (rs := [r for r in reports if r.engine is e])}
    return {"engines": engines, "step_seconds": round(step, 3), "update_seconds": round(update, 3),
            "build_seconds": round(sum(r.timing.get("build_seconds", 0.0) for r in reports), 3),
            "segment_steps": sum(r.timing.get("segment_steps", 0) for r in reports),
            **frame_timing(frame_seconds, 1)}


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
        pruned = ref.get("returned_broken", 0) if ref else 0
        notes.append(f"trees came back to the linear tier {returned} time"
                     f"{'s' if returned > 1 else ''}, back in its range"
                     + (f"; {pruned} of them without the parts that broke off, which lie "
                        "where they came to rest" if pruned else ""))
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

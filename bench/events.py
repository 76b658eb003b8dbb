"""Events on both solvers: does a cut, a hit or a blast create energy?

For each preset (felling, boxes, explosion; hurricane and tornado when asked)
and the 50 kg blast at 3 m from a sapling,
bake with the planar LOD and with the MuJoCo reference and measure from the
bakes alone (independent of either solver's bookkeeping):

- energy proxy: kinetic + gravitational energy of the segment midpoints,
  mass ~ width^2 x length (solid cylinders, unit density), per tree, as a
  ratio to the tree's energy at frame 0 measured from the lowest point it
  reaches (so a tree that only falls stays <= 1);
- centre of mass of the tree (its height at the event and the highest it
  reaches after);
- the events (cut, hinge snap, breaks), broken joints, how far parts land;
- peak displacement of any segment end (% of height), and the tree's peak
  sway: of the segments still joined to the stump at the end (a broken
  twig's fall dominates the first);
- felling: time from the cut to the stem touching the ground, resting
  azimuth of the stem; boxes: the highest point a box reaches after a hit.

    python bench/events.py [--cases felling boxes explosion blast hurricane tornado]
                           [--solvers planar full]
                           [--timestep 1/64000]   # the full reference's step (s)
                           [--quality final]      # the LOD's level (default: the scene's)
                           [--engine pymunk]      # the LOD's engine for every reason

A blast on a sapling is the case to convergence-check (`--timestep`): the
reference's peak twig moments ("closest to breaking", the largest moment /
strength any joint reached on the reference) depend on its step; the joints
broken (15 at 1/2000 s, 16-17 at 1/8000-1/32000 s) much less.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treebake.accuracy import event_metrics  # noqa: E402
from treebake.pipeline import bake_scene  # noqa: E402
from treebake.quality import QUALITIES  # noqa: E402
from treebake.scene import load_scene, parse_scene  # noqa: E402
from treebake.sim.events import Event  # noqa: E402
from treebake.sway import segment_ends  # noqa: E402

G = 9.81


def tree_energy(tree, fps: float) -> dict:
    """Energy proxy and centre of mass per frame of one baked tree."""
    ends = segment_ends(tree, np.arange(tree.n_segments))
    mids = 0.5 * (tree.positions + ends)
    length = np.linalg.norm(tree.points[tree.seg_end] - tree.points[tree.seg_start], axis=1)
    mass = np.pi / 4 * tree.width**2 * length
    v = np.gradient(mids, axis=0) * fps if len(mids) > 2 else np.zeros_like(mids)
    ke = 0.5 * (mass[None, :, None] * v * v).sum(axis=(1, 2))
    com = (mass[None, :, None] * mids).sum(1) / mass.sum()
    pe = mass.sum() * G * (com[:, 2] - min(0.0, float(mids[..., 2].min())))
    e = ke + pe
    return {"energy": e, "ratio": e / max(e[0], 1e-12), "com": com, "mids": mids}


def still_attached(tb, events) -> np.ndarray:
    """Segments (S,) bool still joined to the stump at the end: neither a
    broken joint's segment nor anything it carries, and the tree not
    uprooted."""
    gone = np.zeros(tb.n_segments, dtype=bool)
    if any(e["kind"] == "uprooted" for e in events):
        return ~gone
    index = {p: s for s, p in enumerate(tb.paths)}
    for e in events:
        if e["kind"] == "broke" and e.get("segment") in index:
            gone[index[e["segment"]]] = True
    for s in range(tb.n_segments):  # parents come first
        p = tb.seg_parent[s]
        gone[s] |= p >= 0 and gone[p]
    return ~gone


def measure(bake, scene) -> dict:
    out = {"trees": []}
    for tb in bake.trees:
        if tb.static:
            continue
        en = tree_energy(tb, bake.fps)
        events = tb.info.get("events", [])
        broken = sum(1 for e in events if e["kind"] in ("broke", "uprooted"))
        base = tb.rest_base
        reach = float(np.linalg.norm(en["mids"][-1, :, :2] - base[0, :2], axis=1).max())
        moved = np.linalg.norm(segment_ends(tb, np.arange(tb.n_segments))
                               - tb.points[tb.seg_end], axis=-1)  # (F, S) m
        attached = still_attached(tb, events)
        out["trees"].append({
            "name": tb.name, "max_energy_ratio": round(float(en["ratio"].max()), 4),
            "at_frame": int(np.argmax(en["ratio"])),
            "com_start": round(float(en["com"][0, 2]), 3),
            "com_max_after_start": round(float(en["com"][1:, 2].max()), 3),
            "com_end": round(float(en["com"][-1, 2]), 3),
            "broken": broken, "events": [Event.from_record(e).text() for e in events][:6],
            "uprooted": sum(1 for e in events if e["kind"] == "uprooted"),
            "farthest_part_m": round(reach, 2),
            "peak_displacement_pct": round(100 * float(moved.max()) / tb.height, 2),
            # the tree's own sway: the parts still on it (a falling twig's
            # fall is not the blast's effect on the tree)
            "peak_sway_pct": round(100 * float(moved[:, attached].max(initial=0.0))
                                   / tb.height, 2),
            "audit": bake.meta.get("energy", {}).get(tb.name, {}),
            **{k: v for k, v in event_metrics(tb, bake.fps).items() if k != "broken"}})
    if bake.objects is not None:
        pos = bake.objects.positions.astype(float)
        out["objects_max_height_after_launch"] = [
            round(float(pos[:, i, 2].max()), 2) for i in range(pos.shape[1])]
    return out


CASES = {
    "felling": lambda: load_scene(ROOT / "presets" / "felling.toml"),
    "boxes": lambda: load_scene(ROOT / "presets" / "boxes.toml"),
    "explosion": lambda: load_scene(ROOT / "presets" / "explosion.toml"),
    # (wind that uproots: not in the default run)
    "hurricane": lambda: load_scene(ROOT / "presets" / "hurricane.toml"),
    "tornado": lambda: load_scene(ROOT / "presets" / "tornado.toml"),
    "blast": lambda: parse_scene({
        "name": "blast50", "duration": 5.0, "fps": 24.0,
        "tree": [{"grammar": str(ROOT / "grammars" / "sapling.lsys")}],
        "explosion": [{"position": [3.0, 0.0, 1.0], "time": 0.5, "charge": 50.0}]},
        file="<blast>"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*", default=["felling", "boxes", "explosion", "blast"],
                    choices=list(CASES))
    ap.add_argument("--solvers", nargs="*", default=["planar", "full"])
    ap.add_argument("--timestep", type=Fraction, default=None,
                    help="the full reference's step, s (e.g. 1/64000; default: its own)")
    ap.add_argument("--quality", choices=list(QUALITIES), default=None,
                    help="the planar LOD's level (default: the scene's own)")
    ap.add_argument("--engine", choices=["auto", "pymunk", "reference"], default="auto",
                    help="the planar LOD's nonlinear engine: auto (the engine table of "
                         "docs/physics.md), or pymunk or reference for every reason")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    args = ap.parse_args()
    level = QUALITIES[args.quality] if args.quality else None
    if args.engine != "auto":  # the presets' own level is `default`
        level = dataclasses.replace(level or QUALITIES["default"], nonlinear=args.engine)
    step = float(args.timestep) if args.timestep else None
    rows = []
    for case in args.cases:
        for solver in args.solvers:
            scene = CASES[case]()
            bake = bake_scene(scene, solver=solver, workers=1,
                              timestep=step if solver == "full" else None,
                              quality=level if solver == "planar" else None)
            m = measure(bake, scene)
            m.update(case=case, solver=solver, timestep=bake.meta.get("substep"),
                     quality=args.quality if solver == "planar" else None,
                     engine=args.engine if solver == "planar" else None)
            rows.append(m)
            label = solver
            if solver == "planar":
                label = " ".join([solver] + [x for x in (args.quality, args.engine)
                                             if x not in (None, "auto")])
            for t in m["trees"]:
                print(f"{case:<8} {label:<7} {t['name']:<8} energy x{t['max_energy_ratio']:<7.3f}"
                      f" (frame {t['at_frame']:>3})  COM z {t['com_start']:.2f} -> max "
                      f"{t['com_max_after_start']:.2f} -> end {t['com_end']:.2f}  broken "
                      f"{t['broken']:>3}  farthest {t['farthest_part_m']:.1f} m  peak "
                      f"{t['peak_displacement_pct']:.1f} % (sway {t['peak_sway_pct']:.1f} %)  "
                      "audit gain "
                      f"{t['audit'].get('max_gain_fraction', 0):.2%}", flush=True)
                if "to_ground_s" in t:
                    print(f"{'':<17}stem on the ground {t['to_ground_s']:.3f} s after the cut, "
                          f"resting azimuth {t['azimuth_deg']:.1f} deg")
                for e in t["events"]:
                    print(f"{'':<17}{e}")
            if len(m["trees"]) > 4:
                gains = [t["audit"].get("max_gain_fraction", 0) for t in m["trees"]]
                print(f"{case:<8} {label:<7} all      broken {sum(t['broken'] for t in m['trees'])}"
                      f" (uprooted {sum(t['uprooted'] for t in m['trees'])})  worst audit gain "
                      f"{max(gains):.2%}", flush=True)
            closest = bake.meta.get("stats", {}).get("closest_to_breaking")
            m["closest_to_breaking"] = closest
            if closest:  # the reference's (the LOD's tiers do not keep it)
                print(f"{'':<17}closest to breaking: {closest['fraction']:.3f} of strength at "
                      f"{closest['tree']} {closest['segment']}, t = {closest['time_s']:.3f} s")
            if "objects_max_height_after_launch" in m:
                print(f"{'':<17}objects' highest points: {m['objects_max_height_after_launch']}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = f"events-{args.timestep}".replace("/", "_") if args.timestep else "events"
    if args.quality:
        name += f"-{args.quality}"
    if args.engine != "auto":
        name += f"-{args.engine}"
    (out / f"{name}.json").write_text(json.dumps(rows, indent=2, default=str) + "\n")


if __name__ == "__main__":
    main()

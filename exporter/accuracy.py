"""Error against run time: the planar LOD (and the reference at coarser
steps) measured against the full 3D reference at a fine step.

For each case (a species in a scenario) the truth is the reference at
TRUTH_STEP. Every setting then bakes the same case, in the same process,
and is compared with the truth:

- position error of every segment's end over all frames (RMS and max), as
  % of the tree's height; RMS rotation error (degrees); the ratio of the
  dominant sway frequency of the main stem's top to the truth's;
- cost: CPU seconds per simulated second, microseconds per segment-step
  (segments x the setting's own steps);
- for LOD settings, the split of the error into a model part (the same
  model at a fine step against the truth) and a time-step part (the setting
  against that fine run).

`treebake accuracy` writes out/accuracy/report.md, report.json and plot.png
(error against cost, log axes, the Pareto front drawn).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .bake import Bake
from .errors import SimulationError
from .fileio import atomic_path, write_text
from .library import grammars_folder
from .pipeline import bake_scene, grow
from .rotations import angle_between
from .scene import Scene, parse_scene
from .sim.quality import QUALITIES, Quality
from .sway import segment_ends

TRUTH_STEP = 1 / 4000  # s

SCENARIOS = {  # name: scene keys around one tree at the origin
    "calm": {"prestress": False},  # gravity switched on at t = 0: sag and settle
    "breeze": {"wind": {"beaufort": "moderate breeze", "turbulence": 0.2, "ramp": 1.0}},
    "gusty": {"wind": {"beaufort": "fresh breeze", "turbulence": 0.35, "ramp": 1.0}},
    "gale": {"wind": {"beaufort": "gale", "turbulence": 0.25, "ramp": 1.0}},
    "boxes": {"projectile": [{"shape": "box", "size": 0.3, "mass": 8.0,
                              "position": [-5.0, 0.0, 1.2], "velocity": [8.0, 0.0, 1.5],
                              "time": 0.3}]},
    "explosion": {"explosion": [{"position": [15.0, 0.0, 1.0], "time": 0.3, "charge": 2.0}]},
}

SPECIES = {"sapling": "grammars/sapling.lsys", "palm": "grammars/palm.lsys",
           "broadleaf": "grammars/forest/broadleaf.lsys",
           "conifer": "grammars/forest/conifer.lsys", "oak": "grammars/oak.lsys"}


def _q(base: str, **kw) -> Quality:
    return replace(QUALITIES[base], name="custom", **kw)


# the LOD settings compared; the named levels are among them
LOD_SETTINGS = {
    "draft": QUALITIES["draft"],
    "default": QUALITIES["default"],
    "final": QUALITIES["final"],
    "480Hz p1 it6": _q("default", substep_rate=480.0, force_rate=60.0, iterations=6, planes=1),
    "960Hz p1 it6": _q("default", force_rate=120.0, iterations=6, planes=1),
    "960Hz p1 it10": _q("default", planes=1),
    "960Hz p2 it10 f60": _q("default", force_rate=60.0),
    "1920Hz p2 it10": _q("default", substep_rate=1920.0, force_rate=240.0),
    "default rigid": _q("default", coupling="rigid"),
    "default bones 0": _q("default", bone_length=0.0),
    "default bones 1/12": _q("default", bone_length=1 / 12),
}
REFERENCE_STEPS = {"reference 1/2000": 1 / 2000, "reference 1/1000": 1 / 1000,
                   "reference 1/480": 1 / 480}


@dataclass
class Run:
    case: str
    setting: str
    solver: str
    cpu_per_sim_second: float  # CPU s per simulated s
    us_per_segment_step: float
    rms_position_pct: float  # % of tree height
    max_position_pct: float
    rms_angle_deg: float
    frequency_ratio: float  # dominant sway frequency / truth's
    model_rms_pct: float = math.nan  # LOD: the model at a fine step vs truth
    step_rms_pct: float = math.nan  # LOD: this setting vs the model at a fine step
    error: str = ""  # the SimulationError, if the run failed


def unbreakable(species: str, folder: Path) -> Path:
    """The species' grammar without breaking (no rupture, strength or
    anchor): a break is a branching event, after which two runs need not
    follow each other at all, so errors would measure chaos, not accuracy."""
    src = (grammars_folder().parent / SPECIES[species]).read_text().splitlines()
    keep = [ln for ln in src if not ln.split(":")[0].strip() in ("rupture", "strength", "anchor")]
    path = folder / f"{species}.lsys"
    path.write_text("\n".join(keep) + "\n")
    return path


def case_scene(species: str, scenario: str, duration: float, folder: Path,
               fps: float = 30.0) -> Scene:
    raw = {"name": f"{species}-{scenario}", "duration": duration, "fps": fps,
           "tree": [{"grammar": str(unbreakable(species, folder))}], **SCENARIOS[scenario]}
    return parse_scene(raw, file=f"<accuracy {species} {scenario}>")


def _ends(bake: Bake) -> np.ndarray:
    t = bake.trees[0]
    ends = segment_ends(t, np.arange(t.n_segments))
    if t.static:
        ends = np.repeat(ends, len(bake.times), axis=0)
    return ends


def _rotations(bake: Bake) -> np.ndarray:
    r = bake.trees[0].rotations.astype(float)
    return np.repeat(r, len(bake.times), axis=0) if r.shape[0] == 1 else r


def errors(a: Bake, truth: Bake) -> tuple[float, float, float]:
    """RMS and max position error (% of height) and RMS rotation error (deg)."""
    height = max(truth.trees[0].height, 1e-9)
    d = np.linalg.norm(_ends(a) - _ends(truth), axis=-1)
    ang = np.degrees(angle_between(_rotations(a), _rotations(truth)))
    return (100 * float(np.sqrt(np.mean(d * d))) / height, 100 * float(d.max()) / height,
            float(np.sqrt(np.mean(ang * ang))))


def dominant_frequency(bake: Bake, stem_top: int) -> float:
    """Peak of the main stem top's horizontal motion spectrum (Hz)."""
    x = segment_ends(bake.trees[0], [stem_top])[:, 0, :2]
    if len(x) < 8:
        return math.nan
    x = x - x.mean(axis=0)
    _u, _s, vt = np.linalg.svd(x, full_matrices=False)
    y = x @ vt[0]
    y = (y - y.mean()) * np.hanning(len(y))
    n = 8 * len(y)
    spec = np.abs(np.fft.rfft(y, n))
    freqs = np.fft.rfftfreq(n, 1.0 / bake.fps)
    spec[freqs < 0.1] = 0
    return float(freqs[int(np.argmax(spec))]) if spec.max() > 0 else math.nan


def _timed(scene: Scene, **kw) -> tuple[Bake, float]:
    start = time.process_time()
    bake = bake_scene(scene, **kw)
    return bake, time.process_time() - start


def _steps(setting: Quality | float, scene: Scene) -> float:
    """The setting's own steps per simulated second."""
    if isinstance(setting, Quality):
        spf = max(1, round(setting.substep_rate / scene.fps))
        return spf * scene.fps
    return 1.0 / setting


def run_case(species: str, scenario: str, duration: float, lod: dict[str, Quality],
             reference: dict[str, float], log=None) -> list[Run]:
    log = log or (lambda msg: None)
    with tempfile.TemporaryDirectory() as tmp:
        return _run_case(species, scenario, case_scene(species, scenario, duration, Path(tmp)),
                         duration, lod, reference, log)


def _run_case(species, scenario, scene, duration, lod, reference, log) -> list[Run]:
    model = grow(scene)[0].model
    segments = model.n_segments
    stem_top = model.main_stem()[-1]
    truth, _ = _timed(scene, solver="full", timestep=TRUTH_STEP)
    f_truth = dominant_frequency(truth, stem_top)
    runs = []

    def failed(name, solver, exc):
        log(f"  {species}/{scenario:<14} {name:<20} FAILED: {exc}")
        runs.append(Run(f"{species}/{scenario}", name, solver, math.nan, math.nan, math.inf,
                        math.inf, math.inf, math.nan, error=str(exc)))

    def record(name, solver, bake, cpu, steps, **extra):
        rms, mx, ang = errors(bake, truth)
        f = dominant_frequency(bake, stem_top)
        run = Run(f"{species}/{scenario}", name, solver, cpu / duration,
                  1e6 * cpu / (segments * steps * duration), rms, mx, ang,
                  f / f_truth if f_truth and not math.isnan(f_truth) else math.nan, **extra)
        log(f"  {run.case:<22} {name:<20} {rms:8.3f} % rms {mx:8.3f} % max "
            f"{run.cpu_per_sim_second:7.3f} cpu s/s")
        runs.append(run)

    for name, step in reference.items():
        try:
            bake, cpu = _timed(scene, solver="full", timestep=step)
        except SimulationError as exc:
            failed(name, "full", exc)
            continue
        record(name, "full", bake, cpu, _steps(step, scene))
    fine_cache: dict[tuple, Bake | None] = {}
    for name, q in lod.items():
        try:
            bake, cpu = _timed(scene, quality=q)
        except SimulationError as exc:
            failed(name, "planar", exc)
            continue
        key = (q.planes, q.bone_length, q.coupling, q.iterations)
        if key not in fine_cache:
            fine = replace(q, substep_rate=q.substep_rate * 4, force_rate=q.force_rate * 4,
                           iterations=max(q.iterations, 20))
            try:
                fine_cache[key] = bake_scene(scene, quality=fine)
            except SimulationError:
                fine_cache[key] = None
        model_rms = errors(fine_cache[key], truth)[0] if fine_cache[key] else math.nan
        step_rms = errors(bake, fine_cache[key])[0] if fine_cache[key] else math.nan
        record(name, "planar", bake, cpu, _steps(q, scene), model_rms_pct=model_rms,
               step_rms_pct=step_rms)
    return runs


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both cost and error."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def summarise(runs: list[Run]) -> list[dict]:
    """Per setting: median cost and error over the cases."""
    out = []
    for name in dict.fromkeys(r.setting for r in runs):
        rs = [r for r in runs if r.setting == name]

        def med(field, rs=rs):
            vals = [getattr(r, field) for r in rs if not math.isnan(getattr(r, field))]
            return float(np.median(vals)) if vals else math.nan

        out.append({"setting": name, "solver": rs[0].solver, "cases": len(rs),
                    "failed": sum(1 for r in rs if r.error),
                    "cpu_per_sim_second": med("cpu_per_sim_second"),
                    "us_per_segment_step": med("us_per_segment_step"),
                    "rms_position_pct": med("rms_position_pct"),
                    "max_position_pct": med("max_position_pct"),
                    "worst_rms_position_pct": max(r.rms_position_pct for r in rs),
                    "rms_angle_deg": med("rms_angle_deg"),
                    "frequency_ratio": med("frequency_ratio"),
                    "model_rms_pct": med("model_rms_pct"), "step_rms_pct": med("step_rms_pct")})
    return out


def report_markdown(summary: list[dict], runs: list[Run], meta: dict) -> str:
    lines = ["# Accuracy: the planar LOD against the full 3D reference", "",
             (f"Truth: the MuJoCo reference at {meta['truth_step']:.6g} s. Cases: "
             f"{', '.join(meta['cases'])}; {meta['duration']} s each. Medians over the cases "
             "(worst case in its own column). Position errors are of every segment's end, as % "
             "of the tree's height; cost is CPU time in this process, one core."), "",
             ("| setting | solver | CPU s per sim s | us / segment-step | RMS pos % | worst RMS % "
             "| max pos % | RMS rot deg | f / f_truth | model part % | step part % | failed |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        lines.append(
            f"| {s['setting']} | {s['solver']} | {s['cpu_per_sim_second']:.3g} | "
            f"{s['us_per_segment_step']:.3g} | {s['rms_position_pct']:.3g} | "
            f"{s['worst_rms_position_pct']:.3g} | {s['max_position_pct']:.3g} | "
            f"{s['rms_angle_deg']:.3g} | {s['frequency_ratio']:.3g} | "
            f"{s['model_rms_pct']:.3g} | {s['step_rms_pct']:.3g} | {s['failed']} |")
    lines += ["", "## Every run", "",
              "| case | setting | CPU s/s | RMS pos % | max pos % | RMS rot deg | f ratio |",
              "|---|---|---|---|---|---|---|"]
    for r in runs:
        lines.append(f"| {r.case} | {r.setting} | {r.cpu_per_sim_second:.3g} | "
                     f"{r.rms_position_pct:.3g} | {r.max_position_pct:.3g} | "
                     f"{r.rms_angle_deg:.3g} | {r.frequency_ratio:.3g} |")
    return "\n".join(lines) + "\n"


def plot(summary: list[dict], path: Path) -> Path | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    pts = [(s["cpu_per_sim_second"], max(s["rms_position_pct"], 1e-6)) for s in summary]
    front = pareto(pts)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for s, (x, y) in zip(summary, pts):
        marker = "s" if s["solver"] == "full" else "o"
        ax.scatter([x], [y], marker=marker, color="tab:red" if s["solver"] == "full"
                   else "tab:blue")
        ax.annotate(s["setting"], (x, y), fontsize=7, xytext=(4, 3), textcoords="offset points")
    fx = [pts[i][0] for i in front]
    fy = [pts[i][1] for i in front]
    ax.step(fx, fy, where="post", color="0.4", lw=1, ls="--", label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU seconds per simulated second (median over cases)")
    ax.set_ylabel("RMS position error, % of tree height (median)")
    ax.set_title("planar LOD (circles) and reference (squares) vs the fine reference")
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
    plt.close(fig)
    return path


def accuracy(out: str | Path = "out/accuracy", species: list[str] | None = None,
             scenarios: list[str] | None = None, duration: float = 5.0,
             lod: dict[str, Quality] | None = None, reference: dict[str, float] | None = None,
             log=None) -> dict:
    """Run every case and write the report; returns its JSON content."""
    species = species or ["sapling", "broadleaf", "conifer"]
    scenarios = scenarios or list(SCENARIOS)
    lod = LOD_SETTINGS if lod is None else lod
    reference = REFERENCE_STEPS if reference is None else reference
    runs: list[Run] = []
    cases = []
    for sp in species:
        for sc in scenarios:
            cases.append(f"{sp}/{sc}")
            runs += run_case(sp, sc, duration, lod, reference, log)
    summary = summarise(runs)
    meta = {"truth_step": TRUTH_STEP, "cases": cases, "duration": duration,
            "settings": {k: asdict(v) for k, v in lod.items()}, "reference_steps": reference}
    data = {"meta": meta, "summary": summary, "runs": [asdict(r) for r in runs]}
    out = Path(out)
    write_text(out / "report.json", json.dumps(data, indent=2) + "\n")
    write_text(out / "report.md", report_markdown(summary, runs, meta))
    plot(summary, out / "plot.png")
    return data

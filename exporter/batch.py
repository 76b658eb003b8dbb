"""Batch bakes: many jobs from one job file, in parallel worker processes
(or on a Dask cluster), resumable, each output written atomically.

A job is a scene (or a grammar baked alone, or a grammar placed in a
scene's forces) with overrides and export formats; docs/batch.md describes
the job file. A finished job leaves `job.json` in its folder, written last:
its `hash` covers the tool version, the job's settings and the content of
every input file, so a rerun skips jobs whose inputs did not change and
redoes the rest. Files appear only when complete (temporary name, then
rename), so a killed batch leaves no half-written file and resumes cleanly.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import queue as queue_module
import re
import time
import tomllib
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from .errors import InputError, SceneError, TreebakeError
from .fileio import write_text

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
QUALITY_NAMES = ("draft", "default", "final")
JOB_KEYS = {"name", "scene", "grammar", "seed", "seeds", "quality", "formats", "duration", "fps",
            "wind", "solver"}


@dataclass(frozen=True)
class Job:
    """One bake. `scene` and/or `grammar` are absolute paths; with both, the
    grammar's tree stands alone in the scene's forces."""

    name: str
    scene: str | None = None
    grammar: str | None = None
    seed: int | None = None
    quality: str | None = None
    formats: tuple[str, ...] = ("glb",)
    duration: float | None = None
    fps: float | None = None
    wind: float | None = None  # m/s at 10 m
    solver: str = "planar"

    def inputs(self) -> list[Path]:
        """Every file the job reads: the scene, its grammars, the grammar."""
        files = []
        if self.scene:
            from .scene import load_scene

            files.append(Path(self.scene))
            if not self.grammar:
                files += sorted({Path(t.grammar) for t in load_scene(self.scene).trees})
        if self.grammar:
            files.append(Path(self.grammar))
        return files

    def digest(self) -> str:
        """Hash of the tool version, the settings and the inputs' content."""
        h = hashlib.sha256(f"treebake {__version__}\n".encode())
        h.update(json.dumps({k: v for k, v in asdict(self).items() if k != "name"},
                            sort_keys=True).encode())
        for path in self.inputs():
            h.update(path.name.encode())
            h.update(path.read_bytes())
        return h.hexdigest()


# ---------------------------------------------------------------------------
# job files


def _fail(file: str, key: str, message: str) -> SceneError:
    return SceneError(key, message, file)


def _check_name(file: str, key: str, name: str) -> str:
    """Output names stay inside the output folder: one plain path component."""
    if not isinstance(name, str) or not NAME.match(name) or name in (".", ".."):
        raise _fail(file, key, f"= {name!r} must be a plain name of letters, digits, '.', '_' "
                               "or '-' (it names a folder inside the output folder; no '/', "
                               "'..' or absolute paths)")
    return name


def _path(file: str, base: Path, key: str, value: Any) -> str:
    if not isinstance(value, str):
        raise _fail(file, key, f"must be a path string, got {value!r}")
    p = (base / value).resolve()
    if not p.is_file():
        raise _fail(file, key, f"file not found: {p}")
    return str(p)


def _job(file: str, base: Path, raw: dict, key: str, defaults: dict) -> list[Job]:
    if not isinstance(raw, dict):
        raise _fail(file, key, "must be a table")
    for k in raw:
        if k not in JOB_KEYS:
            raise _fail(file, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(JOB_KEYS))})")
    data = {**defaults, **raw}
    scene = _path(file, base, f"{key}.scene", data["scene"]) if "scene" in data else None
    grammar = _path(file, base, f"{key}.grammar", data["grammar"]) if "grammar" in data else None
    if scene is None and grammar is None:
        raise _fail(file, key, "needs a scene or a grammar")
    default_name = Path(grammar or scene).stem
    if scene and grammar:
        default_name = f"{Path(grammar).stem}-{Path(scene).stem}"
    name = _check_name(file, f"{key}.name", data.get("name", default_name))
    quality = data.get("quality")
    if quality is not None and quality not in QUALITY_NAMES:
        raise _fail(file, f"{key}.quality", f"= {quality!r} is not one of: "
                                            f"{', '.join(QUALITY_NAMES)}")
    formats = data.get("formats", ["glb"])
    if isinstance(formats, str):
        formats = [formats]
    from .export import parse_formats

    try:
        formats = parse_formats(formats)
    except InputError as exc:
        raise _fail(file, f"{key}.formats", str(exc)) from None
    solver = data.get("solver", "planar")
    if solver not in ("planar", "full"):
        raise _fail(file, f"{key}.solver", f"= {solver!r} is not one of: planar, full")
    numbers = {}
    for k, lo, hi in (("duration", 0.0, 3600.0), ("fps", 1.0, 1000.0), ("wind", 0.0, 120.0)):
        if k in data:
            v = data[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise _fail(file, f"{key}.{k}", f"= {v!r} is out of range [{lo:g}, {hi:g}]")
            numbers[k] = float(v)
    seeds = data.get("seeds", [data["seed"]] if "seed" in data else [None])
    if not isinstance(seeds, list) or not all(s is None or (isinstance(s, int) and s >= 0)
                                              for s in seeds) or not seeds:
        raise _fail(file, f"{key}.seeds", f"must be a list of whole numbers >= 0, got {seeds!r}")
    jobs = []
    for seed in seeds:
        suffix = f"-s{seed}" if len(seeds) > 1 else ""
        jobs.append(Job(name + suffix, scene, grammar, seed, quality, tuple(formats),
                        numbers.get("duration"), numbers.get("fps"), numbers.get("wind"),
                        solver))
    return jobs


def load_jobs(path: str | Path) -> list[Job]:
    """Read a job file: `[defaults]`, `[[job]]` tables and `[[product]]`
    tables (grammars x scenes x seeds). Every key is checked."""
    p = Path(path)
    file = str(p)
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise _fail(file, "(file)", f"cannot read job file: {exc.strerror}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise _fail(file, "(syntax)", str(exc)) from None
    for k in raw:
        if k not in ("defaults", "job", "product"):
            raise _fail(file, k, "unknown key (allowed: defaults, job, product)")
    defaults = raw.get("defaults", {})
    if not isinstance(defaults, dict):
        raise _fail(file, "defaults", "must be a table")
    for k in defaults:
        if k not in JOB_KEYS - {"name", "scene", "grammar"}:
            raise _fail(file, f"defaults.{k}", "unknown key")
    base = p.resolve().parent
    jobs: list[Job] = []
    for i, job in enumerate(_tables(file, raw, "job")):
        jobs += _job(file, base, job, f"job[{i}]", defaults)
    for i, prod in enumerate(_tables(file, raw, "product")):
        key = f"product[{i}]"
        allowed = {"grammars", "scenes", "seeds", "quality", "formats", "duration", "fps",
                   "solver"}
        for k in prod:
            if k not in allowed:
                raise _fail(file, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(allowed))})")
        grammars = prod.get("grammars") or [None]
        scenes = prod.get("scenes") or [None]
        if grammars == [None] and scenes == [None]:
            raise _fail(file, key, "needs grammars and/or scenes")
        rest = {k: v for k, v in prod.items() if k not in ("grammars", "scenes")}
        for g, s in itertools.product(grammars, scenes):
            one = dict(rest)
            if g is not None:
                one["grammar"] = g
            if s is not None:
                one["scene"] = s
            jobs += _job(file, base, one, key, defaults)
    if not jobs:
        raise _fail(file, "job", "the job file lists no jobs ([[job]] or [[product]])")
    seen: dict[str, int] = {}
    for j in jobs:
        if j.name in seen:
            raise _fail(file, "name", f"two jobs are named {j.name!r}: names must be unique "
                                      "(they are output folders)")
        seen[j.name] = 1
    return jobs


def _tables(file: str, raw: dict, key: str) -> list[dict]:
    v = raw.get(key, [])
    if isinstance(v, dict):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise _fail(file, key, f"must be an array of tables ([[{key}]])")
    return v


# ---------------------------------------------------------------------------
# running one job


@dataclass
class JobResult:
    name: str
    status: str  # "done", "skipped", "failed"
    seconds: float = 0.0
    message: str = ""
    files: list[str] = field(default_factory=list)
    frames: int = 0
    segments: int = 0


def scene_of(job: Job):
    """The Scene a job bakes (validated, overrides applied)."""
    from .scene import load_scene, parse_scene

    overrides = {k: v for k, v in (("duration", job.duration), ("fps", job.fps),
                                   ("quality", job.quality), ("wind.speed", job.wind))
                 if v is not None}
    if job.scene and not job.grammar:
        if job.seed is not None:
            overrides["seed"] = job.seed
        return load_scene(job.scene, overrides)
    tree = {"grammar": job.grammar}
    if job.seed is not None:
        tree["seed"] = job.seed
    if job.scene:
        raw = tomllib.loads(Path(job.scene).read_text(encoding="utf-8"))
        raw = {k: v for k, v in raw.items() if k not in ("tree", "forest", "cut", "pull")}
        raw["tree"] = [tree]
        base = Path(job.scene).parent
    else:
        raw = {"tree": [tree], "wind": {"speed": 6.7, "turbulence": 0.25}}
        base = Path(job.grammar).parent
    raw["name"] = job.name
    if "wind.speed" in overrides:
        raw["wind"] = {**raw.get("wind", {}), "speed": overrides.pop("wind.speed")}
        raw["wind"].pop("beaufort", None)
    raw.update(overrides)
    return parse_scene(raw, file=job.scene or job.grammar, base=base,
                       source_hash=job.digest())


def _clean_stale(folder: Path) -> None:
    """Temporary files a killed run left behind (`.name.xxxx.tmp`)."""
    if folder.is_dir():
        for tmp in folder.rglob(".*.tmp"):
            tmp.unlink(missing_ok=True)


def finished(job: Job, out: Path) -> bool:
    """The job's outputs exist and were made from the same inputs."""
    record = out / job.name / "job.json"
    try:
        data = json.loads(record.read_text())
    except (OSError, ValueError):
        return False
    if data.get("hash") != job.digest():
        return False
    return all((out / job.name / f).is_file() for f in data.get("files", []))


def run_job(job: Job, out: str, force: bool = False, progress=None) -> JobResult:
    """Bake and export one job into `out/<name>/`; never raises."""
    from .bake import save_bake
    from .export import ExportOptions, export_bake
    from .pipeline import bake_scene

    start = time.perf_counter()
    root = Path(out)
    folder = root / job.name
    try:
        if not force and finished(job, root):
            return JobResult(job.name, "skipped", message="up to date")
        _clean_stale(folder)
        (folder / "job.json").unlink(missing_ok=True)
        scene = scene_of(job)
        tick = None
        if progress is not None:
            def tick(done, total, name=job.name):
                progress(name, done, total)
        bake = bake_scene(scene, solver=job.solver, progress=tick)
        bake_path = save_bake(bake, folder / f"{job.name}.npz")
        files = [bake_path]
        exports = [f for f in job.formats if f != "npz"]
        if exports:
            report = export_bake(bake, root, job.name, ExportOptions(formats=tuple(exports)),
                                 bake_path=bake_path)
            files += report.files
        rel = sorted({p.resolve().relative_to(folder.resolve()).as_posix() for p in files})
        record = {"tool": f"treebake {__version__}", "job": asdict(job), "hash": job.digest(),
                  "files": rel}
        write_text(folder / "job.json", json.dumps(record, indent=2, sort_keys=True) + "\n")
        return JobResult(job.name, "done", time.perf_counter() - start, "", rel,
                         len(bake.times), sum(t.n_segments for t in bake.trees))
    except TreebakeError as exc:
        return JobResult(job.name, "failed", time.perf_counter() - start, str(exc))
    except Exception as exc:  # noqa: BLE001 - a job reports any failure, never stops the batch
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return JobResult(job.name, "failed", time.perf_counter() - start,
                         f"internal error: {type(exc).__name__}: {exc} "
                         f"({Path(last.filename).name}:{last.lineno})")


# ---------------------------------------------------------------------------
# running many


def run_batch(jobs: list[Job], out: str | Path, workers: int | None = None, force: bool = False,
              executor: str = "process", scheduler: str | None = None,
              report: Callable[[str, Any], None] | None = None) -> list[JobResult]:
    """Run the jobs; results in job order. `report(event, data)` receives
    ("start", name), ("progress", (name, done, total)), ("end", JobResult)."""
    out = str(Path(out))
    report = report or (lambda event, data: None)
    if executor == "dask":
        return _run_dask(jobs, out, force, scheduler, report)
    workers = workers or os.cpu_count() or 1
    if workers == 1:
        results = []
        for job in jobs:
            report("start", job.name)
            r = run_job(job, out, force, lambda *p: report("progress", p))
            report("end", r)
            results.append(r)
        return results
    return _run_processes(jobs, out, force, workers, report)


def _run_processes(jobs, out, force, workers, report) -> list[JobResult]:
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    ctx = mp.get_context("spawn")  # no inherited pymunk/numpy state, same as a fresh run
    manager = ctx.Manager()
    queue = manager.Queue()
    results: dict[str, JobResult] = {}
    try:
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            pending = {pool.submit(_worker, job, out, force, queue): job for job in jobs}
            started = set()
            while pending:
                done, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                _drain(queue, report, started)
                for fut in done:
                    job = pending.pop(fut)
                    try:
                        r = fut.result()
                    except Exception as exc:  # noqa: BLE001 - the worker process died
                        r = JobResult(job.name, "failed", message=f"worker died: {exc}")
                    results[job.name] = r
                    report("end", r)
            _drain(queue, report, started)
    finally:
        manager.shutdown()
    return [results[j.name] for j in jobs]


def _worker(job: Job, out: str, force: bool, queue) -> JobResult:
    queue.put(("start", job.name))
    last = [0.0]

    def progress(name, done, total):
        now = time.perf_counter()
        if now - last[0] > 0.25 or done >= total:
            last[0] = now
            queue.put(("progress", (name, done, total)))

    return run_job(job, out, force, progress)


def _drain(queue, report, started) -> None:
    while True:
        try:
            event, data = queue.get_nowait()
        except queue_module.Empty:
            return
        if event == "start":
            started.add(data)
        report(event, data)


def _run_dask(jobs, out, force, scheduler, report) -> list[JobResult]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise InputError("--executor dask needs dask.distributed: "
                         "pip install 'treebake[dask]'") from None
    if not scheduler:
        raise InputError("--executor dask needs --scheduler ADDRESS (e.g. tcp://host:8786)")
    results: dict[str, JobResult] = {}
    with Client(scheduler) as client:
        futures = {client.submit(run_job, job, out, force, pure=False, key=f"treebake-{job.name}"):
                   job for job in jobs}
        for job in jobs:
            report("start", job.name)
        for fut in as_completed(list(futures)):
            job = futures[fut]
            try:
                r = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails its job only
                r = JobResult(job.name, "failed", message=f"dask worker failed: {exc}")
            results[job.name] = r
            report("end", r)
    return [results[j.name] for j in jobs]


def summary(results: list[JobResult], wall: float, workers: int) -> dict:
    """Machine-readable summary of a batch."""
    return {
        "tool": f"treebake {__version__}", "jobs": len(results), "wall_seconds": round(wall, 3),
        "workers": workers,
        "done": sum(r.status == "done" for r in results),
        "skipped": sum(r.status == "skipped" for r in results),
        "failed": sum(r.status == "failed" for r in results),
        "results": [{**asdict(r), "seconds": round(r.seconds, 3)} for r in results],
    }


def format_table(results: list[JobResult]) -> str:
    width = max([len(r.name) for r in results] + [4])
    lines = [f"{'job':<{width}}  {'status':<7} {'s':>7}  {'frames':>6} {'segments':>8}  message"]
    for r in results:
        lines.append(f"{r.name:<{width}}  {r.status:<7} {r.seconds:>7.1f}  {r.frames:>6} "
                     f"{r.segments:>8}  {r.message}")
    return "\n".join(lines)

"""Batch bakes: many jobs from one job file, in parallel worker processes
(or on a Dask cluster), resumable, each output written atomically.

A job is a scene (or a grammar baked alone, or a grammar placed in a
scene's forces) with overrides and export formats; docs/batch.md describes
the job file. A finished job leaves `job.json` in its folder, written last:
its `hash` covers the tool version, the package's own code, the job's
settings and the content of every input file, and it records every output's
size and sha256; a rerun skips a job only if the hash matches and every
output still has its recorded size and sha256, and redoes the rest. Files
appear only when complete (temporary name, then rename), so a killed batch
leaves no half-written file and resumes cleanly. A lost worker process
costs only its job (retried up to MAX_ATTEMPTS times); SIGINT/SIGTERM stop
the batch cleanly; workers die with their parent.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import signal
import sys
import threading
import time
import tomllib
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from .errors import InputError, SceneError, TreebakeError
from .fileio import job_lock, write_text
from .fingerprint import code_fingerprint

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
QUALITY_NAMES = ("draft", "default", "final")
MAX_ATTEMPTS = 3  # a job whose worker process dies is run at most this often
DASK_WORKER_TIMEOUT = 120.0  # s without any Dask worker before the batch fails
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

    def inputs_digest(self) -> str:
        """Hash of the tool version, the settings and the inputs' content:
        the bake's `scene_hash` (so a bake's bytes do not depend on the code
        that made it beyond its motion)."""
        h = hashlib.sha256(f"treebake {__version__}\n".encode())
        h.update(json.dumps({k: v for k, v in asdict(self).items() if k != "name"},
                            sort_keys=True).encode())
        for path in self.inputs():
            h.update(path.name.encode())
            h.update(path.read_bytes())
        return h.hexdigest()

    def digest(self) -> str:
        """The resume hash: inputs_digest plus the package's code fingerprint,
        so editing treebake itself reruns the jobs it could change."""
        return hashlib.sha256(f"{self.inputs_digest()} code {code_fingerprint()}".encode()
                              ).hexdigest()


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
    status: str  # "done", "skipped", "failed", "interrupted" (stopped by SIGINT/SIGTERM)
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
                       source_hash=job.inputs_digest())


def _clean_stale(folder: Path) -> None:
    """Temporary files a killed run left behind (`.name.xxxx.tmp`)."""
    if folder.is_dir():
        for tmp in folder.rglob(".*.tmp"):
            tmp.unlink(missing_ok=True)


def file_record(folder: Path, path: Path) -> dict:
    """{path relative to the job folder, bytes, sha256} of one output."""
    from .export import sha256

    return {"path": path.resolve().relative_to(folder.resolve()).as_posix(),
            "bytes": path.stat().st_size, "sha256": sha256(path)}


def stale_reason(job: Job, out: Path) -> str | None:
    """Why the job must be (re)done, or None if its outputs are complete:
    job.json present, made by the same code from the same inputs, and every
    recorded file still of its recorded size and sha256."""
    from .export import sha256

    folder = out / job.name
    try:
        data = json.loads((folder / "job.json").read_text())
    except FileNotFoundError:
        return "not run yet"
    except (OSError, ValueError):
        return "job.json unreadable"
    if data.get("hash") != job.digest():
        return "inputs, settings or treebake's code changed"
    files = data.get("files")
    if not isinstance(files, list) or not files or not all(isinstance(f, dict) for f in files):
        return "job.json has no output checksums (older treebake)"
    for f in files:
        path = folder / str(f.get("path"))
        try:
            size = path.stat().st_size
        except OSError:
            return f"{f.get('path')} is missing"
        if size != f.get("bytes"):
            return f"{f.get('path')} is {size} bytes, recorded {f.get('bytes')}"
        if sha256(path) != f.get("sha256"):
            return f"{f.get('path')} does not match its recorded sha256"
    return None


def finished(job: Job, out: Path) -> bool:
    """The job's outputs are complete and were made from the same inputs and code."""
    return stale_reason(job, out) is None


def run_job(job: Job, out: str, force: bool = False, progress=None) -> JobResult:
    """Bake and export one job into `out/<name>/`; never raises."""
    from .bake import save_bake
    from .export import ExportOptions, export_bake
    from .pipeline import bake_scene

    start = time.perf_counter()
    root = Path(out)
    folder = root / job.name
    try:
        with job_lock(folder):
            reason = "forced" if force else stale_reason(job, root)
            if reason is None:
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
                report = export_bake(bake, root, job.name,
                                     ExportOptions(formats=tuple(exports)), bake_path=bake_path)
                files += report.files
            records = sorted((file_record(folder, p) for p in set(files)),
                             key=lambda r: r["path"])
            record = {"tool": f"treebake {__version__}", "job": asdict(job),
                      "hash": job.digest(), "files": records}
            write_text(folder / "job.json", json.dumps(record, indent=2, sort_keys=True) + "\n")
            redone = "" if reason in ("not run yet", "forced") else f"redone: {reason}"
            return JobResult(job.name, "done", time.perf_counter() - start, redone,
                             [r["path"] for r in records], len(bake.times),
                             sum(t.n_segments for t in bake.trees))
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
              report: Callable[[str, Any], None] | None = None,
              worker_timeout: float = DASK_WORKER_TIMEOUT) -> list[JobResult]:
    """Run the jobs; results in job order. `report(event, data)` receives
    ("workers", count actually running jobs), ("start", name),
    ("progress", (name, done, total)), ("retry", (name, why)) and
    ("end", JobResult). SIGINT/SIGTERM (main thread only) stop the batch:
    no new job starts, running ones are stopped, and every job not finished
    comes back as "interrupted". `worker_timeout`: s a Dask run may go
    without any worker before its unfinished jobs fail."""
    out = str(Path(out).resolve())  # here, on the client: a Dask worker's cwd is not ours
    report = report or (lambda event, data: None)
    workers = workers or os.cpu_count() or 1
    serial = executor != "dask" and min(workers, len(jobs)) <= 1
    with _StopSignals(interrupt=serial) as stop:
        if executor == "dask":
            results = _run_dask(jobs, out, force, scheduler, report, stop, worker_timeout)
        elif serial:
            report("workers", 1)
            results = _run_serial(jobs, out, force, report, stop)
        else:
            report("workers", min(workers, len(jobs)))
            results = _run_processes(jobs, out, force, workers, report, stop)
    why = f"not started: stopped by {stop.name}" if stop.name else "not started"
    return [results.get(j.name) or JobResult(j.name, "interrupted", message=why) for j in jobs]


class _StopSignals:
    """SIGINT/SIGTERM while a batch runs: remember the signal (no new jobs
    start); the serial runner also interrupts its running job. Installed
    only in the main thread, restored afterwards."""

    def __init__(self, interrupt: bool) -> None:
        self.interrupt = interrupt
        self.name: str | None = None
        self._old: dict[int, Any] = {}

    def __enter__(self) -> _StopSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        first = self.name is None
        self.name = signal.Signals(signum).name
        if self.interrupt and first:
            raise KeyboardInterrupt

    def __exit__(self, *exc) -> bool:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        return False

    @property
    def stopped(self) -> bool:
        return self.name is not None


def _run_serial(jobs, out, force, report, stop: _StopSignals) -> dict[str, JobResult]:
    results: dict[str, JobResult] = {}
    for job in jobs:
        if stop.stopped:
            break
        report("start", job.name)
        try:
            r = run_job(job, out, force, lambda *p: report("progress", p))
        except KeyboardInterrupt:  # our signal handler, or Ctrl-C outside the main thread
            r = JobResult(job.name, "interrupted",
                          message=f"stopped by {stop.name or 'SIGINT'} while running")
            results[job.name] = r
            report("end", r)
            break
        results[job.name] = r
        report("end", r)
    return results


@dataclass
class _Worker:
    """One worker process, its end of the pipe, and the job it runs."""

    process: Any
    conn: Any
    job: Job | None = None


def _run_processes(jobs, out, force, workers, report, stop: _StopSignals) -> dict[str, JobResult]:
    """A pool of our own (not concurrent.futures, which fails every pending
    job when one worker dies): each worker gets one job at a time over its
    own pipe, so a worker that dies costs only the job it held, which is
    retried in a fresh worker up to MAX_ATTEMPTS times."""
    import multiprocessing as mp
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")  # no inherited pymunk/numpy state, same as a fresh run
    todo = list(jobs)
    attempts: dict[str, int] = {}
    results: dict[str, JobResult] = {}
    pool: list[_Worker] = []

    def finish(r: JobResult) -> None:
        results[r.name] = r
        report("end", r)

    def lost(w: _Worker) -> None:
        w.process.join(timeout=2)
        why = _exit_reason(w.process.exitcode)
        pool.remove(w)
        w.conn.close()
        job, w.job = w.job, None
        if job is None:
            return
        if attempts[job.name] < MAX_ATTEMPTS:
            todo.insert(0, job)
            report("retry", (job.name, f"worker process {why}; retrying"))
        else:
            finish(JobResult(job.name, "failed", message=f"worker process {why} "
                                                         f"(tried {MAX_ATTEMPTS} times)"))

    def collect(w: _Worker) -> None:
        try:
            while w.job is not None and w.conn.poll():
                event, data = w.conn.recv()
                if event == "end":
                    w.job = None
                    finish(data)
                else:
                    report(event, data)
        except (EOFError, OSError):
            pass  # the worker is gone: its sentinel says so below

    try:
        while True:
            if not stop.stopped:
                busy = sum(w.job is not None for w in pool)
                while len(pool) < min(workers, busy + len(todo)):
                    parent_end, child_end = ctx.Pipe()
                    proc = ctx.Process(target=_worker_main, args=(child_end, os.getpid()),
                                       name="treebake-worker", daemon=True)
                    proc.start()
                    child_end.close()
                    pool.append(_Worker(proc, parent_end))
                for w in list(pool):
                    if w.job is None and todo:
                        w.job = todo.pop(0)
                        attempts[w.job.name] = attempts.get(w.job.name, 0) + 1
                        report("start", w.job.name)
                        try:
                            w.conn.send((w.job, out, force))
                        except OSError:
                            lost(w)
            running = [w for w in pool if w.job is not None]
            if stop.stopped or (not running and not todo):
                break
            wait([w.conn for w in running] + [w.process.sentinel for w in running], timeout=0.5)
            for w in running:
                collect(w)
                if w.job is not None and not w.process.is_alive():
                    collect(w)  # a last message may have arrived just before it died
                    if w.job is not None:
                        lost(w)
    finally:
        for w in pool:
            if w.job is not None:
                results.setdefault(w.job.name, JobResult(
                    w.job.name, "interrupted",
                    message=f"stopped by {stop.name or 'an error'} while running"))
                report("end", results[w.job.name])
                w.process.terminate()  # SIGTERM: the job removes its temporary file
            else:
                try:
                    w.conn.send(None)  # idle: exit
                except OSError:
                    pass
        for w in pool:
            w.process.join(timeout=10)
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
    return results


def _exit_reason(code: int | None) -> str:
    if code is None:
        return "stopped responding"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        oom = " (out of memory? the kernel's OOM killer sends it)" if -code == signal.SIGKILL \
            else ""
        return f"was killed by {name}{oom}"
    return f"exited with code {code}"


def _worker_main(conn, parent_pid: int) -> None:
    """A worker: run the jobs its pipe brings, until None or the pipe closes."""
    _die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C reaches the whole group:
    # the parent decides what stops
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # unwinds: temporaries removed
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        if message is None:
            return
        job, out, force = message
        if os.environ.get("TREEBAKE_FAULT_KILL_JOB") == job.name:  # bench/faults.py, tests
            os.kill(os.getpid(), signal.SIGKILL)
        last = [0.0]

        def progress(name, done, total):
            now = time.monotonic()
            if now - last[0] > 0.25 or done >= total:
                last[0] = now
                conn.send(("progress", (name, done, total)))

        conn.send(("end", run_job(job, out, force, progress)))


def _die_with_parent(parent_pid: int) -> None:
    """A worker must not outlive its batch (re-parented to PID 1 it would
    write on, then block forever). Linux: the kernel SIGKILLs it when the
    parent dies (prctl PR_SET_PDEATHSIG); elsewhere, and as a second line,
    a thread checks the parent pid every second."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # 1: PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="treebake-parent-watch", daemon=True).start()


def _run_dask(jobs, out, force, scheduler, report, stop: _StopSignals,
              worker_timeout: float) -> dict[str, JobResult]:
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--executor dask needs dask.distributed: "
                         "pip install 'treebake[dask]'") from None
    if not scheduler:
        raise InputError("--executor dask needs --scheduler ADDRESS (e.g. tcp://host:8786)")
    if not worker_timeout > 0:
        raise InputError(f"--worker-timeout must be > 0 s, got {worker_timeout}")
    try:
        client = Client(scheduler, timeout=30)
    except OSError as exc:
        raise TreebakeError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    results: dict[str, JobResult] = {}
    with client:
        most = _dask_workers(client)
        if most == 0:
            try:
                client.wait_for_workers(1, timeout=worker_timeout)
            except (TimeoutError, OSError):
                raise TreebakeError(f"no Dask worker joined {scheduler} within "
                                    f"{worker_timeout:g} s (--worker-timeout); start workers "
                                    "with `dask worker ADDRESS --nthreads 1`") from None
            most = _dask_workers(client)
        report("workers", most)
        futures = {client.submit(run_job, job, out, force, pure=False,
                                 key=f"treebake-{job.name}"): job for job in jobs}
        for job in jobs:
            report("start", job.name)
        pending = set(futures)
        seen_worker = last_check = time.monotonic()
        while pending and not stop.stopped:
            ready = [f for f in pending if f.done()]
            for fut in ready:
                pending.discard(fut)
                job = futures[fut]
                try:
                    r = fut.result()
                except Exception as exc:  # noqa: BLE001 - a lost worker fails its job only
                    r = JobResult(job.name, "failed", message=f"dask worker failed: {exc}")
                results[job.name] = r
                report("end", r)
            now = time.monotonic()
            if not ready and now - last_check >= 1.0:
                last_check = now
                count = _dask_workers(client)
                if count > most:
                    most = count
                    report("workers", most)
                if count:
                    seen_worker = now
                elif now - seen_worker > worker_timeout:
                    client.cancel(list(pending))
                    for fut in pending:
                        job = futures[fut]
                        r = JobResult(job.name, "failed",
                                      message=f"no Dask worker left for {worker_timeout:g} s "
                                              "(--worker-timeout); rerun to resume")
                        results[job.name] = r
                        report("end", r)
                    pending.clear()
            if not ready:
                time.sleep(0.2)
        if pending:  # stopped by a signal
            client.cancel(list(pending))
    return results


def _dask_workers(client) -> int:
    try:
        return len(client.scheduler_info(n_workers=-1).get("workers", {}))
    except TypeError:  # older distributed: no n_workers argument
        return len(client.scheduler_info().get("workers", {}))


def summary(results: list[JobResult], wall: float, workers: int) -> dict:
    """Machine-readable summary of a batch; `workers`: how many processes
    (or Dask workers, the most seen) actually ran jobs."""
    return {
        "tool": f"treebake {__version__}", "jobs": len(results), "wall_seconds": round(wall, 3),
        "workers": workers,
        "done": sum(r.status == "done" for r in results),
        "skipped": sum(r.status == "skipped" for r in results),
        "failed": sum(r.status == "failed" for r in results),
        "interrupted": sum(r.status == "interrupted" for r in results),
        "results": [{**asdict(r), "seconds": round(r.seconds, 3)} for r in results],
    }


def format_table(results: list[JobResult]) -> str:
    width = max([len(r.name) for r in results] + [4])
    lines = [f"{'job':<{width}}  {'status':<11} {'s':>7}  {'frames':>6} {'segments':>8}  message"]
    for r in results:
        lines.append(f"{r.name:<{width}}  {r.status:<11} {r.seconds:>7.1f}  {r.frames:>6} "
                     f"{r.segments:>8}  {r.message}")
    return "\n".join(lines)

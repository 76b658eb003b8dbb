"""Batch bakes: many jobs from one job file, in parallel worker processes
(or on a Dask cluster), resumable, each output written atomically.

A job is a scene (or a grammar baked alone, or a grammar placed in a
scene's forces) with overrides and export formats; docs/batch.md describes
the job file. A finished job leaves `job.json` in its folder, written last:
its `hash` covers the tool version, the package's own code, the installed
versions of the libraries that decide the motion (treebake.versions), the
job's settings and the content of every input file, and it records those
versions and every output's size and sha256; a rerun skips a job only if
the hash matches and every output still has its recorded size and sha256,
and redoes the rest, saying why (which version changed, if one did). Files
appear only when complete (temporary name, then rename), so a killed batch
leaves no half-written file and resumes cleanly. A lost worker process
costs only its job (retried up to MAX_ATTEMPTS times); SIGINT/SIGTERM stop
the batch cleanly; workers die with their parent.

This module runs one job (`run_job`, with its resume check) and a batch
(`run_batch`); the rest lives beside it and is re-exported here:
batch_jobs (job files, Job, JobResult), batch_pool (this machine's
runners), batch_dask (a Dask cluster), batch_summary (summary, table).
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any

from . import __version__
from .batch_dask import DASK_WORKER_TIMEOUT, run_dask
from .batch_jobs import Job, JobResult, load_jobs, scene_of
from .batch_pool import MAX_ATTEMPTS, StopSignals, run_processes, run_serial
from .batch_summary import format_table, summary
from .errors import BusyError, TreebakeError
from .fileio import job_lock, temporary_files, write_text
from .fingerprint import ResumeFingerprint, code_fingerprint
from .resources import Budget
from .versions import NOT_INSTALLED, UNKNOWN, VersionChange, runtime_versions, version_changes

__all__ = ["DASK_WORKER_TIMEOUT", "MAX_ATTEMPTS", "Job", "JobResult", "code_fingerprint",
           "file_record", "finished", "format_table", "load_jobs", "resume_fingerprint",
           "run_batch", "run_job", "runtime_versions", "scene_of", "settle_busy", "stale_reason",
           "summary"]


# ---------------------------------------------------------------------------
# resume checks


def resume_fingerprint(job: Job) -> ResumeFingerprint:
    """The job's inputs_digest, the package's code fingerprint and this
    install's library versions: editing treebake itself, or running on a
    node with another MuJoCo, numpy or pymunk, reruns the job."""
    # both looked up in this module: tests and bench/faults.py stand in others here
    return ResumeFingerprint(job.inputs_digest(), code_fingerprint(), runtime_versions())


def _clean_stale(folder: Path) -> None:
    """Temporary files a killed run left behind (fileio.temporary_files)."""
    for tmp in temporary_files(folder):
        tmp.unlink(missing_ok=True)


def file_record(folder: Path, path: Path) -> dict:
    """{path relative to the job folder, bytes, sha256} of one output."""
    from .export import sha256

    return {"path": path.resolve().relative_to(folder.resolve()).as_posix(),
            "bytes": path.stat().st_size, "sha256": sha256(path)}


def stale_reason(job: Job, out: Path, fingerprint: ResumeFingerprint | None = None
                 ) -> str | None:
    """Why the job must be (re)done, or None if its outputs are complete:
    job.json present, made by the same code with the same library versions
    from the same inputs, and every recorded file still of its recorded size
    and sha256. `fingerprint`: resume_fingerprint(job), if already known."""
    from .export import sha256

    folder = out / job.name
    try:
        data = json.loads((folder / "job.json").read_text())
    except FileNotFoundError:
        return "not run yet"
    except (OSError, ValueError):
        return "job.json unreadable"
    if not isinstance(data, dict):
        return "job.json unreadable"
    fingerprint = fingerprint or resume_fingerprint(job)
    if data.get("hash") != fingerprint.hash:
        return _changed(data, fingerprint, job)
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


def _changed(record: dict, now: ResumeFingerprint, job: Job) -> str:
    """Why a job.json's hash is not `now.hash`: the library versions that
    changed, the settings, input files and code that did (what job.json
    records of them), else "inputs, settings or treebake's code"."""
    recorded = record.get("versions")
    if not isinstance(recorded, dict):
        return "job.json records no library versions (older treebake)"
    why = [_version_reason(c) for c in version_changes(recorded, now.versions)]
    if record.get("hash") != now.with_versions(recorded).hash:
        what = _what_changed(record, now, job)
        why.append(what or "inputs, settings or treebake's code changed")
    return "; ".join(why)


def _what_changed(record: dict, now: ResumeFingerprint, job: Job) -> str:
    """The settings ("wind 9.0 -> 10.0"), input files and code that differ
    from what job.json records ("" where it records none of them)."""
    out = []
    before = record.get("job")
    if isinstance(before, dict):
        after = asdict(job)
        out += [f"{k} {before.get(k)!r} -> {after[k]!r}" for k in sorted(after)
                if k not in ("name", "scheduler") and _plain(before.get(k)) != _plain(after[k])]
    files = record.get("input_files")
    if isinstance(files, dict):
        current = input_files(job)
        out += [f"{Path(p).name} changed" for p in sorted(set(files) | set(current))
                if files.get(p) != current.get(p)]
    if record.get("code") not in (None, now.code):
        out.append("treebake's code changed")
    return "; ".join(out)


def _plain(value: Any) -> Any:
    """A job setting as JSON reads it back (tuples as lists)."""
    return list(value) if isinstance(value, tuple) else value


def input_files(job: Job) -> dict[str, str]:
    """Each file the job reads (path) -> the sha256 of its content."""
    from .export import sha256

    return {str(p): sha256(p) for p in job.inputs()}


def _version_reason(change: VersionChange) -> str:
    """'made with mujoco 3.13.0, this install has 4.0.0' and its variants
    for a library installed on one side only, or not recorded."""
    name, before, after = change.name, change.before, change.after
    made = {NOT_INSTALLED: f"made without {name}",
            UNKNOWN: f"made with no recorded {name} version"}.get(before,
                                                                  f"made with {name} {before}")
    has = {NOT_INSTALLED: f"this install has no {name}",
           UNKNOWN: f"this install does not record {name}"}.get(after,
                                                                f"this install has {after}")
    return f"{made}, {has}"


def finished(job: Job, out: Path) -> bool:
    """The job's outputs are complete and were made from the same inputs and
    code, with the same library versions."""
    return stale_reason(job, out) is None


# ---------------------------------------------------------------------------
# running one job

BUSY = "another run holds its folder and is writing it"


def run_job(job: Job, out: str, force: bool = False, progress=None) -> JobResult:
    """Bake and export one job into `out/<name>/`; never raises."""
    from .export import ExportOptions, export_bake, remove_exports
    from .pipeline import bake_scene

    start = time.perf_counter()
    root = Path(out)
    folder = root / job.name
    try:
        with job_lock(folder):
            fingerprint = resume_fingerprint(job)
            reason = "forced" if force else stale_reason(job, root, fingerprint)
            if reason is None:
                return _skipped(job.name, folder, time.perf_counter() - start, "up to date")
            _clean_stale(folder)
            (folder / "job.json").unlink(missing_ok=True)
            scene = scene_of(job)
            tick = None if progress is None else partial(progress, job.name)  # (done, total)
            bake_path = folder / f"{job.name}.npz"
            bake = bake_scene(scene, solver=job.solver, progress=tick,
                              budget=Budget(folder=folder), path=bake_path,
                              scheduler=job.scheduler)
            remove_exports(folder, bake_path.name)  # the previous bake's: a dropped format's stay
            files = [bake_path]
            exports = [f for f in job.formats if f != "npz"]
            if exports:
                # one process per job, as its bake: the batch runs the jobs side by side
                report = export_bake(bake, root, job.name,
                                     ExportOptions(formats=tuple(exports), workers=1),
                                     bake_path=bake_path)
                files += report.files
            records = sorted((file_record(folder, p) for p in set(files)),
                             key=lambda r: r["path"])
            frames, segments = len(bake.times), sum(t.n_segments for t in bake.trees)
            record = {"tool": f"treebake {__version__}", "job": asdict(job),
                      "hash": fingerprint.hash, "versions": fingerprint.versions,
                      "code": fingerprint.code, "input_files": input_files(job),
                      "files": records, "frames": frames, "segments": segments}
            write_text(folder / "job.json", json.dumps(record, indent=2, sort_keys=True) + "\n")
            redone = "" if reason in ("not run yet", "forced") else f"redone: {reason}"
            return JobResult(job.name, "done", time.perf_counter() - start, redone,
                             [r["path"] for r in records], frames, segments)
    except BusyError:  # another run writes this job now: its outcome is that run's to report
        return JobResult(job.name, "busy", time.perf_counter() - start, BUSY)
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
    with StopSignals(interrupt=serial) as stop:
        if executor == "dask":
            results = run_dask(jobs, out, force, scheduler, report, stop, worker_timeout, run_job)
        elif serial:
            report("workers", 1)
            results = run_serial(jobs, out, force, report, stop, run_job)
        else:
            report("workers", min(workers, len(jobs)))
            results = run_processes(jobs, out, force, workers, report, stop, run_job)
    why = f"not started: stopped by {stop.name}" if stop.name else "not started"
    out_results = [results.get(j.name) or JobResult(j.name, "interrupted", message=why)
                   for j in jobs]
    if executor == "dask" or stop.name:  # (the resume check belongs on the workers there)
        return out_results
    return settle_busy(jobs, out_results, out)


def settle_busy(jobs: list[Job], results: list[JobResult], out: str | Path) -> list[JobResult]:
    """The "busy" jobs (another run held them) looked at again once this
    run's own jobs are done, without waiting: still held -> "busy"; free
    and finished (the resume check) -> "skipped", "written by another
    run"; free and not finished -> "failed" (the other run failed it or was
    stopped: rerun to redo it). So of two runs of one job file, the later
    to finish (whose batch-summary.json stays) tells the whole outcome."""
    by_name = {j.name: j for j in jobs}
    root = Path(out)
    settled = []
    for r in results:
        job = by_name.get(r.name)
        if r.status != "busy" or job is None:
            settled.append(r)
            continue
        reason = "its folder is gone"
        if (root / job.name).is_dir():
            try:
                with job_lock(root / job.name):
                    reason = stale_reason(job, root)
            except BusyError:
                settled.append(r)
                continue
            except (OSError, TreebakeError) as exc:
                reason = str(exc)
        if reason is None:
            settled.append(_skipped(r.name, root / job.name, r.seconds, "written by another run"))
        else:
            settled.append(JobResult(r.name, "failed", r.seconds,
                                     f"another run was writing it and did not finish it "
                                     f"({reason}); rerun to redo it"))
    return settled


def _skipped(name: str, folder: Path, seconds: float, message: str) -> JobResult:
    """A job not rerun, with the files, frames and segments its job.json
    records (a summary that lists what the job made, done now or before)."""
    try:
        record = json.loads((folder / "job.json").read_text())
        files = [str(f["path"]) for f in record["files"]]
        frames, segments = int(record.get("frames", 0)), int(record.get("segments", 0))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        files, frames, segments = [], 0, 0
    return JobResult(name, "skipped", seconds, message, files, frames, segments)

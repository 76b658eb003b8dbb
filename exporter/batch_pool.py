"""Batch runners on this machine: in this process (one worker), or in a
pool of worker processes of our own; SIGINT/SIGTERM stop either cleanly.

A lost worker process costs only its job (retried up to MAX_ATTEMPTS
times); workers die with their parent. A runner calls `run(job, out, force,
progress) -> JobResult` (treebake.batch.run_job) for each job and reports
("start", name), ("progress", (name, done, total)), ("retry", (name, why))
and ("end", JobResult) through `report(event, data)`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .batch_jobs import Job, JobResult

MAX_ATTEMPTS = 3  # a job whose worker process dies is run at most this often

Report = Callable[[str, Any], None]
RunJob = Callable[..., JobResult]  # run(job, out, force, progress) -> JobResult, never raises


class StopSignals:
    """SIGINT/SIGTERM while a batch runs: remember the signal (no new jobs
    start); the serial runner also interrupts its running job. Installed
    only in the main thread, restored afterwards."""

    def __init__(self, interrupt: bool) -> None:
        self.interrupt = interrupt
        self.name: str | None = None
        self._old: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
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


def run_serial(jobs: list[Job], out: str, force: bool, report: Report, stop: StopSignals,
               run: RunJob) -> dict[str, JobResult]:
    """The jobs one after another in this process; a signal interrupts the
    running job (StopSignals(interrupt=True))."""
    results: dict[str, JobResult] = {}
    for job in jobs:
        if stop.stopped:
            break
        report("start", job.name)
        try:
            r = run(job, out, force, lambda *p: report("progress", p))
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


def run_processes(jobs: list[Job], out: str, force: bool, workers: int, report: Report,
                  stop: StopSignals, run: RunJob) -> dict[str, JobResult]:
    """The jobs in up to `workers` worker processes (see _ProcessPool)."""
    return _ProcessPool(jobs, out, force, workers, report, stop, run).run_all()


class _ProcessPool:
    """A pool of our own (not concurrent.futures, which fails every pending
    job when one worker dies): each worker gets one job at a time over its
    own pipe, so a worker that dies costs only the job it held, which is
    retried in a fresh worker up to MAX_ATTEMPTS times."""

    def __init__(self, jobs: list[Job], out: str, force: bool, workers: int, report: Report,
                 stop: StopSignals, run: RunJob) -> None:
        import multiprocessing as mp

        self.ctx = mp.get_context("spawn")  # no inherited pymunk/numpy state, same as a fresh run
        self.todo = list(jobs)
        self.out, self.force, self.workers = out, force, workers
        self.report, self.stop, self.run = report, stop, run
        self.attempts: dict[str, int] = {}
        self.results: dict[str, JobResult] = {}
        self.pool: list[_Worker] = []

    def run_all(self) -> dict[str, JobResult]:
        """Run every job (or until a signal); results by job name."""
        from multiprocessing.connection import wait

        try:
            while True:
                if not self.stop.stopped:
                    self._grow()
                    self._hand_out()
                running = [w for w in self.pool if w.job is not None]
                if self.stop.stopped or (not running and not self.todo):
                    break
                wait([w.conn for w in running] + [w.process.sentinel for w in running],
                     timeout=0.5)
                for w in running:
                    self._collect(w)
                    if w.job is not None and not w.process.is_alive():
                        self._collect(w)  # a last message may have arrived just before it died
                        if w.job is not None:
                            self._lost(w)
        finally:
            self._shut_down()
        return self.results

    def _grow(self) -> None:
        """Start workers up to `workers`, no more than there are jobs for."""
        busy = sum(w.job is not None for w in self.pool)
        while len(self.pool) < min(self.workers, busy + len(self.todo)):
            parent_end, child_end = self.ctx.Pipe()
            proc = self.ctx.Process(target=_worker_main, args=(child_end, os.getpid(), self.run),
                                    name="treebake-worker", daemon=True)
            proc.start()
            child_end.close()
            self.pool.append(_Worker(proc, parent_end))

    def _hand_out(self) -> None:
        """Give every idle worker the next job."""
        for w in list(self.pool):
            if w.job is None and self.todo:
                w.job = self.todo.pop(0)
                self.attempts[w.job.name] = self.attempts.get(w.job.name, 0) + 1
                self.report("start", w.job.name)
                try:
                    w.conn.send((w.job, self.out, self.force))
                except OSError:
                    self._lost(w)

    def _finish(self, r: JobResult) -> None:
        self.results[r.name] = r
        self.report("end", r)

    def _lost(self, w: _Worker) -> None:
        """A worker died: retry its job in a fresh one, or fail it after
        MAX_ATTEMPTS tries."""
        w.process.join(timeout=2)
        why = _exit_reason(w.process.exitcode)
        self.pool.remove(w)
        w.conn.close()
        job, w.job = w.job, None
        if job is None:
            return
        if self.attempts[job.name] < MAX_ATTEMPTS:
            self.todo.insert(0, job)
            self.report("retry", (job.name, f"worker process {why}; retrying"))
        else:
            self._finish(JobResult(job.name, "failed", message=f"worker process {why} "
                                                               f"(tried {MAX_ATTEMPTS} times)"))

    def _collect(self, w: _Worker) -> None:
        """Pass on what the worker sent: progress, and its job's end."""
        try:
            while w.job is not None and w.conn.poll():
                event, data = w.conn.recv()
                if event == "end":
                    w.job = None
                    self._finish(data)
                else:
                    self.report(event, data)
        except (EOFError, OSError):
            pass  # the worker is gone: its sentinel says so

    def _shut_down(self) -> None:
        """Stop running jobs (as interrupted), let idle workers exit, reap all."""
        for w in self.pool:
            if w.job is not None:
                self.results.setdefault(w.job.name, JobResult(
                    w.job.name, "interrupted",
                    message=f"stopped by {self.stop.name or 'an error'} while running"))
                self.report("end", self.results[w.job.name])
                w.process.terminate()  # SIGTERM: the job removes its temporary file
            else:
                try:
                    w.conn.send(None)  # idle: exit
                except OSError:
                    pass
        for w in self.pool:
            w.process.join(timeout=10)
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()


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


def _worker_main(conn, parent_pid: int, run: RunJob) -> None:
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

        conn.send(("end", run(job, out, force, progress)))


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

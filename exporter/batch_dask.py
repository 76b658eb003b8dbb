"""Batch runner on a Dask cluster: one task per job, run by
`run(job, out, force)` (treebake.batch.run_job) on the workers; a lost node
costs only its running job. If no worker is left (or none ever joined) for
`worker_timeout` seconds, the unfinished jobs fail instead of waiting forever.
"""

from __future__ import annotations

import time

from .batch_jobs import Job, JobResult
from .batch_pool import Report, RunJob, StopSignals
from .errors import InputError, TreebakeError

DASK_WORKER_TIMEOUT = 120.0  # s without any Dask worker before the batch fails


def run_dask(jobs: list[Job], out: str, force: bool, scheduler: str | None, report: Report,
             stop: StopSignals, worker_timeout: float, run: RunJob) -> dict[str, JobResult]:
    """The jobs as tasks on the Dask scheduler at `scheduler`; results by job
    name. `worker_timeout`: s the cluster may go without any worker."""
    client = _connect(scheduler, worker_timeout)
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
        futures = {client.submit(run, job, out, force, pure=False,
                                 key=f"treebake-{job.name}"): job for job in jobs}
        for job in jobs:
            report("start", job.name)
        return _gather(client, futures, most, report, stop, worker_timeout)


def _connect(scheduler: str | None, worker_timeout: float):
    """A distributed.Client for `scheduler`; InputError for missing
    dask.distributed or bad options, TreebakeError if it cannot connect."""
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
        return Client(scheduler, timeout=30)
    except OSError as exc:
        raise TreebakeError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None


def _gather(client, futures: dict, most: int, report: Report, stop: StopSignals,
            worker_timeout: float) -> dict[str, JobResult]:
    """Collect the futures' results as they finish, until all are in or a
    signal stops the batch; fail what is left when no worker was seen for
    `worker_timeout` s. Reports ("workers", n) when the cluster grows."""
    results: dict[str, JobResult] = {}
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

"""One shot's chunks on a Dask cluster (`treebake bake --scheduler`): each
chunk is a task running scheduler.simulate_chunk on a worker, as a local
worker process would; chunks are fixed by the scene (lod.py), so the bake
is byte-identical to a local one when the workers run the same versions,
which is checked first. Dask re-runs the chunk of a worker that is lost;
Ctrl-C cancels the chunks not yet finished."""

from __future__ import annotations

import uuid

from ..errors import InputError, TreebakeError
from ..versions import runtime_versions

CONNECT_TIMEOUT = 10.0  # s to reach the scheduler
WORKER_TIMEOUT = 120.0  # s to wait for a first worker
RETRIES = 2  # re-runs of a chunk whose task failed (a worker lost counts apart)


def connect(address: str):
    """A distributed.Client for the scheduler at `address`; InputError
    (exit 2) for a missing dask.distributed or an address nothing answers."""
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: "
                         "pip install 'treebake[dask]'") from None
    if "://" not in address:
        raise InputError(f"--scheduler = {address!r} is not a scheduler address "
                         "(tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786)")
    try:
        return Client(address, timeout=CONNECT_TIMEOUT)
    except (OSError, ValueError, TypeError) as exc:  # refused, timed out, unparsable
        raise InputError(f"--scheduler {address}: no Dask scheduler answered within "
                         f"{CONNECT_TIMEOUT:g} s ({type(exc).__name__}: {exc})") from None


def check_versions(client) -> int:
    """The workers' count, once every worker runs the versions that decide
    the motion (versions.py) this process runs; TreebakeError naming a
    worker that does not (its chunks would bake other motion)."""
    try:
        client.wait_for_workers(1, timeout=WORKER_TIMEOUT)
    except (TimeoutError, OSError):
        raise TreebakeError(f"no Dask worker joined {client.scheduler.address} within "
                            f"{WORKER_TIMEOUT:g} s; start workers with "
                            "`dask worker ADDRESS --nthreads 1`") from None
    mine = runtime_versions()
    theirs = client.run(runtime_versions)
    for worker, versions in sorted(theirs.items()):
        differ = [f"{k} {versions.get(k)} (here {v})" for k, v in mine.items()
                  if versions.get(k) != v]
        if differ:
            raise TreebakeError(f"Dask worker {worker} runs {', '.join(differ)}: its chunks "
                                "would bake other motion than this machine; install the same "
                                "versions on every worker")
    return len(theirs)


def run_chunks(address: str, calls: list[tuple], progress=None, log=None):
    """simulate_chunk(*args) for each of `calls` as tasks on the cluster at
    `address`, results yielded in order; `progress.chunk_done(k)` as each
    comes."""
    from .scheduler import results_in_order, simulate_chunk

    client = connect(address)
    with client:
        workers = check_versions(client)
        if log:
            log(f"dask: {len(calls)} chunks on {workers} workers at {address}")
        run = uuid.uuid4().hex[:8]  # keys of this run only: a rerun never reuses old results
        futures = [client.submit(simulate_chunk, *args, pure=False, retries=RETRIES,
                                 key=f"treebake-chunk-{run}-{k}")
                   for k, args in enumerate(calls)]
        try:
            yield from results_in_order(futures, progress)
        except BaseException:
            client.cancel([f for f in futures if f is not None])
            raise

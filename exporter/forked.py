"""A function over many items in forked worker processes, for the stages
before the simulation (grow, rig) that are the same work per tree: on a
10,000-tree shot they were 25 s of one process while the other cores
waited.

The workers are forked after the function is set, so it may be a closure
over data already in memory (grammars, grown trees): only the items
go to the workers and only the results come back, pickled. Results come in
the items' order and are the same values the function gives in one
process, so what follows is the same bytes with any number of workers."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Sequence

PER_TASK = 50  # items a worker takes at a time: enough to amortise a task's round trip

_work: Callable | None = None  # the function the forked workers run (set before they fork)


def forked_map(fn: Callable, items: Sequence, workers: int) -> list:
    """[fn(x) for x in items], spread over `workers` forked processes when
    there are enough items to pay for them (in this process otherwise, and
    where fork does not exist). An exception in `fn` is raised here, the
    first in the items' order."""
    global _work
    if workers <= 1 or len(items) < 2 * PER_TASK or os.name != "posix":
        return [fn(x) for x in items]
    import multiprocessing as mp

    parts = [items[i:i + PER_TASK] for i in range(0, len(items), PER_TASK)]
    _work = fn
    try:
        with mp.get_context("fork").Pool(min(workers, len(parts)), _ignore_interrupt) as pool:
            return [y for part in pool.imap(_run, parts) for y in part]
    finally:
        _work = None


def _ignore_interrupt() -> None:
    # Ctrl-C reaches the whole process group: this process stops the
    # workers (the pool's exit terminates them), each without a traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run(part: Sequence) -> list:
    return [_work(x) for x in part]

"""How an exporting process's C heap returns freed memory to the system.

An export frees and allocates arrays of a few MB for every tree (numpy's
temporaries, USD's layers). glibc's malloc gives the free top of its heap
back to the system as soon as it passes a threshold and then takes fresh
pages again, each a page fault: measured, a fifth of a 1,000-tree glb
export's CPU was the kernel's (1.7 M faults). Keeping 64 MiB at the heap's
top cut them to 0.62 M there, and from 0.30 M to 0.06 M in the USD
export of the same trees (docs/benchmarks.md), with the same peak RSS
(the pad is reused, not added). Only glibc has the knob; elsewhere this
does nothing. It never changes what is written."""

from __future__ import annotations

import ctypes

M_TOP_PAD = -2  # glibc's malloc.h
TOP_PAD_BYTES = 64 * 2**20


def keep_heap_top() -> bool:
    """Ask glibc's malloc to keep TOP_PAD_BYTES free at its heap's top
    (process-wide, from now on); False where there is no such malloc."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(M_TOP_PAD, TOP_PAD_BYTES))

"""What a bake will need, known before the work: each tree's segments
counted from its derived string (before the turtle draws it), then the
bake's peak memory and disk from the trees it will animate and the frames,
checked against a cap per tree, the machine (available memory, free disk)
and the user's `--max-memory`. A bake that would not fit is refused
(exit 2) with the figures and the key that changes them.

The cost model, measured 2026-11-28 on the forest species (scenes of 100
and 400 trees, 5 and 20 s at 24 fps, `--workers 1`: peak RSS 117, 201 and
554 MB for 0.34, 1.36 and 5.39 million segment-frames): about 88 MB to
start and 85 B per animated segment and frame (the simulation's float64
records, the chunks' results, the bake's float32 arrays); the estimate
takes 100 MB and 100 B, 1.15-1.25x those peaks. On disk a segment-frame
is at most 28 B (float32 position and rotation, before compression)."""

from __future__ import annotations

import errno
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from .errors import InputError, OutputError

DISK_PER_SEGMENT_FRAME = 28  # B: float32 position (3) and rotation (4)
MEMORY_PER_SEGMENT_FRAME = 100  # B at the bake's peak (measured 85)
MEMORY_PER_SEGMENT = 6 * 1024  # B: the grown tree, its rig, an engine's model (the reference's MuJoCo)
BASE_MEMORY = 100 * 2**20  # B: Python, numpy, MuJoCo and pymunk loaded (measured 88 MB)
WORKER_MEMORY = 100 * 2**20  # B: each further worker process's own start
DEFAULT_MAX_SEGMENTS = 100_000  # per tree: 7.6x the largest bundled grammar (fig. 2.8, 13,121)


@dataclass(frozen=True)
class Budget:
    """What a bake may use: `max_memory` (B, None: what the machine has
    available), `folder` (whose disk the bake goes to, None: not checked),
    `max_segments` per tree."""

    max_memory: int | None = None
    folder: Path | None = None
    max_segments: int = DEFAULT_MAX_SEGMENTS


@dataclass(frozen=True)
class Estimate:
    """A bake's needs: segments animated and static, frames, peak memory
    and disk (B)."""

    animated: int
    static: int
    frames: int
    workers: int
    memory: int
    disk: int

    def line(self) -> str:
        """The plan line's figures."""
        frames = f"{self.frames} frame{'' if self.frames == 1 else 's'}"
        return (f"estimated: {self.animated:,} animated segments x {frames}: "
                f"peak memory about {mib(self.memory)}, bake {mib(self.disk)} on disk")


def mib(n: float) -> str:
    """A size in bytes as kB, MB or GB (powers of 1024), to read."""
    if n < 2**20:
        return f"{n / 2**10:,.0f} kB"
    return f"{n / 2**20:,.0f} MB" if n < 10 * 2**30 else f"{n / 2**30:,.1f} GB"


def parse_size(text: str) -> int:
    """'8G', '500M', '2.5GB', '1000000' -> bytes (K, M, G, T are powers of 1024)."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)i?b?\s*", text, re.IGNORECASE)
    if not m or float(m.group(1)) <= 0:
        raise InputError(f"--max-memory = {text!r} is not a size (e.g. 8G, 500M)")
    return int(float(m.group(1)) * 1024 ** " kmgt".index(m.group(2).lower() or " "))


def too_many_segments(grammar_file: str | Path, segments: int, budget: Budget) -> InputError:
    """The error for a tree of more segments than `budget` allows (its
    max_segments), naming its grammar and what the tree would need."""
    return InputError(
        f"{grammar_file}: the tree would have {segments:,} segments, more than the "
        f"{budget.max_segments:,} a tree may have (about {mib(segments * MEMORY_PER_SEGMENT)} "
        f"to grow and {mib(segments * DISK_PER_SEGMENT_FRAME)} per baked frame); fewer "
        "`iterations` make it smaller, and `--max-segments` raises the cap")


def estimate(animated: int, static: int, frames: int, workers: int,
             held: int | None = None) -> Estimate:
    """The needs of a bake of `animated` and `static` segments (a static
    tree is baked as one frame) over `frames`, in `workers` processes, of
    which `held` animated segments have their frames in memory at once (a
    bake streamed to its file holds a few chunks; None: all of them)."""
    seg_frames = animated * frames + static
    held = animated if held is None else min(held, animated)
    memory = (BASE_MEMORY + (max(workers, 1) - 1) * WORKER_MEMORY
              + (animated + static) * MEMORY_PER_SEGMENT
              + (held * frames + static) * MEMORY_PER_SEGMENT_FRAME)
    return Estimate(animated, static, frames, workers, memory,
                    seg_frames * DISK_PER_SEGMENT_FRAME)


def available_memory() -> int | None:
    """Memory (B) the machine can give a new process now (Linux's
    MemAvailable); None where it is not known."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check(est: Estimate, budget: Budget) -> None:
    """Refuse (InputError, exit 2) a bake whose estimate does not fit the
    budget's memory or its folder's free disk."""
    limit, what = budget.max_memory, "--max-memory"
    if limit is None:
        limit, what = available_memory(), "the memory this machine has available"
    if limit is not None and est.memory > limit:
        raise InputError(
            f"this bake needs about {mib(est.memory)} of memory at its peak ({est.animated:,} "
            f"animated segments x {est.frames} frames), more than {what} ({mib(limit)}): a "
            "shorter `duration`, a lower `fps`, fewer trees or fewer `iterations` make it "
            "smaller" + ("" if budget.max_memory is None else ", or raise --max-memory"))
    if budget.folder is not None:
        free = free_disk(budget.folder)
        if free is not None and est.disk > free:
            raise InputError(
                f"{budget.folder}: the bake needs about {mib(est.disk)} on disk and the disk "
                f"has {mib(free)} free: free some space or write elsewhere (--out)")


def free_disk(folder: Path) -> int | None:
    """Free bytes on the disk that holds `folder` (or its nearest existing parent)."""
    p = Path(folder).resolve()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return shutil.disk_usage(p).free
    except OSError:
        return None


def disk_full(target: Path, exc: OSError) -> OutputError | None:
    """The error for a write to `target` that ran out of space (ENOSPC,
    EDQUOT), naming the file and what is free; None for other errors."""
    if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
        return None
    free = free_disk(target.parent)
    room = "" if free is None else f" ({mib(free)} free)"
    return OutputError(f"{target}: the disk is full{room}; nothing of this file was kept: "
                       f"{os.strerror(exc.errno)}")

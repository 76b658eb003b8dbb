"""Atomic file output: write to a temporary file in the target folder, then
rename over the target, so a crash or kill never leaves a half-written file.
Also: proving an output folder writable before expensive work, and the
per-job-folder lock that keeps two runs from interleaving their files."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .errors import BusyError, OutputError

try:
    import fcntl
except ImportError:  # not POSIX: no job locks (the farm targets are Linux)
    fcntl = None

LOCK_NAME = ".treebake.lock"


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it to `path` on success,
    delete it on failure."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; files are for sharing
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _read_umask()  # read once: os.umask is process-wide, not thread-safe


def write_bytes(path: str | Path, data: bytes) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    return write_bytes(path, text.encode("utf-8"))


def check_writable(folder: str | Path) -> Path:
    """Create `folder` if needed and write (then delete) a probe file in it,
    so an unwritable output fails before a simulation, not after.
    Permission bits alone would not tell (root ignores them)."""
    p = Path(folder)
    try:
        if p.exists() and not p.is_dir():
            raise NotADirectoryError(20, "it is a file, not a folder")
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".treebake-probe.", suffix=".tmp", dir=p)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"cannot write to output folder {p}: "
                          f"{exc.strerror or exc}") from None
    return p


def check_writable_file(path: str | Path) -> Path:
    """Like check_writable, for one output file (its folder, and not a folder itself)."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"cannot write {p}: it is a folder")
    check_writable(p.parent if str(p.parent) else Path("."))
    return p


@contextlib.contextmanager
def job_lock(folder: str | Path) -> Iterator[None]:
    """Hold `folder/.treebake.lock` (an exclusive flock) while a run writes
    the folder. A second run does not wait: it fails at once with
    BusyError, before simulating (a farm retries; a silent wait looks like
    a hang). The kernel drops the lock when its process dies, kill -9 too;
    the empty lock file stays (deleting it would race a new holder)."""
    p = check_writable(folder)
    if fcntl is None:
        yield
        return
    fd = os.open(p / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o666 & ~_UMASK)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise BusyError(f"{p}: another treebake run is writing this job folder (it holds "
                            f"{LOCK_NAME}); wait for it to finish, or write elsewhere "
                            "(--out or --name)") from None
        yield
    finally:
        os.close(fd)  # releases the lock

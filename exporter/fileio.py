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
from .resources import disk_full

try:
    import fcntl
except ImportError:  # not POSIX: no job locks (the farm targets are Linux)
    fcntl = None

LOCK_NAME = ".treebake.lock"


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary path next to `path` (ending in `suffix`: a writer
    that picks its format by the extension gets the target's); rename it
    to `path` on success, delete it on failure."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; files are for sharing
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        full = disk_full(target, exc) if isinstance(exc, OSError) else None
        if full is not None:
            raise full from None
        raise


def temporary_files(folder: str | Path) -> list[Path]:
    """The temporary files atomic_path makes below `folder` and a killed
    run leaves behind: `.NAME.XXXX.tmp`, or `.NAME.XXXX.tmp.EXT` where the
    writer needs the target's extension (USD)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for pattern in (".*.tmp", ".*.tmp.*") for p in folder.rglob(pattern)
                  if p.is_file())


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


def _make_writable(p: Path) -> None:
    """mkdir -p, then write and delete a probe file; OSError as it comes."""
    for q in (p, *p.parents):  # the nearest that exists: a file there is no folder to write in
        if q.exists():
            if not q.is_dir():
                raise NotADirectoryError(20, "it is a file, not a folder" if q == p
                                         else f"{q} is a file, not a folder")
            break
    p.mkdir(parents=True, exist_ok=True)
    fd, probe = tempfile.mkstemp(prefix=".treebake-probe.", suffix=".tmp", dir=p)
    os.close(fd)
    os.unlink(probe)


def _cannot_write(p: Path, exc: OSError) -> OutputError:
    return OutputError(f"cannot write to output folder {p}: {exc.strerror or exc}")


def check_writable(folder: str | Path) -> Path:
    """Create `folder` if needed and write (then delete) a probe file in it,
    so an unwritable output fails before a simulation, not after.
    Permission bits alone would not tell (root ignores them)."""
    p = Path(folder)
    try:
        _make_writable(p)
    except OSError as exc:
        raise _cannot_write(p, exc) from None
    return p


def _missing(p: Path) -> list[Path]:
    """`p` and those of its parents that do not exist yet, innermost first."""
    out = []
    for q in (p, *p.parents):
        if q.exists() or q == q.parent:
            break
        out.append(q)
    return out


def _remove_if_empty(folders: list[Path]) -> None:
    """rmdir each folder (innermost first) while it is empty; a folder that
    another run has meanwhile put a file in stays, and so do its parents."""
    for q in folders:
        try:
            q.rmdir()
        except OSError:
            return


@contextlib.contextmanager
def output_folder(folder: str | Path) -> Iterator[Path]:
    """check_writable(folder) for a block that writes into it: if the block
    fails, the folders this call created are removed again while empty, so
    a run that fails (a grammar that does not parse, a limit) leaves no
    empty OUT/NAME/ behind."""
    p = Path(folder)
    made = _missing(p)
    try:
        yield check_writable(p)
    except BaseException:
        _remove_if_empty(made)
        raise


def check_writable_file(path: str | Path) -> Path:
    """Like check_writable, for one output file (its folder, and not a folder itself)."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"cannot write {p}: it is a folder")
    check_writable(p.parent if str(p.parent) else Path("."))
    return p


LOCK_TRIES = 100  # a lock file removed under us this often in a row: report busy


@contextlib.contextmanager
def job_lock(folder: str | Path) -> Iterator[Path]:
    """Hold `folder/.treebake.lock` (an exclusive flock) while a run writes
    the folder; yields the folder (created, proven writable). A second run
    does not wait: it fails at once with BusyError, before simulating (a
    farm retries; a silent wait looks like a hang). The kernel drops the
    lock when its process dies, kill -9 too.

    The lock file goes when the run releases it: the holder unlinks it
    while still holding the lock, and a run that acquires a lock checks
    that the path still names the file it locked (fstat against stat) and
    starts over if not, so a run that opened the file just before the
    unlink never holds a lock that a third run, creating a new file, holds
    too. Only a killed run leaves the (empty, unlocked) file behind. If the
    run fails, folders this call created are removed while empty
    (output_folder)."""
    p = Path(folder)
    made = _missing(p)
    try:
        fd = _acquire(p)
        try:
            yield p
        finally:
            if fd is not None:
                # while holding: a run that opened this file re-checks and starts over
                with contextlib.suppress(FileNotFoundError):
                    if os.path.samestat(os.fstat(fd), os.stat(p / LOCK_NAME)):
                        os.unlink(p / LOCK_NAME)
                os.close(fd)  # releases the lock
    except BaseException:
        _remove_if_empty(made)
        raise


def _acquire(p: Path) -> int | None:
    """The locked descriptor of `p/.treebake.lock` (None without flock),
    making `p` and proving it writable first; BusyError if another run
    holds it."""
    for _ in range(LOCK_TRIES):
        try:
            _make_writable(p)
            if fcntl is None:
                return None
            fd = os.open(p / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o666 & ~_UMASK)
        except FileNotFoundError:
            continue  # a failed run removed the empty folder under us: make it again
        except OSError as exc:
            raise _cannot_write(p, exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise _busy(p) from None
        try:
            if os.path.samestat(os.fstat(fd), os.stat(p / LOCK_NAME)):
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)  # the file we locked was released and unlinked: take the new one
    raise _busy(p)


def _busy(p: Path) -> BusyError:
    return BusyError(f"{p}: another treebake run is writing this job folder (it holds "
                     f"{LOCK_NAME}); wait for it to finish, or write elsewhere (--out or --name)")

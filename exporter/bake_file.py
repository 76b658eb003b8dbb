"""The bake file: one `.npz` (a zip of `.npy` arrays) that is written tree
by tree as the simulation finishes them and read tree by tree on demand.

Layout: per tree i, `tree{i}.info` (JSON) and its arrays (`tree{i}.points`,
`.positions`, ...; bake.TreeBake), then the frame times, the projectiles
(`objects.*`) and `meta` (JSON, last: it sums up the whole shot). Members
keep the order the trees were finished in (`Bake.order`), which the plan
of the simulation fixes, so the same inputs give the same bytes with any
number of workers; zip timestamps are fixed.

Memory follows one tree, not the shot: `BakeWriter` holds no tree once it
is written, and `load_bake(path, lazy=True)` keeps the archive open and
reads a tree when it is asked for (zip's directory gives random access to
each member; `_npy` reads a member's array). The file appears under
its name only once whole (fileio.atomic_path): a crash or a full disk
leaves nothing that looks like a bake. Each member carries zip's CRC-32,
checked as it is read.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import zipfile
import zlib
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from .bake import Bake, ObjectsBake, TreeBake
from .errors import InputError
from .fileio import atomic_path
from .model import Twigs

# 2: trees may carry twigs (`twig_*` arrays); a bake without any is written
# as 1, the same bytes as before twigs, and an older reader refuses a 2
# instead of dropping its twigs
FORMAT_VERSION = 2
FORMATS = (1, 2)  # read
_FIXED_TIME = (1980, 1, 1, 0, 0, 0)
_ARRAYS = ("points", "seg_start", "seg_end", "seg_parent", "seg_limb", "width", "leaf",
           "leaf_size", "limb_parent", "limb_attach", "positions", "rotations")
_EXTRAS = ("extra_times", "extra_positions", "extra_rotations")
# a tree's twigs (model.Twigs), stored as `twig_<field>` when it has any
_TWIGS = ("start", "end", "width", "leaf", "leaf_size", "segment")
# what reading a damaged archive can raise: reported as a damaged bake
_DAMAGE = (OSError, EOFError, zipfile.BadZipFile, zlib.error, KeyError, ValueError, TypeError,
           IndexError, AttributeError)


# Members stored as they are, not deflated: a tree's rotations (float32
# quaternions) deflate only to 0.87 of their size at level 1, for 2.3 ms
# of CPU per forest tree, in the main process that writes the bake (23 s
# of a 10,000-tree bake, whose critical path that process is). Stored,
# the bake is 10 % larger.
_STORED = frozenset({"rotations"})


def _add(zf: zipfile.ZipFile, name: str, array: np.ndarray, deflate: bool = True) -> None:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(array), allow_pickle=False)
    info = zipfile.ZipInfo(name + ".npy", date_time=_FIXED_TIME)
    info.compress_type = zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED
    info.external_attr = 0o644 << 16
    # deflate's fastest level: on a spruce's bake it writes 0.14 % more bytes
    # than the default level 6 in 0.65x its CPU time (motion compresses little)
    zf.writestr(info, buf.getvalue(), compresslevel=1)


def _json_array(obj) -> np.ndarray:
    return np.frombuffer(json.dumps(obj, sort_keys=True).encode("utf-8"), dtype=np.uint8)


def _json(data: np.ndarray):
    return json.loads(bytes(data).decode("utf-8"))


# the header numpy writes for a plain array (format.write_array): dtype,
# C order, shape; anything else is read by numpy itself
_NPY_HEADER = re.compile(r"\{'descr': '([<>|=][biufcSU]\d+)', 'fortran_order': False, "
                         r"'shape': \(((?:\d+, )*\d+,?|)\), \} *\n")


def _npy(data: bytes) -> np.ndarray:
    """The array in the bytes of a .npy file (writable, like numpy.load's).
    A plain array's header is parsed here: numpy parses every header as a
    Python literal, most of the cost of reading a tree's small arrays."""
    if data[:6] == b"\x93NUMPY" and data[6] in (1, 2):
        size, start = (int.from_bytes(data[8:10], "little"), 10) if data[6] == 1 else \
            (int.from_bytes(data[8:12], "little"), 12)
        plain = _NPY_HEADER.fullmatch(data[start:start + size].decode("latin1"))
        if plain is not None:
            dtype = np.dtype(plain.group(1))
            shape = tuple(int(v) for v in plain.group(2).replace(",", " ").split())
            count = math.prod(shape)
            if len(data) - start - size != count * dtype.itemsize:
                raise ValueError(f"array data of {len(data) - start - size} bytes, "
                                 f"expected {count * dtype.itemsize}")
            return np.frombuffer(data, dtype, count, start + size).reshape(shape).copy()
    return np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)


class _Archive:
    """A bake's zip archive, read member by member as arrays (the mapping
    numpy.load gives, member names without `.npy`); zip checks each
    member's CRC-32 as it is read."""

    def __init__(self, path: Path):
        self._zip = zipfile.ZipFile(path)
        names = self._zip.namelist()
        self.files = [n.removesuffix(".npy") for n in names]
        self._names = dict(zip(self.files, names))

    def __contains__(self, key: str) -> bool:
        return key in self._names

    def __getitem__(self, key: str) -> np.ndarray:
        return _npy(self._zip.read(self._names[key]))

    def close(self) -> None:
        self._zip.close()


class BakeWriter:
    """A bake file written as its trees come: `add(i, tree)` as each is
    finished (any order; each index once), then `finish(meta, objects)`.
    Use as a context manager: the file appears at `path` when the block
    ends after `finish`, and not at all if it raises."""

    def __init__(self, path: str | Path, times: np.ndarray, trees: int):
        self.path, self.times, self.trees = Path(path), np.asarray(times, np.float64), trees
        self.order: list[int] = []
        self._seen: set[int] = set()
        self._stack = contextlib.ExitStack()
        self._zip: zipfile.ZipFile | None = None
        self._done = False
        self._twigs = False  # any tree with twigs: format 2

    def __enter__(self) -> BakeWriter:
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._zip = self._stack.enter_context(zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED))
        return self

    def add(self, index: int, tree: TreeBake) -> None:
        """Write tree `index` (0 <= index < trees) now; it is not kept."""
        if not 0 <= index < self.trees or index in self._seen:
            raise ValueError(f"tree {index}: outside 0..{self.trees - 1} or written twice")
        if len(tree.extra_times):
            tree.check_extras(self.times)
        p = f"tree{index}."
        _add(self._zip, p + "info", _json_array(dict(tree.info, name=tree.name, paths=tree.paths)))
        for key in _ARRAYS:
            _add(self._zip, p + key, getattr(tree, key), deflate=key not in _STORED)
        if len(tree.extra_times):  # only when present: bakes without them keep their bytes
            for key in _EXTRAS:
                _add(self._zip, p + key, getattr(tree, key))
        if len(tree.twigs):  # likewise
            self._twigs = True
            for key in _TWIGS:
                _add(self._zip, p + "twig_" + key, getattr(tree.twigs, key))
        lengths = np.asarray([len(lp) for lp in tree.limb_points], dtype=np.int64)
        flat = np.concatenate(tree.limb_points) if tree.limb_points else np.zeros(0, np.int64)
        _add(self._zip, p + "limb_point_counts", lengths)
        _add(self._zip, p + "limb_points", flat)
        self.order.append(index)
        self._seen.add(index)

    def finish(self, meta: dict, objects: ObjectsBake | None = None) -> None:
        """The frame times, the projectiles and the meta, once every tree is in."""
        missing = self.trees - len(self.order)
        if missing:
            raise ValueError(f"{missing} of {self.trees} trees were never written")
        _add(self._zip, "times", self.times)
        if objects is not None:
            _add(self._zip, "objects.info", _json_array({"shapes": objects.shapes}))
            _add(self._zip, "objects.sizes", objects.sizes)
            _add(self._zip, "objects.positions", objects.positions.astype(np.float32))
            _add(self._zip, "objects.rotations", objects.rotations.astype(np.float32))
        version = FORMAT_VERSION if self._twigs else 1
        _add(self._zip, "meta", _json_array(dict(meta, format_version=version,
                                                 trees=self.trees)))
        self._done = True

    def __exit__(self, kind, exc, tb) -> None:
        if kind is None and not self._done:
            exc = ValueError(f"{self.path}: the bake was not finished")
            self._stack.__exit__(type(exc), exc, None)
            raise exc
        self._stack.__exit__(kind, exc, tb)


def save_bake(bake: Bake, path: str | Path) -> Path:
    """Write `bake` atomically, its trees in `bake.order` (index order if
    None); identical bakes give identical bytes."""
    order = bake.order if bake.order is not None else range(len(bake.trees))
    with BakeWriter(path, bake.times, len(bake.trees)) as out:
        for i in order:
            out.add(i, bake.trees[i])
        out.finish(bake.meta, bake.objects)
    return Path(path)


class StoredTrees(Sequence[TreeBake]):
    """A bake's trees read from its open archive one at a time, as they
    are asked for (the last one read is kept); each is checked as it is
    read (shapes, finite motion)."""

    def __init__(self, archive, path: Path, count: int, times: np.ndarray):
        self._archive, self._path, self._count, self._times = archive, path, count, times
        self._last: tuple[int, TreeBake] | None = None

    def __len__(self) -> int:
        return self._count

    @property
    def path(self) -> Path:
        """The bake file the trees are read from."""
        return self._path

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._count))]
        i = range(self._count)[i]  # negative indices, IndexError
        if self._last is None or self._last[0] != i:
            self._last = (i, _read_tree(self._archive, i, self._times, self._path))
        return self._last[1]

    def __iter__(self) -> Iterator[TreeBake]:
        for i in range(self._count):
            yield self[i]

    def field(self, i: int, key: str) -> np.ndarray:
        """One array of tree i (`leaf`, `width`, ...), reading nothing else."""
        try:
            return self._archive[f"tree{i}.{key}"]
        except _DAMAGE as exc:
            raise InputError(f"{self._path}: not a readable treebake bake: damaged or "
                             f"truncated ({type(exc).__name__}: {exc})") from None

    def has(self, i: int, key: str) -> bool:
        """Whether tree i stores array `key` (optional ones: `twig_leaf`, ...)."""
        return f"tree{i}.{key}" in self._archive

    def info(self, i: int) -> dict:
        """Tree i's info (TreeBake.info with its name and paths), reading
        nothing else."""
        return _json(self.field(i, "info"))


def tree_field(trees: Sequence[TreeBake], i: int, key: str) -> np.ndarray:
    """One array of tree i of a bake's trees, in memory or stored (then
    only that array is read)."""
    if isinstance(trees, StoredTrees):
        return trees.field(i, key)
    return getattr(trees[i], key)


def tree_leaf_fields(trees: Sequence[TreeBake], i: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tree i's segment leaf types, its twigs' leaf types and the segments
    they ride on (0 = no leaves), in memory or stored (then only those
    arrays are read)."""
    if isinstance(trees, StoredTrees):
        if trees.has(i, "twig_leaf"):
            return (trees.field(i, "leaf"), trees.field(i, "twig_leaf"),
                    trees.field(i, "twig_segment"))
        return trees.field(i, "leaf"), np.zeros(0, np.int64), np.zeros(0, np.int64)
    t = trees[i]
    return t.leaf, t.twigs.leaf, t.twigs.segment


def tree_info(trees: Sequence[TreeBake], i: int) -> dict:
    """Tree i's info with its name and segment paths, in memory or stored
    (then only that entry is read)."""
    if isinstance(trees, StoredTrees):
        return trees.info(i)
    return dict(trees[i].info, name=trees[i].name, paths=list(trees[i].paths))


def _read_tree(z, i: int, times: np.ndarray, path: Path) -> TreeBake:
    pre = f"tree{i}."
    try:
        info = _json(z[pre + "info"])
        counts = z[pre + "limb_point_counts"]
        flat = z[pre + "limb_points"]
        splits = np.cumsum(counts)[:-1]
        present = [pre + "twig_" + k in z for k in _TWIGS]
        if any(present) and not all(present):
            raise ValueError("some of its twig arrays are missing")
        twigs = Twigs(**{k: z[pre + "twig_" + k] for k in _TWIGS}) if all(present) \
            else Twigs.none()
        tree = TreeBake(name=info.pop("name"), paths=info.pop("paths"),
                        limb_points=list(np.split(flat, splits)) if len(counts) else [],
                        info=info, **{k: z[pre + k] for k in _ARRAYS},
                        **{k: z[pre + k] for k in _EXTRAS if pre + k in z}, twigs=twigs)
        _check_tree(tree, times)
    except _DAMAGE as exc:
        raise InputError(f"{path}: not a readable treebake bake: damaged or truncated "
                         f"({type(exc).__name__}: {exc})") from None
    _check_finite(tree, str(path))
    return tree


def load_bake(path: str | Path, lazy: bool = False) -> Bake:
    """Read a bake; anything that is not a whole treebake bake (empty,
    truncated, another kind of file, damaged arrays) is an InputError.
    `lazy`: read each tree only when it is asked for (bounded memory for a
    shot of any size; the archive stays open while the Bake lives)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: bake file not found")
    if p.stat().st_size == 0:
        raise InputError(f"{p}: the bake file is empty (0 bytes): an interrupted write or a "
                         "damaged copy; bake it again")
    if not zipfile.is_zipfile(p):
        raise InputError(f"{p}: not a treebake bake (a bake is a .npz zip archive written by "
                         "`treebake bake`)")
    try:
        z = _Archive(p)
        if "meta" not in z:
            raise InputError(f"{p}: a .npz archive, but not a treebake bake (no meta)")
        meta = _json(z["meta"])
        if meta.get("format_version") not in FORMATS:
            raise InputError(f"{p}: bake format {meta.get('format_version')} is not "
                             f"supported (this treebake reads {', '.join(map(str, FORMATS))})")
        times = z["times"]
        objects = None
        if "objects.info" in z:
            objects = ObjectsBake(_json(z["objects.info"])["shapes"], z["objects.sizes"],
                                  z["objects.positions"], z["objects.rotations"])
        count = int(meta["trees"])
        order = [int(name[4:].split(".", 1)[0]) for name in z.files
                 if name.startswith("tree") and name.endswith(".info")]
    except InputError:
        raise
    except _DAMAGE as exc:
        raise InputError(f"{p}: not a readable treebake bake: damaged or truncated "
                         f"({type(exc).__name__}: {exc})") from None
    if sorted(order) != list(range(count)):
        raise InputError(f"{p}: not a readable treebake bake: damaged or truncated (its meta "
                         f"has {count} trees, the archive {len(order)})")
    trees = StoredTrees(z, p, count, times)
    if not lazy:
        trees = list(trees)
        z.close()
    if objects is not None and objects.positions.shape[0] != len(times):
        raise InputError(f"{p}: not a readable treebake bake: damaged or truncated (the "
                         f"projectiles have {objects.positions.shape[0]} frames, the bake "
                         f"{len(times)})")
    return Bake(times, trees, meta, objects, order=order)


def check_finite(bake: Bake, where: str = "the bake") -> None:
    """Raise InputError if any tree's positions or rotations (frames and
    sub-frame samples) hold NaN or infinity: junk to diff or export, named
    with the tree and the first frame."""
    for t in bake.trees:
        _check_finite(t, where)


def _check_finite(t: TreeBake, where: str) -> None:
    for what, frames in (("positions", t.positions), ("rotations", t.rotations),
                         ("sub-frame positions", t.extra_positions),
                         ("sub-frame rotations", t.extra_rotations)):
        if not len(frames):
            continue
        bad = ~np.isfinite(frames).reshape(len(frames), -1).all(axis=1)
        if bad.any():
            raise InputError(f"{where}: tree {t.name!r} has non-finite {what} from "
                             f"{'sample' if 'sub' in what else 'frame'} "
                             f"{int(np.argmax(bad))} on: a broken bake")


def _check_twigs(t: TreeBake) -> None:
    """Twig arrays that disagree with each other or with the tree raise
    ValueError: lengths, integer segments and leaf types, a segment the
    tree has, finite geometry, widths and leaf sizes >= 0."""
    tw, n = t.twigs, len(t.twigs)
    shapes = [tw.start.shape == (n, 3), tw.end.shape == (n, 3)] + \
        [getattr(tw, k).shape == (n,) for k in ("width", "leaf", "leaf_size")]
    if not all(shapes):
        raise ValueError(f"tree {t.name!r}: its twig arrays disagree in length")
    if not n:
        return
    if not (np.issubdtype(tw.segment.dtype, np.integer) and np.issubdtype(tw.leaf.dtype,
                                                                           np.integer)):
        raise ValueError(f"tree {t.name!r}: twig segments and leaf types are not integers")
    if tw.segment.min() < 0 or tw.segment.max() >= t.n_segments:
        raise ValueError(f"tree {t.name!r}: a twig hangs on a segment it does not have")
    sizes = np.concatenate([tw.width, tw.leaf_size])
    if not (np.isfinite(tw.start).all() and np.isfinite(tw.end).all()
            and np.isfinite(sizes).all() and (sizes >= 0).all() and (tw.leaf >= 0).all()):
        raise ValueError(f"tree {t.name!r}: non-finite or negative twig geometry, widths, "
                         "leaf sizes or leaf types")


def _check_tree(t: TreeBake, times: np.ndarray) -> None:
    """Arrays that disagree with each other (a damaged file) raise ValueError."""
    frames, s = len(times), t.n_segments
    if t.positions.shape not in ((frames, s, 3), (1, s, 3)) or \
            t.rotations.shape != t.positions.shape[:2] + (4,):
        raise ValueError(f"tree {t.name!r}: positions {t.positions.shape} and rotations "
                         f"{t.rotations.shape} do not fit {frames} frames x {s} segments")
    for key in ("seg_end", "seg_parent", "seg_limb", "width", "leaf", "leaf_size"):
        if getattr(t, key).shape != (s,):
            raise ValueError(f"tree {t.name!r}: {key} has shape {getattr(t, key).shape}, "
                             f"expected ({s},)")
    if len(t.paths) != s:
        raise ValueError(f"tree {t.name!r}: {len(t.paths)} paths for {s} segments")
    if s and (t.seg_start.max() >= len(t.points) or t.seg_end.max() >= len(t.points)):
        raise ValueError(f"tree {t.name!r}: a segment points past its {len(t.points)} points")
    _check_twigs(t)
    try:  # the extra sub-frame samples, when present, keep their contract too
        t.check_extras(times)
    except InputError as exc:
        raise ValueError(str(exc)) from None

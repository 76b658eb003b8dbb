"""Streamed bakes (bake_file.py): a bake written tree by tree as the
simulation finishes each chunk, read back tree by tree; the same bytes as
the in-memory bake saved whole; nothing left behind by a failure."""

import numpy as np
import pytest
from conftest import ROOT

from treebake import bake_file
from treebake.bake_file import BakeWriter, load_bake, save_bake
from treebake.errors import InputError
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.sim import lod, scheduler

FOREST = [str(ROOT / "grammars" / "forest" / f"{g}.lsys") for g in ("conifer", "broadleaf",
                                                                     "birch")]


def forest(count=90, duration=0.5):
    """`count` forest trees in a breeze (two or more chunks), seen by a
    camera that sees the far ones at draft quality (chunks of two
    qualities: not the trees' order), and one tree it never sees (static)."""
    raw = {"name": "stream", "duration": duration, "fps": 24.0, "seed": 3,
           "wind": {"speed": 8.0, "direction": 30.0, "turbulence": 0.3},
           "forest": {"grammars": FOREST, "count": count, "area": [100.0, 100.0],
                      "min_spacing": 6.0},
           "tree": [{"grammar": FOREST[0], "position": [5000.0, 5000.0]}],
           "camera": {"fov": 60.0, "margin": 10.0, "far": 60.0, "far_quality": "draft",
                      "keys": [{"time": 0.0, "position": [-80.0, 0.0, 2.0],
                                "target": [0.0, 0.0, 2.0]}]}}
    return parse_scene(raw, file="<stream test>")


@pytest.fixture(scope="module")
def streamed(tmp_path_factory):
    """The forest baked straight to its file, and how the work went: each
    chunk simulated, each tree written, in the order they happened."""
    path = tmp_path_factory.mktemp("stream") / "stream.npz"
    happened = []
    real_chunk, real_add = scheduler.simulate_chunk, BakeWriter.add

    def chunk(trees, *args, **kw):
        happened.append(("chunk", [t.name for t in trees]))
        return real_chunk(trees, *args, **kw)

    def add(self, index, tree):
        happened.append(("tree", tree.name))
        return real_add(self, index, tree)

    mp = pytest.MonkeyPatch()
    mp.setattr(lod, "simulate_chunk", chunk)
    mp.setattr(BakeWriter, "add", add)
    try:
        bake = bake_scene(forest(), path=path, workers=1)
    finally:
        mp.undo()
    return path, bake, happened


def test_each_chunk_is_written_before_the_next_is_simulated(streamed):
    _, bake, happened = streamed
    chunks = [names for what, names in happened if what == "chunk"]
    assert len(chunks) >= 2 and bake.meta["chunks"] == len(chunks)
    # after the static tree, every chunk's trees are written right after it
    # ran, before the next chunk starts: the bake never holds the whole shot
    first = next(k for k, (what, _) in enumerate(happened) if what == "chunk")
    static = sorted(t.name for t in bake.trees if t.static)
    assert len(static) >= 1 and sorted(n for _, n in happened[:first]) == static
    pos = first
    for names in chunks:
        assert happened[pos] == ("chunk", names)
        assert [n for _, n in happened[pos + 1:pos + 1 + len(names)]] == names
        pos += 1 + len(names)
    assert pos == len(happened)


def test_a_streamed_bake_has_the_bytes_of_the_bake_saved_whole(streamed, tmp_path):
    path, _, _ = streamed
    whole = save_bake(bake_scene(forest(), workers=2), tmp_path / "whole.npz")
    assert whole.read_bytes() == path.read_bytes()
    again = save_bake(load_bake(path), tmp_path / "again.npz")  # order kept on a round trip
    assert again.read_bytes() == path.read_bytes()


def test_a_lazy_bake_reads_a_tree_only_when_asked(streamed, monkeypatch):
    path, bake, _ = streamed
    read = []
    real = bake_file._read_tree
    monkeypatch.setattr(bake_file, "_read_tree", lambda z, i, *a: read.append(i) or real(z, i, *a))
    lazy = load_bake(path, lazy=True)
    assert read == [] and len(lazy.trees) == len(bake.trees) > 80
    eager = load_bake(path)
    read.clear()
    t = lazy.trees[57]
    assert read == [57]
    assert t.name == eager.trees[57].name
    np.testing.assert_array_equal(t.positions, eager.trees[57].positions)
    np.testing.assert_array_equal(lazy.trees[-1].rotations, eager.trees[-1].rotations)
    assert [x.name for x in lazy.trees] == [x.name for x in eager.trees]


def test_a_bake_that_fails_midway_leaves_no_file(tmp_path, monkeypatch):
    path = tmp_path / "stream.npz"
    calls = []
    real = scheduler.simulate_chunk

    def chunk(*args, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt  # Ctrl-C in the second chunk
        return real(*args, **kw)

    monkeypatch.setattr(lod, "simulate_chunk", chunk)
    with pytest.raises(KeyboardInterrupt):
        bake_scene(forest(duration=0.2), path=path, workers=1)
    assert len(calls) == 2
    assert list(tmp_path.iterdir()) == []  # no bake, no temporary


def test_a_damaged_tree_in_a_lazy_bake_is_named_when_read(streamed, tmp_path):
    path, _, _ = streamed
    data = bytearray(path.read_bytes())
    start = data.find(b"tree40.positions.npy")  # its local header; the data follows
    data[start + 200:start + 260] = bytes(60)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(bytes(data))
    lazy = load_bake(bad, lazy=True)  # the directory is whole: it opens
    lazy.trees[3]
    with pytest.raises(InputError, match="damaged or truncated"):
        lazy.trees[40]
    with pytest.raises(InputError, match="damaged or truncated"):
        load_bake(bad)  # read whole: refused at once


@pytest.mark.parametrize("array", [
    np.zeros((241, 28, 3), np.float32), np.arange(7, dtype=np.int64), np.float64(2.5),
    np.zeros((0, 3)), np.array([True, False]), np.frombuffer(b"{}", np.uint8),
    np.array(["ab", "c"]), np.arange(6.0).reshape(2, 3).T, np.arange(6, dtype=">i4")],
    ids=["motion", "ints", "scalar", "empty", "bools", "json", "text", "fortran", "big-endian"])
def test_a_member_reads_as_numpy_reads_it(array):
    """bake_file reads a member's .npy bytes itself (numpy parses every
    header as a Python literal): the same dtype, shape and values, a
    writable array, for the plain arrays a bake holds and any other
    numpy writes (Fortran order: numpy's own reader)."""
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, array, allow_pickle=False)
    got = bake_file._npy(buf.getvalue())
    want = np.lib.format.read_array(io.BytesIO(buf.getvalue()))
    assert got.dtype == want.dtype and got.shape == want.shape
    assert got.tobytes() == want.tobytes() and got.flags.writeable
    with pytest.raises(ValueError):  # cut short: refused, never a short array
        bake_file._npy(buf.getvalue()[:-1] if array.size else buf.getvalue() + b"x")


def test_an_object_member_is_refused_not_unpickled():
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="pickle"):
        bake_file._npy(buf.getvalue())


def world_joints(path, load=True, times=(1, 7, 12)):
    """Every skeleton's joint world transforms at `times` (USD time codes),
    by skeleton prim path, from a stage opened with payloads loaded or not."""
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll if load else Usd.Stage.LoadNone)
    cache, out = UsdSkel.Cache(), {}
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Root):
            root = UsdSkel.Root(prim)
            cache.Populate(root, Usd.PrimDefaultPredicate)
            for b in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
                q = cache.GetSkelQuery(b.GetSkeleton())
                out[str(prim.GetPath())] = np.array([
                    np.array(q.ComputeJointWorldTransforms(UsdGeom.XformCache(Usd.TimeCode(t))))
                    for t in times])
    return out, stage


def test_a_usd_of_many_trees_is_a_root_stage_of_payloads_with_the_same_motion(
        streamed, tmp_path, monkeypatch):
    pytest.importorskip("pxr")  # TREEBAKE_REQUIRE_TOOLS: see conftest
    from treebake import export
    from treebake.export import ExportOptions, export_bake

    monkeypatch.setattr(export, "USD_LAYER_TREES", 50)  # "auto" past 50 trees here

    path, _, _ = streamed
    bake = load_bake(path, lazy=True)
    one = export_bake(bake, tmp_path, "one", ExportOptions(formats=("usd",), usd_layers="one"))
    layered = export_bake(bake, tmp_path, "many", ExportOptions(formats=("usd",)))  # auto
    assert one.manifest["usd"]["layers"] == "one"
    assert layered.manifest["usd"]["layers"] == "tree"
    assert layered.manifest["usd"]["tree_layers_validated"] == 20
    layers = sorted((tmp_path / "many" / "many.trees").iterdir())
    assert len(layers) == len(bake.trees)
    unloaded, stage = world_joints(tmp_path / "many" / "many.usd", load=False)
    assert unloaded == {}  # opened with nothing loaded: no skeleton read
    assert len([p for p in stage.TraverseAll() if p.HasPayload()]) == len(bake.trees)
    whole, _ = world_joints(tmp_path / "one" / "one.usd")
    loaded, _ = world_joints(tmp_path / "many" / "many.usd")
    assert len(whole) == sum(not t.static for t in bake.trees) > 50
    assert {k.replace("/many/", "/one/") for k in loaded} == set(whole)
    for key, value in loaded.items():
        np.testing.assert_allclose(value, whole[key.replace("/many/", "/one/")], atol=1e-6)
    # the root is validated unloaded: a payload whose layer is gone is an error
    from treebake.exchange.usd import validate

    assert validate(tmp_path / "many" / "many.usd", load=False) == []
    layers[3].unlink()
    assert validate(tmp_path / "many" / "many.usd", load=False) == [
        f"MissingPayload: /many/{layers[3].stem}: ./many.trees/{layers[3].name} not found"]


@pytest.mark.parametrize("fmt", ["usd", "glb"])
def test_files_written_by_worker_processes_are_the_same_bytes(streamed, tmp_path, monkeypatch,
                                                              fmt):
    """Two worker processes (export_pool.py) write the USD tree layers or
    the glb files of 30 trees, each from its own lazy read of the bake:
    every file, the manifest (with each tree's facts, noted in the workers)
    included, is the bytes one process writes."""
    if fmt == "usd":
        pytest.importorskip("pxr")  # TREEBAKE_REQUIRE_TOOLS: see conftest
    from treebake import export_pool
    from treebake.export import ExportOptions, export_bake

    monkeypatch.setattr(export_pool, "MIN_TREES_PER_WORKER", 20)  # 91 trees: two workers
    pools = []
    for maker in ("layer_writer", "file_writer"):
        def spy(source, workers, facts, real=getattr(export_pool, maker), kind=maker):
            pools.append((kind, workers))
            return real(source, workers, facts)

        monkeypatch.setattr(export_pool, maker, spy)
    path, _, _ = streamed
    opts = dict(formats=(fmt,), usd_layers="tree", trees_per_file=30)
    for workers, name in ((1, "serial"), (2, "pool")):
        export_bake(load_bake(path, lazy=True), tmp_path, "shot",
                    ExportOptions(**opts, workers=workers))
        (tmp_path / "shot").rename(tmp_path / name)
    assert pools == [("layer_writer" if fmt == "usd" else "file_writer", 2)]  # serial: none
    files = sorted(p.relative_to(tmp_path / "serial") for p in (tmp_path / "serial").rglob("*")
                   if p.is_file())
    assert len(files) > (90 if fmt == "usd" else 4)
    assert files == sorted(p.relative_to(tmp_path / "pool") for p in
                           (tmp_path / "pool").rglob("*") if p.is_file())
    for f in files:
        assert (tmp_path / "serial" / f).read_bytes() == (tmp_path / "pool" / f).read_bytes(), f


def test_gltf_of_many_trees_comes_in_files_of_n_trees_with_every_tree_once(streamed, tmp_path):
    from treebake.exchange.gltf_read import read_gltf_bake
    from treebake.export import ExportOptions, export_bake

    path, _, _ = streamed
    bake = load_bake(path)
    rep = export_bake(bake, tmp_path, "f", ExportOptions(formats=("glb",), trees_per_file=40))
    parts = sorted((tmp_path / "f").glob("f.part*.glb"))
    assert [p.name for p in parts] == ["f.part0001.glb", "f.part0002.glb", "f.part0003.glb"]
    assert not (tmp_path / "f" / "f.glb").exists()
    seen = {}
    for p in parts:
        for t in read_gltf_bake(p).trees:
            assert t.name not in seen
            seen[t.name] = t
    moving = {t.name: t for t in bake.trees if not t.static}
    assert set(moving) <= set(seen) and len(seen) == len(bake.trees)
    for name, t in moving.items():  # within the keyframe reduction's tolerance
        assert np.abs(seen[name].positions - t.positions).max() < 0.004
    assert rep.manifest["settings"]["trees_per_file"] == 40


def test_a_glb_export_reports_its_trees_as_each_file_is_written(streamed, tmp_path):
    """Progress of a glb export in files of 40 trees: the trees written so
    far after each file (its file already on disk), not one tick at the end."""
    from treebake.export import ExportOptions, export_bake

    path, _, _ = streamed
    bake = load_bake(path, lazy=True)
    ticks = []

    def progress(stage, done, total):
        if stage == "glb":
            parts = len(list((tmp_path / "f").glob("f.part*.glb")))
            ticks.append((done, total, parts))

    export_bake(bake, tmp_path, "f", ExportOptions(formats=("glb",), trees_per_file=40),
                progress=progress)
    n = len(bake.trees)
    assert n == 91
    assert ticks == [(0, n, 0), (40, n, 1), (80, n, 2), (n, n, 3)]


def _obj_objects(path) -> dict[str, list[str]]:
    """An OBJ file's objects: name -> its `v` and `vn` lines (the posed mesh)."""
    objects: dict[str, list[str]] = {}
    current = None
    for line in path.read_text().splitlines():
        if line.startswith("o "):
            current = objects.setdefault(line[2:], [])
        elif line.startswith(("v ", "vn ")):
            current.append(line)
    return objects


def test_obj_of_many_trees_comes_in_sequences_of_n_trees(streamed, tmp_path, monkeypatch):
    """An OBJ export in sequences of 40 trees (91 trees: three) poses every
    tree as the one-sequence export does, each tree in exactly one
    sequence, one shared .mtl; the disk check counts every sequence's first
    frame (the bytes it then wrote), not the first sequence's alone."""
    from treebake.exchange import obj
    from treebake.export import ExportOptions, export_bake

    path, _, _ = streamed
    measured = []
    real = obj.check_room
    monkeypatch.setattr(obj, "check_room", lambda out, size, frames, stride:
                        measured.append(size) or real(out, size, frames, stride))
    one = export_bake(load_bake(path, lazy=True), tmp_path / "one", "f",
                      ExportOptions(formats=("obj",), obj_stride=4))
    parts = export_bake(load_bake(path, lazy=True), tmp_path / "parts", "f",
                        ExportOptions(formats=("obj",), obj_stride=4, trees_per_file=40))
    folder = tmp_path / "parts" / "f" / "obj"
    stems = sorted({p.name.rsplit(".", 2)[0] for p in folder.glob("f.part*.obj")})
    assert stems == ["f.part0001", "f.part0002", "f.part0003"]
    assert sorted(p.name for p in folder.glob("*.mtl")) == ["f.mtl"]
    frames = sorted(p.name.rsplit(".", 2)[1] for p in folder.glob("f.part0001.*.obj"))
    assert len(frames) == 4 and frames == sorted(
        p.name.rsplit(".", 2)[1] for p in (tmp_path / "one" / "f" / "obj").glob("f.*.obj"))
    for frame in frames:
        whole = _obj_objects(tmp_path / "one" / "f" / "obj" / f"f.{frame}.obj")
        seen: dict[str, list[str]] = {}
        for stem in stems:
            got = _obj_objects(folder / f"{stem}.{frame}.obj")
            assert not set(got) & set(seen)
            seen.update(got)
        assert seen == whole and len(seen) == 91
    first = sum((folder / f"{stem}.{frames[0]}.obj").stat().st_size for stem in stems)
    assert measured[-1] == first > (folder / f"f.part0001.{frames[0]}.obj").stat().st_size
    assert parts.manifest["frames"]["obj"]["files"] == 12
    assert parts.manifest["frames"]["obj"]["sequences"] == 3
    assert "sequences" not in one.manifest["frames"]["obj"]

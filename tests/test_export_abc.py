"""Alembic export (issue 41): the archive read back with the Alembic library
itself (tests/tools/abcread.py, PyAlembic from alembic3d) gives every
segment's and projectile's world transform of the bake on every frame
within 1 mm; the xform hierarchy and names are the glTF's; the point
caches are the posed mesh of every frame (the OBJ sequence's vertices);
frame N is sampled at N / fps s; the same bake gives the same bytes;
without the extra, asking for abc is exit 2 before any simulation."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

import abcread
from bakes import preset_bake
from conftest import ROOT, need
from treebake.bake_file import load_bake
from treebake.exchange.mesh import pose
from treebake.export import ExportOptions, export_bake
from treebake.names import joint_names

# Y up (file) -> Z up (bake): (x, y, z) -> (x, -z, y)
Z_FROM_Y = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
GOLDEN = ROOT / "tests" / "golden" / "sapling-box.npz"


@pytest.fixture
def alembic():
    """alembic3d (treebake[alembic]): skip without it, fail under
    TREEBAKE_REQUIRE_TOOLS=1. The missing-extra tests below run without it."""
    return need("alembic3d")


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 3) rotated by unit quaternions q (..., 4) x y z w (written
    out here, not treebake's: the test's own reading of the bake)."""
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def world_z_up(world_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 4, 4) file world matrices -> origin (F, 3) and rotation (F, 3, 3), Z up."""
    origin = world_y[:, :3, 3] @ Z_FROM_Y.T
    rot = Z_FROM_Y @ world_y[:, :3, :3] @ Z_FROM_Y.T
    return origin, rot


def export(bake, folder, name, **kw):
    return export_bake(bake, folder, name, ExportOptions(formats=("abc",), **kw))


def segment_errors(archive, tree) -> dict:
    """Worst differences between the archive's segment xforms and the bake
    over every frame: origin and tip (m), angle (rad)."""
    names = joint_names(tree.name, tree.paths)
    path = {}
    for s, name in enumerate(names):  # the hierarchy follows the segments
        p = int(tree.seg_parent[s])
        path[s] = f"/{tree.name}/{name}" if p < 0 else f"{path[p]}/{name}"
    vec = tree.points[tree.seg_end] - tree.points[tree.seg_start]
    worst = {"origin": 0.0, "tip": 0.0, "angle": 0.0}
    for s in range(tree.n_segments):
        origin, rot = world_z_up(archive.world[path[s]])
        want = tree.positions[:, s].astype(np.float64)
        q = tree.rotations[:, s].astype(np.float64)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        tip_want = want + rotate(q, np.broadcast_to(vec[s], want.shape))
        tip = origin + rot @ vec[s]
        worst["origin"] = max(worst["origin"], float(np.linalg.norm(origin - want, axis=1).max()))
        worst["tip"] = max(worst["tip"], float(np.linalg.norm(tip - tip_want, axis=1).max()))
        for axis in np.eye(3):  # each rotated axis: the angle between file and bake
            a = rot @ axis
            b = rotate(q, np.broadcast_to(axis, want.shape))
            angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1))
            worst["angle"] = max(worst["angle"], float(angle.max()))
    return worst


@pytest.mark.parametrize("preset", ["demo", "felling", "boxes"])
def test_every_segment_world_transform_reads_back_within_1_mm(alembic, tmp_path, preset):
    """demo: the README's three trees; felling: a tree cut and falling fast
    (large rotations); boxes: projectiles and broken branches."""
    bake = preset_bake(preset)
    n = len(bake.times)
    report = export(bake, tmp_path, preset)
    archive = abcread.read(report.folder / f"{preset}.abc", n)
    worst = {"origin": 0.0, "tip": 0.0, "angle": 0.0}
    moving = 0.0
    for tree in bake.trees:
        assert not tree.static
        e = segment_errors(archive, tree)
        worst = {k: max(worst[k], e[k]) for k in worst}
        moving = max(moving, float(np.abs(np.diff(tree.positions, axis=0)).max()))
    o = bake.objects
    if o is not None and len(o.sizes):
        for k in range(len(o.sizes)):
            origin, _ = world_z_up(archive.world[f"/projectile_{k}"])
            worst["origin"] = max(worst["origin"], float(
                np.linalg.norm(origin - o.positions[:, k], axis=1).max()))
    print(f"{preset}: worst origin {worst['origin'] * 1e3:.2e} mm, tip "
          f"{worst['tip'] * 1e3:.2e} mm, angle {np.degrees(worst['angle']):.2e} deg "
          f"over {n} frames")
    assert moving > 5e-3  # frames differ: a wrong frame would show
    assert worst["origin"] < 1e-3 and worst["tip"] < 1e-3, worst
    assert worst["angle"] < 1e-4, worst


def test_hierarchy_and_names_are_the_gltfs(alembic, tmp_path):
    bake = preset_bake("boxes")
    report = export(bake, tmp_path, "job")
    archive = abcread.read(report.folder / "job.abc", len(bake.times))
    top = {p for p, parent in archive.parents.items() if parent == ""}
    want = set()
    for tree in bake.trees:
        want |= {f"/{tree.name}", f"/{tree.name}_mesh"}
        names = joint_names(tree.name, tree.paths)
        for s, name in enumerate(names):
            p = int(tree.seg_parent[s])
            parent = f"/{tree.name}" if p < 0 else None
            found = [q for q, nm in archive.names.items() if nm == name]
            assert len(found) == 1, name
            if parent is None:
                assert archive.names[archive.parents[found[0]]] == names[p]
            else:
                assert archive.parents[found[0]] == parent
        assert f"/{tree.name}_mesh/{tree.name}_geo" in archive.meshes
    want |= {f"/projectile_{k}" for k in range(len(bake.objects.sizes))}
    assert top == want
    for k, (shape, size) in enumerate(zip(bake.objects.shapes, bake.objects.sizes)):
        assert f"/projectile_{k}/{shape}_{round(float(size) * 1000)}mm" in archive.meshes
    assert report.manifest["alembic"]["xforms"] == (
        sum(t.n_segments for t in bake.trees) + len(bake.objects.sizes))


def test_point_cache_is_the_posed_mesh_of_every_frame(alembic, tmp_path):
    """The mesh samples are the skinned mesh (treebake's pose(), the OBJ
    sequence's vertices) of each frame; faces are the mesh's triangles wound
    the other way (Alembic's clockwise); one face set per material."""
    bake = preset_bake("demo")
    report = export(bake, tmp_path, "demo")
    n = len(bake.times)
    archive = abcread.read(report.folder / "demo.abc", n)
    for tree, mesh in zip(bake.trees, report_meshes(bake)):
        m = archive.meshes[f"/{tree.name}_mesh/{tree.name}_geo"]
        assert len(m.positions) == n
        np.testing.assert_allclose(m.times, (1 + np.arange(n)) / bake.fps, rtol=0, atol=1e-12)
        for f in (0, n // 2, n - 1):
            p, nrm = pose(mesh, tree, f)
            got = m.positions[f].astype(np.float64) @ Z_FROM_Y.T
            assert np.abs(got - p).max() < 1e-5  # float32 of a few metres
            got_n = m.normals[f].astype(np.float64) @ Z_FROM_Y.T
            assert np.abs(got_n - nrm).max() < 1e-5
        faces = mesh.faces()
        np.testing.assert_array_equal(m.faces, faces[:, [0, 2, 1]])
        np.testing.assert_array_equal(m.uv_indices, m.faces.ravel())
        np.testing.assert_array_equal(m.normal_indices, m.faces.ravel())
        np.testing.assert_allclose(m.uvs, mesh.uvs, atol=1e-7)
        assert m.uv_scope == "kFacevaryingScope"
        first = 0
        for part in mesh.parts:
            np.testing.assert_array_equal(m.face_sets[part.material],
                                          np.arange(first, first + len(part.faces)))
            first += len(part.faces)
        # as written, the winding is clockwise seen from outside: its normal
        # points against the outward vertex normals
        v = m.positions[0].astype(np.float64)
        a, b, c = v[m.faces[:, 0]], v[m.faces[:, 1]], v[m.faces[:, 2]]
        face_n = np.cross(b - a, c - a)
        outward = m.normals[0][m.faces].sum(axis=1)
        bark = m.face_sets["bark"]
        assert ((face_n[bark] * outward[bark]).sum(-1) < 0).mean() > 0.99


def report_meshes(bake):
    from treebake.exchange.mesh import MeshOptions
    from treebake.tree_meshes import build_meshes

    return build_meshes(bake, MeshOptions())[0]


def test_static_trees_are_constant_meshes(alembic, tmp_path):
    bake = preset_bake("calm")
    assert all(t.static for t in bake.trees)
    report = export(bake, tmp_path, "calm")
    archive = abcread.read(report.folder / "calm.abc", 1)
    for tree, mesh in zip(bake.trees, report_meshes(bake)):
        m = archive.meshes[f"/{tree.name}/{tree.name}_geo"]
        assert len(m.positions) == 1
        got = m.positions[0].astype(np.float64) @ Z_FROM_Y.T
        assert np.abs(got - mesh.positions).max() < 1e-5
    assert report.manifest["alembic"]["point_caches"] == 0


@pytest.mark.parametrize("start", [0, 1, 101])
def test_frame_n_is_sampled_at_n_over_fps(alembic, tmp_path, start):
    """The convention of glTF (keys at N / fps s) and USD (time code N):
    bake frame f is frame number N = frame_start + f, at N / fps s."""
    bake = load_bake(GOLDEN)
    n, fps = len(bake.times), bake.fps
    report = export(bake, tmp_path, "box", frame_start=start)
    archive = abcread.read(report.folder / "box.abc", n)
    np.testing.assert_allclose(archive.times * fps, start + np.arange(n), rtol=0, atol=1e-9)
    assert archive.start_end[0] * fps == pytest.approx(start, abs=1e-9)
    assert archive.start_end[1] * fps == pytest.approx(start + n - 1, abs=1e-9)
    m = report.manifest["alembic"]
    assert m["frames"] == [start, start + n - 1]
    assert m["start_s"] == pytest.approx(start / fps) and m["frame_s"] == pytest.approx(1 / fps)
    assert m["end_s"] == pytest.approx((start + n - 1) / fps)


def test_same_bake_same_bytes(alembic, tmp_path):
    """No time stamps: two exports of one bake are byte-identical (the
    archive records the Alembic library's version, the same here)."""
    bake = preset_bake("boxes")
    a = export(bake, tmp_path / "a", "job")
    b = export(bake, tmp_path / "b", "job")
    one = (a.folder / "job.abc").read_bytes()
    assert one == (b.folder / "job.abc").read_bytes()
    assert a.manifest["files"] == b.manifest["files"]
    assert b"_ai_DateWritten" not in one  # CreateArchiveWithInfo's time stamp
    assert [p.name for p in a.folder.iterdir() if p.name.startswith(".")] == []  # no temp files


def _blocked_env(tmp_path) -> dict:
    """An environment in which `import alembic3d` fails (a stand-in package
    first on the path), as without the extra."""
    stub = tmp_path / "stub" / "alembic3d"
    stub.mkdir(parents=True)
    (stub / "__init__.py").write_text(  # what Python raises when it is not installed
        "raise ModuleNotFoundError(\"No module named 'alembic3d'\", name='alembic3d')\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(stub.parent), env.get("PYTHONPATH", "")])
    return env


def test_without_the_extra_abc_is_exit_2_before_simulating(tmp_path):
    env = _blocked_env(tmp_path)
    tb = [sys.executable, "-m", "treebake.cli"]
    out = tmp_path / "out"
    bake = subprocess.run([*tb, "bake", "sapling", "--duration", "0.2", "--format", "glb,abc",
                           "--out", str(out)], capture_output=True, text=True, env=env, check=False,
                          timeout=120, cwd=tmp_path)
    assert bake.returncode == 2, bake.stderr
    assert "pip install 'treebake[alembic]'" in bake.stderr and "Traceback" not in bake.stderr
    assert "simulating" not in bake.stderr and not out.exists()  # nothing simulated, no folder
    scene = tmp_path / "s.toml"
    scene.write_text('name = "s"\nduration = 0.2\nformats = ["abc"]\n[[tree]]\n'
                     'grammar = "sapling"\n')
    by_scene = subprocess.run([*tb, "bake", str(scene), "-q", "--out", str(out)],
                              capture_output=True, text=True, env=env, timeout=120, check=False)
    assert by_scene.returncode == 2 and "treebake[alembic]" in by_scene.stderr, by_scene.stderr
    assert not out.exists()
    exp = subprocess.run([*tb, "export", str(GOLDEN), "--format", "abc", "--out", str(out)],
                         capture_output=True, text=True, env=env, timeout=120, check=False)
    assert exp.returncode == 2 and "treebake[alembic]" in exp.stderr, exp.stderr
    assert "Traceback" not in exp.stderr and not out.exists()
    jobs = tmp_path / "jobs.toml"
    jobs.write_text(f'[[job]]\nname = "j"\ngrammar = "{ROOT / "grammars" / "sapling.lsys"}"\n'
                    'duration = 0.2\nformats = ["abc"]\n')
    batch = subprocess.run([*tb, "batch", str(jobs), "--jobs", "1", "--out", str(out)],
                           capture_output=True, text=True, env=env, timeout=120, check=False)
    assert batch.returncode == 2 and "treebake[alembic]" in batch.stderr, batch.stderr


def test_cli_exports_abc_with_the_manifest(alembic, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "treebake.cli", "export", str(GOLDEN),
                           "--format", "abc", "--out", str(tmp_path), "--name", "box", "--json"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    manifest = json.loads((tmp_path / "box" / "manifest.json").read_text())
    assert [f["path"] for f in manifest["files"]] == ["box.abc"]
    assert manifest["alembic"]["up_axis"] == "Y" and manifest["alembic"]["point_caches"] == 1

"""USD export: pxr.UsdValidation finds zero errors; stage metadata, frame
range and joints read back with pxr; UsdSkel's own skinning of the file
reproduces our posed mesh; byte-identical re-export."""

import sys
from pathlib import Path

import numpy as np
import pytest

pxr = pytest.importorskip("pxr", reason="usd-core is an optional dependency")
from pxr import Usd, UsdGeom, UsdSkel

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from treebake.exchange.mesh import pose, tree_mesh
from treebake.exchange.usd import export_usd, validate

C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])


@pytest.fixture(scope="module")
def boxes_usd(tmp_path_factory):
    bake = preset_bake("boxes")
    meshes = [tree_mesh(t) for t in bake.trees]
    folder = tmp_path_factory.mktemp("usd")
    return bake, meshes, export_usd(bake, meshes, folder, "job"), folder


def test_usd_validates_with_zero_errors(boxes_usd, tmp_path):
    res = boxes_usd[2]
    assert res.validation_errors == []
    assert validate(res.files[0]) == []
    calm = preset_bake("calm")  # static trees: plain meshes
    text = export_usd(calm, [tree_mesh(t) for t in calm.trees], tmp_path, "calm", ascii=True)
    assert text.files[0].suffix == ".usda" and text.validation_errors == []


def test_usd_metadata_frame_range_and_joints_read_back(boxes_usd):
    bake, _, res, _ = boxes_usd
    stage = Usd.Stage.Open(str(res.files[0]))
    n = len(bake.times)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == bake.fps == stage.GetFramesPerSecond()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, float(n))
    assert stage.GetDefaultPrim().GetName() == "job"
    skels = [UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton)]
    assert [len(s.GetJointsAttr().Get()) for s in skels] == [t.n_segments for t in bake.trees]
    for s, t in zip(skels, bake.trees):
        assert list(s.GetPrim().GetAttribute("treebake:segmentPaths").Get()) == t.paths
        anim = UsdSkel.Animation(s.GetPrim().GetChild("Anim"))
        samples = anim.GetRotationsAttr().GetTimeSamples()
        # every frame, plus the bake's sub-frame samples where a bone turned fast
        extra = list(1.0 + np.asarray(t.extra_times) * bake.fps)
        assert samples == pytest.approx(sorted([float(f) for f in range(1, n + 1)] + extra))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/job/Projectiles/projectile_0"))
    assert xf.GetTimeSamples()[-1] == float(n)


def test_usdskel_skinning_reproduces_the_posed_mesh(boxes_usd):
    bake, meshes, res, _ = boxes_usd
    stage = Usd.Stage.Open(str(res.files[0]))
    cache = UsdSkel.Cache()
    for tree, mesh in zip(bake.trees, meshes):
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/job/{tree.name}"))
        cache.Populate(root, Usd.PrimDefaultPredicate)
        (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        bark = next(q for q in binding.GetSkinningTargets() if q.GetPrim().GetName() == "bark")
        used = np.unique(mesh.parts[0].faces)
        for f in (0, len(bake.times) // 2, len(bake.times) - 1):
            code = float(f + 1)
            xforms = query.ComputeSkinningTransforms(code)
            pts = UsdGeom.Mesh(bark.GetPrim()).GetPointsAttr().Get(code)
            assert bark.ComputeSkinnedPoints(xforms, pts, code)
            ours, _ = pose(mesh, tree, f)
            np.testing.assert_allclose(np.array(pts), ours[used] @ C.T, atol=1e-4)


def test_usd_is_byte_reproducible(boxes_usd, tmp_path):
    bake, meshes, res, _ = boxes_usd
    again = export_usd(bake, meshes, tmp_path, "job", check=False)
    assert again.files[0].read_bytes() == res.files[0].read_bytes()



def test_without_usd_core_usd_is_exit_2_before_simulating(tmp_path):
    """As for Alembic: a missing extra is named before any work (it was
    exit 1 after the simulation)."""
    import os
    import subprocess
    import sys

    stub = tmp_path / "stub" / "pxr"
    stub.mkdir(parents=True)
    (stub / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'pxr'\", name='pxr')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(stub.parent),
                                                       os.environ.get("PYTHONPATH", "")]))
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "treebake.cli", "bake", "sapling", "--duration",
                           "0.2", "--format", "glb,usd", "--out", str(out)],
                          capture_output=True, text=True, env=env, check=False, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "pip install 'treebake[usd]'" in done.stderr and "Traceback" not in done.stderr
    assert "simulating" not in done.stderr and not out.exists()


@pytest.mark.parametrize("message, full", [
    ("Error occurred writing file: No space left on device", True),
    ("Error occurred writing file: Input/output error", False)])
def test_a_layer_usd_cannot_write_is_an_output_error_and_leaves_nothing(tmp_path, message, full):
    """A layer is exported straight into the temporary file that replaces
    it: when USD fails (a full disk, found by writing into a tiny tmpfs),
    the error names the file, a full disk as such, and no file is left."""
    from treebake.errors import OutputError
    from treebake.exchange import usd

    class Layer:
        def Export(self, path):
            Path(path).write_bytes(b"PXR-USDC half a layer")
            raise pxr.Tf.ErrorException(f"\n\tError in 'WriteToAsset' : '{message}'")

    w = usd._Writer(preset_bake("calm"), "job")
    w.layer = Layer()
    target = tmp_path / "job.usd"
    with pytest.raises((OutputError, OSError)) as caught:
        w.save(target)
    if full:
        assert isinstance(caught.value, OutputError)
        assert f"{target}: the disk is full" in str(caught.value)
        assert "nothing of this file was kept" in str(caught.value)
    else:  # the CLI prints an OSError as "treebake: error: FILE: MESSAGE", exit 1
        assert caught.value.filename == str(target)
        assert caught.value.strerror == f"USD could not write the layer: {message}"
    assert list(tmp_path.iterdir()) == []


def test_a_layer_export_that_reports_failure_leaves_no_empty_file(tmp_path):
    """Export returning False without raising: an error, not the empty
    temporary file renamed over the target."""
    from treebake.exchange import usd

    w = usd._Writer(preset_bake("calm"), "job")
    w.layer = type("Layer", (), {"Export": lambda self, path: False})()
    with pytest.raises(OSError, match="USD could not write the layer"):
        w.save(tmp_path / "job.usd")
    assert list(tmp_path.iterdir()) == []

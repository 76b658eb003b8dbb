"""One shot over a Dask cluster (`bake --scheduler`, issue 39): its chunks
run as tasks on the workers and the bake is byte-identical to a local one,
even when a worker is killed mid-shot; a bad address is a clear error."""

import os
import signal

import pytest
from treebake.bake_file import save_bake
from treebake.cli import main
from treebake.grow import grow
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.sim.lod import chunks
from treebake.sim.rigging import rig_scene

SCENE = {"name": "shot", "duration": 1.0, "fps": 24, "seed": 3,
         "forest": {"grammars": ["forest/conifer", "forest/broadleaf", "forest/birch"],
                    "count": 150, "area": [120.0, 120.0], "min_spacing": 6.0},
         "wind": {"beaufort": "strong breeze", "direction": 30.0, "turbulence": 0.3}}


def scene():
    return parse_scene(SCENE, file="<dask>")


def test_the_shot_has_several_chunks():
    s = scene()
    rigged = rig_scene(s, grow(s), None, None)
    assert len(chunks(rigged.trees, rigged.qualities, whole=False)) >= 3


def test_a_shot_on_a_dask_cluster_is_the_local_bake_even_when_a_worker_dies(tmp_path):
    distributed = pytest.importorskip("distributed")
    local = save_bake(bake_scene(scene(), workers=1), tmp_path / "local.npz").read_bytes()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        pids = sorted(client.run(os.getpid).values())
        killed = []

        def kill_one(done, total):  # the first progress report: chunks are running
            if not killed:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])

        remote = bake_scene(scene(), scheduler=cluster.scheduler_address, progress=kill_one)
        assert killed
    assert save_bake(remote, tmp_path / "dask.npz").read_bytes() == local


def test_a_bad_scheduler_address_is_exit_2_before_any_work(tmp_path, capsys):
    code = main(["bake", "sapling", "--out", str(tmp_path), "--scheduler", "localhost:8786"])
    assert code == 2
    assert "is not a scheduler address (tcp://HOST:PORT" in capsys.readouterr().err
    code = main(["bake", "sapling", "--out", str(tmp_path), "--solver", "full",
                 "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2 and "--solver full simulates the scene as one model" in \
        capsys.readouterr().err
    assert not list(tmp_path.iterdir())

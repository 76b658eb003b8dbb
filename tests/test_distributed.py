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


def test_a_batch_job_with_a_scheduler_key_bakes_its_chunks_there(tmp_path):
    """The job file's `scheduler` key: the job's chunks on the cluster, the
    bake the local one's bytes, and the key no input of the fingerprint."""
    distributed = pytest.importorskip("distributed")
    from treebake.batch_jobs import load_jobs

    (tmp_path / "shot.toml").write_text(
        'name = "shot"\nduration = 0.5\nfps = 24\nseed = 3\n'
        '[forest]\ngrammars = ["forest/conifer", "forest/birch"]\ncount = 80\n'
        'area = [100.0, 100.0]\nmin_spacing = 6.0\n'
        '[wind]\nbeaufort = "strong breeze"\ndirection = 30.0\n')
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        jobs = tmp_path / "jobs.toml"
        jobs.write_text(f'[[job]]\nname = "remote"\nscene = "shot.toml"\nformats = ["npz"]\n'
                        f'scheduler = "{cluster.scheduler_address}"\n'
                        '[[job]]\nname = "local"\nscene = "shot.toml"\nformats = ["npz"]\n')
        remote, local = load_jobs(jobs)
        assert remote.scheduler == cluster.scheduler_address and local.scheduler is None
        assert remote.inputs_digest() == local.inputs_digest()
        assert main(["batch", str(jobs), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 0
        ran = {str(t[0]) for t in cluster.scheduler.transition_log}
    assert any(k.startswith("treebake-chunk-") for k in ran)  # the chunks went to the cluster
    a = (tmp_path / "out" / "remote" / "remote.npz").read_bytes()
    b = (tmp_path / "out" / "local" / "local.npz").read_bytes()
    assert a == b


def test_a_batch_scheduler_key_is_checked(tmp_path, capsys):
    (tmp_path / "jobs.toml").write_text('[[job]]\ngrammar = "x.lsys"\nscheduler = "host:1"\n')
    (tmp_path / "x.lsys").write_text("")
    assert main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path)]) == 2
    assert "job[0].scheduler = 'host:1' is not a Dask scheduler address" in \
        capsys.readouterr().err

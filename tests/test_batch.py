"""treebake batch: parallel jobs, a broken job does not stop the others,
killed-and-restarted batches produce the same bytes and skip finished jobs,
output names stay inside the output folder, Dask runs the same jobs."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from treebake.batch import load_jobs, run_batch
from treebake.errors import SceneError

SAPLING = "grammars/sapling.lsys"


def job_file(tmp_path: Path, root: Path, body: str, name: str = "jobs.toml") -> Path:
    """A job file in tmp_path whose paths point into the repository."""
    path = tmp_path / name
    path.write_text(body.replace("ROOT", str(root)))
    return path


QUICK = """
[defaults]
duration = 0.4
fps = 12
formats = ["glb"]
quality = "draft"

[[job]]
name = "a"
grammar = "ROOT/grammars/sapling.lsys"
seed = 1

[[job]]
name = "b"
scene = "ROOT/presets/breeze.toml"

[[job]]
name = "c"
grammar = "ROOT/grammars/palm.lsys"
"""


def tree_bytes(folder: Path) -> dict[str, bytes]:
    """Every output file's bytes (not the run's own summary, which has times)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name != "batch-summary.json"}


def test_products_expand_and_names_are_checked(tmp_path, root):
    jobs = load_jobs(job_file(tmp_path, root, """
[[product]]
grammars = ["ROOT/grammars/oak.lsys", "ROOT/grammars/spruce.lsys"]
scenes = ["ROOT/presets/breeze.toml", "ROOT/presets/gale.toml"]
seeds = [1, 2]
"""))
    assert len(jobs) == 8
    assert {j.name for j in jobs} >= {"oak-breeze-s1", "spruce-gale-s2"}
    for bad in ["../escape", "/abs", "a/b", ".."]:
        with pytest.raises(SceneError, match="plain name"):
            load_jobs(job_file(tmp_path, root, f'[[job]]\nname = "{bad}"\n'
                                               f'grammar = "ROOT/{SAPLING}"\n'))
    with pytest.raises(SceneError, match=r"job\[0\]\.duration = -1 is out of range"):
        load_jobs(job_file(tmp_path, root, f'[[job]]\ngrammar = "ROOT/{SAPLING}"\n'
                                           "duration = -1\n"))
    with pytest.raises(SceneError, match="two jobs are named"):
        load_jobs(job_file(tmp_path, root, f'[[job]]\ngrammar = "ROOT/{SAPLING}"\n'
                                           f'[[job]]\ngrammar = "ROOT/{SAPLING}"\n'))


def test_a_broken_job_does_not_stop_the_others(tmp_path, root):
    bad = tmp_path / "bad.lsys"
    bad.write_text("axiom: F\nF -> F(1/0)\niterations: 2\n")  # division by zero when derived
    jobs = load_jobs(job_file(tmp_path, root, QUICK + f'\n[[job]]\nname = "broken"\n'
                                                      f'grammar = "{bad}"\n'))
    out = tmp_path / "out"
    results = run_batch(jobs, out, workers=2)
    status = {r.name: r.status for r in results}
    assert status == {"a": "done", "b": "done", "c": "done", "broken": "failed"}
    broken = next(r for r in results if r.name == "broken")
    assert "bad.lsys" in broken.message and "division" in broken.message
    for name in "abc":
        record = json.loads((out / name / "job.json").read_text())
        assert f"{name}.glb" in record["files"] and f"{name}.npz" in record["files"]
    assert not (out / "broken" / "job.json").exists()
    # a rerun skips what is done and tries the broken one again
    again = {r.name: r.status for r in run_batch(jobs, out, workers=1)}
    assert again == {"a": "skipped", "b": "skipped", "c": "skipped", "broken": "failed"}


def test_parallel_equals_serial_byte_for_byte(tmp_path, root):
    jobs = load_jobs(job_file(tmp_path, root, QUICK))
    run_batch(jobs, tmp_path / "serial", workers=1)
    run_batch(jobs, tmp_path / "parallel", workers=2)
    assert tree_bytes(tmp_path / "serial") == tree_bytes(tmp_path / "parallel")


def test_killed_batch_resumes_to_the_same_bytes(tmp_path, root):
    body = QUICK.replace("duration = 0.4", "duration = 1.5")
    jobs_path = job_file(tmp_path, root, body)
    clean = tmp_path / "clean"
    run_batch(load_jobs(jobs_path), clean, workers=1)
    killed = tmp_path / "killed"
    cmd = [sys.executable, "-m", "treebake.cli", "batch", str(jobs_path), "--out", str(killed),
           "--jobs", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 240
    while not (killed / "a" / "job.json").exists():  # job a finished, b under way
        assert time.time() < deadline and proc.poll() is None
        time.sleep(0.05)
    time.sleep(0.3)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (killed / "c" / "job.json").exists()
    done = subprocess.run([*cmd, "--json"], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    status = {r["name"]: r["status"] for r in summary["results"]}
    assert status["a"] == "skipped" and status["c"] == "done"
    assert tree_bytes(killed) == tree_bytes(clean)  # no leftovers, same bytes


def test_force_redoes_finished_jobs_and_changed_inputs_are_redone(tmp_path, root):
    grammar = tmp_path / "g.lsys"
    grammar.write_text((root / SAPLING).read_text())
    jobs_path = job_file(tmp_path, root, f'[defaults]\nduration = 0.3\nfps = 12\n'
                                         f'[[job]]\nname = "g"\ngrammar = "{grammar}"\n')
    out = tmp_path / "out"
    assert run_batch(load_jobs(jobs_path), out, workers=1)[0].status == "done"
    assert run_batch(load_jobs(jobs_path), out, workers=1)[0].status == "skipped"
    assert run_batch(load_jobs(jobs_path), out, workers=1, force=True)[0].status == "done"
    grammar.write_text(grammar.read_text().replace("seed: 2", "seed: 3"))
    assert run_batch(load_jobs(jobs_path), out, workers=1)[0].status == "done"


def test_dask_local_cluster_runs_the_same_jobs(tmp_path, root):
    distributed = pytest.importorskip("distributed")
    jobs = load_jobs(job_file(tmp_path, root, QUICK))
    run_batch(jobs[:2], tmp_path / "local", workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        results = run_batch(jobs[:2], tmp_path / "dask", executor="dask",
                            scheduler=cluster.scheduler_address)
    assert [r.status for r in results] == ["done", "done"]
    assert tree_bytes(tmp_path / "dask") == tree_bytes(tmp_path / "local")

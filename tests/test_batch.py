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


def test_jobs_name_bundled_scenes_and_grammars_as_the_command_line_does(tmp_path, root):
    """`preset:NAME`, `grammar:NAME` and a bare bundled name resolve to the
    same files as `treebake bake` takes; a file beside the job file wins
    over a bundled name; a wrong name is the job file's error, naming the key."""
    from treebake import library

    jobs = load_jobs(job_file(tmp_path, root, """
[[job]]
scene = "preset:gale"
[[job]]
grammar = "oak"
scene = "breeze"
[[job]]
grammar = "grammar:forest/birch"
"""))
    assert [(j.name, j.scene, j.grammar) for j in jobs] == [
        ("gale", str(library.preset_path("gale").resolve()), None),
        ("oak-breeze", str(library.preset_path("breeze").resolve()),
         str(library.grammar_path("oak").resolve())),
        ("birch", None, str(library.grammar_path("forest/birch").resolve()))]
    (tmp_path / "oak").write_text((root / SAPLING).read_text())  # a local file named oak
    local = load_jobs(job_file(tmp_path, root, '[[job]]\ngrammar = "oak"\n'))
    assert local[0].grammar == str(tmp_path / "oak")
    for body, message in [('scene = "preset:nope"', r"job\[0\]\.scene: no bundled preset 'nope'"),
                          ('grammar = "preset:gale"', r"job\[0\]\.grammar: 'preset:gale' is neither"),
                          ('scene = "missing.toml"', r"job\[0\]\.scene: file not found")]:
        with pytest.raises(SceneError, match=message):
            load_jobs(job_file(tmp_path, root, f"[[job]]\n{body}\n"))


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
        paths = {f["path"] for f in record["files"]}
        assert f"{name}.glb" in paths and f"{name}.npz" in paths
    assert not (out / "broken" / "job.json").exists()
    # a rerun skips what is done and tries the broken one again
    rerun = run_batch(jobs, out, workers=1)
    again = {r.name: r.status for r in rerun}
    assert again == {"a": "skipped", "b": "skipped", "c": "skipped", "broken": "failed"}
    # a skipped job reports what it made, as when it was done (a summary
    # said 0 frames, 0 segments and no files)
    for first, later in zip(results[:3], rerun[:3]):
        assert (later.files, later.frames, later.segments) == \
               (first.files, first.frames, first.segments) and later.frames > 0


def test_parallel_equals_serial_byte_for_byte(tmp_path, root):
    jobs = load_jobs(job_file(tmp_path, root, QUICK))
    run_batch(jobs, tmp_path / "serial", workers=1)
    run_batch(jobs, tmp_path / "parallel", workers=2)
    assert tree_bytes(tmp_path / "serial") == tree_bytes(tmp_path / "parallel")


def test_killed_batch_resumes_to_the_same_bytes(tmp_path, root):
    # job b long enough (oak and sapling, 20 s) to be under way when the batch is killed:
    # on the linear tier 1.5 s jobs ended within the 0.3 s wait
    body = QUICK.replace("duration = 0.4", "duration = 1.5").replace(
        'scene = "ROOT/presets/breeze.toml"', 'scene = "ROOT/presets/breeze.toml"\nduration = 20.0')
    assert "duration = 20.0" in body
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


# ---------------------------------------------------------------------------
# faults: damaged outputs, code changes, lost workers, signals, locks, Dask

ONE = """
[defaults]
duration = 0.4
fps = 12
quality = "draft"
formats = ["glb"]

[[job]]
name = "a"
grammar = "ROOT/grammars/sapling.lsys"
seed = 1
"""


def test_resume_redoes_damaged_outputs_and_records_checksums(tmp_path, root):
    jobs = load_jobs(job_file(tmp_path, root, ONE))
    out = tmp_path / "out"
    assert run_batch(jobs, out, workers=1)[0].status == "done"
    good = tree_bytes(out)
    record = json.loads((out / "a" / "job.json").read_text())
    import hashlib

    for entry in record["files"]:  # every output's size and sha256, checked independently
        data = (out / "a" / entry["path"]).read_bytes()
        assert entry["bytes"] == len(data) and entry["sha256"] == hashlib.sha256(data).hexdigest()
    assert {e["path"] for e in record["files"]} == {"a.npz", "a.glb", "manifest.json"}
    (out / "a" / "a.npz").write_bytes(b"")  # blanked, job.json intact
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done" and "a.npz is 0 bytes" in r.message
    glb = out / "a" / "a.glb"
    glb.write_bytes(glb.read_bytes()[:1000])  # truncated
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done" and "a.glb" in r.message
    data = bytearray(glb.read_bytes())  # same size, 10 bytes overwritten
    data[5000:5010] = b"\xab" * 10
    glb.write_bytes(bytes(data))
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done" and "sha256" in r.message
    assert run_batch(jobs, out, workers=1)[0].status == "skipped"
    assert tree_bytes(out) == good


def test_a_change_of_treebake_code_reruns_jobs(tmp_path, root, monkeypatch):
    import treebake.batch as batch

    jobs = load_jobs(job_file(tmp_path, root, ONE))
    out = tmp_path / "out"
    assert run_batch(jobs, out, workers=1)[0].status == "done"
    assert run_batch(jobs, out, workers=1)[0].status == "skipped"
    monkeypatch.setattr(batch, "code_fingerprint", lambda: "0" * 64)  # as if a .py changed
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done" and "code" in r.message


def test_another_library_version_reruns_jobs_and_says_which(tmp_path, root, monkeypatch):
    import treebake.batch as batch
    from treebake.versions import runtime_versions

    here = runtime_versions()
    jobs = load_jobs(job_file(tmp_path, root, ONE))
    out = tmp_path / "out"
    assert run_batch(jobs, out, workers=1)[0].status == "done"
    assert json.loads((out / "a" / "job.json").read_text())["versions"] == here
    assert run_batch(jobs, out, workers=1)[0].status == "skipped"
    # a farm node with another MuJoCo: redone, and the reason names the version
    monkeypatch.setattr(batch, "runtime_versions", lambda: {**here, "mujoco": "99.0.0"})
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done"
    assert r.message == (f"redone: made with mujoco {here['mujoco']}, this install has 99.0.0")
    assert json.loads((out / "a" / "job.json").read_text())["versions"]["mujoco"] == "99.0.0"
    assert run_batch(jobs, out, workers=1)[0].status == "skipped"
    # two libraries at once, each named; numpy missing on this node
    monkeypatch.setattr(batch, "runtime_versions",
                        lambda: {**here, "numpy": "not installed", "pymunk": "0.1"})
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done" and "inputs" not in r.message
    assert r.message == (f"redone: made with numpy {here['numpy']}, this install has no numpy; "
                         f"made with mujoco 99.0.0, this install has {here['mujoco']}; "
                         f"made with pymunk {here['pymunk']}, this install has 0.1")


def test_a_version_change_with_another_change_says_both(tmp_path, root, monkeypatch):
    import treebake.batch as batch
    from treebake.versions import runtime_versions

    here = runtime_versions()
    grammar = tmp_path / "sapling.lsys"
    grammar.write_text((root / SAPLING).read_text())
    jobs = load_jobs(job_file(tmp_path, root, ONE.replace("ROOT/grammars/sapling.lsys",
                                                          str(grammar))))
    out = tmp_path / "out"
    assert run_batch(jobs, out, workers=1)[0].status == "done"
    grammar.write_text(grammar.read_text() + "\n# edited\n")
    monkeypatch.setattr(batch, "runtime_versions", lambda: {**here, "numpy": "9.9"})
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done"
    assert r.message == (f"redone: made with numpy {here['numpy']}, this install has 9.9; "
                         "sapling.lsys changed")


def test_a_rerun_says_which_setting_input_or_code_changed(tmp_path, root, monkeypatch):
    """'redone: inputs, settings or treebake's code changed' named none of
    them: now the settings (old -> new), the input files and the code."""
    import treebake.batch as batch

    grammar = tmp_path / "sapling.lsys"
    grammar.write_text((root / SAPLING).read_text())
    body = ONE.replace("ROOT/grammars/sapling.lsys", str(grammar))
    out = tmp_path / "out"
    assert run_batch(load_jobs(job_file(tmp_path, root, body)), out, workers=1)[0].status == "done"
    windy = load_jobs(job_file(tmp_path, root, body + "wind = 9.0\n"))
    r = run_batch(windy, out, workers=1)[0]
    assert r.message == "redone: wind None -> 9.0", r.message
    grammar.write_text(grammar.read_text() + "\n# edited\n")
    monkeypatch.setattr(batch, "code_fingerprint", lambda: "0" * 64)
    r = run_batch(windy, out, workers=1)[0]
    assert r.message == "redone: sapling.lsys changed; treebake's code changed", r.message


def test_outputs_of_an_older_treebake_without_versions_are_redone(tmp_path, root):
    import hashlib

    from treebake.fingerprint import code_fingerprint

    jobs = load_jobs(job_file(tmp_path, root, ONE))
    out = tmp_path / "out"
    assert run_batch(jobs, out, workers=1)[0].status == "done"
    path = out / "a" / "job.json"
    record = json.loads(path.read_text())
    del record["versions"]  # what an older treebake wrote: its hash without versions
    record["hash"] = hashlib.sha256(f"{jobs[0].inputs_digest()} code {code_fingerprint()}"
                                    .encode()).hexdigest()
    path.write_text(json.dumps(record))
    r = run_batch(jobs, out, workers=1)[0]
    assert r.status == "done"
    assert r.message == "redone: job.json records no library versions (older treebake)"
    assert "versions" in json.loads(path.read_text())
    assert run_batch(jobs, out, workers=1)[0].status == "skipped"


def test_the_code_fingerprint_covers_every_module():
    from treebake import fingerprint

    files = {p.relative_to(fingerprint.PACKAGE).as_posix()
             for p in fingerprint.PACKAGE.rglob("*.py")}
    assert {"batch.py", "sim/chains/tier.py", "exchange/gltf.py", "lsystem/derive.py"} <= files
    assert len(fingerprint.code_fingerprint()) == 64


SLOW_JOBS = """
[defaults]
duration = 3.0
fps = 24
quality = "draft"
formats = ["npz"]

[[job]]
name = "a"
grammar = "ROOT/grammars/sapling.lsys"
seed = 1

[[job]]
name = "b"
grammar = "ROOT/grammars/sapling.lsys"
seed = 2

[[job]]
name = "c"
grammar = "ROOT/grammars/sapling.lsys"
seed = 3

[[job]]
name = "d"
grammar = "ROOT/grammars/sapling.lsys"
seed = 4
"""


def _workers_of(pid: int) -> list[int]:
    """Pids of the batch's worker processes (children running spawn_main)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            children = (task / "children").read_text().split()
        except OSError:
            continue
        for c in children:
            try:
                cmd = Path(f"/proc/{c}/cmdline").read_bytes()
            except OSError:
                continue
            if b"spawn_main" in cmd:
                found.append(int(c))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_batch(tmp_path, root, body, *extra, env=None):
    jobs_path = job_file(tmp_path, root, body)
    cmd = [sys.executable, "-m", "treebake.cli", "batch", str(jobs_path), "--out",
           str(tmp_path / "out"), *extra]
    full_env = {**os.environ, "TREEBAKE_PROGRESS_SECONDS": "0", **(env or {})}
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=full_env, start_new_session=True)


def _busy_workers(proc, count: int, timeout: float = 120) -> list[int]:
    deadline = time.time() + timeout
    while True:
        assert proc.poll() is None, proc.communicate()
        pids = _workers_of(proc.pid)
        if len(pids) >= count:
            return pids
        assert time.time() < deadline, "workers did not start"
        time.sleep(0.1)


def _wait_running(tmp_path, timeout: float = 120) -> None:
    """Until some job is under way (its stale temporaries or lock appear)."""
    deadline = time.time() + timeout
    while not any((tmp_path / "out").glob("*/.treebake.lock")):
        assert time.time() < deadline
        time.sleep(0.05)
    time.sleep(1.0)  # into the simulation


def test_kill_9_of_one_worker_retries_only_its_job(tmp_path, root):
    # 60 s of a sapling: a few seconds per job on the linear tier, long enough to be killed
    proc = _start_batch(tmp_path, root, SLOW_JOBS.replace("duration = 3.0", "duration = 60.0"),
                        "--jobs", "2", "--json")
    _wait_running(tmp_path)
    victim = _busy_workers(proc, 2)[0]
    os.kill(victim, signal.SIGKILL)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    summary = json.loads(out)
    assert [r["status"] for r in summary["results"]] == ["done"] * 4
    assert summary["workers"] == 2


def test_a_job_whose_worker_always_dies_fails_alone(tmp_path, root):
    # fault injection: the worker SIGKILLs itself when it starts job "b"
    proc = _start_batch(tmp_path, root, SLOW_JOBS.replace("duration = 3.0", "duration = 0.5"),
                        "--jobs", "2", "--json", env={"TREEBAKE_FAULT_KILL_JOB": "b"})
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    status = {r["name"]: (r["status"], r["message"]) for r in json.loads(out)["results"]}
    assert {k: v[0] for k, v in status.items()} == {"a": "done", "b": "failed", "c": "done",
                                                  "d": "done"}
    assert "killed by SIGKILL" in status["b"][1] and "tried 3 times" in status["b"][1]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sigint_or_sigterm_stops_cleanly_with_a_summary(tmp_path, root, sig):
    # 600 s jobs: still under way when the signal comes (the linear tier ran 20 s ones in ~1 s)
    proc = _start_batch(tmp_path, root, SLOW_JOBS.replace("duration = 3.0", "duration = 600.0"),
                        "--jobs", "2")
    _wait_running(tmp_path)
    workers = _busy_workers(proc, 2)
    started = time.time()
    os.kill(proc.pid, sig)  # the main process only, as a farm manager or `kill` does
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert time.time() - started < 30  # did not run the queued jobs on
    assert "Traceback" not in err
    summary = json.loads((tmp_path / "out" / "batch-summary.json").read_text())
    assert summary["interrupted"] == 4 and summary["done"] == 0
    assert not any(_alive(w) for w in workers)
    assert not list((tmp_path / "out").rglob("*.npz"))  # nothing half-done looks finished


def test_workers_die_with_a_killed_batch(tmp_path, root):
    proc = _start_batch(tmp_path, root, SLOW_JOBS.replace("duration = 3.0", "duration = 600.0"),
                        "--jobs", "2")
    _wait_running(tmp_path)
    workers = _busy_workers(proc, 2)
    os.kill(proc.pid, signal.SIGKILL)  # the main process only: workers are orphaned
    proc.communicate(timeout=30)
    deadline = time.time() + 10
    while any(_alive(w) for w in workers):
        assert time.time() < deadline, "orphaned workers kept running"
        time.sleep(0.1)


def test_a_locked_job_folder_is_busy_for_the_second_run_at_once(tmp_path, root):
    from treebake.fileio import job_lock

    jobs = load_jobs(job_file(tmp_path, root, ONE))
    out = tmp_path / "out"
    with job_lock(out / "a"):
        r = run_batch(jobs, out, workers=1)[0]
        assert r.status == "busy" and "another run" in r.message  # not a failure of this run
        cli = subprocess.run([sys.executable, "-m", "treebake.cli", "bake", str(root / SAPLING),
                              "--out", str(out), "--name", "a", "--format", "glb"],
                             capture_output=True, text=True, timeout=120)
        assert cli.returncode == 1 and "another treebake run" in cli.stderr
        assert "simulating" not in cli.stderr and not (out / "a" / "a.npz").exists()
    assert run_batch(jobs, out, workers=1)[0].status == "done"  # released


def test_dask_resolves_out_on_the_client_and_counts_real_workers(tmp_path, root, monkeypatch):
    distributed = pytest.importorskip("distributed")
    jobs = load_jobs(job_file(tmp_path, root, ONE))
    monkeypatch.chdir(tmp_path)
    seen = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        results = run_batch(jobs, "rel-out", workers=7, executor="dask",
                            scheduler=cluster.scheduler_address,
                            report=lambda e, d: seen.append(d) if e == "workers" else None)
    assert results[0].status == "done"
    assert (tmp_path / "rel-out" / "a" / "job.json").exists()
    assert seen and max(seen) == 1  # the cluster's workers, not --jobs


def test_dask_without_workers_fails_clearly_after_the_timeout(tmp_path, root):
    distributed = pytest.importorskip("distributed")
    from treebake.errors import TreebakeError

    jobs = load_jobs(job_file(tmp_path, root, ONE))
    with distributed.LocalCluster(n_workers=0, processes=True, dashboard_address=None) as cluster:
        started = time.time()
        with pytest.raises(TreebakeError, match="no Dask worker"):
            run_batch(jobs, tmp_path / "out", executor="dask",
                      scheduler=cluster.scheduler_address, worker_timeout=2.0)
        assert time.time() - started < 30


def test_a_resumed_job_removes_the_temporaries_a_killed_run_left(tmp_path):
    """atomic_path's temporaries, `.NAME.XXXX.tmp` and (USD's, which keep
    the target's extension) `.NAME.XXXX.tmp.EXT`, are removed before a job
    runs again; finished files and other dotfiles stay."""
    from treebake.batch import _clean_stale

    layers = tmp_path / "job.trees"
    layers.mkdir()
    stale = [tmp_path / ".job.npz.a1b2.tmp", tmp_path / ".job.usd.c3d4.tmp.usd",
             layers / ".oak_1.usda.e5f6.tmp.usda"]
    kept = [tmp_path / "job.usd", layers / "oak_1.usda", tmp_path / ".treebake.lock"]
    for p in stale + kept:
        p.write_bytes(b"x")
    _clean_stale(tmp_path)
    assert [p for p in stale if p.exists()] == []
    assert all(p.exists() for p in kept)


def test_the_docs_example_job_file_loads(root, tmp_path):
    """docs/batch.md's job file, as a user copies it into an empty folder
    (its bundled names need no checkout)."""
    import re

    text = (root / "docs" / "batch.md").read_text(encoding="utf-8")
    example = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    (tmp_path / "jobs.toml").write_text(example)
    jobs = load_jobs(tmp_path / "jobs.toml")
    assert [j.name for j in jobs][:4] == ["oak-gale", "sapling-s1", "sapling-s2", "sapling-s3"]
    assert len(jobs) == 4 + 8 and {j.formats for j in jobs[4:]} == {("glb", "usd")}

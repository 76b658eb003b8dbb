"""The commands as a new user meets them (issue 42): every command run from
an empty folder, with bundled files found by name. Self-contained (no
conftest fixtures): the bundled files come from treebake.library."""

from pathlib import Path

from treebake import library
from treebake.cli import main
from treebake.fileio import temporary_files

QUICK = ["--duration", "0.2", "--fps", "10", "--quality", "draft", "-q"]


def _grammar_named(folder: Path, file: str, name: str) -> Path:
    """The bundled sapling under another file name, its `name:` changed."""
    text = library.grammar_path("sapling").read_text(encoding="utf-8")
    path = folder / file
    path.write_text(text.replace("name: sapling", f"name: {name}"), encoding="utf-8")
    return path


def test_inspect_and_bake_write_a_grammar_into_the_same_folder(tmp_path, monkeypatch, capsys):
    # the folder is the grammar's file name for both, not its free-text `name:`
    monkeypatch.chdir(tmp_path)
    _grammar_named(tmp_path, "my.lsys", "My Sapling")
    assert main(["inspect", "my.lsys", "--size", "64", "--json"]) == 0
    assert main(["bake", "my.lsys", *QUICK]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["my"]
    assert (tmp_path / "out" / "my" / "summary.json").is_file()
    assert (tmp_path / "out" / "my" / "my.npz").is_file()
    # a bundled grammar in a subfolder: its file name too, as `bake forest/birch` writes
    assert main(["inspect", "forest/birch", "--size", "64", "--json"]) == 0
    assert (tmp_path / "out" / "birch" / "preview.png").is_file()
    assert main(["inspect", "my.lsys", "--size", "64", "--json", "--name", "other"]) == 0
    assert (tmp_path / "out" / "other" / "summary.json").is_file()
    capsys.readouterr()


def test_a_copy_of_every_bundled_preset_loads_and_bakes(tmp_path, monkeypatch, capsys):
    # the path `treebake list presets --json` gives, copied and edited in an
    # empty folder: its grammars are bundled names, not paths into the package
    import json

    from treebake.scene import load_scene

    monkeypatch.chdir(tmp_path)
    assert main(["list", "presets", "--json"]) == 0
    entries = json.loads(capsys.readouterr().out)
    assert len(entries) == len(library.presets()) >= 12
    failed = {}
    for e in entries:
        copy = tmp_path / f"my-{e['name']}.toml"
        copy.write_text(Path(e["path"]).read_text(encoding="utf-8"), encoding="utf-8")
        try:
            bundled, mine = load_scene(e["path"]), load_scene(copy)
        except Exception as exc:  # noqa: BLE001 - list every preset that fails
            failed[e["name"]] = str(exc)
            continue
        assert [(t.name, t.grammar.resolve(), t.position) for t in mine.trees] == \
               [(t.name, t.grammar.resolve(), t.position) for t in bundled.trees]
    assert not failed, failed
    for name in ("forest", "tornado"):  # `grammars = [...]` of names, subfolder ones too
        assert {t.grammar.parent.name for t in load_scene(f"my-{name}.toml").trees} == {"forest"}
    assert main(["bake", "my-felling.toml", *QUICK]) == 0
    assert (tmp_path / "out" / "felling" / "felling.npz").is_file()
    capsys.readouterr()


def test_an_obj_sequence_prints_as_one_entry(tmp_path, monkeypatch, capsys):
    # not one name per frame on one line: the sequence, its count and range
    # (manifest.json still lists every file)
    import json

    monkeypatch.chdir(tmp_path)
    assert main(["bake", "sapling", *QUICK, "--format", "glb,obj"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("exported"))
    assert "obj/sapling.####.obj (3 files, 0001-0003)" in line, line
    assert "sapling.0002" not in line and "sapling.glb" in line and "manifest.json" in line
    manifest = json.loads((tmp_path / "out" / "sapling" / "manifest.json").read_text())
    assert "obj/sapling.0002.obj" in {f["path"] for f in manifest["files"]}
    assert main(["export", "out/sapling/sapling.npz", "--format", "obj", "--name", "again",
                 "-q"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    # issue 40: the sapling's own bark and its normal map
    assert line.endswith(": obj/again.####.obj (3 files, 0001-0003), obj/again.mtl, "
                         "obj/textures/bark_sapling.png, obj/textures/bark_sapling_normal.png, "
                         "obj/textures/leaf.png, manifest.json"), line


def test_export_and_preview_write_beside_a_bake_named_with_name(tmp_path, monkeypatch, capsys):
    """A bake made with --name exports into its own folder by default,
    not into the scene's (where it overwrote another bake's files)."""
    monkeypatch.chdir(tmp_path)
    assert main(["bake", "sapling", *QUICK, "--name", "take2"]) == 0
    assert main(["export", "out/take2/take2.npz", "--format", "glb", "-q"]) == 0
    assert main(["preview", "out/take2/take2.npz", "--size", "64", "-q"]) == 0
    capsys.readouterr()
    assert (tmp_path / "out" / "take2" / "take2.glb").is_file()
    assert list((tmp_path / "out" / "take2").glob("take2*.gif"))
    assert not (tmp_path / "out" / "sapling").exists()


def test_file_lists_collapse_numbered_sequences():
    from treebake.cli_bake import file_list

    obj = [f"obj/felling.{i:04d}.obj" for i in range(1, 290)]
    assert file_list(["felling.glb", "felling.usd", *obj, "obj/felling.mtl", "manifest.json"]) \
        == ("felling.glb, felling.usd, obj/felling.####.obj (289 files, 0001-0289), "
            "obj/felling.mtl, manifest.json")
    assert file_list(obj[::3]) == "obj/felling.####.obj (97 files, 0001-0289, step 3)"
    assert file_list(["a.0001.obj", "a.0002.obj"]) == "a.0001.obj, a.0002.obj"  # too few
    split = [f"f.birch_{i}.glb" for i in range(1, 12)]  # tree names: unpadded numbers
    assert file_list(split) == "f.birch_*.glb (11 files, 1-11)"
    many = file_list([f"f.{c}.glb" for c in "abcdefghijklmnopqrst"])
    assert many.endswith("f.k.glb, ... 9 more (manifest.json lists every file)")


def test_sway_shows_progress_like_bake(tmp_path):
    # without a terminal: plain lines (here every 0 s) and one at the end,
    # as `treebake bake` prints them; -q: nothing on stderr
    import os
    import subprocess
    import sys

    env = {**os.environ, "TREEBAKE_PROGRESS_SECONDS": "0"}
    cmd = [sys.executable, "-m", "treebake.cli", "sway", "sapling", "--quality", "draft"]

    def run(*extra):
        return subprocess.run([*cmd, *extra], cwd=tmp_path, capture_output=True, text=True,
                              env=env, timeout=300, check=False)

    r = run()
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("sapling: H 3.0 m")
    lines = r.stderr.splitlines()
    assert lines and lines[-1].startswith("simulating: done in "), r.stderr
    assert "\r" not in r.stderr  # no bar redraws in a log
    assert "1 tree, 1 simulated" in r.stderr
    quiet = run("-q")
    assert quiet.returncode == 0 and quiet.stderr == "" and quiet.stdout == r.stdout
    assert not os.listdir(tmp_path)  # writes nothing


def test_a_bake_leaves_no_lock_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["bake", "sapling", *QUICK, "--format", "glb"]) == 0
    assert main(["export", "out/sapling/sapling.npz", "-q", "--format", "glb,usd,usda"]) == 0
    assert not list(tmp_path.rglob(".treebake.lock"))
    assert temporary_files(tmp_path) == []


def test_a_bake_that_fails_leaves_no_empty_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.lsys").write_text("name: bad\naxiom: F\nF -> F[+F\n")
    (tmp_path / "scene.toml").write_text('name = "shot"\n[[tree]]\ngrammar = "bad.lsys"\n')
    for args in (["bake", "bad.lsys", "-q"], ["bake", "scene.toml", "-q"],
                 ["bake", "bad.lsys", "-q", "--out", "new/deeper"],
                 ["inspect", "oak", "--max-modules", "10"]):
        assert main(args) == 2, args  # the grammar does not parse; too many modules
    capsys.readouterr()
    assert not (tmp_path / "out").exists() and not (tmp_path / "new").exists()
    (tmp_path / "out" / "mine").mkdir(parents=True)  # a folder that was there stays
    assert main(["bake", "bad.lsys", "-q", "--name", "mine"]) == 2
    assert (tmp_path / "out" / "mine").is_dir()


def test_a_run_that_opened_the_lock_file_as_it_went_takes_a_new_one(tmp_path, monkeypatch):
    # run A releases (and removes) the lock file just after run B opened it:
    # B must not hold the removed file while a third run takes a new one
    import pytest
    from treebake import fileio
    from treebake.errors import BusyError

    folder = tmp_path / "job"
    lock = folder / fileio.LOCK_NAME
    a = fileio.job_lock(folder)
    a.__enter__()
    flock = fileio.fcntl.flock
    opened = []

    def a_finishes_first(fd, op):
        if not opened:  # B has opened A's file and is about to lock it
            opened.append(fd)
            a.__exit__(None, None, None)
        return flock(fd, op)

    monkeypatch.setattr(fileio.fcntl, "flock", a_finishes_first)
    with fileio.job_lock(folder):  # run B
        assert opened and lock.exists()
        with pytest.raises(BusyError), fileio.job_lock(folder):  # a third run
            pass
    assert not lock.exists() and folder.is_dir()


def _jobs(tmp_path: Path, durations: dict[str, float]) -> Path:
    """A job file of sapling bakes (npz only), one per name."""
    grammar = library.grammar_path("sapling").as_posix()
    text = '[defaults]\nformats = ["npz"]\nquality = "draft"\n'
    for name, duration in durations.items():
        text += f'\n[[job]]\nname = "{name}"\ngrammar = "{grammar}"\nduration = {duration}\n'
    path = tmp_path / "jobs.toml"
    path.write_text(text)
    return path


def test_a_batch_job_that_another_run_writes_is_busy_not_failed(tmp_path):
    from treebake.batch import load_jobs, run_batch, run_job, summary
    from treebake.fileio import job_lock

    jobs = load_jobs(_jobs(tmp_path, {"a": 0.2, "b": 0.2}))
    out = tmp_path / "out"
    with job_lock(out / "a"):  # another run is writing job a, all through this one
        results = run_batch(jobs, out, workers=1)
    assert [(r.name, r.status) for r in results] == [("a", "busy"), ("b", "done")]
    assert "another run" in results[0].message
    data = summary(results, 1.0, 1)
    assert (data["failed"], data["busy"], data["done"]) == (0, 1, 1)

    # the other run finishes job a while this one still works: skipped, not failed
    other = job_lock(out / "a")
    other.__enter__()

    def the_other_run_finishes(event, data):
        if event == "end" and data.name == "a":
            assert data.status == "busy"
            other.__exit__(None, None, None)
            assert run_job(jobs[0], str(out), force=True).status == "done"

    results = run_batch(jobs, out, workers=1, force=True, report=the_other_run_finishes)
    assert [(r.name, r.status, r.message) for r in results] == [
        ("a", "skipped", "written by another run"), ("b", "done", "")]
    assert "a.npz" in results[0].files


def test_a_batch_job_that_another_run_left_unfinished_fails(tmp_path):
    from treebake.batch import load_jobs, run_batch
    from treebake.fileio import job_lock

    jobs = load_jobs(_jobs(tmp_path, {"a": 0.2, "b": 0.2}))
    out = tmp_path / "out"
    other = job_lock(out / "a")
    other.__enter__()

    def the_other_run_stops(event, data):  # releases job a without writing it
        if event == "end" and data.name == "a":
            other.__exit__(None, None, None)

    results = run_batch(jobs, out, workers=1, report=the_other_run_stops)
    assert [r.status for r in results] == ["failed", "done"]
    assert "another run was writing it and did not finish it" in results[0].message


def test_two_batch_runs_of_one_job_file_at_once(tmp_path):
    # run 2 starts while run 1 writes job a (long); it finds a busy, does b
    # (short) and ends before run 1: busy is no failure (exit 75, "rerun
    # later"); run 1 finds b written (skipped) and ends with a clean summary
    import json
    import os
    import subprocess
    import sys
    import time

    jobs = _jobs(tmp_path, {"a": 100.0, "b": 0.5})  # about 10 s and 0.1 s here
    out = tmp_path / "out"

    def batch(n):
        return subprocess.Popen([sys.executable, "-m", "treebake.cli", "batch", str(jobs),
                                 "-j", "1", "--out", str(out), "--summary",
                                 str(tmp_path / f"summary-{n}.json")], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "TREEBAKE_PROGRESS_SECONDS": "60"})

    first = batch(1)
    deadline = time.time() + 120
    while not (out / "a" / ".treebake.lock").exists():  # run 1 is writing job a
        assert first.poll() is None and time.time() < deadline, first.communicate()
        time.sleep(0.02)
    second = batch(2)
    out2, err2 = second.communicate(timeout=300)
    _, err1 = first.communicate(timeout=300)
    s1, s2 = (json.loads((tmp_path / f"summary-{n}.json").read_text()) for n in (1, 2))
    status = [{r["name"]: r["status"] for r in s["results"]} for s in (s1, s2)]
    assert status == [{"a": "done", "b": "skipped"}, {"a": "busy", "b": "done"}], (err1, err2)
    assert (s1["failed"], s2["failed"], s2["busy"]) == (0, 0, 1)
    assert first.returncode == 0, err1
    assert second.returncode == 75, err2
    assert "1 done, 0 skipped, 0 failed, 1 busy" in out2
    assert "still being written by another run" in err2
    assert all((out / n / "job.json").is_file() for n in "ab")


def test_a_new_bake_removes_the_exports_of_the_one_it_replaces(tmp_path, monkeypatch, capsys):
    """A rebake left the previous bake's glb, OBJ frames and manifest (its
    sha256 the old bake's) beside the new .npz, passing for its exports."""
    import json

    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "out" / "sapling"
    assert main(["bake", "sapling", *QUICK, "--format", "glb,obj"]) == 0
    listed = [f["path"] for f in json.loads((folder / "manifest.json").read_text())["files"]]
    assert "sapling.glb" in listed and any(p.startswith("obj/") for p in listed)
    (folder / "notes.txt").write_text("mine")  # not an export: it stays
    outside = tmp_path / "out" / "keep.txt"
    outside.write_text("outside the job folder")
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["files"].append({"path": "../keep.txt"})  # a tampered manifest: never followed out
    (folder / "manifest.json").write_text(json.dumps(manifest))
    capsys.readouterr()
    assert main(["bake", "sapling", "--duration", "0.1", "--fps", "10", "--quality", "draft"]) == 0
    err = capsys.readouterr().err
    assert f"removed {len(listed)} files exported from the previous bake" in err, err
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt", "sapling.npz"]
    assert outside.read_text() == "outside the job folder"
    # an export of another bake into this folder is not the rebaked one's: it stays
    other = tmp_path / "other.npz"
    other.write_bytes((folder / "sapling.npz").read_bytes())
    assert main(["export", str(other), "--name", "sapling", "--format", "glb", "-q"]) == 0
    assert main(["bake", "sapling", "--duration", "0.1", "--fps", "10", "--quality", "draft"]) == 0
    assert "removed" not in capsys.readouterr().err
    assert (folder / "sapling.glb").is_file() and (folder / "manifest.json").is_file()

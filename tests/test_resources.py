"""Resources known before the work (issue 39): a tree too large is refused
as soon as it is derived, naming its grammar; a bake's peak memory and
disk are estimated from the trees it animates and checked before it
simulates; a full disk names the file and leaves nothing of it."""

import errno
import subprocess
import sys
import zipfile

import pytest
from treebake import resources
from treebake.bake_file import save_bake
from treebake.errors import InputError, OutputError
from treebake.pipeline import bake_scene
from treebake.resources import Budget, estimate, parse_size
from treebake.scene import parse_scene

# the CLI in a child that reports its own peak RSS (kB, Linux's VmHWM: unlike
# getrusage's ru_maxrss, not inherited from the test process across exec)
# on its last stderr line
RUN = ("import re, sys\nfrom treebake.cli import main\ncode = main(sys.argv[1:])\n"
       "hwm = re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1)\n"
       "print('peak_kb', hwm, file=sys.stderr)\nsys.exit(code)\n")


def run(tmp_path, *args):
    r = subprocess.run([sys.executable, "-c", RUN, *args], cwd=tmp_path, capture_output=True,
                       text=True, timeout=600, check=False)
    peak = int(r.stderr.strip().splitlines()[-1].split()[1]) * 1024
    return r, peak


def test_a_tree_too_large_is_refused_as_soon_as_it_is_derived(tmp_path):
    """The issue's 32-byte grammar (F -> FF, 20 iterations: 1,048,576
    segments, under the module cap) baked in 4.48 GB, exit 0, on eb8e296;
    now it is refused with its file named, in the derivation's memory."""
    (tmp_path / "big.lsys").write_text("axiom: F\niterations: 20\nF -> FF\n")
    r, peak = run(tmp_path, "bake", "big.lsys", "--workers", "1")
    assert r.returncode == 2, r.stderr
    assert "big.lsys: the tree would have 1,048,576 segments, more than the 100,000" in r.stderr
    assert "--max-segments" in r.stderr
    assert peak < 300 * 2**20, peak
    assert not (tmp_path / "out" / "big").exists()


def test_max_segments_raises_and_lowers_the_cap(tmp_path):
    (tmp_path / "g.lsys").write_text("axiom: F\niterations: 6\nF -> FF\n")  # 64 segments
    r, _ = run(tmp_path, "bake", "g.lsys", "--max-segments", "63", "--duration", "0.1")
    assert r.returncode == 2 and "64 segments, more than the 63" in r.stderr, r.stderr
    r, _ = run(tmp_path, "bake", "g.lsys", "--max-segments", "64", "--duration", "0.1", "-q")
    assert r.returncode == 0, r.stderr


def test_the_estimate_is_above_the_measured_peak(tmp_path):
    """The plan line's estimate against the peak RSS the bake reached: above
    it (a refusal never lets through what does not fit) and within 1.5x (a
    bake that fits is not refused)."""
    (tmp_path / "f.toml").write_text(
        'name = "f"\nduration = 5.0\nfps = 24\nseed = 3\n'
        '[forest]\ngrammars = ["forest/conifer", "forest/broadleaf", "forest/birch"]\n'
        'count = 100\narea = [100.0, 100.0]\nmin_spacing = 6.0\n'
        '[wind]\nbeaufort = "strong breeze"\ndirection = 30.0\nturbulence = 0.3\n')
    r, peak = run(tmp_path, "bake", "f.toml", "--workers", "1")
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stderr.splitlines() if x.startswith("estimated:"))
    mb = float(line.split("peak memory about ")[1].split(" MB")[0].replace(",", ""))
    assert peak <= mb * 2**20 <= 1.5 * peak, (line, peak / 2**20)
    npz = (tmp_path / "out" / "f" / "f.npz").stat().st_size
    disk = float(line.split("bake ")[1].split(" MB")[0].replace(",", ""))
    assert npz <= disk * 2**20 + 2**20  # the disk estimate is an upper bound


def test_max_memory_refuses_before_simulating(tmp_path):
    r, _ = run(tmp_path, "bake", "oak", "--max-memory", "50M", "--workers", "1")
    assert r.returncode == 2, r.stderr
    assert "more than --max-memory (50 MB)" in r.stderr and "shorter `duration`" in r.stderr
    assert "simulating" not in r.stderr
    assert not list((tmp_path / "out").rglob("*.npz"))


def test_a_bake_larger_than_the_free_disk_is_refused(tmp_path, monkeypatch, root):
    monkeypatch.setattr(resources, "free_disk", lambda folder: 50_000)
    scene = parse_scene({"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}],
                         "duration": 5.0, "wind": {"speed": 8.0}}, file="<test>")
    with pytest.raises(InputError, match=r"needs about \d+ kB on disk and the disk has 49 kB free"):
        bake_scene(scene, budget=Budget(folder=tmp_path))


def test_a_full_disk_names_the_file_and_leaves_nothing(tmp_path, monkeypatch, root):
    """The issue: "internal error: OSError: [Errno 28] ... (zipfile.py:1181)"
    after simulating; now the file is named and no part of it stays."""
    scene = parse_scene({"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}],
                         "duration": 0.2}, file="<test>")
    bake = bake_scene(scene)
    real = zipfile.ZipFile.writestr

    def full(self, *args, **kwargs):
        real(self, *args, **kwargs)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(zipfile.ZipFile, "writestr", full)
    target = tmp_path / "b.npz"
    with pytest.raises(OutputError, match=r"b\.npz: the disk is full .*nothing of this file"):
        save_bake(bake, target)
    assert list(tmp_path.iterdir()) == []


def test_estimate_counts_static_trees_as_one_frame():
    one = estimate(1000, 0, 241, 1)
    assert one.disk == 1000 * 241 * 28
    assert estimate(0, 1000, 241, 1).disk == 1000 * 28
    assert estimate(1000, 0, 241, 3).memory - one.memory == 2 * resources.WORKER_MEMORY


@pytest.mark.parametrize("text,size", [("8G", 8 * 2**30), ("500M", 500 * 2**20),
                                       ("2.5GB", int(2.5 * 2**30)), ("1000", 1000),
                                       ("64k", 64 * 1024), ("1TiB", 2**40)])
def test_parse_size(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "-1G", "lots", "8X", "0"])
def test_parse_size_refuses_what_is_not_a_size(text):
    with pytest.raises(InputError, match="--max-memory"):
        parse_size(text)


def test_a_tree_the_rig_cannot_take_names_its_grammar(tmp_path):
    """A 1,000,000-segment chain was refused by the rig with a message that
    named no file (`min_bone_length = 250.08 m is out of range`)."""
    (tmp_path / "tall.lsys").write_text("axiom: F(5000)\n")
    r, _ = run(tmp_path, "bake", "tall.lsys", "--duration", "0.1", "--quality", "draft")
    assert r.returncode == 2
    assert "tall.lsys: min_bone_length" in r.stderr, r.stderr


def test_a_batch_on_a_full_disk_still_prints_its_table(tmp_path, monkeypatch, capsys, root):
    """The issue: with the disk already full the batch printed no table and
    wrote no summary. The table still shows, the unwritten summary is named,
    exit 1."""
    from treebake import cli_batch
    from treebake.cli import main

    (tmp_path / "jobs.toml").write_text(
        f'[[job]]\nname = "s"\ngrammar = "{root / "grammars" / "sapling.lsys"}"\n'
        "duration = 0.2\n")
    summary = tmp_path / "out" / "batch-summary.json"

    def full(path, text):
        raise OutputError(f"{path}: the disk is full (0 kB free); nothing of this file was kept")

    monkeypatch.setattr(cli_batch, "write_text", full)
    code = main(["batch", str(tmp_path / "jobs.toml"), "--out", str(tmp_path / "out"),
                 "--jobs", "1"])
    out, err = capsys.readouterr()
    assert code == 1
    assert "s     done" in out and "summary not written" in out, out
    assert f"{summary}: the disk is full" in err


@pytest.mark.parametrize("threshold, announced", [(3, True), (4, False)])
def test_a_large_shot_says_it_is_growing_before_the_silent_stages(monkeypatch, root,
                                                                  threshold, announced):
    """Growing and rigging 10,000 trees takes 12 s before the plan line: a
    shot of ANNOUNCE_TREES trees or more says so first; a smaller one does
    not add the line."""
    from treebake import pipeline

    monkeypatch.setattr(pipeline, "ANNOUNCE_TREES", threshold)
    sapling = str(root / "grammars" / "sapling.lsys")
    scene = parse_scene({"tree": [{"grammar": sapling, "position": [4.0 * k, 0.0]}
                                  for k in range(3)], "duration": 0.1}, file="<test>")
    lines: list[str] = []
    bake_scene(scene, log=lines.append)
    grow_line = [k for k, x in enumerate(lines) if x == "growing and rigging 3 trees"]
    plan = next(k for k, x in enumerate(lines) if x.startswith("3 trees, "))
    assert grow_line == ([0] if announced else []), lines
    assert plan > 0 if announced else plan == 0

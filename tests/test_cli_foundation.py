"""CLI: derive and inspect, exit codes, help."""

import json
import subprocess
import sys

import pytest
from treebake.cli import main


def run(*args):
    return subprocess.run([sys.executable, "-m", "treebake.cli", *args], capture_output=True,
                          text=True, check=False)


def test_help_everywhere():
    for cmd in ([], ["derive"], ["inspect"]):
        r = run(*cmd, "--help")
        assert r.returncode == 0 and "usage:" in r.stdout


def test_derive_prints_the_string_and_stats(root, capsys):
    code = main(["derive", str(root / "grammars/abop/fig1.24a.lsys"), "-n", "1", "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and out.strip() == "F[+F]F[-F]F"
    stats = json.loads(err)
    assert stats["modules"] == 11 and stats["symbols"]["F"] == 5


def test_inspect_writes_summary_and_preview(root, tmp_path, capsys):
    code = main(["inspect", str(root / "grammars/oak.lsys"), "--out", str(tmp_path), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["segments"] > 100 and 10 < summary["height_m"] < 20
    assert (tmp_path / "oak" / "preview.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((tmp_path / "oak" / "summary.json").read_text()) == summary


@pytest.mark.parametrize("args, fragment", [
    (["derive", "nope.lsys"], "cannot read"),
    (["derive", "{bad}"], "bad.lsys:2:"),
    (["derive", "{big}", "--max-modules", "100"], "exceeds 100 modules"),
])
def test_bad_input_exits_2_with_a_message(tmp_path, args, fragment):
    (tmp_path / "bad.lsys").write_text("axiom: F\nF -> F(\n")
    (tmp_path / "big.lsys").write_text("axiom: F\niterations: 30\nF -> FF\n")
    args = [a.format(bad=tmp_path / "bad.lsys", big=tmp_path / "big.lsys") for a in args]
    r = run(*args)
    assert r.returncode == 2
    assert fragment in r.stderr and "Traceback" not in r.stderr


def test_bad_usage_exits_2():
    assert run("derive").returncode == 2
    assert run("no-such-command").returncode == 2


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_log_says_once_when_the_simulation_is_done_whatever_the_chunks(tmp_path, workers):
    """The gusty preset (3,764 segments) simulates in two chunks; a log (not
    a terminal) says once that the simulation is done, for any workers."""
    r = run("bake", "preset:gusty", "--duration", "0.5", "--workers", workers,
            "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("simulating: done in ") == 1, r.stderr

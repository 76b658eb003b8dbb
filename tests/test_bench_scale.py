"""bench/scale.py at CI size: it runs the installed CLI, reports every
column for the bake and each export, and the peak it reports is the summed
RSS of the command's whole process tree (no timing assertions)."""

import json
import os
import shutil
import subprocess
import sys

from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))
import scale  # noqa: E402


def test_script_reports_every_column(tmp_path):
    treebake = shutil.which("treebake", path=os.path.dirname(sys.executable))
    out = tmp_path / "scale.json"
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "scale.py"), "--counts", "12",
                           "--duration", "0.3", "--formats", "usd", "glb", "--workers", "2",
                           "--treebake", treebake, "--json", str(out)],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [r["step"] for r in rows] == ["bake", "export usd", "export glb"]
    for r in rows:
        assert r["trees"] == 12 and r["size_mb"] > 0 and r["cpu_s"] > 0
        assert r["peak_rss_mb"] > 40  # a Python process with numpy loaded: tens of MB
    assert rows[1]["root_open_s"] > 0


def test_the_peak_counts_every_process_of_the_tree(tmp_path):
    """A parent that starts two children each holding 200 MB: the summed
    peak sees all three, not the parent alone."""
    code = ("import subprocess, sys\n"
            "hold = 'x = bytearray(200 * 2**20); import time; time.sleep(1.5)'\n"
            "ps = [subprocess.Popen([sys.executable, '-c', hold]) for _ in range(2)]\n"
            "[p.wait() for p in ps]\n")
    r = scale.run([sys.executable, "-c", code], tmp_path)
    assert r["peak_rss_mb"] > 400
    assert r["cpu_s"] >= 0

"""bench/pole.py at CI size: it runs the installed CLI's sway test on poles
it writes, reports every column, and the poles sway at the beam's first
frequency (no timing assertions)."""

import json
import os
import shutil
import subprocess
import sys

from conftest import ROOT


def test_script_reports_every_column(tmp_path):
    treebake = shutil.which("treebake", path=os.path.dirname(sys.executable))
    out = tmp_path / "pole.json"
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "pole.py"), "--bones", "20",
                           "30", "--treebake", treebake, "--json", str(out)],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [r["bones"] for r in rows] == [20, 30]
    for r in rows:
        assert r["cpu_s"] > 0 and r["cpu_s_per_bone"] == r["cpu_s"] / r["bones"]
        # Euler-Bernoulli's cantilever, 5.53 Hz; gravity and the step take ~1 %
        assert abs(r["f1_error"]) < 0.03 and abs(r["beam_f1_hz"] - 5.53) < 0.01
        assert 0.005 < r["damping"] < 0.015  # the grammar's 0.01
    assert "CPU per bone" in done.stdout

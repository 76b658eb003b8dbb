"""bench/forest.py at CI size: it runs, reports every figure, and the culled
parallel bake is byte-identical to the serial one (no timing assertions)."""

import json
import subprocess
import sys

import pytest
from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))
import forest


def test_parallel_and_serial_forest_bakes_are_identical():
    one = forest.run_one(10, "lod-culled", 1.0, workers=1)
    two = forest.run_one(10, "lod-culled", 1.0, workers=2)
    assert one["bake_sha256"] == two["bake_sha256"]
    assert one["simulated_trees"] <= 10 and one["segments"] > 0


# the calibration (the every-segment truth on 50 trees: 45 s) runs once, under
# -m slow; by default the reference's step is given
@pytest.mark.parametrize("count,step", [(0, "1/240"), (10, "1/240"),
                                        pytest.param(10, None, marks=pytest.mark.slow)])
def test_script_reports_every_figure(tmp_path, count, step):
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "forest.py"), "--counts",
                           str(count), "--duration", "1", "--settings", "lod", "reference",
                           "--out", str(tmp_path), *(["--step", step] if step else [])],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    data = json.loads((tmp_path / "forest.json").read_text())
    for row in data["rows"]:
        for key in ("frame_mean_ms", "frame_p95_ms", "substep_mean_ms", "substep_p95_ms",
                    "wall_seconds", "peak_memory_mb", "export_seconds"):
            assert key in row
        if count:
            assert row["us_per_segment_step"] > 0 and row["simulated_trees"] == count
    if count:
        lod = next(r for r in data["rows"] if r["setting"] == "lod")
        assert lod["reference_over_lod_physics"] > 0

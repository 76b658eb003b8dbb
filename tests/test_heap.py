"""heap.keep_heap_top: an export's process keeps its freed heap top
instead of faulting fresh pages in again (measured by the kernel's count
of minor page faults, in a fresh process each way)."""

import subprocess
import sys

import pytest

CHURN = """
import resource, sys
import numpy as np
if sys.argv[1] == "pad":
    from treebake.heap import keep_heap_top
    assert keep_heap_top()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(100):
    held = [np.ones(12_000) for _ in range(50)]  # 50 arrays of 96 kB, then freed
    del held
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", CHURN, mode], capture_output=True, text=True,
                          check=True)
    return int(done.stdout.split()[-1])


def test_the_padded_heap_top_takes_a_tenth_of_the_page_faults():
    from treebake.heap import keep_heap_top

    if not sys.platform.startswith("linux") or not keep_heap_top():
        pytest.skip("glibc's malloc only")
    plain, padded = _faults("plain"), _faults("pad")
    assert plain > 50_000  # 100 rounds of 4.8 MB given back and faulted in again
    assert padded < plain / 10


def test_an_export_pads_its_heap_top(tmp_path, monkeypatch):
    """export_bake asks for the padded heap top before it writes (the
    workers' initializer does the same: export_pool._open)."""
    import treebake.export as export
    from simkit import bake_text

    bake = bake_text(tmp_path, "#define iterations 1\naxiom: F\nF -> F[+F]F\n", duration=0.2)
    calls = []
    monkeypatch.setattr(export, "keep_heap_top", lambda: calls.append(1) or True)
    export.export_bake(bake, tmp_path / "out", "t", export.ExportOptions(formats=("glb",)))
    assert calls and (tmp_path / "out" / "t" / "t.glb").exists()

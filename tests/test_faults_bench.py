"""Long checks behind the `slow` marker (pytest -m slow): the whole
fault-injection bench, and the stress cases the default suite leaves out."""

import subprocess
import sys

import pytest
from conftest import ROOT


@pytest.mark.slow
def test_every_fault_case_behaves_as_expected():
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "faults.py")], capture_output=True,
                       text=True, timeout=1800)
    assert r.returncode == 0, r.stdout + r.stderr[-3000:]
    assert " as expected" in r.stdout


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["planar", "full"])
def test_the_other_stress_cases(solver):
    from test_accuracy_stability import STRESS
    from treebake.stress import ENERGY_TOLERANCE, GAP_TOLERANCE, run
    from treebake.stress_cases import cases

    for case in cases(long=False):
        if case.name in STRESS:
            continue
        r = run(case, solver)
        assert r.finite, (case.name, r.error)
        assert r.spin > 1e-4, case.name  # the tree moved
        assert r.energy_growth <= ENERGY_TOLERANCE, case.name
        assert r.gap <= GAP_TOLERANCE, case.name

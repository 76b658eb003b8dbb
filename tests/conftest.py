import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GRAMMARS = ROOT / "grammars"
PRESETS = ROOT / "presets"


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


# TREEBAKE_REQUIRE_TOOLS=1 (CI): a skipped test proves nothing, so every skip
# (an importorskip of mujoco, pxr or distributed, a missing validator, a
# pytest.skip anywhere, at collection or at run time) becomes a failure.
REQUIRE_TOOLS = os.environ.get("TREEBAKE_REQUIRE_TOOLS") == "1"


def _fail_skip(report) -> None:
    reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
    report.outcome = "failed"
    report.longrepr = f"skipped, but TREEBAKE_REQUIRE_TOOLS=1 forbids skips: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if REQUIRE_TOOLS and report.skipped and not hasattr(report, "wasxfail"):
        _fail_skip(report)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    report = outcome.get_result()
    if REQUIRE_TOOLS and report.skipped:
        _fail_skip(report)


def need(module: str):
    """Import an optional test dependency (usd-core's `pxr`, trimesh): skip
    without it, except under TREEBAKE_REQUIRE_TOOLS=1 (CI), where a missing
    one fails, so a skipped check never passes for a run one."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        if REQUIRE_TOOLS:
            pytest.fail(f"{module} is needed (TREEBAKE_REQUIRE_TOOLS=1)")
        pytest.skip(f"{module} is an optional dependency")


@pytest.fixture
def engine_calls(monkeypatch):
    """Every SceneLoads.forces call a bake makes: (t, force (B, 3) N)
    (test_flows.py, test_keyed_forces.py)."""
    from treebake.sim.loads import SceneLoads

    calls = []
    forces = SceneLoads.forces

    def spy(self, t, com, vel, axis, props, *args, **kw):
        out = forces(self, t, com, vel, axis, props, *args, **kw)
        calls.append((t, out.copy()))
        return out

    monkeypatch.setattr(SceneLoads, "forces", spy)
    return calls

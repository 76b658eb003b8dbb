from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
GRAMMARS = ROOT / "grammars"
PRESETS = ROOT / "presets"


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


def need(module: str):
    """Import an optional test dependency (usd-core's `pxr`, trimesh): skip
    without it, except under TREEBAKE_REQUIRE_TOOLS=1 (CI), where a missing
    one fails, so a skipped check never passes for a run one."""
    import importlib
    import os

    try:
        return importlib.import_module(module)
    except ImportError:
        if os.environ.get("TREEBAKE_REQUIRE_TOOLS") == "1":
            pytest.fail(f"{module} is needed (TREEBAKE_REQUIRE_TOOLS=1)")
        pytest.skip(f"{module} is an optional dependency")

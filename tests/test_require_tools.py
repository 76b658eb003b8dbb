"""TREEBAKE_REQUIRE_TOOLS=1 turns every skip into a failure: an optional tool
skipped in CI proves nothing."""

import os
import shutil
import subprocess
import sys

from conftest import ROOT


def run_pytest(folder, require: bool):
    env = {k: v for k, v in os.environ.items() if k != "TREEBAKE_REQUIRE_TOOLS"}
    if require:
        env["TREEBAKE_REQUIRE_TOOLS"] = "1"
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           str(folder)], capture_output=True, text=True, env=env, cwd=folder,
                          timeout=120)


def test_skips_become_failures_when_tools_are_required(tmp_path):
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_runtime.py").write_text(
        "import pytest\ndef test_skipped(): pytest.skip('validator missing')\n"
        "def test_fine(): pass\n")
    (tmp_path / "test_module.py").write_text(
        "import pytest\npytest.importorskip('no_such_module_treebake')\n"
        "def test_x(): pass\n")
    relaxed = run_pytest(tmp_path, require=False)
    assert relaxed.returncode == 0 and "2 skipped" in relaxed.stdout, relaxed.stdout
    strict = run_pytest(tmp_path, require=True)
    assert strict.returncode != 0
    assert "TREEBAKE_REQUIRE_TOOLS=1 forbids skips" in strict.stdout
    (tmp_path / "test_module.py").unlink()
    runtime = run_pytest(tmp_path, require=True)
    assert runtime.returncode == 1 and "1 failed, 1 passed" in runtime.stdout, runtime.stdout

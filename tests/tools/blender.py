"""Blender for the tests: the `bpy` module from PyPI (Blender as a Python
module, pinned below; it reads and writes USD, which Debian's blender
package is built without), installed on first use into its own virtual
environment tests/tools/.blender (git-ignored). Without it the tests skip,
unless TREEBAKE_REQUIRE_TOOLS=1 (CI), where they fail."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parent
VENV = TOOLS / ".blender"
BPY = "bpy==5.0.1"  # Blender 5.0; needs Python 3.11


def _missing(reason: str):
    if os.environ.get("TREEBAKE_REQUIRE_TOOLS") == "1":
        pytest.fail(f"{reason} (TREEBAKE_REQUIRE_TOOLS=1: Blender must run)")
    pytest.skip(reason)


def blender_python() -> Path:
    """The Python of the Blender venv, with bpy importable."""
    py = VENV / "bin" / "python"
    stamp = VENV / "installed.txt"
    if not (py.is_file() and stamp.is_file() and stamp.read_text().strip() == BPY):
        if sys.version_info[:2] != (3, 11):
            _missing(f"{BPY} needs Python 3.11")
        proc = subprocess.run([sys.executable, "-m", "venv", "--clear", str(VENV)],
                              capture_output=True, text=True, timeout=300, check=False)
        if proc.returncode == 0:
            proc = subprocess.run([str(py), "-m", "pip", "install", "-q", BPY],
                                  capture_output=True, text=True, timeout=1800, check=False)
        if proc.returncode != 0:
            _missing(f"could not install {BPY}: {proc.stderr[-500:]}")
        stamp.write_text(BPY + "\n")
    return py


def run(script: str, *args: str, timeout: float = 600) -> None:
    """Run tests/tools/<script> in Blender's Python (background, no GPU)."""
    py = blender_python()
    proc = subprocess.run([str(py), str(TOOLS / script), *args], capture_output=True,
                          text=True, timeout=timeout, check=False)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]


def frames(glb: Path, usd: Path, out: Path, numbers: list[int]) -> dict:
    """blender_frames.py: pose bone heads per frame number, glb and USD."""
    run("blender_frames.py", str(glb), str(usd), str(out), *map(str, numbers))
    return json.loads(out.read_text())

"""Run the Khronos glTF Validator (npm package gltf-validator, pinned in
tests/tools/package.json) from the tests. First use installs it into
tests/tools/node_modules (git-ignored). Without node/npm the tests skip,
unless TREEBAKE_REQUIRE_TOOLS=1 (CI), where they fail."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parent
MODULE = TOOLS / "node_modules" / "gltf-validator"


def _missing(reason: str):
    if os.environ.get("TREEBAKE_REQUIRE_TOOLS") == "1":
        pytest.fail(f"{reason} (TREEBAKE_REQUIRE_TOOLS=1: the validator must run)")
    pytest.skip(reason)


def ensure_validator() -> str:
    """Path of node, with gltf-validator installed; skips/fails if it cannot be."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        _missing("node and npm are needed for the Khronos glTF Validator")
    if not MODULE.is_dir():
        proc = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--prefix", str(TOOLS)],
                              cwd=TOOLS, capture_output=True, text=True, timeout=300,
                              check=False)
        if proc.returncode != 0 or not MODULE.is_dir():
            _missing(f"npm could not install gltf-validator: {proc.stderr[-500:]}")
    return node


def validate(paths: list[Path]) -> list[dict]:
    """One report per file: errors, warnings, infos, hints, messages."""
    node = ensure_validator()
    proc = subprocess.run([node, str(TOOLS / "validate.cjs"), *map(str, paths)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return [json.loads(line) for line in proc.stdout.splitlines()]

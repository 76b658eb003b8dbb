"""Run the Node tools of the tests: the Khronos glTF Validator (npm package
gltf-validator) and three.js's GLTFLoader (npm package three), both pinned
in tests/tools/package.json. First use installs them into
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
MODULES = [TOOLS / "node_modules" / m for m in ("gltf-validator", "three")]


def _missing(reason: str):
    if os.environ.get("TREEBAKE_REQUIRE_TOOLS") == "1":
        pytest.fail(f"{reason} (TREEBAKE_REQUIRE_TOOLS=1: the validator must run)")
    pytest.skip(reason)


def ensure_validator() -> str:
    """Path of node, with gltf-validator installed; skips/fails if it cannot be."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        _missing("node and npm are needed for the Khronos glTF Validator")
    if not all(m.is_dir() for m in MODULES):
        proc = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--prefix", str(TOOLS)],
                              cwd=TOOLS, capture_output=True, text=True, timeout=300,
                              check=False)
        if proc.returncode != 0 or not all(m.is_dir() for m in MODULES):
            _missing(f"npm could not install the Node tools: {proc.stderr[-500:]}")
    return node


def validate(paths: list[Path]) -> list[dict]:
    """One report per file: errors, warnings, infos, hints, messages."""
    node = ensure_validator()
    proc = subprocess.run([node, str(TOOLS / "validate.cjs"), *map(str, paths)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return [json.loads(line) for line in proc.stdout.splitlines()]


def three_check(path: Path, times: list[float] = ()) -> dict:
    """What three.js's GLTFLoader makes of a .glb (three_check.mjs): node
    names it rewrote, duplicates, and joint world positions (Y up, m) after
    AnimationMixer.setTime(t) for each t in `times` (s)."""
    node = ensure_validator()
    args = [node, str(TOOLS / "three_check.mjs"), str(path)]
    if times:
        args += ["--times", ",".join(repr(float(t)) for t in times)]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)

"""The installed package's own code as one hash, so a batch reruns jobs when
treebake itself changed (a constant, a solver fix), not only its inputs;
and the resume fingerprint that combines it with a job's inputs and the
installed library versions (treebake.versions)."""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """sha256 over every .py file of the package (relative path and bytes,
    in sorted order); computed once per process."""
    h = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        h.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


@dataclass(frozen=True)
class ResumeFingerprint:
    """What decides a batch job's outputs: `inputs` (Job.inputs_digest: tool
    version, settings, input files' content), `code` (code_fingerprint) and
    `versions` (runtime_versions: the libraries that decide the motion)."""

    inputs: str
    code: str
    versions: dict[str, str]

    @property
    def hash(self) -> str:
        """sha256 over all three: job.json's `hash`, equal only if all are."""
        versions = json.dumps(self.versions, sort_keys=True)
        return hashlib.sha256(f"{self.inputs} code {self.code} versions {versions}".encode()
                              ).hexdigest()

    def with_versions(self, versions: dict[str, str]) -> ResumeFingerprint:
        """The same inputs and code with other versions (a recorded set)."""
        return ResumeFingerprint(self.inputs, self.code, dict(versions))

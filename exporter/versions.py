"""What made a bake: the installed versions of the distributions that decide
its motion. A bake records them in `meta["versions"]`; batch resume reruns a
job whose outputs another set made, and `treebake diff` names the versions
that differ between two bakes whose motion differs. Bakes made before
versions were recorded have none: their side reads "unknown"."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import metadata

# the distributions whose version can change a bake's motion, in report order
DISTRIBUTIONS = ("treebake", "numpy", "mujoco", "pymunk")
NOT_INSTALLED = "not installed"
UNKNOWN = "unknown"  # a side that records no version (a bake older than versions)


@functools.lru_cache(maxsize=1)
def _installed() -> tuple[tuple[str, str], ...]:
    from . import __version__  # the code that runs, even from a source checkout

    found = []
    for name in DISTRIBUTIONS:
        if name == "treebake":
            found.append((name, __version__))
            continue
        try:
            found.append((name, metadata.version(name)))
        except metadata.PackageNotFoundError:
            found.append((name, NOT_INSTALLED))
    return tuple(found)


def runtime_versions() -> dict[str, str]:
    """{distribution: installed version, or "not installed"} for
    DISTRIBUTIONS, in that order; read once per process (a fresh dict each
    call, so callers may keep or change it)."""
    return dict(_installed())


@dataclass(frozen=True)
class VersionChange:
    """One distribution whose version differs between two records."""

    name: str
    before: str  # the first record's version, or UNKNOWN
    after: str  # the second record's, or UNKNOWN

    def __str__(self) -> str:
        return f"{self.name} {self.before} -> {self.after}"


def recorded_versions(value: object) -> dict[str, str]:
    """A `versions` record as read from a bake or job.json: {name: version}
    with string keys and values; anything else (absent, damaged) is {}."""
    if not isinstance(value, dict):
        return {}
    return {str(k): str(v) for k, v in value.items()}


def version_changes(a: dict | None, b: dict | None) -> list[VersionChange]:
    """The distributions whose versions differ from `a` to `b`, DISTRIBUTIONS
    first then the others by name; a side without the name reads UNKNOWN
    (None or a damaged record: no versions at all)."""
    a, b = recorded_versions(a), recorded_versions(b)
    names = [n for n in DISTRIBUTIONS if n in a or n in b]
    names += sorted((set(a) | set(b)) - set(DISTRIBUTIONS))
    return [VersionChange(n, a.get(n, UNKNOWN), b.get(n, UNKNOWN)) for n in names
            if a.get(n, UNKNOWN) != b.get(n, UNKNOWN)]


def version_differences(a: dict | None, b: dict | None) -> list[str]:
    """Human-readable lines for version_changes, e.g. "mujoco 3.13.0 -> 4.0.0";
    [] when the records agree (two records both without versions agree)."""
    return [str(c) for c in version_changes(a, b)]

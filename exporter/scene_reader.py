"""Reading a scene file's keys by their scene_keys.Key records: type,
default and range checks, keys {time, value} read into keys.Keyed curves
(each time within the shot, in order), every error a SceneError naming the
file, the key, the value and the allowed range with its unit."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from .errors import SceneError
from .keys import INTERPOLATIONS, Keyed
from .settings import Key

INTERPOLATION = "_interpolation"  # `speed_interpolation`: how `speed`'s keys interpolate
KEYS_FORM = "[{time = ..., value = ...}, ...]"


def is_keys(value: Any) -> bool:
    """Whether a scene value is a list of keys (tables), not a plain value."""
    return isinstance(value, list) and any(isinstance(x, dict) for x in value)


class SceneReader:
    """Reads keys by their scene_keys.Key: type, default and range checks,
    errors naming the key, the value and the range with its unit."""

    _UNSET = object()

    def __init__(self, file: str):
        self.file = file
        self.tree_names: set[str] = set()
        self.horizon = math.inf  # s: keys' times must be within [0, horizon] (the shot)

    def fail(self, key: str, message: str) -> SceneError:
        return SceneError(key, message, self.file)

    def table(self, data: Any, key: str) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, f"must be a table, got {type(data).__name__}")
        return data

    def check_keys(self, data: dict, path: str, allowed) -> None:
        """Every key of `data` is in `allowed` (names or a table of Keys,
        whose keyed ones also take `<name>_interpolation`, beside keys)."""
        if isinstance(allowed, dict):
            keyed = [k for k, spec in allowed.items() if spec.keyed]
            allowed = [*allowed, *(f"{k}{INTERPOLATION}" for k in keyed)]
            for k in keyed:
                if f"{k}{INTERPOLATION}" in data and not is_keys(data.get(k)):
                    raise self.fail(f"{path}{k}{INTERPOLATION}",
                                    f"applies to keys, and {path}{k} is not a list of keys")
        for k in data:
            if k not in allowed:
                raise self.fail(f"{path}{k}", f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def key(self, data: dict, spec: Key, path: str, default: Any = _UNSET,
            hi: float | None = None) -> Any:
        """The value of `spec` in `data` (its default when absent; `default`
        and `hi` override the table's where they depend on the scene)."""
        full = f"{path}{spec.name}"
        default = spec.default if default is self._UNSET else default
        if spec.keyed and is_keys(data.get(spec.name)):
            return self.keyed(data, spec, path, hi)
        if spec.name not in data:
            if default is None and spec.required:
                raise self.fail(full, "is required")
            return default
        v = data[spec.name]
        hi = spec.hi if hi is None else hi
        if spec.keyed and v == []:
            raise self.fail(full, f"is an empty list: give a value or keys {KEYS_FORM}")
        if spec.kind in ("number", "integer"):
            return self._number(full, v, spec, hi)
        if spec.kind == "bool":
            if not isinstance(v, bool):
                raise self.fail(full, f"must be true or false, got {v!r}")
            return v
        if spec.kind in ("string", "choice"):
            if not isinstance(v, str):
                raise self.fail(full, f"must be a string, got {v!r}")
            if spec.choices and v not in spec.choices:
                raise self.fail(full, f"= {v!r} is not one of: {', '.join(spec.choices)}")
            return v
        if spec.kind == "vector":
            if not isinstance(v, list) or len(v) != spec.n or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                keys = f", or keys {KEYS_FORM}" if spec.keyed else ""
                raise self.fail(full, f"must be a list of {spec.n} numbers{keys}, got {v!r}")
            for x in v:
                if not spec.lo <= x <= spec.hi:
                    raise self.fail(full, f"value {x!r} is out of range {spec.range_text()}"
                                    + (f" {spec.unit.split()[0]}" if spec.unit else ""))
            return tuple(float(x) for x in v)
        raise ValueError(f"key kind {spec.kind!r} is read by its own code")

    def _number(self, full: str, v, spec: Key, hi) -> Any:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            keys = f", or keys {KEYS_FORM}" if spec.keyed else ""
            raise self.fail(full, f"must be a number{keys}, got {v!r}")
        integer = spec.kind == "integer"
        if integer and int(v) != v:
            raise self.fail(full, f"must be a whole number, got {v!r}")
        lo = -math.inf if spec.lo is None else spec.lo
        top = math.inf if hi is None else hi
        if not (lo <= v <= top) or (isinstance(v, float) and math.isnan(v)):
            shown = Key(spec.name, "", spec.unit, lo=spec.lo, hi=hi)
            raise self.fail(full, shown.out_of_range(v))
        return int(v) if integer else float(v)

    def keyed(self, data: dict, spec: Key, path: str, hi: float | None = None,
              convert=None) -> Keyed:
        """The keys of `spec` in `data` (a list of {time, value} tables) as
        a Keyed curve with the interpolation `<name>_interpolation` names
        (linear unless given): each time within the shot and later than
        the one before, each value checked as the key's plain value is
        (then passed through `convert`, e.g. a Beaufort name to m/s)."""
        full = f"{path}{spec.name}"
        times: list[float] = []
        values: list = []
        plain = replace(spec, name="value", keyed=False)
        shot = Key("time", "", "s", lo=0.0, hi=self.horizon)
        for i, k in enumerate(data[spec.name]):
            kp = f"{full}[{i}]"
            if not isinstance(k, dict):
                raise self.fail(kp, f"must be a key {{time, value}}, got {k!r}")
            self.check_keys(k, f"{kp}.", ("time", "value"))
            for need in ("time", "value"):
                if need not in k:
                    raise self.fail(f"{kp}.{need}", "is required")
            t = self._number(f"{kp}.time", k["time"], shot, self.horizon)
            if times and t <= times[-1]:
                raise self.fail(f"{kp}.time", f"= {t:g} s must be later than the key before "
                                f"it ({times[-1]:g} s): keys go in time order, one per time")
            value = self.key({"value": k["value"]}, plain, f"{kp}.", hi=hi)
            times.append(t)
            values.append(value if convert is None else convert(value))
        name = f"{full}{INTERPOLATION}"
        how = data.get(f"{spec.name}{INTERPOLATION}", "linear")
        if not isinstance(how, str) or how not in INTERPOLATIONS:
            raise self.fail(name, f"= {how!r} is not one of: {', '.join(INTERPOLATIONS)}")
        return Keyed(tuple(times), tuple(values), how, angular=spec.unit == "degrees")

    def keys(self, data: dict, table: dict[str, Key], path: str, **given) -> dict:
        """Every key of a table that plain reading covers, checked; `given`
        are values the caller reads itself."""
        self.check_keys(data, path, table)
        return {name: given[name] if name in given else self.key(data, spec, path)
                for name, spec in table.items()}

"""The scene's moving wind sources, `[[gust]]` and `[[downwash]]`: their
records and how their tables are read and checked (scene.py's reader,
scene_keys.py's GUST and DOWNWASH tables; the fields: flows.py). Units:
m, s, m/s, N, degrees."""

from __future__ import annotations

from dataclasses import dataclass

from .keys import Keyed
from .scene_keys import DOWNWASH, GUST


# A keyed key's field holds a plain value, or a keys.Keyed curve through its keys.
@dataclass
class GustSpec:
    position: tuple[float, float, float] | Keyed  # m
    speed: float | Keyed  # m/s, at the centre
    radius: float  # m
    profile: str = GUST["profile"].default  # "bump" or "gaussian"
    direction: float | Keyed | None = GUST["direction"].default  # degrees; None: along travel
    time: float = GUST["time"].default  # s
    ramp: float = GUST["ramp"].default  # s
    end: float = GUST["end"].default  # s


@dataclass
class DownwashSpec:
    position: tuple[float, float, float] | Keyed  # m, the hub
    thrust: float | Keyed  # N
    radius: float  # m
    time: float = DOWNWASH["time"].default  # s
    ramp: float = DOWNWASH["ramp"].default  # s
    end: float = DOWNWASH["end"].default  # s
    floor: float = DOWNWASH["floor"].default  # m, where the wake turns outward


def read_gust(r, data: dict, p: str) -> GustSpec:
    """A `[[gust]]` table (path `p`, e.g. "gust[0].") read by the scene's
    reader `r`: a gust whose air blows along its travel needs a path."""
    spec = GustSpec(**r.keys(data, GUST, p))
    if spec.direction is None and not isinstance(spec.position, Keyed):
        raise r.fail(f"{p}direction", "is required for a gust that stands still (a fixed "
                     "position): give a direction, or keys of position to blow along its path")
    _check_interval(r, spec, p)
    return spec


def read_downwash(r, data: dict, p: str) -> DownwashSpec:
    """A `[[downwash]]` table read by the scene's reader `r`: the hub stays
    above the floor at every key."""
    spec = DownwashSpec(**r.keys(data, DOWNWASH, p))
    keyed = isinstance(spec.position, Keyed)
    points = spec.position.values if keyed else (spec.position,)
    for i, point in enumerate(points):
        if point[2] <= spec.floor:
            key = f"{p}position[{i}].value" if keyed else f"{p}position"
            raise r.fail(key, f"z = {point[2]:g} m: the rotor's hub must be above the floor "
                         f"(z > floor = {spec.floor:g} m)")
    _check_interval(r, spec, p)
    return spec


def _check_interval(r, spec, p: str) -> None:
    if spec.end < spec.time:
        raise r.fail(f"{p}end", f"= {spec.end:g} s is before time ({spec.time:g} s)")

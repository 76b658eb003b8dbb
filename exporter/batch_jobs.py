"""Batch job files: the `Job` record, reading and checking a job file
(docs/batch.md), the Scene a job bakes, and the `JobResult` a run returns."""

from __future__ import annotations

import hashlib
import itertools
import json
import re
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from .errors import InputError, SceneError

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
QUALITY_NAMES = ("draft", "default", "final")
JOB_KEYS = {"name", "scene", "grammar", "seed", "seeds", "quality", "formats", "duration", "fps",
            "wind", "solver", "scheduler"}


@dataclass(frozen=True)
class Job:
    """One bake. `scene` and/or `grammar` are absolute paths; with both, the
    grammar's tree stands alone in the scene's forces."""

    name: str
    scene: str | None = None
    grammar: str | None = None
    seed: int | None = None
    quality: str | None = None
    formats: tuple[str, ...] = ("glb",)
    duration: float | None = None
    fps: float | None = None
    wind: float | None = None  # m/s at 10 m
    solver: str = "planar"
    # a Dask scheduler (tcp://HOST:PORT) whose workers simulate the job's
    # chunks; not an input: the bake is the same wherever its chunks ran
    scheduler: str | None = None

    def inputs(self) -> list[Path]:
        """Every file the job reads: the scene, its grammars, the grammar."""
        files = []
        if self.scene:
            from .scene import load_scene

            files.append(Path(self.scene))
            if not self.grammar:
                files += sorted({Path(t.grammar) for t in load_scene(self.scene).trees})
        if self.grammar:
            files.append(Path(self.grammar))
        return files

    def inputs_digest(self) -> str:
        """Hash of the tool version, the settings and the inputs' content:
        the bake's `scene_hash` (so a bake's bytes do not depend on the code
        that made it beyond its motion)."""
        h = hashlib.sha256(f"treebake {__version__}\n".encode())
        h.update(json.dumps({k: v for k, v in asdict(self).items()
                             if k not in ("name", "scheduler")}, sort_keys=True).encode())
        for path in self.inputs():
            h.update(path.name.encode())
            h.update(path.read_bytes())
        return h.hexdigest()


# ---------------------------------------------------------------------------
# job files


def _fail(file: str, key: str, message: str) -> SceneError:
    return SceneError(key, message, file)


def _check_name(file: str, key: str, name: str) -> str:
    """Output names stay inside the output folder: one plain path component."""
    if not isinstance(name, str) or not NAME.match(name) or name in (".", ".."):
        raise _fail(file, key, f"= {name!r} must be a plain name of letters, digits, '.', '_' "
                               "or '-' (it names a folder inside the output folder; no '/', "
                               "'..' or absolute paths)")
    return name


def _path(file: str, base: Path, key: str, value: Any, kind: str) -> str:
    """A job's `scene` (kind "preset") or `grammar` ("grammar") as an
    absolute path: a file relative to the job file, else a bundled one
    named as on the command line (`preset:gale`, `oak`, `grammar:forest/birch`)."""
    from . import library

    if not isinstance(value, str):
        raise _fail(file, key, f"must be a path string, got {value!r}")
    p = (base / value).resolve()
    if p.is_file():
        return str(p)
    prefixed = value.startswith((library.PRESET_PREFIX, library.GRAMMAR_PREFIX))
    if prefixed or (Path(value).suffix == "" and not p.exists()):
        try:
            return str(library.resolve(value, (kind,)).resolve())
        except InputError as exc:
            raise _fail(file, key, str(exc)) from None
    raise _fail(file, key, f"file not found: {p}")


def _job(file: str, base: Path, raw: dict, key: str, defaults: dict) -> list[Job]:
    if not isinstance(raw, dict):
        raise _fail(file, key, "must be a table")
    for k in raw:
        if k not in JOB_KEYS:
            raise _fail(file, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(JOB_KEYS))})")
    data = {**defaults, **raw}
    scene = _path(file, base, f"{key}.scene", data["scene"], "preset") if "scene" in data else None
    grammar = (_path(file, base, f"{key}.grammar", data["grammar"], "grammar")
               if "grammar" in data else None)
    if scene is None and grammar is None:
        raise _fail(file, key, "needs a scene or a grammar")
    default_name = Path(grammar or scene).stem
    if scene and grammar:
        default_name = f"{Path(grammar).stem}-{Path(scene).stem}"
    name = _check_name(file, f"{key}.name", data.get("name", default_name))
    quality = data.get("quality")
    if quality is not None and quality not in QUALITY_NAMES:
        raise _fail(file, f"{key}.quality", f"= {quality!r} is not one of: "
                                            f"{', '.join(QUALITY_NAMES)}")
    formats = data.get("formats", ["glb"])
    if isinstance(formats, str):
        formats = [formats]
    from .export import check_extras, parse_formats

    try:
        formats = parse_formats(formats)
        check_extras(formats)  # a missing extra: now, not after the job's simulation
    except InputError as exc:
        raise _fail(file, f"{key}.formats", str(exc)) from None
    solver = data.get("solver", "planar")
    if solver not in ("planar", "full"):
        raise _fail(file, f"{key}.solver", f"= {solver!r} is not one of: planar, full")
    scheduler = data.get("scheduler")
    if scheduler is not None:
        if not isinstance(scheduler, str) or "://" not in scheduler:
            raise _fail(file, f"{key}.scheduler", f"= {scheduler!r} is not a Dask scheduler "
                                                  "address (tcp://HOST:PORT)")
        if solver == "full":
            raise _fail(file, f"{key}.scheduler", "spreads the planar LOD's chunks; solver = "
                                                  "\"full\" simulates the scene as one model")
    numbers = {}
    for k, lo, hi in (("duration", 0.0, 3600.0), ("fps", 1.0, 1000.0), ("wind", 0.0, 120.0)):
        if k in data:
            v = data[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise _fail(file, f"{key}.{k}", f"= {v!r} is out of range [{lo:g}, {hi:g}]")
            numbers[k] = float(v)
    seeds = data.get("seeds", [data["seed"]] if "seed" in data else [None])
    if not isinstance(seeds, list) or not all(s is None or (isinstance(s, int) and s >= 0)
                                              for s in seeds) or not seeds:
        raise _fail(file, f"{key}.seeds", f"must be a list of whole numbers >= 0, got {seeds!r}")
    jobs = []
    for seed in seeds:
        suffix = f"-s{seed}" if len(seeds) > 1 else ""
        jobs.append(Job(name + suffix, scene, grammar, seed, quality, tuple(formats),
                        numbers.get("duration"), numbers.get("fps"), numbers.get("wind"),
                        solver, scheduler))
    return jobs


def load_jobs(path: str | Path) -> list[Job]:
    """Read a job file: `[defaults]`, `[[job]]` tables and `[[product]]`
    tables (grammars x scenes x seeds). Every key is checked."""
    p = Path(path)
    file = str(p)
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise _fail(file, "(file)", f"cannot read job file: {exc.strerror}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise _fail(file, "(syntax)", str(exc)) from None
    except RecursionError:  # arrays or tables nested hundreds deep
        raise _fail(file, "(syntax)", "nested too deep to be a job file") from None
    for k in raw:
        if k not in ("defaults", "job", "product"):
            raise _fail(file, k, "unknown key (allowed: defaults, job, product)")
    defaults = raw.get("defaults", {})
    if not isinstance(defaults, dict):
        raise _fail(file, "defaults", "must be a table")
    for k in defaults:
        if k not in JOB_KEYS - {"name", "scene", "grammar"}:
            raise _fail(file, f"defaults.{k}", "unknown key")
    base = p.resolve().parent
    jobs: list[Job] = []
    for i, job in enumerate(_tables(file, raw, "job")):
        jobs += _job(file, base, job, f"job[{i}]", defaults)
    for i, prod in enumerate(_tables(file, raw, "product")):
        key = f"product[{i}]"
        allowed = {"grammars", "scenes", "seeds", "quality", "formats", "duration", "fps",
                   "solver", "scheduler"}
        for k in prod:
            if k not in allowed:
                raise _fail(file, f"{key}.{k}",
                            f"unknown key (allowed: {', '.join(sorted(allowed))})")
        grammars = prod.get("grammars") or [None]
        scenes = prod.get("scenes") or [None]
        if grammars == [None] and scenes == [None]:
            raise _fail(file, key, "needs grammars and/or scenes")
        rest = {k: v for k, v in prod.items() if k not in ("grammars", "scenes")}
        for g, s in itertools.product(grammars, scenes):
            one = dict(rest)
            if g is not None:
                one["grammar"] = g
            if s is not None:
                one["scene"] = s
            jobs += _job(file, base, one, key, defaults)
    if not jobs:
        raise _fail(file, "job", "the job file lists no jobs ([[job]] or [[product]])")
    seen: dict[str, int] = {}
    for j in jobs:
        if j.name in seen:
            raise _fail(file, "name", f"two jobs are named {j.name!r}: names must be unique "
                                      "(they are output folders)")
        seen[j.name] = 1
    return jobs


def _tables(file: str, raw: dict, key: str) -> list[dict]:
    v = raw.get(key, [])
    if isinstance(v, dict):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise _fail(file, key, f"must be an array of tables ([[{key}]])")
    return v


# ---------------------------------------------------------------------------
# what a job bakes, and what comes back


@dataclass
class JobResult:
    """One job's outcome; `seconds` of wall time, `files` relative to the
    job folder."""

    name: str
    # "done", "skipped" (up to date, or written by another run), "failed", "busy" (another
    # run was writing it at the end of this one), "interrupted" (stopped by SIGINT/SIGTERM)
    status: str
    seconds: float = 0.0
    message: str = ""
    files: list[str] = field(default_factory=list)
    frames: int = 0
    segments: int = 0


def scene_of(job: Job):
    """The Scene a job bakes (validated, overrides applied)."""
    from .scene import key_horizon, load_scene, parse_scene, with_wind_speed

    overrides = {k: v for k, v in (("duration", job.duration), ("fps", job.fps),
                                   ("quality", job.quality), ("wind.speed", job.wind))
                 if v is not None}
    if job.scene and not job.grammar:
        if job.seed is not None:
            overrides["seed"] = job.seed
        return load_scene(job.scene, overrides)
    tree = {"grammar": job.grammar}
    if job.seed is not None:
        tree["seed"] = job.seed
    if job.scene:
        raw = tomllib.loads(Path(job.scene).read_text(encoding="utf-8"))
        raw = {k: v for k, v in raw.items() if k not in ("tree", "forest", "cut", "pull")}
        raw["tree"] = [tree]
        base = Path(job.scene).parent
    else:
        raw = {"tree": [tree], "wind": {"speed": 6.7, "turbulence": 0.25}}
        base = Path(job.grammar).parent
    raw["name"] = job.name
    if "wind.speed" in overrides:
        raw["wind"] = with_wind_speed(raw.get("wind", {}), overrides.pop("wind.speed"))
    horizon = key_horizon(raw, overrides)
    raw.update(overrides)
    return parse_scene(raw, file=job.scene or job.grammar, base=base,
                       source_hash=job.inputs_digest(), horizon=horizon)

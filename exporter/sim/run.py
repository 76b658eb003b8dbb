"""The simulate stage: the scene's rigged trees through the solver asked
for (solver.Solver), and the energy audit of what it gives back."""

from __future__ import annotations

from enum import StrEnum

from ..errors import InputError
from ..scene import Scene
from .audit import AuditedSink, gain_notes
from .events import summary
from .notes import log_lines
from .rigging import RiggedScene
from .solver import Solver, SolveResult, TreeSink


class SolverKind(StrEnum):
    """`--solver`: PLANAR, the planar LOD (a linear tier for whole trees,
    the pymunk tier and the MuJoCo reference for trees that leave its
    range); FULL, the MuJoCo reference for everything."""

    PLANAR = "planar"
    FULL = "full"


def solver_kind(solver: str) -> SolverKind:
    """The solver asked for ("planar" or "full"), once MuJoCo is known to
    load: it is a dependency, and a bake never silently switches engines
    (InputError, before any work, where it does not)."""
    kind = SolverKind(solver)
    require_mujoco()
    return kind


def segments_held(kind: SolverKind, scene: Scene, workers: int) -> int | None:
    """At most how many animated segments have their motion in memory at
    once when each tree is handed on as soon as it is final (None: all):
    the planar LOD's chunks being simulated or waiting to be taken; the
    full reference and scenes with projectiles are one model."""
    if kind is SolverKind.FULL or scene.projectiles:
        return None
    from .lod import CHUNK_SEGMENTS

    return CHUNK_SEGMENTS * (2 * max(workers, 1) + 1)


def require_mujoco() -> None:
    """Raise InputError if MuJoCo cannot be imported."""
    try:
        import mujoco  # noqa: F401
    except ImportError as exc:
        raise InputError(f"MuJoCo cannot be loaded ({exc}): treebake needs it for every "
                         "bake; reinstall it with `pip install --force-reinstall mujoco`") \
            from None


def simulate(kind: SolverKind, rigged: RiggedScene, scene: Scene, workers: int = 1,
             timestep: float | None = None, log=None, progress=None,
             scheduler: str | None = None, on_tree: TreeSink | None = None) -> SolveResult:
    """The scene's active trees through the solver of `kind` (`timestep` s:
    the full reference's step, default its own; `workers` processes, or the
    Dask cluster at `scheduler`, share the planar LOD's chunks); its result
    with the energy audit in its meta (meta["energy"]) and the audit's
    warnings among its notes, and for people one log line per tree and
    kind of event, then the notes. With `on_tree` (solver.TreeSink) each
    tree's motion goes there as soon as it is final (audited first) and the
    result keeps none: memory follows the chunk, not the shot."""
    log = log or (lambda msg: None)
    sink = AuditedSink([t.name for t in rigged.trees], scene.fps, on_tree)
    result = solver_for(kind, rigged, scene, workers, timestep, log, scheduler).run(progress,
                                                                                   sink)
    result.meta["energy"] = sink.energy
    result.notes = result.notes + gain_notes(sink.energy)
    if on_tree is None:  # kept for the caller, in the order they came
        result.motions = sink.kept
    for line in summary(sink.events) + log_lines(result.notes):
        log(line)
    return result


def solver_for(kind: SolverKind, rigged: RiggedScene, scene: Scene, workers: int = 1,
               timestep: float | None = None, log=None,
               scheduler: str | None = None) -> Solver:
    """The solver of `kind` for the scene's rigged trees."""
    if kind is SolverKind.PLANAR:
        from .lod import PlanarLOD

        return PlanarLOD(rigged.trees, rigged.qualities, scene, rigged.loads, workers, log,
                         scheduler)
    if scheduler:
        raise InputError("--scheduler spreads the planar LOD's chunks over a Dask cluster; "
                         "--solver full simulates the scene as one model, in one process")
    from .reference import ReferenceSolver

    return ReferenceSolver(rigged.trees, scene, scene.quality, rigged.loads, log=log,
                           timestep=timestep)

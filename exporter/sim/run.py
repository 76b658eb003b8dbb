"""The simulate stage: the scene's rigged trees through the solver asked
for (solver.Solver), and the energy audit of what it gives back."""

from __future__ import annotations

from enum import StrEnum

from ..errors import InputError
from ..scene import Scene
from .audit import audit_motions, gain_notes
from .events import summary
from .rigging import RiggedScene
from .solver import Solver, SolveResult


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
             scheduler: str | None = None) -> SolveResult:
    """The scene's active trees through the solver of `kind` (`timestep` s:
    the full reference's step, default its own; `workers` processes, or the
    Dask cluster at `scheduler`, share the planar LOD's chunks); its result with the energy audit in its meta
    (meta["energy"]) and the audit's warnings among its notes, and for
    people one log line per tree and kind of event, then the notes."""
    log = log or (lambda msg: None)
    result = solver_for(kind, rigged, scene, workers, timestep, log, scheduler).run(progress)
    result.meta["energy"] = audit_motions(result.motions, scene.fps)
    result.notes = result.notes + gain_notes(result.meta["energy"])
    for line in summary({name: m.events for name, m in result.motions.items()}) + result.notes:
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

"""The simulate stage: the scene's rigged trees through the solver asked
for (solver.Solver), and the energy audit of what it gives back."""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from ..errors import InputError
from ..scene import Scene
from .audit import audit_motions, gain_notes
from .loads import SceneLoads
from .rigging import RiggedScene
from .solver import Solver, SolveResult


class SolverKind(StrEnum):
    """`--solver`: PLANAR, the planar LOD (a linear tier for whole trees,
    the pymunk tier and the MuJoCo reference for trees that leave its
    range); FULL, the MuJoCo reference for everything."""

    PLANAR = "planar"
    FULL = "full"


def require_mujoco() -> None:
    """Raise InputError, before any work, if MuJoCo cannot be imported: it
    is a dependency, and a bake never silently switches engines."""
    try:
        import mujoco  # noqa: F401
    except ImportError as exc:
        raise InputError(f"MuJoCo cannot be loaded ({exc}): treebake needs it for every "
                         "bake; reinstall it with `pip install --force-reinstall mujoco`") \
            from None


def solver_for(kind: SolverKind, rigged: RiggedScene, scene: Scene, loads: SceneLoads,
               extent: np.ndarray, workers: int = 1, timestep: float | None = None,
               log=None) -> Solver:
    """The solver of `kind` for the scene's active trees; `timestep` (s):
    the full reference's step (default its own); `workers` processes share
    the planar LOD's chunks."""
    if SolverKind(kind) is SolverKind.PLANAR:
        from .lod import PlanarLOD

        return PlanarLOD(rigged.trees, rigged.qualities, scene, extent, workers, log)
    from .reference import ReferenceSolver

    return ReferenceSolver(rigged.trees, scene, scene.quality, loads, log=log,
                           timestep=timestep)


def simulate(solver: Solver, fps: float, progress=None) -> SolveResult:
    """Run the solver; its result with the energy audit in its meta
    (meta["energy"]) and the audit's warnings among its notes."""
    result = solver.run(progress)
    result.meta["energy"] = audit_motions(result.motions, fps)
    result.notes = result.notes + gain_notes(result.meta["energy"])
    return result

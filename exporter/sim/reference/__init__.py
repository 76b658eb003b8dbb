"""The full-3D reference in MuJoCo, by job: `model.py` builds the models,
`events.py` fells, breaks and frees parts, `stepper.py` steps them with
the loads and the damping, `solver.py` runs it as the `--solver full`
solver and as a tier of the planar LOD."""

from .solver import ReferenceSolver, ReferenceTier
from .stepper import DEFAULT_TIMESTEP, TIMESTEPS, ReferenceEngine

__all__ = ["DEFAULT_TIMESTEP", "TIMESTEPS", "ReferenceEngine", "ReferenceSolver",
           "ReferenceTier"]

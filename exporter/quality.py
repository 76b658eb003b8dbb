"""Quality levels: how finely the planar LOD simulates. Scenes and the
command line pick a level by name (`QUALITIES`) or override single keys
(docs/scenes.md); the simulation reads the record. No imports from the rest
of the package, so that scenes and engines both depend on it and not on
each other."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class TierPolicy(StrEnum):
    """Where a tree starts. AUTO: the linear tier, a nonlinear engine when it
    leaves its range; PYMUNK: every tree in the pymunk tier all shot (the
    design card's all-pymunk LOD)."""

    AUTO = "auto"
    PYMUNK = "pymunk"


class NonlinearPolicy(StrEnum):
    """The engine for trees that leave the linear tier. AUTO: the engine
    table (sim/handoff.py, docs/physics.md: the MuJoCo reference for every
    reason); REFERENCE: the same, said outright; PYMUNK: the pymunk tier for
    every reason."""

    AUTO = "auto"
    REFERENCE = "reference"
    PYMUNK = "pymunk"


@dataclass(frozen=True)
class Quality:
    """Simulation settings of one level.

    linear_rate (Hz): the linear tier's implicit steps per second;
    relinearise (rad): the linear tier takes its matrices again at the
    trees' mean pose once a bone of it has turned this far from the pose
    they were taken at. reference_step (s): MuJoCo's step when it takes a
    tree from the linear tier. The pymunk tier: substep_rate (Hz) physics
    steps, force_rate (Hz) load updates (held between), iterations (pymunk
    solver iterations), planes (1: one bending plane per limb, 2: two),
    stability (the largest omega*h before a rotary-inertia floor applies),
    joint_correction (fraction of a joint's position error corrected per
    substep), coupling ("apparent" or "rigid": how a parent chain carries
    its children). bone_length: bones are merged segments at least this
    fraction of the tree height (0: one bone per segment). tier, nonlinear:
    which engine moves a tree (the enums above; strings are converted).
    hand_back: a tree a nonlinear engine took for large motion or a joint
    near breaking comes back to the linear tier once back in its range
    (False: it stays)."""

    name: str = "default"
    substep_rate: float = 960.0
    force_rate: float = 120.0
    iterations: int = 10
    planes: int = 2
    bone_length: float = 0.0
    stability: float = 1.0
    joint_correction: float = 0.02
    coupling: str = "apparent"
    linear_rate: float = 48.0
    relinearise: float = 0.25
    tier: TierPolicy = TierPolicy.AUTO
    nonlinear: NonlinearPolicy = NonlinearPolicy.AUTO
    reference_step: float = 1 / 480
    hand_back: bool = True

    def __post_init__(self):
        object.__setattr__(self, "tier", TierPolicy(self.tier))
        object.__setattr__(self, "nonlinear", NonlinearPolicy(self.nonlinear))


QUALITIES = {
    "draft": Quality("draft", 480.0, 60.0, 8, 2, 1 / 12, linear_rate=24.0,
                     reference_step=1 / 240),
    "default": Quality("default", 960.0, 120.0, 10, 2, 0.0, linear_rate=24.0,
                       reference_step=1 / 480),
    "final": Quality("final", 1920.0, 240.0, 20, 2, 0.0, linear_rate=96.0, relinearise=0.2,
                     reference_step=1 / 1000),
}

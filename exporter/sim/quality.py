"""Quality levels: how finely the planar LOD simulates (the simulation side
owns them; scenes and the command line only pick one by name)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Quality:
    """Simulation settings. substep_rate: physics steps per second (Hz).
    force_rate: how often forces are re-evaluated (Hz); between evaluations
    they are held. iterations: pymunk solver iterations. planes: 1 = one
    bending plane per limb (the card's design), 2 = two perpendicular planes.
    bone_length: bones are merged segments at least this fraction of the tree
    height (0 = one bone per segment). stability: the largest allowed
    omega*h of any joint before a rotary-inertia floor is applied
    (see docs/physics.md). joint_correction: fraction of a joint's position
    error corrected per substep. coupling: how a parent chain carries its
    children (docs/physics.md): "apparent" (their apparent mass at the
    parent's frequency) or "rigid"."""

    name: str = "default"
    substep_rate: float = 960.0
    force_rate: float = 120.0
    iterations: int = 10
    planes: int = 2
    bone_length: float = 0.0
    stability: float = 1.0
    joint_correction: float = 0.02
    coupling: str = "apparent"  # "apparent": children's apparent mass; "rigid": plain lumping
    linear_rate: float = 48.0  # Hz, the linear tier's implicit steps
    relinearise: float = 0.25  # rad: the linear tier takes its matrices again at the
    # trees' mean pose once a bone of it has turned this far from the pose they were taken at
    tier: str = "auto"  # "auto": linear, nonlinear engine when needed; "pymunk": pymunk only
    nonlinear: str = "auto"  # trees that leave the linear range: "reference" (MuJoCo,
    # when installed: "auto"), "articulated" (else: "auto"; the pymunk tier for
    # what may break, cuts and hits) or "pymunk"
    reference_step: float = 1 / 480  # s, the reference's step when it is the nonlinear engine
    articulated_step: float = 1 / 480  # s, the articulated tier's step (articulated.py)
    cut_engine: str = "pymunk"  # under nonlinear "auto", the engine for a felled tree:
    # "pymunk" (robust at any step) or "nonlinear" (the nonlinear engine)


def reference_available() -> bool:
    """Whether MuJoCo (the `reference` extra) can be imported."""
    import importlib.util

    return importlib.util.find_spec("mujoco") is not None


def nonlinear_engine(quality: Quality) -> str:
    """The engine for trees that leave the linear range: "reference",
    "articulated" (with the pymunk tier for breaks, cuts and hits) or "pymunk"."""
    if quality.nonlinear == "auto":
        return "reference" if reference_available() else "articulated"
    return quality.nonlinear


QUALITIES = {
    "draft": Quality("draft", 480.0, 60.0, 8, 2, 1 / 12, linear_rate=24.0,
                     reference_step=1 / 240, articulated_step=1 / 240),
    "default": Quality("default", 960.0, 120.0, 10, 2, 0.0, linear_rate=24.0,
                       reference_step=1 / 480),
    # a felled tree at `final` goes to the reference (when installed): at 1/1000 s it
    # gained at most 0.17 % on every felled species, where the pymunk tier's one-way
    # coupling makes 1.7 % of a sapling's (docs/physics.md), in 0.2-1.1x its time
    # (3.2-3.7x on the willow, whose 1,328 broken parts are free bodies in contact)
    "final": Quality("final", 1920.0, 240.0, 20, 2, 0.0, linear_rate=96.0, relinearise=0.2,
                     reference_step=1 / 1000, articulated_step=1 / 960, cut_engine="nonlinear"),
}

"""The physics rules every engine applies, each written once: breaking,
damping as an exact decay, free parts' inertia floor and spin clamp,
felling's push (fell_push), when a tree is at rest, and the load rates for hits.
docs/physics.md has the reasons and the measurements behind the values."""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from .events import BROKE, UPROOTED, Event

FELL_NUDGE = 0.05  # rad/s: the feller's push at the cut, toward the felling direction
FELL_MARGIN = 1.5  # the push's margin over the least that tips a stem over its hinge


def fell_push(height: float, behind: float, gravity: float) -> float:
    """The turn rate (rad/s) the feller gives a cut stem: FELL_NUDGE, or
    more where its centre of mass, `height` m above the hinge and `behind`
    m behind it (the stem's radius for an upright stem, its hinge being the
    falling side's edge), must first be lifted over the hinge: what a
    point mass needs (1/2 w^2 (h^2 + b^2) = g (|(h, b)| - h)) times
    FELL_MARGIN, which covers a stem's larger moment of inertia (a
    uniform pole's about its base is 4/3 of the point mass's at its
    centre). `gravity` m/s^2."""
    if behind <= 0.0 or height <= 0.0:
        return FELL_NUDGE
    reach = float(np.hypot(height, behind))
    need = np.sqrt(2.0 * gravity * (reach - height)) / reach
    return max(FELL_NUDGE, FELL_MARGIN * float(need))
SETTLE_SPEED = 0.05  # m/s and rad/s: a fallen tree slower than this ...
SETTLE_TIME = 0.5  # s: ... for this long is at rest
STILL_SPEED = 0.005  # m/s and rad/s: the same for a standing tree no changing load reaches
MAX_SPIN = 100.0  # rad/s: a free part's spin is clamped here (counted)
MIN_INERTIA_RATIO = 0.1  # a free part's smallest principal moment / its largest, at least
# the pymunk tier's substep and load rates (Hz) for trees a projectile can
# reach, at least: a hit jolts the stem and its chains feel their frame's
# jolt one load update later (docs/physics.md, "Hits")
HIT_SUBSTEP_RATE = 960.0
HIT_FORCE_RATE = 120.0
# A blast's twigs ring on after its push at tens of Hz, which a
# stiffness-implicit step damps by about pi f h: the nonlinear engines step
# at most BLAST_STEP from a blast's arrival at a tree until BLAST_RING after
# its push (docs/physics.md, "The step while a blast rings, converged")
BLAST_STEP = 1 / 32000  # s
BLAST_RING = 0.05  # s (50 Hz: 2.5 periods)


def exact_decay(alpha: np.ndarray | float, hold: float) -> np.ndarray | float:
    """The rate (1/s) that, held over `hold` s as -rate x momentum, removes
    what a decay at `alpha` (1/s) removes over that time exactly:
    (1 - exp(-alpha hold)) / hold. Structural damping on every engine."""
    return -np.expm1(-alpha * hold) / hold


def limb_damping(mass: np.ndarray, rate: np.ndarray, same_limb=True) -> np.ndarray:
    """Structural damping's matrix entries C_ij = rate_i M_ij from the
    joint-space mass matrix's entries M_ij whose two hinges move one limb
    (`same_limb`; 0 elsewhere): every bone's motion relative to its limb's
    frame, with all the limb carries, decays at `rate_i` (1/s: the rig's
    alpha, or exact_decay of it over a held step). Both hinge-coordinate
    engines (joint_space.py, reference/stepper.py) take C from here."""
    if same_limb is True:  # (the reference keeps only one limb's entries: no copy)
        return rate * mass
    return np.where(same_limb, rate * mass, 0.0)


def past_strength(moment: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """Which joints break: bending moment (N m) above strength (N m)."""
    return moment > strength


def break_event(t: float, tree: str, path: str, root: bool, moment: float,
                strength: float) -> Event:
    """The record of a joint at segment `path` that broke at t s under
    `moment` N m (an uprooting where it is a root joint)."""
    return Event(t, tree, UPROOTED if root else BROKE, path,
                 f"{moment:.0f} N m > strength {strength:.0f} N m")


def floored_inertia(inertia: np.ndarray) -> np.ndarray:
    """An inertia tensor (3, 3) kg m^2 with its principal moments floored at
    MIN_INERTIA_RATIO of the largest: a free thin stick would otherwise spin
    about its own axis without bound (explicit steps, contact friction)."""
    lam, vec = np.linalg.eigh(inertia)
    lam = np.maximum(lam, MIN_INERTIA_RATIO * lam[-1])
    return (vec * lam) @ vec.T


def still_for(still: float, speed: float, limit: float, dt: float) -> float:
    """How long (s) a tree has been slower than `limit` (m/s and rad/s),
    after a further `dt` s at `speed`: it is at rest past SETTLE_TIME."""
    return still + dt if speed < limit else 0.0


class Felling(StrEnum):
    """A cut tree's stage: STANDING until its cut, HINGED (the notch frees
    the felling hinge, the hinge wood holds) until it leans past the scene's
    `hinge` angle, then FALLING (off its stump)."""

    STANDING = "standing"
    HINGED = "hinged"
    FALLING = "falling"


def broken_note(by_engine: dict[str, int]) -> str | None:
    """The bake's note on breaks: how many joints broke, on which engine
    (its name: count); None where none did."""
    total = sum(by_engine.values())
    if not total:
        return None
    where = ", ".join(f"{n} on the {name}" for name, n in by_engine.items() if n)
    return (f"{total} joint{'s' if total > 1 else ''} broke ({where}); what broke off fell on "
            "as free bodies")

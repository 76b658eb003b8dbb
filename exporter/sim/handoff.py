"""What passes between the planar LOD's tiers: why a tree left one (`Reason`),
the state it left in (`HandOff`), which engine takes it (`engine_for`), the
stretches of its shot in each engine (`TierSpan`, in words `spans_text`), and
the protocol every tier implements (`Tier`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Protocol

import numpy as np

from ..quality import NonlinearPolicy, Quality, TierPolicy
from .common import ProjectileTracks, TreeMotion
from .range import BREAK_MARGIN, CONE_FRACTION, MAX_TURN
from .rules import HIT_SUBSTEP_RATE


class Engine(StrEnum):
    """The engines of the planar LOD: the linear tier (linear.py), the pymunk
    tier (chains/) and the MuJoCo reference (reference/)."""

    LINEAR = "linear"
    PYMUNK = "pymunk"
    REFERENCE = "reference"


class Reason(StrEnum):
    """Why a tree leaves the linear tier (checked in this order, linear.py),
    or why an engine hands it back."""

    NEAR_BREAK = "break"  # a joint's moment past range.BREAK_MARGIN of its strength
    GROUND = "ground"  # a branch tip reached the ground
    TURN = "turn"  # a bone turned past range.MAX_TURN from its grown pose
    CONE = "cone"  # a hinge past range.CONE_FRACTION of its cone
    CUT = "cut"  # its felling cut
    PROJECTILE = "projectile"  # a thrown object can reach it: it starts in the nonlinear engine
    BACK = "back"  # a nonlinear engine hands it back: in the linear range again
    BLAST = "blast"  # (a HandOff.restart: the state a blast under way found it in)
    PAST_STRENGTH = "past strength"  # (a HandOff.restart: the start of the step in which a
    # joint passed its strength)


# trees taken for these may come back to the linear tier once back in its range
RETURNABLE = frozenset({Reason.TURN, Reason.CONE, Reason.NEAR_BREAK})


def engine_for(reason: Reason, quality: Quality) -> Engine:
    """The one engine that takes a tree leaving the linear tier for `reason`
    (docs/physics.md, "Which engine takes a tree"): the MuJoCo reference,
    for every reason, unless the quality asks for the pymunk tier (`tier`
    or `nonlinear` = "pymunk"). bench/engines.py measured the pymunk tier
    against it on cuts, ground contact and thrown objects: never cheaper,
    as accurate on ground contact and far less on cuts and hits."""
    if reason is Reason.BACK:
        return Engine.LINEAR
    if quality.tier is TierPolicy.PYMUNK or quality.nonlinear is NonlinearPolicy.PYMUNK:
        return Engine.PYMUNK
    return Engine.REFERENCE


@dataclass(frozen=True)
class BrokenOff:
    """What a tree handed back to the linear tier has lost: `standing` (B,)
    which of its bones still stand on its roots; the others lie still, at
    `quaternions` (B, 4) x y z w from rest and `pivots` (B, 3) m (rows of
    standing bones unused), holding `energy` J (the audit's: gravity above
    z = 0 and their springs); `hold` (2B,) N m, each hinge spring's
    prestress torque, which the standing tree keeps (the wood keeps its
    set, JointSpace.hold)."""

    standing: np.ndarray
    quaternions: np.ndarray
    pivots: np.ndarray
    energy: float
    hold: np.ndarray


@dataclass(frozen=True)
class HandOff:
    """A tree leaving a tier at `time` s = `substep` pymunk substeps from
    t = 0 (the pymunk tier starts there; -1 where it has no meaning: a
    hand-back to the linear tier, which starts at `frame`), with its state: hinge angles `q`
    and rates `v` (2B,) rad and rad/s from the grown shape; rotations
    relative to rest `rot` (B, 3, 3) and world spins `omega` (B, 3) rad/s
    (None where the tier does not have them: a hand-back). `frame`: the
    first frame the next tier owns (a hand-back), else -1. `work` J: done on
    the tree since the bake's start. `before_blast`: the tree as the blast
    under way found it (None: no blast under way): the next engine starts
    there (a nonlinear engine cannot take a blast's impulse half delivered).
    `step_length` s: the linear tier's step (a tree coming back gets it).
    `broken`: what a tree handed back has lost (None: nothing)."""

    tree: int  # index among the chunk's trees
    time: float
    substep: int
    q: np.ndarray
    v: np.ndarray
    reason: Reason
    detail: str
    rot: np.ndarray | None = None
    omega: np.ndarray | None = None
    frame: int = -1
    work: float = 0.0
    step_length: float = 0.0
    restart: HandOff | None = None
    broken: BrokenOff | None = None

    def origin(self) -> HandOff:
        """The state the next engine starts from: `restart`, else here
        (with this hand-off's reason either way)."""
        if self.restart is None:
            return self
        return replace(self.restart, reason=self.reason, detail=self.detail,
                       step_length=self.step_length, restart=None)

    def offset_work(self, joules: float) -> HandOff:
        """The same hand-off with `joules` J added to its work (and its
        restart's): a tier counts work from its own start."""
        restart = None if self.restart is None else self.restart.offset_work(joules)
        return replace(self, work=self.work + joules, restart=restart)


@dataclass(frozen=True)
class TierSpan:
    """A stretch of a tree's shot in one engine, from `start` s (None: from
    the shot's start), and why it came there."""

    engine: Engine
    start: float | None = None
    reason: Reason | None = None
    detail: str = ""


def spans_text(spans: list[TierSpan]) -> str:
    """Which engines moved a tree and from when, in words: "linear, then
    reference from 1.234 s (trunk/2:0: a joint past 80% of its strength)"."""
    first = spans[0]
    parts = [f"{first.engine.value} ({first.detail})" if first.detail else first.engine.value]
    parts += [f"{s.engine.value} from {s.start:.3f} s ({s.detail})" for s in spans[1:]]
    return ", then ".join(parts)


class Tier(Protocol):
    """An engine running some trees of a chunk. It is started (by its own
    constructor) from rest or from hand-offs; `first_frame` is the first
    frame whose pose is its own; `advance_to(frame)` steps to that frame,
    recording every frame, and returns the trees that left it (hand-offs:
    to another engine, or back to the linear tier); `motions()` gives per
    tree the frames it spent there (zero elsewhere), its events, energy and
    work (J, from the tier's start); `report()` its counts, notes and
    timings; `tracks()` the flight of the projectiles it moved (or None)."""

    first_frame: int

    def advance_to(self, frame: int) -> list[HandOff]: ...

    def motions(self) -> list[TreeMotion]: ...

    def report(self) -> TierReport: ...

    def tracks(self) -> ProjectileTracks | None: ...


@dataclass
class TierReport:
    """What a tier run did, for the bake's meta (deterministic `stats`,
    counts that add up over runs), its `notes` (in words) and `timing` (s,
    never in the bake)."""

    engine: Engine
    stats: dict
    notes: list[str]
    timing: dict


LEAVING = {  # what each reason means, for the docs' engine table
    Reason.TURN: f"range: a bone turned past {MAX_TURN:g} rad from its grown pose",
    Reason.CONE: f"range: a hinge past {CONE_FRACTION:.0%} of its cone",
    Reason.NEAR_BREAK: f"a joint's moment past {BREAK_MARGIN:.0%} of its strength (it may "
                       "break)",
    Reason.GROUND: "a branch tip reached the ground",
    Reason.CUT: "its felling cut",
    Reason.PROJECTILE: "a thrown object can reach it (from the start)",
}


def engine_table(levels: dict[str, Quality]) -> str:
    """The docs' table (docs/physics.md): for each reason a tree leaves the
    linear tier, at each quality level, the one engine that takes it and
    its step."""
    def cell(reason: Reason, q: Quality) -> str:
        engine = engine_for(reason, q)
        if engine is Engine.REFERENCE:
            return f"reference, 1/{round(1 / q.reference_step)} s"
        rate = max(q.substep_rate, HIT_SUBSTEP_RATE) if reason is Reason.PROJECTILE \
            else q.substep_rate
        return f"pymunk, 1/{rate:.0f} s"

    rows = ["| the tree leaves the linear tier for | " + " | ".join(f"`{n}`" for n in levels)
            + " |", "|---" * (len(levels) + 1) + "|"]
    rows += [f"| {text} (`{reason.value}`) | " + " | ".join(cell(reason, q)
                                                           for q in levels.values()) + " |"
             for reason, text in LEAVING.items()]
    return "\n".join(rows)

"""The energy audit: per tree and frame, the mechanical energy of its bones
and broken-off parts and the work the outside did on it, in every solver.

    U(t) = E(t) - W(t),   gain = the largest rise of U above its lowest value before

E: kinetic energy of every bone (its COM's speed and its spin, with its true
mass and inertia), its gravitational energy above z = 0, and the energy the
joint springs hold (prestress included). W: the work of the external loads
(air, blasts, attractors, pulls: the force held over an interval times the
displacement of the COM it acts on) plus the energy thrown objects lose in
their hits on the tree. Damping, drag against the motion, ground contact
and breaking (a broken joint's spring energy is gone) only ever lower U; a
rise is energy the solver made up (measured from the lowest U before it, so
that earlier dissipation cannot hide a later gain). Its largest value, when, and the event
nearest to it go into every bake's meta; `treebake bake` warns past
GAIN_TOLERANCE of the tree's own scale (E(0) plus the work done on it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GAIN_TOLERANCE = 0.02  # unexplained gain, fraction of E(0) + max |W|


def bone_energy(mass: np.ndarray, inertia0: np.ndarray, rot: np.ndarray, com: np.ndarray,
                vcom: np.ndarray, omega: np.ndarray, g: float) -> np.ndarray:
    """Kinetic plus gravitational energy (J) of bones (B,): mass kg, rest
    inertia about the COM (B, 3, 3) kg m^2, rotation from rest, COM (m),
    COM velocity (m/s), angular velocity (rad/s, world), gravity m/s^2."""
    w_rest = np.einsum("bji,bj->bi", rot, omega)  # the spin in the bone's rest frame
    spin = np.einsum("bi,bij,bj->b", w_rest, inertia0, w_rest)
    return 0.5 * mass * (vcom * vcom).sum(1) + 0.5 * spin + mass * g * com[:, 2]


def per_tree(values: np.ndarray, bone_tree: np.ndarray, trees: int) -> np.ndarray:
    return np.bincount(bone_tree, values, minlength=trees)


@dataclass
class Ledger:
    """Energy E (J) at each frame and work W (J) done on each tree up to it."""

    frames: int
    trees: int
    energy: np.ndarray = field(init=False)
    work: np.ndarray = field(init=False)
    running: np.ndarray = field(init=False)  # work so far, per tree

    def __post_init__(self):
        self.energy = np.full((self.frames, self.trees), np.nan)
        self.work = np.full((self.frames, self.trees), np.nan)
        self.running = np.zeros(self.trees)

    def add_work(self, per_tree_work: np.ndarray) -> None:
        self.running += per_tree_work

    def record(self, frame: int, energy: np.ndarray, pending: np.ndarray | None = None) -> None:
        """The frame's energy per tree, and the work so far plus `pending`
        (J per tree: what the loads held now did since their update)."""
        self.energy[frame] = energy
        self.work[frame] = self.running if pending is None else self.running + pending


class LoadWork:
    """Work of loads between updates: a force held over the interval (a
    solver that holds its loads, `trapezoid` False) times the displacement of
    its point until the next update; or, for the implicit trapezoidal steps
    whose loads act at the step ends, the mean of the two ends' forces."""

    def __init__(self, trapezoid: bool = False):
        self.trapezoid = trapezoid
        self.force = None
        self.point = None

    def pending(self, point: np.ndarray) -> np.ndarray:
        """Per-bone work (J) the held force has done since its update, its
        points now at `point`: a frame between updates records it (else an
        impulsive push shows as a gain until the next update; docs/physics.md,
        "The audit's frames between load updates"). Trapezoidal steps hold
        nothing."""
        if self.trapezoid or self.force is None or len(self.force) != len(point):
            return np.zeros(len(point))
        return (self.force * (point - self.point)).sum(1)

    def keep(self, rows: np.ndarray) -> None:
        """Keep only these rows (bones) of the held force and its points
        (a solver that drops bones and renumbers the rest)."""
        if self.force is not None:
            self.force, self.point = self.force[rows], self.point[rows]

    def update_rows(self, rows: np.ndarray, force: np.ndarray, point: np.ndarray) -> np.ndarray:
        """Per-bone work (J) of `rows` since their previous update, and hold
        their new force (a model updated more often than the rest: the
        others' forces hold on). For held loads only."""
        work = (self.force[rows] * (point - self.point[rows])).sum(1)
        self.force[rows], self.point[rows] = force, point
        return work

    def update(self, force: np.ndarray, point: np.ndarray) -> np.ndarray:
        """Per-bone work (J) since the previous update, and hold the new force."""
        if self.force is None or len(self.force) != len(point):
            work = np.zeros(len(point))
        else:
            acting = 0.5 * (self.force + force) if self.trapezoid else self.force
            work = (acting * (point - self.point)).sum(1)
        self.force, self.point = force.copy(), point.copy()
        return work


def summary(names: list[str], energy: np.ndarray, work: np.ndarray, fps: float,
            events: list) -> dict:
    """Per tree: E(0), the largest unexplained gain (J, and as a fraction of
    E(0) + max |W|), when it peaked, and the events of the frames it grew in."""
    out = {}
    for ti, name in enumerate(names):
        e, w = energy[:, ti], work[:, ti]
        ok = np.isfinite(e) & np.isfinite(w)
        if not ok.any():
            continue
        first = int(np.argmax(ok))
        u = np.where(ok, e - w, np.nan)[first:]
        u = np.where(np.isnan(u), np.fmax.accumulate(np.where(np.isnan(u), -np.inf, u)), u)
        low = np.minimum.accumulate(u)
        rise = u - low
        k = int(np.argmax(rise))
        start = int(np.nonzero(u[:k + 1] == low[k])[0][-1]) if k else 0
        gain = np.concatenate([np.zeros(first), rise])
        k += first
        scale = abs(float(e[first])) + float(np.nanmax(np.abs(w - w[first])))
        t = k / fps
        t0 = (start + first) / fps
        near = [ev for ev in events if ev.tree == name and t0 - 0.5 / fps <= ev.time <= t]
        out[name] = {"initial_j": round(float(e[first]), 3),
                     "external_work_j": round(float(w[ok][-1] - w[first]), 3),
                     "max_gain_j": round(max(float(gain[k]), 0.0), 3),
                     "max_gain_fraction": round(max(float(gain[k]), 0.0) / max(scale, 1e-9), 6),
                     "at_s": round(t, 4),
                     "from_s": round(t0, 4),
                     "events": [ev.text() for ev in near[:3]]}
    return out


def gain_notes(audit: dict) -> list[str]:
    """Warnings for trees whose unexplained gain passes GAIN_TOLERANCE."""
    notes = []
    for name, a in audit.items():
        if a["max_gain_fraction"] > GAIN_TOLERANCE:
            during = f" (events: {'; '.join(a['events'])})" if a["events"] else ""
            notes.append(f"warning: energy audit: tree {name!r} gained {a['max_gain_j']:.0f} J "
                         f"({a['max_gain_fraction']:.1%} of its energy and the work done on it) "
                         f"that no load supplied, between t = {a['from_s']:.2f} and "
                         f"{a['at_s']:.2f} s{during}")
    return notes


def audit_motions(motions: dict, fps: float) -> dict:
    """summary() over the trees' motions (TreeMotion.energy and .work)."""
    names = [n for n, m in motions.items() if m.energy is not None]
    if not names:
        return {}
    energy = np.stack([motions[n].energy for n in names], 1)
    work = np.stack([motions[n].work for n in names], 1)
    events = [e for n in names for e in motions[n].events]
    return summary(names, energy, work, fps, events)


@dataclass
class AuditedSink:
    """A TreeSink (sim.solver) that audits each tree's motion as it comes
    (its `energy` record by tree name, audit_motions at `fps` frames/s) and
    keeps its `events`, then hands it to `on_tree`, or keeps it in `kept`
    (by name, in the order they came) when there is none. `names`: the
    rigged trees' names by index."""

    names: list[str]
    fps: float
    on_tree: object = None
    energy: dict = field(default_factory=dict)
    events: dict = field(default_factory=dict)
    kept: dict = field(default_factory=dict)

    def __call__(self, index: int, motion, engines: str) -> None:
        name = self.names[index]
        self.energy.update(audit_motions({name: motion}, self.fps))
        self.events[name] = motion.events
        if self.on_tree is not None:
            self.on_tree(index, motion, engines)
        else:
            self.kept[name] = motion

"""The linear range: the limits past which a tree leaves the linear tier
(checked every step, linear.py) and the margins within which a nonlinear
engine hands it back (RETURN_*: hysteresis, so that it does not bounce
between engines). docs/physics.md, "Leaving the linear range" and "Coming
back"."""

from __future__ import annotations

import numpy as np

from .common import Bones

MAX_TURN = 1.0  # rad: a bone turned further from its grown pose leaves the linear range
CONE_FRACTION = 0.9  # a hinge past this fraction of its cone leaves it (the cone would act)
BREAK_MARGIN = 0.8  # a joint whose moment passes this fraction of its strength leaves it
CONTACT_MARGIN = 0.05  # m: a tip this close to the ground (and below its rest height) leaves it
RETURN_FRACTION = 0.5  # back within this fraction of every limit above ...
RETURN_WINDOW = 0.5  # s: ... for this long, standing, what broke off lying still, ...
RETURN_TURN = 0.02  # rad: ... with no hinge turning more than this per linear step
BACK_DETAIL = "back in the linear range"
RETURN_DETAIL = f"to linear: {BACK_DETAIL}"  # the tier event's


class ReturnWatch:
    """How long (s) a nonlinear engine's trees have been back in range, a
    frame (1/fps s) at a time: they go back once it reaches RETURN_WINDOW."""

    def __init__(self, fps: float):
        self.frame = 1.0 / fps
        self.returning = 0.0

    def update(self, in_range: bool) -> bool:
        """The trees are (`in_range`) or are not back in range at this
        frame: whether they have been for RETURN_WINDOW."""
        self.returning = self.returning + self.frame if in_range else 0.0
        return self.returning >= RETURN_WINDOW - 1e-9


def in_return_range(bones: Bones, rot: np.ndarray, pivot: np.ndarray, q: np.ndarray,
                    v: np.ndarray, moment: np.ndarray, h: float,
                    standing: np.ndarray | None = None) -> bool:
    """Whether intact bones, turned by `rot` (B, 3, 3) from rest with
    pivots `pivot` (B, 3) m, hinge angles and rates q, v (2B,) rad, rad/s
    and joint moments `moment` (B,) N m, are back in this tier's range with
    RETURN_FRACTION's margin: bones turned less than MAX_TURN, hinges within
    CONE_FRACTION of their cones, moments below BREAK_MARGIN of their
    strengths, tips clear of the ground (or no lower than they grew), no
    hinge turning more than RETURN_TURN in a step of `h` s. `standing` (B,)
    bool: only those bones are checked (the rest broke off; None: all)."""
    b = slice(None) if standing is None else standing
    hinge = slice(None) if standing is None else np.repeat(standing, 2)  # as pruning.py's
    rot, pivot, q, v, moment = rot[b], pivot[b], q[hinge], v[hinge], moment[b]
    tip0, pivot0 = bones.tip0[b], bones.pivot0[b]
    cos = np.clip(0.5 * (np.trace(rot, axis1=1, axis2=2) - 1.0), -1.0, 1.0)
    tip_z = pivot[:, 2] + np.einsum("bj,bj->b", rot[:, 2], tip0 - pivot0)
    return bool(np.all(np.arccos(cos) < RETURN_FRACTION * MAX_TURN)
                and np.all(np.abs(q).reshape(-1, 2)
                           < RETURN_FRACTION * CONE_FRACTION * bones.cone[b][:, None])
                and np.all(moment < RETURN_FRACTION * BREAK_MARGIN * bones.strength[b])
                and np.all((tip_z > bones.radius[b] + 2 * CONTACT_MARGIN)
                           | (tip_z >= tip0[:, 2] - 1e-3))
                and np.all(np.abs(v) * h < RETURN_TURN))

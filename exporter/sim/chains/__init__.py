"""The planar LOD's pymunk tier: every limb a chain of 2D bodies in its own
bending planes (tier.py has the design). The tier, and pymunk with it, is
loaded only when asked for: a bake whose motion stays linear never needs it."""

from .stats import StartState, Stats

__all__ = ["PymunkTier", "StartState", "Stats"]


def __getattr__(name: str):
    if name == "PymunkTier":
        from .tier import PymunkTier

        return PymunkTier
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

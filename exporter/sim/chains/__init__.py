"""The planar LOD's pymunk tier: every limb a chain of 2D bodies in its own
bending planes (tier.py has the design)."""

from .tier import PymunkTier, Stats

__all__ = ["PymunkTier", "Stats"]

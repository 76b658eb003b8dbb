"""treebake: L-system trees, physics in wind and impacts, baked animation files."""

__version__ = "0.1.0"

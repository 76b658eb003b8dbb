"""Which texture each mesh material gets: the generic bark, a species'
bark (bark.py) or a leaf-card atlas (textures.py), at a detail level."""

from __future__ import annotations

from .bark import species_bark
from .textures import Texture, bark_texture, leaf_texture


def texture_for(material: str, detail: str = "default") -> Texture | None:
    """The texture of a mesh material ("bark", "bark_oak", "leaf", "leaf2",
    ...) at a detail level (bark.SCALE: the species' bark textures' size),
    or None for materials that stay plain (projectiles)."""
    if material == "bark":
        return bark_texture()
    if material.startswith("bark_"):
        return species_bark(material.removeprefix("bark_"), detail)
    if material.startswith("leaf"):
        kind = int(material[4:] or 1)
        return leaf_texture(kind, "far" if detail == "far" else "default")
    return None

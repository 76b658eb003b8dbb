"""Bundled scene presets (`.toml`), shipped as package data of treebake.

They name grammars by bundled name (`grammar = "oak"`, `grammars =
["forest/birch", ...]`), not by path, so a copy of a preset in any folder
loads the same bundled grammars (treebake.library)."""

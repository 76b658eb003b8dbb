"""Bundled scene presets (`.toml`), shipped as package data of treebake.

They name grammars by relative path (`../grammars/oak.lsys`): installed,
`treebake/presets/` and `treebake/grammars/` stay siblings, so the paths
resolve the same as in the checkout."""

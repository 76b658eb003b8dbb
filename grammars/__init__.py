"""Bundled species grammars (`.lsys`), shipped as package data of treebake.

Read them with `treebake.library` (or importlib.resources); this file only
makes the folder a regular package, so both wheel and editable installs
find it."""

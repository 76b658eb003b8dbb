"""treebake: L-system trees, physics in wind and impacts, baked animation files.

The public API (details in each function's docstring, README "Python API"):

- `load_scene(source, **overrides)`: a scene file, grammar, bundled grammar
  name (`"oak"`) or preset (`"preset:felling"`) -> Scene
- `bake_scene(scene)`: simulate -> Bake (per frame and segment: position, rotation)
- `save_bake(bake, path)` / `load_bake(path)`: the `.npz` bake
- `export_bake(bake, out, formats=("glb", "usd", ...))`: files + manifest.json

Errors a user can cause are `InputError`s (exit code 2 on the command line).
Imports are lazy: `import treebake` loads no simulation code.
"""

__version__ = "0.2.0"

from . import library  # noqa: E402  (the bundled grammars and presets; loads nothing heavy)
from .api import bake_scene, export_bake, load_bake, load_scene, save_bake  # noqa: E402
from .errors import InputError, TreebakeError  # noqa: E402

__all__ = ["InputError", "TreebakeError", "bake_scene", "export_bake", "library", "load_bake",
           "load_scene", "save_bake", "__version__"]

"""Bundled species grammars and scene presets, found by name.

They ship as package data (`treebake.grammars`, `treebake.presets`; in the
checkout the top-level `grammars/` and `presets/` folders) and are read
through importlib.resources, so lookups work from any folder, after a wheel
install or an editable one. Presets name their grammars by bundled name
(`grammar = "oak"`, `grammars = ["forest/birch", ...]`, resolved by
scene.py as for any scene file), not by path, so a preset copied out of
the package (the path `treebake list presets --json` gives) still loads.

Names: a grammar is its path under `grammars/` without `.lsys` (`oak`,
`forest/birch`, `abop/fig1.24a`); a preset its file stem (`felling`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from .errors import InputError

PRESET_PREFIX = "preset:"
GRAMMAR_PREFIX = "grammar:"


def _folder(package: str) -> Path:
    # Traversable -> real folder: treebake installs unzipped (wheel or
    # editable), and the commands take file paths
    return Path(str(resources.files(package)))


def grammars_folder() -> Path:
    """The folder of the bundled grammars."""
    return _folder("treebake.grammars")


def presets_folder() -> Path:
    """The folder of the bundled scene presets."""
    return _folder("treebake.presets")


@dataclass(frozen=True)
class Entry:
    """A bundled file: kind ("grammar" or "preset"), name, path, one-line
    description (the grammar's `description:` or the file's first comment)."""

    kind: str
    name: str
    path: Path
    description: str


def _summary(path: Path, grammar: bool) -> str:
    text = path.read_text(encoding="utf-8")
    if grammar:
        m = re.search(r"^\s*description\s*:\s*(.+)$", text, re.MULTILINE)
        if m:
            return m.group(1).strip()
    lines = []
    for line in text.splitlines():  # the leading comment's first sentence
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("#").strip())
    # a sentence ends at ". " before a capital ("p. 25" and "e.g. the" do not end one)
    first = re.split(r"(?<!\b[a-z])\.\s+(?=[A-Z])", " ".join(lines), maxsplit=1)[0]
    return first.rstrip(".")  # whole: `list --json` carries it, `list` shortens it to read


def grammars() -> list[Entry]:
    """Every bundled grammar, sorted by name."""
    root = grammars_folder()
    return sorted((Entry("grammar", p.relative_to(root).with_suffix("").as_posix(), p,
                         _summary(p, True)) for p in root.rglob("*.lsys")),
                  key=lambda e: (e.name.count("/"), e.name))


def presets() -> list[Entry]:
    """Every bundled scene preset, sorted by name."""
    return sorted((Entry("preset", p.stem, p, _summary(p, False))
                   for p in presets_folder().glob("*.toml")), key=lambda e: e.name)


def grammar_path(name: str) -> Path:
    """A bundled grammar by name (`oak`, `forest/birch`)."""
    path = grammars_folder() / f"{name}.lsys"
    # a name inside the bundle only, not a path out of it ("..", absolute)
    if ".." in Path(name).parts or Path(name).is_absolute() or not path.is_file():
        known = ", ".join(e.name for e in grammars() if "/" not in e.name)
        raise InputError(f"no bundled grammar {name!r} (bundled: {known}; "
                         "`treebake list` shows all)")
    return path


def preset_path(name: str) -> Path:
    """A bundled scene preset by name (`felling`)."""
    path = presets_folder() / f"{name}.toml"
    if "/" in name or "\\" in name or not path.is_file():
        known = ", ".join(e.name for e in presets())
        raise InputError(f"no bundled preset {name!r} (bundled: {known})")
    return path


def resolve(text: str, kinds: tuple[str, ...] = ("grammar", "preset")) -> Path:
    """A command-line job argument as a file: an existing path as given;
    `preset:NAME` / `grammar:NAME` a bundled file; a bare name (no folder, no
    suffix) the bundled grammar of that name, else the preset. `kinds` are
    what the command accepts."""
    p = Path(text)
    if text.startswith(PRESET_PREFIX) and "preset" in kinds:
        return preset_path(text[len(PRESET_PREFIX):])
    if text.startswith(GRAMMAR_PREFIX) and "grammar" in kinds:
        return grammar_path(text[len(GRAMMAR_PREFIX):])
    if p.exists() or p.suffix in (".lsys", ".toml"):
        return p  # a file (a missing one gets the command's own "not found" error)
    if "grammar" in kinds and (grammars_folder() / f"{text}.lsys").is_file():
        return grammar_path(text)
    if "preset" in kinds and "/" not in text and (presets_folder() / f"{text}.toml").is_file():
        return preset_path(text)
    what = " or ".join(f"bundled {k}" for k in kinds)
    raise InputError(f"{text!r} is neither a file nor a {what} (`treebake list` shows them)")

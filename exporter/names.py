"""Names every tool keeps: tree, joint and node names made only of ASCII
letters, digits and `_`, starting with a letter or `_`, at most 63 bytes.

Why this set: three.js's GLTFLoader strips `[ ] . : /` and turns spaces into
`_` (then suffixes duplicates `_N`); Maya reads `:` as a namespace and `|`
as a path; USD prim and joint names must be identifiers; Blender cuts
names at 63 bytes and renames duplicates `.001`. Inside this set and unique
in the file, a name arrives unchanged in all of them.

Joints: `<tree>_<limb path>_s<segment>`, the segment path `trunk/2/1:3` of
tree `oak` becoming `oak_trunk_2_1_s3` (one-to-one: `/` -> `_`, `:` ->
`_s`; limb paths are `trunk`, `trunk2`, ... and child numbers). The
original path travels beside it (glTF node `extras.segment_path`, USD
`treebake:segmentPaths`).
"""

from __future__ import annotations

import re

MAX_NAME = 63  # bytes: Blender's limit for object and bone names
MAX_TREE_NAME = 40  # leaves room for the joint suffix
_VALID = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def is_valid(name: str) -> bool:
    """Whether `name` survives three.js, Blender, Maya, Houdini and USD unchanged."""
    return bool(_VALID.match(name)) and len(name) <= MAX_NAME


def make_valid(text: str) -> str:
    """`text` with every other character replaced by `_` (a leading digit gets
    a `_` in front), cut to MAX_TREE_NAME: for names derived from file names."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", str(text)) or "_"
    if name[0].isdigit():
        name = "_" + name
    return name[:MAX_TREE_NAME]


def joint_name(tree: str, path: str, index: int) -> str:
    """The joint (glTF node, USD joint) name of segment `index` at `path`."""
    limb, _, k = path.rpartition(":")
    name = f"{tree}_{limb.replace('/', '_')}_s{k}" if limb else f"{tree}_s{index}"
    if not is_valid(name):  # a user grammar deeper than any bundled one: still unique
        name = f"{tree}_s{index}"
    return name


def joint_names(tree: str, paths: list[str]) -> list[str]:
    """Every segment's joint name, unique within the tree (checked)."""
    names = [joint_name(tree, p, i) for i, p in enumerate(paths)]
    if len(set(names)) != len(names):  # paths were not unique: fall back to indices
        names = [f"{tree}_s{i}" for i in range(len(paths))]
    return names

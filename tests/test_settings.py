"""One source for settings (issue 15): every grammar and scene key's unit,
default and range live in one table (lsystem/settings.py, scene_keys.py);
the parsers take defaults and ranges from it, their errors quote it, and
the key tables in docs/grammar.md and docs/scenes.md are generated from it
(this test fails when the docs and the tables differ)."""

import math
from dataclasses import replace
from pathlib import Path

import pytest
from treebake import docs_tables, scene_keys
from treebake.errors import GrammarError, SceneError
from treebake.lsystem import parse_grammar
from treebake.lsystem.settings import LSYSTEM, PHYSICS
from treebake.scene import parse_scene

ROOT = Path(__file__).resolve().parent.parent
SAPLING = str(ROOT / "grammars" / "sapling.lsys")


def test_docs_tables_are_generated_from_the_key_tables():
    for rel, tables in docs_tables.doc_tables().items():
        text = (ROOT / rel).read_text(encoding="utf-8")
        assert text.count("<!-- keys:") == len(tables), rel  # every table is in its doc
        assert docs_tables.render(text, tables) == text, (
            f"{rel} is out of date: python -m treebake.docs_tables --write")
    assert docs_tables.main([str(ROOT)]) == 0


# minimal valid tables, to vary one key at a time
MINIMAL = {
    "scene": {},
    "scene.tree": {},
    "scene.forest": {"grammars": [SAPLING], "count": 1, "area": [20.0, 20.0]},
    "scene.wind": {"speed": 5.0},
    "scene.explosion": {"position": [0.0, 0.0, 1.0], "charge": 1.0},
    "scene.vortex": {"start": [0.0, 0.0], "max_speed": 10.0, "core_radius": 5.0},
    "scene.gust": {"position": [0.0, 0.0, 1.0], "speed": 5.0, "radius": 2.0, "direction": 0.0},
    "scene.downwash": {"position": [0.0, 0.0, 10.0], "thrust": 1000.0, "radius": 2.0},
    "scene.attractor": {"position": [0.0, 0.0, 1.0], "strength": 1.0},
    "scene.projectile": {"size": 0.3, "mass": 10.0, "position": [0.0, -5.0, 1.0]},
    "scene.cut": {},
    "scene.pull": {"force": [10.0, 0.0, 0.0], "release": 1.0},
    "scene.camera": {"keys": [{"time": 0.0, "position": [0.0, -20.0, 2.0],
                               "target": [0.0, 0.0, 2.0]}]},
    "scene.camera.keys": {"time": 0.0, "position": [0.0, -20.0, 2.0],
                          "target": [0.0, 0.0, 2.0]},
    "scene.quality": {},
}


def _scene(table: str, values: dict) -> dict:
    raw = {"tree": [{"grammar": SAPLING}]}
    body = {**MINIMAL[table], **values}
    if table == "scene":
        raw.update(body)
    elif table == "scene.tree":
        raw["tree"] = [{"grammar": SAPLING, **values}]
    elif table == "scene.camera.keys":
        raw["camera"] = {"keys": [body]}
    elif table == "scene.forest":
        raw = {"forest": {**body, "grammars": [SAPLING]}}
    else:
        key = table.split(".")[1]
        raw[key] = body if key in ("wind", "camera", "quality", "forest") else [body]
    return raw


def _numeric(table: str):
    for key in scene_keys.TABLES[table].values():
        if key.kind in ("number", "integer") and key.doc_range is None:
            yield key


@pytest.mark.parametrize("table", sorted(scene_keys.TABLES))
def test_scene_parser_checks_every_number_against_its_table(table):
    for key in _numeric(table):
        where = f"{table.split('.', 1)[1]}." if "." in table else ""
        where = {"camera.keys.": r"camera\.keys\[0\]\.", "tree.": r"tree\[0\]\."}.get(
            where, where.replace("vortex.", r"vortex\[0\]\.").replace(
                "explosion.", r"explosion\[0\]\.").replace(
                "attractor.", r"attractor\[0\]\.").replace(
                "projectile.", r"projectile\[0\]\.").replace("pull.", r"pull\[0\]\."))
        for bad in (key.lo - 1 if key.lo is not None else None,
                    key.hi * 2 + 1 if key.hi not in (None, math.inf) else None):
            if bad is None:
                continue
            with pytest.raises(SceneError) as err:
                parse_scene(_scene(table, {key.name: bad}))
            text = str(err.value)
            assert key.name in text and key.range_text() in text, text
            assert text.endswith(key.unit), text
        if key.lo is not None and key.kind == "integer" and table != "scene.forest":
            parse_scene(_scene(table, {key.name: int(key.lo)}))  # the bound itself is fine


def test_scene_defaults_are_the_documented_ones():
    """Against what the README and the standards say, not the table the
    parser reads: standard gravity, film's 24 frames per second, frame 1 the
    first in every tool, a grown shape that does not sag, a ground; wind
    measured at 10 m (WMO) with the open-terrain power-law shear 1/7."""
    scene = parse_scene({"tree": [{"grammar": SAPLING}], "wind": {"speed": 3.0}})
    assert scene.gravity == pytest.approx(9.80665, abs=0.01)
    assert (scene.fps, scene.frame_start, scene.prestress, scene.ground) == (24.0, 1, True, True)
    assert scene.wind.reference_height == 10.0
    assert scene.wind.shear == pytest.approx(1 / 7, abs=0.005)


def test_scene_parser_takes_its_defaults_and_ranges_from_the_table(monkeypatch):
    # the parser reads the table: change the table, the check follows
    parse_scene({"tree": [{"grammar": SAPLING}], "duration": 20.0})
    monkeypatch.setitem(scene_keys.TOP, "duration",
                        replace(scene_keys.TOP["duration"], hi=15.0, default=3.0))
    with pytest.raises(SceneError, match=r"duration:? = 20 is out of range \[0, 15\] s"):
        parse_scene({"tree": [{"grammar": SAPLING}], "duration": 20.0})
    assert parse_scene({"tree": [{"grammar": SAPLING}]}).duration == 3.0


def test_grammar_defaults_are_the_documented_ones():
    """Against the sources (docs/physics-sources.md), not the table the
    parser reads: green wood's Young's modulus (USDA Wood Handbook, 6-12
    GPa), a cylinder's drag coefficient across the flow (about 1.2 at
    sub-critical Reynolds numbers), no breaking unless asked, ABOP's
    defaults (no tropism, unit scale)."""
    p = parse_grammar("axiom: F\n").physics
    assert 6e9 <= p.modulus <= 12e9
    assert p.drag == pytest.approx(1.2, abs=0.1)
    assert math.isinf(p.strength) and math.isinf(p.rupture) and math.isinf(p.anchor)
    g = parse_grammar("axiom: F\n")
    assert g.elasticity == 0.0 and g.scale == 1.0


def test_grammar_parser_checks_every_setting_against_its_table():
    for key in {**LSYSTEM, **PHYSICS}.values():
        if key.kind not in ("number", "integer"):
            continue
        bad = [v for v in (None if key.lo is None else key.lo - 1,
                           None if key.hi in (None, math.inf) else key.hi * 2 + 1)
               if v is not None]
        for v in bad:
            with pytest.raises(GrammarError) as err:
                parse_grammar(f"axiom: F\n{key.name}: {v!r}\n")
            assert f"{key.name} = " in str(err.value) and key.range_text() in str(err.value)
        for alias in key.aliases:  # every spelling the table lists is read
            if alias.isascii():
                ok = key.lo if key.lo is not None else 0
                parse_grammar(f"axiom: F\n{alias}: {ok}\n")

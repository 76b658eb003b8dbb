"""Scene files: every preset loads; bad keys and values give errors that
name the file, the key, the value and the allowed range."""

import numpy as np
import pytest
from conftest import PRESETS
from treebake.errors import InputError, SceneError
from treebake.scene import BEAUFORT, load_scene, parse_scene

SAPLING = str(PRESETS.parent / "grammars" / "sapling.lsys")


@pytest.mark.parametrize("path", sorted(PRESETS.glob("*.toml")), ids=lambda p: p.stem)
def test_every_preset_loads(path):
    scene = load_scene(path)
    assert scene.trees and scene.duration > 0 and scene.fps > 0


def test_required_presets_exist():
    names = {p.stem for p in PRESETS.glob("*.toml")}
    assert {"calm", "breeze", "gale", "hurricane", "gusty", "boxes", "felling", "explosion",
            "tornado", "attractor", "forest"} <= names
    forest = load_scene(PRESETS / "forest.toml")
    assert len(forest.trees) == 250 and forest.wind is not None


def test_beaufort_presets_are_in_their_wmo_bands():
    bands = list(BEAUFORT.items())
    for name, lo_speed in [("breeze", 5.5), ("gale", 17.2)]:
        wind = load_scene(PRESETS / f"{name}.toml").wind
        i = [k for k, _ in bands].index(next(k for k, v in bands if v == lo_speed))
        hi_speed = bands[i + 1][1]
        assert lo_speed <= wind.speed < hi_speed
    assert load_scene(PRESETS / "hurricane.toml").wind.speed >= 32.7


def test_storm_builds_from_calm_to_a_gale_while_it_veers():
    """The storm preset (issue 41): calm at the start, inside the WMO gale
    band (Beaufort 8, 17.2-20.8 m/s at 10 m) at the end, never above it, and a
    change of direction on a few trees."""
    storm = load_scene(PRESETS / "storm.toml")
    speed, heading = storm.wind.speed, storm.wind.direction
    t = np.linspace(0.0, storm.duration, 1401)
    u = speed.at(t)
    assert u[0] < BEAUFORT["light air"] and BEAUFORT["gale"] <= u[-1] < BEAUFORT["strong gale"]
    assert u.max() < BEAUFORT["strong gale"] and np.all(np.diff(u) >= 0)  # builds, no overshoot
    turn = heading.at(storm.duration) - heading.at(0.0)
    assert 30.0 <= abs(turn) <= 90.0
    assert 2 <= len(storm.trees) <= 5


def scene_error(raw, match):
    with pytest.raises(SceneError, match=match) as info:
        parse_scene(raw, file="s.toml")
    assert str(info.value).startswith("s.toml: ")
    return info.value


def test_out_of_range_names_key_value_and_range():
    err = scene_error({"tree": [{"grammar": SAPLING}], "duration": -1},
                      r"duration = -1 is out of range \[0, 3600\]")
    assert err.key == "duration"
    scene_error({"tree": [{"grammar": SAPLING}], "wind": {"speed": 500}},
                r"wind\.speed = 500 is out of range \[0, 120\]")
    scene_error({"tree": [{"grammar": SAPLING}], "explosion": [{"position": [0, 0, 0],
                                                                 "charge": 0}]},
                r"explosion\[0\]\.charge")


def test_unknown_keys_and_wrong_types():
    scene_error({"tree": [{"grammar": SAPLING}], "wnd": {}}, r"wnd: unknown key")
    scene_error({"tree": [{"grammar": SAPLING}], "fps": "fast"}, r"fps: must be a number")
    scene_error({"tree": [{"grammar": SAPLING, "position": [1, 2, 3]}]},
                r"tree\[0\]\.position: must be a list of 2 numbers")
    scene_error({"tree": [{"grammar": "missing.lsys"}]}, r"tree\[0\]\.grammar: file not found")
    scene_error({}, r"tree: the scene has no trees")
    scene_error({"tree": [{"grammar": SAPLING}], "quality": "ultra"},
                r"quality = 'ultra' is not one of")
    scene_error({"tree": [{"grammar": SAPLING}], "cut": [{"tree": 3}]},
                r"cut\[0\]\.tree = 3 is out of range \[0, 0\]")


def test_forest_that_cannot_fit_says_so():
    scene_error({"forest": {"grammars": [SAPLING], "count": 100, "area": [10, 10],
                            "min_spacing": 5}}, r"forest\.count: only \d+ of 100 trees fit")


def test_forest_scatter_is_seeded():
    raw = {"forest": {"grammars": [SAPLING], "count": 20, "area": [60, 60]}, "seed": 4}
    a = [t.position for t in parse_scene(raw).trees]
    b = [t.position for t in parse_scene(raw).trees]
    c = [t.position for t in parse_scene(dict(raw, seed=5)).trees]
    assert a == b and a != c


def test_load_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("duration = [")
    with pytest.raises(SceneError, match="bad.toml"):
        load_scene(bad)
    # a missing scene and a folder say so, as a missing grammar does
    with pytest.raises(InputError, match=r"none\.toml: scene file not found$"):
        load_scene(tmp_path / "none.toml")
    with pytest.raises(InputError, match="is a folder, not a scene file"):
        load_scene(tmp_path)


def test_a_scene_names_bundled_grammars_as_the_command_line_does(tmp_path):
    # `treebake bake oak` works, so `grammar = "oak"` in a scene must too; a
    # file of that name beside the scene comes first
    from treebake import library

    scene = parse_scene({"tree": [{"grammar": "oak"}, {"grammar": "grammar:forest/birch"}],
                         "forest": {"grammars": ["sapling"], "count": 2, "area": [20, 20]}},
                        file="s.toml", base=tmp_path)
    paths = [t.grammar for t in scene.trees]
    assert paths[:3] == [library.grammar_path("oak"), library.grammar_path("forest/birch"),
                         library.grammar_path("sapling")]
    (tmp_path / "oak").write_text((PRESETS.parent / "grammars" / "sapling.lsys").read_text())
    own = parse_scene({"tree": [{"grammar": "oak"}]}, file="s.toml", base=tmp_path)
    assert own.trees[0].grammar == tmp_path / "oak"
    outside = str(PRESETS.parent / "grammars" / "oak")  # absolute: not a bundled name
    for missing in ("nope", "grammar:nope", "oak.lsys", "../grammars/oak", outside):
        scene_error({"tree": [{"grammar": missing}]},
                    r"tree\[0\]\.grammar: file not found: .*nor a bundled grammar")

"""Bundled grammars and presets by name (package data, issue 15): every
preset loads through importlib.resources with its grammars resolved by
name, names resolve the documented way, and the public API works from
another folder. (.ci/wheel-smoke checks the same from an installed wheel.)"""

import json
from pathlib import Path

import pytest
import treebake  # noqa: F401  (the package root: the public API)
from treebake import library
from treebake.cli import main
from treebake.errors import InputError
from treebake.lsystem import load_grammar
from treebake.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent


def test_every_bundled_file_is_listed_and_readable():
    names = {e.name for e in library.grammars()}
    assert names == {p.relative_to(ROOT / "grammars").with_suffix("").as_posix()
                     for p in (ROOT / "grammars").rglob("*.lsys")}
    assert {"oak", "spruce", "forest/birch", "abop/fig1.24a"} <= names
    for e in library.grammars():
        assert load_grammar(library.grammar_path(e.name)).axiom
    presets = {e.name for e in library.presets()}
    assert presets == {p.stem for p in (ROOT / "presets").glob("*.toml")}
    for e in library.presets():
        scene = load_scene(library.preset_path(e.name))  # grammars by bundled name
        assert all(t.grammar.is_file() for t in scene.trees)
        assert e.description and "\n" not in e.description


def test_names_resolve_files_grammars_then_presets(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # another folder: nothing relative to the checkout
    assert library.resolve("oak") == library.grammar_path("oak")
    assert library.resolve("forest/conifer").name == "conifer.lsys"
    assert library.resolve("preset:felling") == library.preset_path("felling")
    assert library.resolve("forest") == library.preset_path("forest")  # no forest.lsys
    assert library.resolve("grammar:sapling").name == "sapling.lsys"
    (tmp_path / "oak").write_text("x")
    assert library.resolve("oak") == Path("oak")  # an existing file wins
    with pytest.raises(InputError, match="no bundled preset 'nope'.*felling"):
        library.resolve("preset:nope")
    with pytest.raises(InputError, match="neither a file nor a bundled grammar"):
        library.resolve("nope")
    with pytest.raises(InputError, match="bundled grammar"):
        library.resolve("preset", ("grammar",))
    with pytest.raises(InputError):
        library.grammar_path("../presets/demo")
    with pytest.raises(InputError):  # an absolute path is not a bundled name
        library.grammar_path(str(library.grammars_folder() / "oak"))


def test_list_command(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "oak" in out and "preset:NAME" in out and "felling" in out
    assert main(["list", "presets", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {d["kind"] for d in data} == {"preset"} and Path(data[0]["path"]).is_file()


def test_public_api_from_another_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    import treebake.bake  # noqa: F401  (submodules must not shadow the API's names)
    import treebake.export  # noqa: F401

    assert callable(treebake.bake_scene) and callable(treebake.export_bake)
    scene = treebake.load_scene("sapling", duration=0.25, wind=9.0)
    assert scene.name == "sapling" and scene.wind.speed == 9.0
    bake = treebake.bake_scene(scene)
    path = treebake.save_bake(bake, "out/s.npz")
    again = treebake.load_bake(path)
    assert len(again.times) == len(bake.times) == 7
    report = treebake.export_bake(again, "out", formats=("glb", "obj"), name="s")
    assert (tmp_path / "out" / "s" / "s.glb").is_file() and report.manifest["files"]
    with pytest.raises(treebake.InputError, match="duration"):
        treebake.load_scene("preset:calm", duration=-1)


def test_the_wheel_lists_every_subpackage_and_bundled_file():
    """setuptools installs only the packages pyproject.toml names (the
    package-dir mapping rules out automatic discovery): a new subpackage
    missing from the list works in the checkout and breaks the wheel."""
    import fnmatch
    import tomllib

    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = {"treebake" + "".join("." + part for part in p.parent.relative_to(
        ROOT / "exporter").parts) for p in (ROOT / "exporter").rglob("__init__.py")}
    assert found | {"treebake.grammars", "treebake.presets"} == set(conf["packages"])
    for package, folder, pattern in (("treebake.grammars", "grammars", "*.lsys"),
                                     ("treebake.presets", "presets", "*.toml")):
        globs = conf["package-data"][package]
        for p in (ROOT / folder).rglob(pattern):
            rel = p.relative_to(ROOT / folder).as_posix()
            assert any(fnmatch.fnmatch(rel, g) and rel.count("/") == g.count("/")
                       for g in globs), f"{rel} is not package data"


def test_a_preset_bake_records_its_grammars_as_before():
    # presets name grammars by bundled name now (issue 42); a bake still
    # records each tree's grammar relative to the preset's folder, as when
    # the presets said "../grammars/spruce.lsys", so preset bakes keep their bytes
    # (but for meta.scene_hash, the hash of the preset file's text)
    from treebake.grow import grow

    scene = load_scene(library.preset_path("boxes"))
    assert {g.grammar for g in grow(scene)} == {"../grammars/sapling.lsys",
                                                "../grammars/oak.lsys"}


def test_a_presets_description_is_its_whole_first_sentence(tmp_path, monkeypatch, capsys):
    """`list --json` cut descriptions at 100 characters with an ellipsis, and
    a sentence ended at "p. 25": the JSON carries the whole first sentence."""
    monkeypatch.setattr(library, "presets_folder", lambda: tmp_path)
    (tmp_path / "long.toml").write_text(
        "# Two oaks after Niklas (1992, p. 25), e.g. in a gale whose gusts reach the crowns of "
        "every tree in the stand, then calm. Not this sentence.\nname = \"long\"\n")
    [entry] = library.presets()
    assert entry.description == (
        "Two oaks after Niklas (1992, p. 25), e.g. in a gale whose gusts reach the crowns of "
        "every tree in the stand, then calm")
    assert main(["list", "presets", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)[0]["description"] == entry.description

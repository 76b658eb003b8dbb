"""`treebake export`, `treebake preview` and `treebake bake --format`:
output folder, manifest, exit codes, and byte-identical re-export."""

import json

import pytest
from PIL import Image
from treebake.cli import main

ALL = "glb,gltf,obj,usd,usda,preview"


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """A 0.5 s sapling in a breeze, baked and exported to every format."""
    from pathlib import Path

    base = tmp_path_factory.mktemp("cli")
    grammar = Path(__file__).resolve().parent.parent / "grammars" / "sapling.lsys"
    scene = base / "tiny.toml"
    scene.write_text(f'name = "tiny"\nduration = 0.5\n[[tree]]\ngrammar = "{grammar}"\n'
                     '[wind]\nspeed = 12.0\n')
    code = main(["bake", str(scene), "--out", str(base / "out"), "--format", ALL, "-q"])
    assert code == 0
    return base / "out" / "tiny"


def test_bake_with_format_writes_everything_and_a_manifest(baked):
    names = {p.name for p in baked.iterdir()}
    assert {"tiny.npz", "tiny.glb", "tiny.gltf", "tiny.bin", "tiny.usd", "tiny.usda",
            "tiny.contact.png", "tiny.gif", "manifest.json", "obj"} <= names
    m = json.loads((baked / "manifest.json").read_text())
    assert m["inputs"]["bake"]["file"] == "tiny.npz" and len(m["inputs"]["bake"]["sha256"]) == 64
    assert m["frames"]["first"] == 1 and m["frames"]["last"] == m["frames"]["count"] == 13
    assert m["sizes"]["joints"] == m["inputs"]["trees"][0]["segments"]
    listed = {e["path"] for e in m["files"]}
    assert "obj/tiny.0001.obj" in listed and "obj/tiny.mtl" in listed and "tiny.glb" in listed
    a = m["animation"]
    assert a["max_position_error_m"] <= m["settings"]["position_tolerance_m"]
    assert a["keys_written"] <= a["keys_full"] and m["usd"]["validation_errors"] == 0
    assert Image.open(baked / "tiny.gif").n_frames == 13
    assert Image.open(baked / "tiny.contact.png").size[0] > 0


def test_re_export_is_byte_identical(baked, tmp_path):
    code = main(["export", str(baked / "tiny.npz"), "--out", str(tmp_path), "--format", ALL,
                 "-q"])
    assert code == 0
    again = tmp_path / "tiny"
    first = json.loads((baked / "manifest.json").read_text())
    for entry in first["files"]:
        assert (again / entry["path"]).read_bytes() == (baked / entry["path"]).read_bytes(), \
            entry["path"]
    assert (again / "manifest.json").read_bytes() == (baked / "manifest.json").read_bytes()


def test_export_options_reach_the_files(baked, tmp_path, capsys):
    code = main(["export", str(baked / "tiny.npz"), "--out", str(tmp_path), "--name", "bare",
                 "--no-leaves", "--no-reduce", "--radial", "5", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["sizes"]["leaf_quads"] == 0 and out["animation"]["max_position_error_m"] < 1e-5
    m = json.loads((tmp_path / "bare" / "manifest.json").read_text())
    assert m["settings"]["radial"] == 5 and m["settings"]["keyframe_reduction"] is False


@pytest.mark.parametrize("argv", [
    ["export", "missing.npz"],
    ["export", "{npz}", "--format", "fbx"],
    ["export", "{npz}", "--radial", "2"],
    ["export", "{npz}", "--position-tolerance", "0"],
    ["export", "{npz}", "--stride", "0"],
    ["preview", "missing.npz"],
])
def test_bad_input_exits_2_without_traceback(baked, tmp_path, capsys, argv):
    argv = [a.replace("{npz}", str(baked / "tiny.npz")) for a in argv]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("treebake: error:") and "Traceback" not in err


def test_not_a_bake_exits_2(tmp_path, capsys):
    bad = tmp_path / "x.npz"
    bad.write_bytes(b"not a zip")
    assert main(["export", str(bad), "--out", str(tmp_path)]) == 2


def test_preview_command(baked, tmp_path):
    assert main(["preview", str(baked / "tiny.npz"), "--out", str(tmp_path), "--size", "128",
                 "-q"]) == 0
    assert Image.open(tmp_path / "tiny" / "tiny.contact.png").format == "PNG"
    assert Image.open(tmp_path / "tiny" / "tiny.gif").n_frames == 13


@pytest.mark.parametrize("cmd", ["export", "preview"])
def test_help(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        main([cmd, "--help"])
    assert exc.value.code == 0 and "usage: treebake" in capsys.readouterr().out

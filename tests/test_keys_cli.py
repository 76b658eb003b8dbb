"""Keyed scene keys under bad input (issue 41): every mistake in a list of
keys is exit 2 from `treebake bake` with a message naming the key as
`wind.speed[2].time` and the allowed range or form, never a traceback."""

import subprocess
import sys

import pytest
from treebake.cli import main
from treebake.errors import SceneError
from treebake.keys import Keyed
from treebake.scene import load_scene

HEAD = 'duration = 5.0\n[[tree]]\ngrammar = "sapling"\n'
OK = "[{time = 0, value = 0}, {time = 4, value = 20}]"


def write(tmp_path, body: str):
    path = tmp_path / "scene.toml"
    path.write_text(HEAD + body, encoding="utf-8")
    return path


CASES = {
    "wrong type": ('[wind]\nspeed = "fast"\n',
                   "wind.speed: must be a number, or keys [{time = ..., value = ...}, ...], "
                   "got 'fast'"),
    "empty list": ("[wind]\nspeed = []\n", "wind.speed: is an empty list: give a value or keys"),
    "not a table": ("[wind]\nspeed = [{time = 0, value = 1}, 3]\n",
                    "wind.speed[1]: must be a key {time, value}, got 3"),
    "no value": ("[wind]\nspeed = [{time = 0}]\n", "wind.speed[0].value: is required"),
    "no time": ("[wind]\nspeed = [{value = 3}]\n", "wind.speed[0].time: is required"),
    "typo in a key": ("[wind]\nspeed = [{time = 0, valeu = 3}]\n",
                      "wind.speed[0].valeu: unknown key (allowed: time, value)"),
    "time not a number": ('[wind]\nspeed = [{time = "soon", value = 3}]\n',
                          "wind.speed[0].time: must be a number, got 'soon'"),
    "unsorted": ("[wind]\nspeed = [{time = 0, value = 1}, {time = 4, value = 2}, "
                 "{time = 2, value = 3}]\n",
                 "wind.speed[2].time = 2 s must be later than the key before it (4 s)"),
    "duplicate time": ("[wind]\nspeed = [{time = 1, value = 1}, {time = 1, value = 2}]\n",
                       "wind.speed[1].time = 1 s must be later than the key before it (1 s)"),
    "after the shot": ("[wind]\nspeed = [{time = 0, value = 1}, {time = 6, value = 2}]\n",
                       "wind.speed[1].time = 6 is out of range [0, 5] s"),
    "before the shot": ("[wind]\nspeed = [{time = -1, value = 1}]\n",
                        "wind.speed[0].time = -1 is out of range [0, 5] s"),
    "value out of range": ("[wind]\nspeed = [{time = 0, value = 1}, {time = 3, value = 500}]\n",
                           "wind.speed[1].value = 500 is out of range [0, 120] m/s"),
    "unknown interpolation": (f'[wind]\nspeed = {OK}\nspeed_interpolation = "cubic"\n',
                              "wind.speed_interpolation = 'cubic' is not one of: linear, "
                              "smooth, step"),
    "interpolation of a value": ('[wind]\nspeed = 4.0\nspeed_interpolation = "smooth"\n',
                                 "wind.speed_interpolation: applies to keys, and wind.speed is "
                                 "not a list of keys"),
    "direction out of range": ("[wind]\nspeed = 4.0\ndirection = [{time = 0, value = 400}]\n",
                               "wind.direction[0].value = 400 is out of range [-360, 360] "
                               "degrees"),
    "turbulence out of range": ("[wind]\nspeed = 4.0\nturbulence = [{time = 0, value = 0.2}, "
                                "{time = 1, value = 1.5}]\n",
                                "wind.turbulence[1].value = 1.5 is out of range [0, 1]"),
    "beaufort name": ('[wind]\nbeaufort = [{time = 0, value = "calm"}, '
                      '{time = 3, value = "gail"}]\n',
                      "wind.beaufort[1].value = 'gail' is not one of: calm, light air"),
    "vortex path not a point": ("[[vortex]]\nmax_speed = 30.0\ncore_radius = 10.0\n"
                                "path = [{time = 0, value = [1.0, 2.0, 3.0]}]\n",
                                "vortex[0].path[0].value: must be a list of 2 numbers, got "
                                "[1.0, 2.0, 3.0]"),
    "vortex path and start": ("[[vortex]]\nstart = [0.0, 0.0]\nmax_speed = 30.0\n"
                              "core_radius = 10.0\npath = [{time = 0, value = [1.0, 2.0]}]\n",
                              "vortex[0].path: give either path or start and velocity, not both"),
    "vortex without a centre": ("[[vortex]]\nmax_speed = 30.0\ncore_radius = 10.0\n",
                                "vortex[0].start: is required (or give path)"),
    "vortex radius": ("[[vortex]]\nstart = [0.0, 0.0]\nmax_speed = 30.0\n"
                      "core_radius = [{time = 0, value = 10.0}, {time = 2, value = 0.5}]\n",
                      "vortex[0].core_radius[1].value = 0.5 is out of range [1, 2000] m"),
    "vortex strength": ("[[vortex]]\nstart = [0.0, 0.0]\ncore_radius = 10.0\n"
                        "max_speed = [{time = 0, value = 10.0}, {time = 9, value = 30.0}]\n",
                        "vortex[0].max_speed[1].time = 9 is out of range [0, 5] s"),
    "attractor position": ("[[attractor]]\nstrength = 3.0\n"
                           "position = [{time = 0, value = [0.0, 0.0, 2e6]}]\n",
                           "attractor[0].position[0].value: value 2000000.0 is out of range "
                           "[-1e+06, 1e+06] m"),
    "attractor strength": ("[[attractor]]\nposition = [0.0, 0.0, 3.0]\n"
                           "strength = [{time = 0, value = -2000}]\n",
                           "attractor[0].strength[0].value = -2000 is out of range "
                           "[-1000, 1000] m/s²"),
}


@pytest.mark.parametrize("case", CASES)
def test_every_mistake_in_keys_is_exit_2_naming_the_key(tmp_path, capsys, case):
    body, message = CASES[case]
    path = write(tmp_path, body)
    assert main(["bake", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: {message}" in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_the_installed_command_says_so_too(tmp_path):
    body, message = CASES["unsorted"]
    path = write(tmp_path, body)
    run = subprocess.run([sys.executable, "-m", "treebake.cli", "bake", str(path), "--out",
                          str(tmp_path / "out")], capture_output=True, text=True, check=False,
                         timeout=120)
    assert run.returncode == 2 and message in run.stderr, run.stderr
    assert "Traceback" not in run.stderr


def test_keys_of_every_keyed_parameter_load(tmp_path):
    path = write(tmp_path, f"""
[wind]
beaufort = [{{time = 0, value = "calm"}}, {{time = 5, value = "gale"}}]
beaufort_interpolation = "smooth"
direction = [{{time = 0, value = 350}}, {{time = 5, value = 10}}]
turbulence = [{{time = 0, value = 0.1}}, {{time = 5, value = 0.3}}]
turbulence_interpolation = "step"

[[vortex]]
path = [{{time = 0, value = [-40.0, 0.0]}}, {{time = 5, value = [40.0, 10.0]}}]
max_speed = {OK}
core_radius = [{{time = 0, value = 10}}, {{time = 5, value = 25}}]

[[attractor]]
position = [{{time = 1, value = [0.0, 0.0, 3.0]}}, {{time = 2, value = [1.0, 0.0, 3.0]}}]
strength = [{{time = 1, value = 2.0}}, {{time = 2, value = -2.0}}]
""")
    s = load_scene(path)
    assert s.wind.speed == Keyed((0.0, 5.0), (0.15, 19.0), "smooth")  # the bands' middles
    assert s.wind.direction.angular and s.wind.direction.at(2.5) % 360 == pytest.approx(0.0)
    assert s.wind.turbulence.interpolation == "step"
    v, a = s.vortices[0], s.attractors[0]
    assert v.start is None and v.path.at(2.5).tolist() == [0.0, 5.0]
    assert v.max_speed.at(2.0) == 10.0 and v.core_radius.at(5.0) == 25.0
    assert a.position.at(1.5).tolist() == [0.5, 0.0, 3.0] and a.strength.at(1.5) == 0.0


def test_overrides_cut_the_keys_or_replace_them(tmp_path):
    path = write(tmp_path, f'[wind]\nspeed = {OK}\nspeed_interpolation = "smooth"\n')
    # a shorter shot from the command line bakes the start of the curve
    short = load_scene(path, {"duration": 1.0})
    assert short.duration == 1.0 and short.wind.speed.times == (0.0, 4.0)
    # but a file whose own keys run past its shot is wrong
    short_file = tmp_path / "short.toml"
    short_file.write_text(HEAD.replace("5.0", "2.0") + f"[wind]\nspeed = {OK}\n")
    with pytest.raises(SceneError, match=r"wind\.speed\[1\]\.time = 4 is out of range \[0, 2\]"):
        load_scene(short_file)
    # --wind is one speed for the whole shot: the keys and their interpolation go
    steady = load_scene(path, {"wind.speed": 7.0})
    assert steady.wind.speed == 7.0


def test_wind_on_a_scene_without_wind_gives_it_one(tmp_path):
    """`bake preset:felling --wind 30` baked the same bytes as without it:
    a scene without [wind] now gets one at that speed, as a batch job does."""
    from treebake.batch_jobs import Job, scene_of

    path = write(tmp_path, "")
    assert load_scene(path).wind is None
    windy = load_scene(path, {"wind.speed": 30.0})
    assert windy.wind is not None and windy.wind.speed == 30.0
    job = Job("j", scene=str(path), wind=30.0)
    assert scene_of(job).wind == windy.wind


def test_the_docs_example_of_keys_is_a_valid_scene(root):
    import re
    import tomllib

    from treebake.scene import parse_scene

    text = (root / "docs" / "scenes.md").read_text(encoding="utf-8")
    section = text.split("## Keys", 1)[1].split("\n## ", 1)[0]
    example = re.search(r"```toml\n(.*?)```", section, re.S).group(1)
    raw = {**tomllib.loads(example), "duration": 12.0, "tree": [{"grammar": "sapling"}]}
    s = parse_scene(raw, file="docs/scenes.md")
    assert s.wind.speed.interpolation == "smooth" and s.vortices[0].path.at(3.0).tolist() == \
        [-40.0, -15.0]

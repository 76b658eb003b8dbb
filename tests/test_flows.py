"""Moving wind sources (issue 41, item 2): a `[[gust]]` and a rotor's
`[[downwash]]` load a rigid test bone with the analytic drag
0.5 rho Cd D l |u| u of their documented air speed in every engine; the
downwash's wake has momentum theory's speed 2 sqrt(T / (2 rho A)); culling
keeps the trees they reach and only those; the audit counts their work; bad
keys are exit 2 naming the key."""

import math

import numpy as np
import pytest
from simkit import bake_text, tip
from treebake.cli import main
from treebake.flows import Downwash, Gust
from treebake.forces import AIR_DENSITY
from treebake.keys import Keyed
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.sim.audit import GAIN_TOLERANCE
from treebake.sim.loads import SceneLoads

# the rigid test bone of tests/test_keyed_forces.py: a 2 m x 0.1 m vertical
# pole, Cd 1.2, no leaves, a joint so stiff that it moves by micrometres
CD, D, L = 1.2, 0.1, 2.0
POLE = (f"density: 800\ndamping: 0.05\ndrag: {CD}\nleaf drag: 0\n"
        f"axiom: @stiffness(1e5)!({D})F({L})\n")
COM = np.array([0.0, 0.0, 1.0])  # the pole's centre of mass, m


def analytic_drag(u):
    """Cross-flow drag (N, (2,)) on the vertical pole in a horizontal air
    velocity u (m/s, (2,)): 0.5 rho Cd D l |u| u."""
    u = np.asarray(u, dtype=float)
    return 0.5 * AIR_DENSITY * CD * D * L * np.linalg.norm(u) * u


def smoothstep_envelope(t, start, ramp, end=math.inf):
    """The documented envelope, written out again: 3x^2 - 2x^3 over the ramps."""
    x = min(1.0, max(0.0, (t - start) / ramp), max(0.0, (end + ramp - t) / ramp))
    return x * x * (3 - 2 * x)


# a gust passing the pole: centre from (-6, 0.5, 1) to (6, 0.5, 1) m in 3 s,
# 15 m/s, bump of radius 4 m, blowing along its travel (+X)
GUST = {"position": [{"time": 0.0, "value": [-6.0, 0.5, 1.0]},
                     {"time": 3.0, "value": [6.0, 0.5, 1.0]}],
        "speed": 15.0, "radius": 4.0, "ramp": 0.5}


def gust_air(t):
    """By hand: the gust's air (m/s, (2,)) at the pole's COM at t s."""
    centre = np.array([-6.0 + 4.0 * min(t, 3.0), 0.5, 1.0])
    x2 = float(np.sum((COM - centre) ** 2)) / 16.0
    bump = (1 - x2) ** 3 if x2 < 1 else 0.0
    return np.array([15.0 * smoothstep_envelope(t, 0.0, 0.5) * bump, 0.0])


# a rotor (R 3 m, 20 kN) flying over the pole at 5 m height, from x = -12 m
# to 12 m in 3 s: its outwash sweeps the pole toward -X, then toward +X
ROTOR = {"position": [{"time": 0.0, "value": [-12.0, 2.0, 5.0]},
                      {"time": 3.0, "value": [12.0, 2.0, 5.0]}],
         "thrust": 20000.0, "radius": 3.0, "ramp": 0.5}


def rotor_air(t):
    """By hand, from docs/physics.md's formulas: the downwash's horizontal air
    (m/s, (2,)) at the pole's COM at t s."""
    v_i = smoothstep_envelope(t, 0.0, 0.5) * math.sqrt(20000.0 / (2 * AIR_DENSITY * math.pi * 9.0))
    hub = np.array([-12.0 + 8.0 * min(t, 3.0), 2.0])
    d = COM[:2] - hub
    r = float(np.linalg.norm(d))
    x = r / 3.0
    peak = 2 * v_i * (1 - math.exp(-x * x)) / x  # 2 v_i R / r far out
    layer = math.exp(-2.0) * math.hypot(r, 3.0)
    n = COM[2] / layer
    return peak * n * math.exp(1 - n) * d / r


ENGINES = pytest.mark.parametrize(
    "solver, quality", [("planar", "draft"), ("full", "draft"),
                        ("planar", {"base": "draft", "tier": "pymunk"})],
    ids=["linear tier", "reference", "pymunk tier"])


def check_drag(calls, air, times):
    """Each engine's force on the pole at the times it asked nearest to
    `times` is the analytic drag of `air(t)`; and between them it varied."""
    t = np.array([c[0] for c in calls])
    top = max(np.linalg.norm(analytic_drag(air(s))) for s in np.linspace(0, 3, 61))
    for want in times:
        i = int(np.argmin(np.abs(t - want)))
        got = calls[i][1][0, :2]
        assert got == pytest.approx(analytic_drag(air(t[i])), rel=0.01, abs=1e-4 * top), t[i]
    assert len({round(float(c[1][0, 0]), 3) for c in calls}) > 20


@ENGINES
def test_each_engine_feels_the_gusts_analytic_drag(tmp_path, engine_calls, solver, quality):
    bake_text(tmp_path, POLE, solver=solver, duration=3.0, fps=24, gust=[GUST], quality=quality)
    # rising, the peak (centre nearest at 1.5 s), falling, gone (d > 4 m after 2.5 s)
    check_drag(engine_calls, gust_air, (0.3, 1.0, 1.5, 1.9, 2.3, 2.8))
    assert abs(engine_calls[-1][1][0, 0]) < 1e-9  # the bump has nothing beyond its radius


@ENGINES
def test_each_engine_feels_the_downwashs_analytic_drag(tmp_path, engine_calls, solver,
                                                       quality):
    bake_text(tmp_path, POLE, solver=solver, duration=3.0, fps=24, downwash=[ROTOR],
              quality=quality)
    check_drag(engine_calls, rotor_air, (0.25, 1.0, 1.4, 1.6, 2.0, 2.9))


def test_the_wake_has_momentum_theorys_speed():
    """Far below the disk (and far above the ground) the wake moves down at
    2 v_i, v_i = sqrt(T / (2 rho pi R^2)); at the disk at v_i, with no jump
    across it."""
    thrust, radius = 49_050.0, 7.0  # a 5 t helicopter hovering
    rotor = Downwash(np.array([0.0, 0.0, 2000.0]), thrust, radius, ramp=0.0)
    v_i = math.sqrt(thrust / (2 * AIR_DENSITY * math.pi * radius**2))
    assert v_i == pytest.approx(11.52, abs=0.01)  # by hand: sqrt(49050 / 369.5)
    wake = rotor.air_velocity(np.array([[0.0, 0.0, 800.0], [0.0, 0.0, 2000.0]]), 1.0)
    assert wake[0] == pytest.approx([0.0, 0.0, -2 * v_i], rel=1e-4)
    assert wake[1] == pytest.approx([0.0, 0.0, -v_i], rel=1e-9)
    across = rotor.air_velocity(np.array([[0.0, 0.0, 2000.0 + 1e-4], [0.0, 0.0, 2000.0 - 1e-4]]),
                                1.0)
    assert across[0, 2] == pytest.approx(across[1, 2], rel=1e-4)  # no jump at the disk
    # a thrust four times larger doubles the speed (T ~ v^2)
    stronger = Downwash(np.array([0.0, 0.0, 2000.0]), 4 * thrust, radius, ramp=0.0)
    assert stronger.air_velocity(np.array([[0.0, 0.0, 800.0]]), 1.0)[0, 2] == pytest.approx(
        2 * wake[0, 2], rel=1e-9)


def test_the_outwash_falls_as_r_over_big_r_and_the_air_is_smooth():
    rotor = Downwash(np.array([0.0, 0.0, 20.0]), 49_050.0, 7.0, ramp=0.0)
    v_w = 2 * rotor.induced(49_050.0)
    # at the layer's peak height the jet is 2 v_i (1 - e^-x^2) / x: R / r far out
    for r in (21.0, 35.0, 70.0):
        z = math.exp(-2.0) * math.hypot(r, 7.0)
        u = rotor.air_velocity(np.array([[0.0, r, z]]), 1.0)[0]
        assert u[1] == pytest.approx(v_w * 7.0 / r, rel=1.5e-4) and u[0] == 0.0
    # no jump anywhere: along lines through the axis, the disk's edge, the ground
    for line in (np.c_[np.linspace(-30, 30, 6001), np.zeros(6001), np.full(6001, 1.0)],
                 np.c_[np.full(6001, 7.0), np.zeros(6001), np.linspace(-1, 40, 6001)]):
        u = rotor.air_velocity(line, 1.0)
        step = np.linalg.norm(np.diff(line, axis=0), axis=1).max()
        assert np.linalg.norm(np.diff(u, axis=0), axis=1).max() < 12 * v_w / 7.0 * step
    # and a gust's bump fades to nothing at its edge (as (1 - x^2)^3)
    gust = Gust(np.array([0.0, 0.0, 1.0]), 10.0, 4.0, direction=90.0, ramp=0.0)
    edge = gust.air_velocity(np.array([[4.0 - 1e-3, 0.0, 1.0], [4.0 + 1e-3, 0.0, 1.0]]), 1.0)
    assert 0 < edge[0, 1] < 1e-8 and not edge[1].any()


def test_over_a_floor_the_wash_is_the_open_grounds_raised_and_still_below():
    """`floor` (a dense canopy's top) is where the wake turns outward: the
    field over it is the open ground's field of the same rotor as high above
    the ground as it is above the floor, raised by the floor's height; below
    the floor the air is still."""
    floor = 14.0
    over = Downwash(np.array([2.0, -1.0, 24.0]), 98_000.0, 8.2, ramp=0.0, floor=floor)
    ground = Downwash(np.array([2.0, -1.0, 24.0 - floor]), 98_000.0, 8.2, ramp=0.0)
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-40, 40, (500, 2)), rng.uniform(0, 30, 500)]
    above = pts[:, 2] >= floor
    assert np.array_equal(over.air_velocity(pts[above], 1.0),
                          ground.air_velocity(pts[above] - [0.0, 0.0, floor], 1.0))
    assert not over.air_velocity(pts[~above], 1.0).any()
    # the crowns beside the hover, 10 m out, 2 m over the floor: an outwash
    # across them of about 2 v_i R / r (momentum theory), not still air
    u = over.air_velocity(np.array([[12.0, -1.0, floor + 2.0]]), 1.0)[0]
    assert u[0] > 0.5 * 2 * over.induced(98_000.0) * 8.2 / 10.0


def test_a_gust_blows_along_its_travel_and_fades_where_it_stops():
    path = Keyed((0.0, 2.0, 4.0), ((0.0, 0.0, 1.0), (0.0, 10.0, 1.0), (0.0, 10.0, 1.0)),
                 "smooth")
    gust = Gust(path, 8.0, 3.0, ramp=0.0)
    u = gust.air_velocity(np.array([[0.0, 5.0, 1.0]]), 1.0)[0]  # centre here, 7.5 m/s along +Y
    assert u == pytest.approx([0.0, 8.0, 0.0])
    # near the end the path slows below 1 m/s: the air slows with it, then stops
    slow = 2.0 - 0.02  # the smooth path's speed there is 6 * 10 / 2 * s (1 - s) ~ 0.3 m/s
    speed = float(np.linalg.norm(path.derivative(slow)))
    assert gust.air_velocity(path.at(slow)[None], slow)[0, 1] == pytest.approx(8.0 * speed)
    assert not gust.air_velocity(path.at(3.0)[None], 3.0).any()


def test_a_gaussian_gust_and_its_reach():
    """exp(-(d/radius)^2): speed / e at the radius; beyond its reach
    radius sqrt(ln(U / 0.5 m/s)) it is slower than 0.5 m/s, inside faster."""
    gust = Gust(np.array([0.0, 0.0, 2.0]), 20.0, 3.0, direction=180.0, profile="gaussian",
                ramp=0.0)
    at_radius = gust.air_velocity(np.array([[0.0, 3.0, 2.0]]), 1.0)[0]
    assert at_radius == pytest.approx([-20.0 / math.e, 0.0, 0.0], abs=1e-12)
    reach = gust.reach(0.5)
    assert reach == pytest.approx(3.0 * math.sqrt(math.log(40.0)))
    speeds = [np.linalg.norm(gust.air_velocity(np.array([[0.0, d, 2.0]]), 1.0))
              for d in (0.99 * reach, 1.01 * reach)]
    assert speeds[0] > 0.5 > speeds[1]


def test_the_pymunk_tiers_planes_follow_a_source(root):
    """A tree bends in the plane of the air that reaches it: a gust's
    heading, away from a rotor's hub."""
    sapling = str(root / "grammars" / "sapling.lsys")
    base = np.array([4.0, 3.0, 0.0])
    gust = SceneLoads(parse_scene({"tree": [{"grammar": sapling}], "gust": [
        {"position": [0.0, 0.0, 1.0], "speed": 5.0, "radius": 9.0, "direction": 90.0}]}))
    assert gust.dominant_direction(base) == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    rotor = SceneLoads(parse_scene({"tree": [{"grammar": sapling}], "downwash": [
        {"position": [0.0, 0.0, 10.0], "thrust": 5000.0, "radius": 2.0}]}))
    assert rotor.dominant_direction(base) == pytest.approx([0.8, 0.6, 0.0])


def two_saplings(root, **forces):
    sapling = str(root / "grammars" / "sapling.lsys")
    return parse_scene({"duration": 1.0, "quality": "draft", "tree": [
        {"grammar": sapling, "position": [0.0, 0.0]},
        {"grammar": sapling, "position": [60.0, 0.0]}], **forces}, file="<cull>")


@pytest.mark.parametrize("kind", ["gust", "downwash"])
def test_culling_keeps_what_a_source_reaches_and_only_that(root, kind):
    """A bump gust of radius 4 m at the first sapling and a small rotor
    (R 1 m, 300 N: 2 v_i = 6.3 m/s, reach sqrt(2) x 6.3 x 1 / 0.5 = 18 m):
    the sapling 60 m away is static; the reached one moves."""
    source = ({"position": [0.0, 0.0, 1.5], "speed": 20.0, "radius": 4.0, "direction": 0.0,
               "ramp": 0.2} if kind == "gust" else
              {"position": [2.0, 0.0, 4.0], "thrust": 300.0, "radius": 1.0, "ramp": 0.2})
    scene = two_saplings(root, **{kind: [source]})
    loads = SceneLoads(scene)
    reach = (loads.gusts or loads.downwashes)[0].reach(0.5)
    assert reach < 55.0
    near, far = bake_scene(scene).trees
    assert far.static and "no force reaches it" in far.info["static"]
    assert not near.static and np.ptp(tip(near)[:, 0]) > 1e-3
    # the bound is a bound: nothing outside the reach blows faster than 0.5 m/s
    x0 = source["position"][0]
    ring = np.array([[x0 + reach * math.cos(a), reach * math.sin(a), z]
                     for a in np.linspace(0, 2 * math.pi, 24) for z in (0.5, 2.0, 6.0)])
    assert max(np.linalg.norm(loads.air_velocity(ring, t), axis=1).max()
               for t in np.linspace(0, 1, 11)) < 0.5


def test_a_keyed_rotor_path_reaches_a_tree_under_its_bend(root):
    sapling = str(root / "grammars" / "sapling.lsys")
    raw = {"duration": 4.0, "tree": [{"grammar": sapling}],
           "downwash": [{"position": [{"time": 0.0, "value": [-300.0, -200.0, 5.0]},
                                      {"time": 2.0, "value": [0.0, 0.0, 5.0]},
                                      {"time": 4.0, "value": [300.0, -200.0, 5.0]}],
                         "thrust": 300.0, "radius": 1.0}]}
    assert SceneLoads(parse_scene(raw, file="<bend>")).quiet_after(
        np.array([0.0, 0.0, 0.0]), 1.0, 3.0) == 4.0
    raw["downwash"][0]["position"][1]["value"] = [0.0, -150.0, 5.0]
    assert SceneLoads(parse_scene(raw, file="<bend>")).quiet_after(
        np.array([0.0, 0.0, 0.0]), 1.0, 3.0) == 0.0


@pytest.mark.parametrize("solver", ["planar", "full"])
def test_the_audit_counts_a_gusts_work(root, solver):
    """A 12 m/s gust of radius 5 m crossing an oak sapling: the audit finds
    work done on the tree (the gust is the only load) and no energy made up."""
    sapling = str(root / "grammars" / "sapling.lsys")
    raw = {"duration": 3.0, "quality": "draft", "tree": [{"grammar": sapling}],
           "gust": [{"position": [{"time": 0.0, "value": [-8.0, 0.0, 2.0]},
                                  {"time": 2.0, "value": [8.0, 0.0, 2.0]}],
                     "speed": 12.0, "radius": 5.0, "ramp": 0.3}]}
    b = bake_scene(parse_scene(raw, file="<audit>"), solver=solver)
    audit = b.meta["energy"]["sapling"]
    assert audit["external_work_j"] > 0.5, audit  # in the still air before, nothing
    assert audit["max_gain_fraction"] <= GAIN_TOLERANCE, audit
    assert np.ptp(tip(b.trees[0])[:, 0]) > 0.01


HEAD = 'duration = 5.0\n[[tree]]\ngrammar = "sapling"\n'
PATH = "[{time = 0, value = [0.0, 0.0, 5.0]}, {time = 4, value = [20.0, 0.0, 5.0]}]"
GUST_OK = f"[[gust]]\nposition = {PATH}\nspeed = 10.0\nradius = 3.0\n"
ROTOR_OK = f"[[downwash]]\nposition = {PATH}\nthrust = 20000.0\nradius = 4.0\n"
CASES = {
    "gust speed type": (GUST_OK.replace("10.0", '"fast"'),
                        "gust[0].speed: must be a number, or keys [{time = ..., value = ...}, "
                        "...], got 'fast'"),
    "gust unsorted path": (GUST_OK.replace("time = 4", "time = 0"),
                           "gust[0].position[1].time = 0 s must be later than the key before "
                           "it (0 s)"),
    "gust path after the shot": (GUST_OK.replace("time = 4", "time = 7"),
                                 "gust[0].position[1].time = 7 is out of range [0, 5] s"),
    "gust path point": (GUST_OK.replace("[20.0, 0.0, 5.0]", "[20.0, 0.0]"),
                        "gust[0].position[1].value: must be a list of 3 numbers"),
    "gust radius": (GUST_OK.replace("radius = 3.0", "radius = 0.0"),
                    "gust[0].radius = 0 is out of range [0.1, 1000] m"),
    "gust profile": (GUST_OK + 'profile = "square"\n',
                     "gust[0].profile = 'square' is not one of: bump, gaussian"),
    "gust direction keys": (GUST_OK + "direction = [{time = 0, value = 10}, "
                            "{time = 6, value = 20}]\n",
                            "gust[0].direction[1].time = 6 is out of range [0, 5] s"),
    "gust standing still": ("[[gust]]\nposition = [0.0, 0.0, 1.0]\nspeed = 10.0\nradius = 3.0\n",
                            "gust[0].direction: is required for a gust that stands still"),
    "gust speed keys": (GUST_OK.replace("10.0", "[{time = 0, value = 3}, {time = 1, "
                                               "value = 300}]"),
                        "gust[0].speed[1].value = 300 is out of range [0, 120] m/s"),
    "gust typo": (GUST_OK + "raduis = 2.0\n", "gust[0].raduis: unknown key"),
    "gust end": (GUST_OK + "time = 3.0\nend = 1.0\n", "gust[0].end = 1 s is before time (3 s)"),
    "rotor thrust type": (ROTOR_OK.replace("20000.0", "true"),
                          "downwash[0].thrust: must be a number, or keys"),
    "rotor thrust keys": (ROTOR_OK.replace("20000.0", "[{time = 2, value = 1}, {time = 1, "
                                                      "value = 2}]"),
                          "downwash[0].thrust[1].time = 1 s must be later than the key before "
                          "it (2 s)"),
    "rotor thrust range": (ROTOR_OK.replace("20000.0", "-5.0"),
                           "downwash[0].thrust = -5 is out of range [0, 1e+07] N"),
    "rotor underground": (ROTOR_OK.replace("[20.0, 0.0, 5.0]", "[20.0, 0.0, 0.0]"),
                          "downwash[0].position[1].value: z = 0 m: the rotor's hub must be "
                          "above the floor (z > floor = 0 m)"),
    "rotor without radius": (ROTOR_OK.replace("radius = 4.0\n", ""),
                             "downwash[0].radius: is required"),
    "rotor interpolation of a value": (ROTOR_OK + "thrust_interpolation = \"smooth\"\n",
                           "downwash[0].thrust_interpolation: applies to keys"),
    "rotor radius keys": (ROTOR_OK.replace("radius = 4.0", "radius = [{time = 0, value = 4}]"),
                          "downwash[0].radius: must be a number, got [{"),
}


@pytest.mark.parametrize("case", CASES)
def test_every_mistake_in_a_source_is_exit_2_naming_the_key(tmp_path, capsys, case):
    body, message = CASES[case]
    path = tmp_path / "scene.toml"
    path.write_text(HEAD + body, encoding="utf-8")
    assert main(["bake", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: {message}" in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_the_docs_examples_of_sources_are_valid_scenes(root):
    import re
    import tomllib

    text = (root / "docs" / "scenes.md").read_text(encoding="utf-8")
    section = text.split("### Gusts and downwash", 1)[1].split("\n## ", 1)[0]
    example = re.search(r"```toml\n(.*?)```", section, re.S).group(1)
    raw = {**tomllib.loads(example), "duration": 10.0, "tree": [{"grammar": "sapling"}]}
    s = parse_scene(raw, file="docs/scenes.md")
    assert len(s.gusts) == 1 and len(s.downwashes) == 1
    assert isinstance(s.downwashes[0].position, Keyed)


def flyover_bake(solver):
    from treebake.library import preset_path
    from treebake.scene import load_scene

    return bake_scene(load_scene(preset_path("flyover")), solver=solver)


def check_flyover(b):
    """The rotor does work on every tree and the audit finds no energy made
    up; the crowns under the wake are pressed down."""
    audit = b.meta["energy"]
    assert len(audit) == 12 and all(a["external_work_j"] > 0.3 for a in audit.values()), audit
    worst = max(a["max_gain_fraction"] for a in audit.values())
    assert worst <= GAIN_TOLERANCE, audit
    assert max(np.ptp(tip(t)[:, 2]) for t in b.trees) > 0.1  # pressed down under the wake


def test_the_flyover_preset_balances_its_energy_on_the_lod():
    check_flyover(flyover_bake("planar"))


@pytest.mark.slow  # 24 CPU s
def test_the_flyover_preset_balances_its_energy_on_the_reference():
    check_flyover(flyover_bake("full"))

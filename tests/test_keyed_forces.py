"""Keyed forces (issue 41, item 1) as the engines receive them: the drag on
a rigid test bone follows keyed wind speed within 1 % of the analytic drag
0.5 rho Cd D l U^2 at every key, in every engine, and is C1 where `smooth`
is asked; a keyed heading turns the short way; keyed gusts keep their
intensity sigma_u = I U and move downwind at the keyed speed; a keyed
vortex and attractor follow their keys, and culling bounds them."""

import math

import numpy as np
import pytest
from simkit import bake_text
from treebake.forces import AIR_DENSITY, Wind
from treebake.keys import Keyed
from treebake.scene import parse_scene
from treebake.sim.loads import BoneProps, SceneLoads

# the rigid test bone: a 2 m x 0.1 m vertical pole, Cd 1.2, no leaves,
# a joint so stiff that it moves by micrometres in a gale
CD, D, L = 1.2, 0.1, 2.0
POLE = (f"density: 800\ndamping: 0.05\ndrag: {CD}\nleaf drag: 0\n"
        f"axiom: @stiffness(1e5)!({D})F({L})\n")
TIMES, SPEEDS = (0.0, 1.0, 2.0, 3.0, 4.0), (0.0, 8.0, 20.0, 20.0, 12.0)  # s, m/s


def analytic_drag(u):
    """Cross-flow drag (N) on the pole in a uniform wind u (m/s) across it."""
    return 0.5 * AIR_DENSITY * CD * D * L * abs(u) * u


def keyed_wind(how="smooth", **more):
    return {"speed": [{"time": t, "value": v} for t, v in zip(TIMES, SPEEDS)],
            "speed_interpolation": how, "shear": 0.0, "ramp": 0.0, **more}


def pole_props():
    return BoneProps(mass=np.array([12.6]), wood_area=np.array([D * L]),
                     leaf_area=np.array([0.0]), diameter=np.array([D]),
                     cd_wood=np.array([CD]), cd_leaf=np.array([0.3]))


def drag_at(loads, times):
    """The horizontal force (N, along +X) SceneLoads.forces, the function every
    engine asks (sim/common.external_loads), gives the pole at rest."""
    com, axis = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]])
    return np.array([loads.forces(float(t), com, np.zeros((1, 3)), axis, pole_props(),
                                  include_gravity=False)[0, 0] for t in np.atleast_1d(times)])


def scene_with(wind, root, duration=5.0):
    return parse_scene({"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}],
                        "duration": duration, "wind": wind}, file="<keys>")


@pytest.mark.parametrize("solver, quality", [("planar", "draft"), ("full", "draft"),
                                             ("planar", {"base": "draft", "tier": "pymunk"})],
                         ids=["linear tier", "reference", "pymunk tier"])
def test_each_engine_feels_the_keyed_drag_at_every_key(tmp_path, engine_calls, solver, quality):
    bake_text(tmp_path, POLE, solver=solver, duration=4.5, fps=24, wind=keyed_wind(),
              quality=quality)
    t = np.array([c[0] for c in engine_calls])
    for key_t, u in zip(TIMES, SPEEDS):
        i = int(np.argmin(np.abs(t - key_t)))
        assert abs(t[i] - key_t) < 1e-6, (key_t, t[i])  # the engine asked at the key
        fx = engine_calls[i][1][0, 0]
        assert fx == pytest.approx(analytic_drag(u), rel=0.01, abs=1e-6), (key_t, fx)
    # and between keys it moved: not a value held from the start
    assert len({round(float(c[1][0, 0]), 3) for c in engine_calls}) > 20


@pytest.mark.parametrize("how", ["linear", "smooth", "step"])
def test_drag_follows_the_keys_exactly_where_the_interpolation_says(root, how):
    loads = SceneLoads(scene_with(keyed_wind(how), root))
    f = drag_at(loads, TIMES[1:])
    assert f == pytest.approx([analytic_drag(u) for u in SPEEDS[1:]], rel=1e-9)
    mid = drag_at(loads, [0.5, 3.5, 4.5])
    if how == "linear":  # by hand: 4 m/s half way to 8; 16 m/s half way from 20 to 12
        assert mid == pytest.approx([analytic_drag(4.0), analytic_drag(16.0),
                                     analytic_drag(12.0)], rel=1e-9)
    elif how == "step":  # the key before holds until the next
        assert mid == pytest.approx([analytic_drag(0.0), analytic_drag(20.0),
                                     analytic_drag(12.0)], rel=1e-9, abs=1e-12)
    else:  # smooth: between its keys, never past them
        assert 0 < mid[0] < analytic_drag(8.0) and analytic_drag(12) < mid[1] < analytic_drag(20)


@pytest.mark.parametrize("how, c1", [("smooth", True), ("linear", False)])
def test_drag_is_c1_where_smooth_is_asked(root, how, c1):
    loads = SceneLoads(scene_with(keyed_wind(how), root))
    h = 1e-5
    for key_t in TIMES[1:]:
        before, at, after = drag_at(loads, [key_t - h, key_t, key_t + h])
        left, right = (at - before) / h, (after - at) / h
        jump = abs(right - left)
        scale = 2 * analytic_drag(1.0) * max(SPEEDS) * 12.0  # a slope of dF/dt's size
        if c1:
            assert jump < 1e-3 * scale, (key_t, left, right)
        elif key_t in (1.0, 2.0, 3.0):  # linear kinks where the slope changes
            assert jump > 0.05 * scale, (key_t, left, right)


def test_a_keyed_heading_turns_the_short_way_through_zero(root):
    wind = {"speed": 10.0, "shear": 0.0, "ramp": 0.0,
            "direction": [{"time": 0.0, "value": 350.0}, {"time": 4.0, "value": 10.0}]}
    loads = SceneLoads(scene_with(wind, root))
    point = np.array([[3.0, -2.0, 5.0]])
    # by hand: 350 -> 370 (= 10) over 4 s, 5 degrees per second
    for t, heading in ((0.5, 352.5), (1.0, 355.0), (2.0, 0.0), (3.0, 5.0), (4.0, 10.0)):
        u = loads.air_velocity(point, t)[0]
        a = math.radians(heading)
        assert u == pytest.approx([10 * math.cos(a), 10 * math.sin(a), 0.0], abs=1e-9), t
    # every heading on the way is within 10 degrees of +X (never past 180)
    xs = [loads.air_velocity(point, t)[0] for t in np.linspace(0.01, 4.0, 100)]
    assert min(x[0] for x in xs) >= 10 * math.cos(math.radians(10.0)) - 1e-9
    # the drag on a bone turns with it: a pole feels it along the heading
    f = loads.forces(2.0, point, np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), pole_props(),
                     include_gravity=False)[0]
    assert f == pytest.approx([analytic_drag(10.0), 0.0, 0.0], abs=1e-9)


def test_keyed_gusts_scale_with_the_keyed_speed_and_move_downwind_at_it():
    """Turbulence of intensity 0.2 in a wind keyed from 6 to 18 m/s: the gusts'
    standard deviation is 0.2 U in each stretch, and a gust reaches a point
    40 m downwind 40 / U s later (frozen turbulence advected at U(t))."""
    speed = Keyed((0.0, 300.0, 310.0, 700.0), (6.0, 6.0, 18.0, 18.0))
    wind = Wind(speed, np.array([1.0, 0.0, 0.0]), shear=0.0, turbulence=0.2, ramp=0.0)
    wind.prepare(np.random.default_rng(2), 700.0, np.array([[-60.0, -5.0], [60.0, 5.0]]))
    dt = 0.05
    points = np.array([[-20.0, 0.0, 10.0], [20.0, 0.0, 10.0]])
    for (t0, t1), u in (((20.0, 295.0), 6.0), ((320.0, 695.0), 18.0)):
        times = np.arange(t0, t1, dt)
        v = np.array([wind.velocity(points, t)[:, 0] for t in times])  # (T, 2)
        assert v.mean(0) == pytest.approx([u, u], rel=0.05)
        assert v[:, 0].std() / u == pytest.approx(0.2, rel=0.15)
        a, b = v[:, 0] - v[:, 0].mean(), v[:, 1] - v[:, 1].mean()
        lags = np.arange(0, int(12.0 / dt))
        corr = [np.dot(a[:len(a) - k], b[k:]) for k in lags]
        assert lags[int(np.argmax(corr))] * dt == pytest.approx(40.0 / u, abs=2 * dt)


def test_keyed_turbulence_intensity_scales_the_gusts():
    turb = Keyed((0.0, 300.0, 310.0, 600.0), (0.1, 0.1, 0.4, 0.4))
    wind = Wind(10.0, np.array([0.0, 1.0, 0.0]), shear=0.0, turbulence=turb, ramp=0.0)
    wind.prepare(np.random.default_rng(5), 600.0, np.array([[-10.0, -10.0], [10.0, 10.0]]))
    point = np.array([[0.0, 0.0, 10.0]])
    for (t0, t1), i in (((10.0, 295.0), 0.1), ((315.0, 595.0), 0.4)):
        v = np.array([wind.velocity(point, t)[0] for t in np.arange(t0, t1, 0.05)])
        assert v[:, 1].std() / 10.0 == pytest.approx(i, rel=0.15)  # along the wind (+Y)
        assert v[:, 0].std() == pytest.approx(0.8 * v[:, 1].std(), rel=0.25)


def test_calm_keys_are_calm_even_with_gusts():
    speed = Keyed((0.0, 5.0, 6.0), (0.0, 0.0, 15.0), "smooth")
    wind = Wind(speed, np.array([1.0, 0.0, 0.0]), turbulence=0.3, ramp=0.0)
    wind.prepare(np.random.default_rng(1), 10.0, np.array([[-10.0, -10.0], [10.0, 10.0]]))
    points = np.array([[0.0, 0.0, 5.0], [4.0, 2.0, 9.0]])
    for t in (0.5, 2.0, 4.9):
        assert not wind.velocity(points, t).any()
    assert np.abs(wind.velocity(points, 8.0)).max() > 5.0


def test_a_keyed_vortex_follows_its_path_strength_and_radius(root):
    sapling = str(root / "grammars" / "sapling.lsys")
    raw = {"tree": [{"grammar": sapling}], "duration": 10.0,
           "vortex": [{"path": [{"time": 0.0, "value": [-50.0, 0.0]},
                                {"time": 4.0, "value": [0.0, 40.0]},
                                {"time": 8.0, "value": [50.0, 0.0]}],
                       "max_speed": [{"time": 0.0, "value": 20.0}, {"time": 8.0, "value": 60.0}],
                       "core_radius": [{"time": 0.0, "value": 10.0},
                                       {"time": 8.0, "value": 30.0}],
                       "inflow": 0.0, "updraft": 0.0}]}
    loads = SceneLoads(parse_scene(raw, file="<v>"))
    v = loads.vortices[0]
    t = 2.0  # by hand: centre (-25, 20) moving at (12.5, 10) m/s; 30 m/s at 15 m
    assert v.centre(t) == pytest.approx([-25.0, 20.0])
    edge = np.array([[-25.0 + 15.0, 20.0, 3.0]])  # on the core's edge, east of the centre
    assert loads.air_velocity(edge, t)[0] == pytest.approx([12.5, 10.0 + 30.0, 0.0])
    far = np.array([[-25.0, 20.0 - 45.0, 3.0]])  # 45 m south: 30 * 15 / 45 = 10 m/s, toward +X
    assert loads.air_velocity(far, t)[0] == pytest.approx([12.5 + 10.0, 10.0, 0.0])
    # culling: a tree under the bend of the path is reached, though the
    # straight line from its first key to its last passes 40 m away
    assert loads.quiet_after(np.array([0.0, 45.0, 0.0]), 3.0, 10.0) > 0
    reach = 30.0 * 60.0 / 0.5  # the largest radius x speed over MIN_AIR_SPEED
    assert loads.quiet_after(np.array([0.0, 40.0 + 0.9 * reach, 0.0]), 3.0, 10.0) > 0
    assert loads.quiet_after(np.array([0.0, 45.0 + reach + 10.0, 0.0]), 3.0, 10.0) == 0


def test_culling_follows_a_keyed_path_round_its_bend(root):
    """A small vortex (reach 10 m/s x 5 m / 0.5 m/s = 100 m) along a path that
    bends 200 m off the straight line between its first and last keys: the
    tree under the bend is reached, one 130 m beyond it is not."""
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 8.0,
           "vortex": [{"path": [{"time": 0.0, "value": [-300.0, 0.0]},
                                {"time": 4.0, "value": [0.0, 200.0]},
                                {"time": 8.0, "value": [300.0, 0.0]}],
                       "max_speed": 10.0, "core_radius": 5.0}]}
    for how in ("linear", "smooth"):
        raw["vortex"][0]["path_interpolation"] = how
        loads = SceneLoads(parse_scene(raw, file="<v>"))
        assert loads.quiet_after(np.array([0.0, 200.0, 0.0]), 3.0, 10.0) == 8.0, how
        assert loads.quiet_after(np.array([0.0, 330.0, 0.0]), 3.0, 10.0) == 0.0, how


def test_a_keyed_attractor_pulls_toward_its_keyed_position(root):
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 6.0,
           "attractor": [{"position": [{"time": 0.0, "value": [0.0, 0.0, 5.0]},
                                       {"time": 4.0, "value": [8.0, 0.0, 5.0]}],
                          "strength": [{"time": 1.0, "value": 0.0}, {"time": 3.0, "value": 6.0}],
                          "strength_interpolation": "step", "radius": 1.0}]}
    loads = SceneLoads(parse_scene(raw, file="<a>"))
    point = np.array([[0.0, 0.0, 5.0]])
    props = pole_props()
    assert not loads.forces(2.0, point, np.zeros((1, 3)), np.array([[0, 0, 1.0]]), props,
                            include_gravity=False).any()  # strength 0 until 3 s (step)
    # at 3.5 s the point is at (7, 0, 5): 6 m/s^2 x (1 / 7)^2 toward +X
    f = loads.forces(3.5, point, np.zeros((1, 3)), np.array([[0, 0, 1.0]]), props,
                     include_gravity=False)[0]
    assert f == pytest.approx([12.6 * 6.0 / 49.0, 0.0, 0.0])
    assert loads.quiet_after(np.array([40.0, 0.0, 0.0]), 2.0, 5.0) == 6.0

"""The planar LOD against independent truths: the spring pendulum, the
Euler-Bernoulli cantilever, the static beam, the drag law and the Kaimal
gust spectrum."""

import itertools
import math

import numpy as np
import pytest
from simkit import BARE, bake_text, tip
from treebake.forces import Explosion, Wind, drag, kaimal_spectrum, synthesize
from treebake.scene import parse_scene
from treebake.sim.loads import MAX_ACCELERATION, BoneProps, SceneLoads
from treebake.sway import damping_ratio, frequency

E, RHO = 8.0e9, 800.0  # green wood, Pa and kg/m^3


def pendulum_frequency(k, m, length, radius, g, hanging):
    """Spring pendulum, small angles: w^2 = (k +- m g d) / I_pivot for a solid
    cylinder pivoting at one end (d = length/2)."""
    i_pivot = m * (length**2 / 3 + radius**2 / 4)
    torque = m * g * length / 2
    return math.sqrt((k + (torque if hanging else -torque)) / i_pivot) / (2 * math.pi)


@pytest.mark.parametrize("hanging", [False, True])
def test_single_bone_matches_spring_pendulum(tmp_path, hanging):
    length, diameter, k = 1.0, 0.05, 50.0
    turn = "&(180)" if hanging else ""
    grammar = f"density: {RHO}\ndamping: 0\n{BARE}axiom: @stiffness({k}){turn}!({diameter})F({length})\n"
    m = RHO * math.pi / 4 * diameter**2 * length
    expected = pendulum_frequency(k, m, length, diameter / 2, 9.81, hanging)
    bake = bake_text(tmp_path, grammar, duration=8.0, fps=240,
                     pull=[{"tree": 0, "force": [2.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    measured = frequency(t[free], x[free])
    assert measured == pytest.approx(expected, rel=0.02)
    # the pull moved it (the test measured a real oscillation)
    assert abs(x[np.searchsorted(t, 1.0)]) > 0.01


@pytest.mark.parametrize("level, step", [("default", 1 / 960), ("final", 1 / 1000)])
def test_pymunk_springs_damp_as_the_reference_step_does(tmp_path, level, step):
    """A spring's damping on the pymunk tier is c = k h_c / 2, h_c the
    substep or 1 ms, whichever is longer: a mode of f Hz decays at
    zeta = omega h_c / 4 = pi f h_c / 2, what the reference's discrete step of
    1/2000 s gives it. At `final` (1920 Hz) that is the 1 ms value, not half
    of it. No structural damping and no gravity: the spring pendulum's free
    decay is all the spring's (Chipmunk: c / (2 sqrt(k I)))."""
    length, diameter, k = 1.0, 0.05, 2000.0
    grammar = f"density: {RHO}\ndamping: 0\n{BARE}axiom: @stiffness({k})!({diameter})F({length})\n"
    m = RHO * math.pi / 4 * diameter**2 * length
    f = pendulum_frequency(k, m, length, diameter / 2, 0.0, False)
    bake = bake_text(tmp_path, grammar, duration=2.5, fps=960, gravity=0.0,
                     quality={"base": level, "tier": "pymunk"},
                     pull=[{"tree": 0, "force": [20.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    assert frequency(t[free], x[free]) == pytest.approx(f, rel=0.02)
    assert damping_ratio(t[free], x[free], cycles=10) == pytest.approx(
        math.pi * f * step / 2, rel=0.1)


def cantilever_grammar(n, length=10.0, diameter=0.2, damping=0.0):
    return (f"density: {RHO}\nmodulus: {E}\ndamping: {damping}\n{BARE}iterations: {n}\n"
            f"axiom: !({diameter})A({n})\nA(n) : n > 0 -> F({length}/{n})A(n-1)\n")


def beam_f1(length=10.0, diameter=0.2):
    ei = E * math.pi * diameter**4 / 64
    mass_per_length = RHO * math.pi * diameter**2 / 4
    return 0.5596 * math.sqrt(ei / (mass_per_length * length**4))


@pytest.mark.parametrize("n", [10, 20, 30])
def test_chain_matches_cantilever_first_frequency(tmp_path, n):
    """Real green-wood stiffness (E = 8 GPa): a 10 m x 0.2 m stem in n bones,
    gravity off (the beam formula has none), pulled at the top and released."""
    bake = bake_text(tmp_path, cantilever_grammar(n), duration=9.0, fps=120, gravity=0.0,
                     pull=[{"tree": 0, "force": [100.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    assert frequency(t[free], x[free]) == pytest.approx(beam_f1(), rel=0.02)


def test_structural_damping_ratio_is_the_grammars(tmp_path):
    """Mass-proportional damping gives the first mode the grammar's ratio."""
    bake = bake_text(tmp_path, cantilever_grammar(20, damping=0.05), duration=8.0, fps=120,
                     gravity=0.0,
                     pull=[{"tree": 0, "force": [100.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    assert damping_ratio(t[free], x[free]) == pytest.approx(0.05, abs=0.01)


def test_horizontal_branch_sags_like_the_static_beam(tmp_path):
    """Uniform load w = rho A g on a horizontal cantilever: tip deflection
    w L^4 / (8 E I), downward, nothing sideways (prestress off)."""
    length, diameter, n = 3.0, 0.05, 15
    grammar = (f"density: {RHO}\nmodulus: {E}\ndamping: 0.5\n{BARE}iterations: {n}\n"
               f"axiom: &(90)!({diameter})A({n})\nA(n) : n > 0 -> F({length}/{n})A(n-1)\n")
    bake = bake_text(tmp_path, grammar, duration=6.0, fps=24, prestress=False)
    end = tip(bake.trees[0])
    rest = end[0]
    w = RHO * math.pi / 4 * diameter**2 * 9.81
    ei = E * math.pi * diameter**4 / 64
    expected = w * length**4 / (8 * ei)
    sag = rest[2] - end[-1, 2]
    assert sag == pytest.approx(expected, rel=0.03)
    sideways = np.abs(end[-1, :2] - rest[:2])
    assert sideways.max() < 0.05 * expected + 1e-4  # shortening along the branch only
    # settled: the last second moves less than 1 % of the sag
    assert np.ptp(end[-24:, 2]) < 0.01 * expected


@pytest.mark.parametrize("engine", ["reference", "pymunk"])
def test_prestressed_tree_stays_still_in_calm_air(tmp_path, engine):
    """The grown shape is the equilibrium under gravity: nothing moves. On
    the engines whose prestress is worked out apart from the linear tier's
    (MuJoCo's gravity torques, the pymunk tier's rest angles): the linear
    tier's prestress is its own right-hand side at rest, so it would stay
    still by construction."""
    grammar = (f"density: {RHO}\nmodulus: {E}\n{BARE}"
               "axiom: !(0.3)F(2)F(2)[&(70)!(0.1)F(1)F(1)F(1)][^(60)!(0.08)F(1)F(1)]F(2)\n")
    solver = {"solver": "full"} if engine == "reference" else {"quality": {"tier": "pymunk"}}
    bake = bake_text(tmp_path, grammar, duration=3.0, fps=24, **solver,
                     pull=[{"tree": 0, "force": [0.0, 0, 0], "release": 0.1}])
    moved = np.abs(bake.trees[0].positions - bake.trees[0].positions[0]).max()
    assert bake.trees[0].positions.shape[0] == 73  # it was simulated
    assert bake.trees[0].info["solver"] == engine
    assert moved < 1e-4


# ---------------------------------------------------------------------------
# drag


def test_drag_on_a_bone_across_the_flow():
    axis = np.array([[0.0, 0.0, 1.0]])
    air = np.array([[10.0, 0.0, 0.0]])
    area = np.array([0.2])  # diameter x length, m^2
    f = drag(air, np.zeros((1, 3)), axis, area, np.zeros(1), 1.2, 0.0)
    assert f[0] == pytest.approx([0.5 * 1.2 * 1.2 * 0.2 * 100.0, 0.0, 0.0])
    # quadratic in the relative speed
    f2 = drag(2 * air, np.zeros((1, 3)), axis, area, np.zeros(1), 1.2, 0.0)
    assert f2[0, 0] == pytest.approx(4 * f[0, 0])


def test_drag_uses_the_relative_velocity_and_the_normal_component():
    axis = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    air = np.array([[10.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    vel = np.array([[10.0, 0.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    f = drag(air, vel, axis, np.full(3, 0.2), np.zeros(3), 1.2, 0.0)
    assert np.allclose(f[0], 0.0)  # moving with the air
    assert np.allclose(f[1], 0.0)  # flow along the bone: no cross-flow drag
    assert f[2, 0] < 0  # moving through still air is resisted (air damping)
    assert f[2, 0] == pytest.approx(-0.5 * 1.2 * 1.2 * 0.2 * 4.0)


def test_foliage_streamlines_above_the_reference_speed():
    """Vogel reconfiguration: F ~ U^2 below u0, F ~ U^(2+b) above (b = -0.7)."""
    axis = np.array([[0.0, 0.0, 1.0]])

    def leaf_force(u):
        return drag(np.array([[u, 0.0, 0.0]]), np.zeros((1, 3)), axis, np.zeros(1),
                    np.ones(1), 0.0, 0.3)[0, 0]

    assert leaf_force(2.0) / leaf_force(1.0) == pytest.approx(4.0)
    assert leaf_force(20.0) / leaf_force(10.0) == pytest.approx(2 ** 1.3)


# ---------------------------------------------------------------------------
# gusts


def test_gust_series_has_the_kaimal_statistics():
    sigma, length, mean, dt, count = 2.0, 50.0, 10.0, 0.05, 2**14
    spectra, variances, means = [], [], []
    for seed in range(40):
        x = synthesize(np.random.default_rng(seed), count, dt, sigma, length, mean)
        means.append(x.mean())
        variances.append(x.var())
        spectra.append(np.abs(np.fft.rfft(x)) ** 2 * 2 * dt / count)  # one-sided PSD
    freqs = np.fft.rfftfreq(count, dt)
    # the variance the record can hold: the spectrum's integral between its
    # lowest and highest resolved frequencies
    df = freqs[1]
    expected_var = float(np.sum(kaimal_spectrum(freqs[1:], sigma, length, mean)) * df)
    assert np.mean(variances) == pytest.approx(expected_var, rel=0.03)
    assert expected_var > 0.8 * sigma**2
    assert abs(np.mean(means)) < 1e-9  # zero mean by construction
    psd = np.mean(spectra, axis=0)
    # compare in octave bands from 0.01 Hz to 5 Hz
    edges = 0.01 * 2.0 ** np.arange(0, 9)
    for lo, hi in itertools.pairwise(edges):
        band = (freqs >= lo) & (freqs < hi)
        model = kaimal_spectrum(freqs[band], sigma, length, mean)
        assert psd[band].mean() == pytest.approx(model.mean(), rel=0.1)
    # the inertial subrange falls as f^(-5/3)
    hi = (freqs > 2) & (freqs < 8)
    slope = np.polyfit(np.log(freqs[hi]), np.log(psd[hi]), 1)[0]
    assert slope == pytest.approx(-5 / 3, abs=0.1)


def test_wind_field_mean_profile_and_turbulence_intensity():
    wind = Wind(12.0, np.array([1.0, 0.0, 0.0]), turbulence=0.2, ramp=0.0)
    wind.prepare(np.random.default_rng(1), 600.0, np.array([[-5, -5], [5, 5]]))
    times = np.arange(0, 600, 0.1)
    at = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 20.0]])
    u = np.array([wind.velocity(at, t) for t in times])  # (T, 2, 3)
    assert u[:, 0, 0].mean() == pytest.approx(12.0, rel=0.05)
    assert u[:, 1, 0].mean() == pytest.approx(12.0 * 2**0.14, rel=0.05)  # power law
    assert u[:, 0, 0].std() / 12.0 == pytest.approx(0.2, rel=0.15)
    assert u[:, 0, 1].std() == pytest.approx(0.8 * u[:, 0, 0].std(), rel=0.2)
    assert u[:, 0, 2].std() == pytest.approx(0.5 * u[:, 0, 0].std(), rel=0.2)


def blast_bones():
    """Three bones 3 m from 50 kg of TNT: a trunk piece and two twigs (the
    twigs asked thousands of g: capped), as SceneLoads sees them."""
    com = np.array([[0.0, 0.0, 1.0], [0.2, 0.1, 2.0], [-0.3, 0.4, 1.5]])
    axis = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])
    props = BoneProps(mass=np.array([3.0, 0.02, 0.005]), wood_area=np.array([0.05, 0.004, 0.001]),
                      leaf_area=np.array([0.0, 0.02, 0.01]), diameter=np.array([0.05, 0.01, 0.003]),
                      cd_wood=np.full(3, 1.2), cd_leaf=np.full(3, 0.5))
    return com, axis, props


def test_blast_impulse_is_the_pulse_integrated():
    # the closed form against the pulse's own force, summed at 0.125 us
    e = Explosion(np.array([3.0, 0.0, 1.0]), 0.5, 50.0)
    com, axis, p = blast_bones()
    args = (axis, p.wood_area, p.leaf_area, p.diameter, p.cd_wood, p.cd_leaf)
    for t in (0.5025, 0.5035, 0.51):
        exact, _, _ = e.impulse(com, t, *args)
        ts = np.linspace(0.5, t, 80_001)
        dt = ts[1] - ts[0]
        summed = sum(e.force(com, s, *args) for s in ts[:-1] + dt / 2) * dt
        assert np.abs(exact - summed).max() < 1e-4 * np.abs(summed).max()


@pytest.mark.parametrize("hold", [1 / 8000, 1 / 2000, 1 / 768, 1 / 192, 1 / 120])
def test_a_capped_blast_passes_its_whole_impulse_whatever_the_hold(hold, root):
    """Every solver holds its loads for a while (the reference 2 ms, the
    linear tier's split steps 1.3 ms, pymunk 8.3 ms): each gets the pulse's
    whole impulse (momentum is kept), never faster than the cap."""
    scene = parse_scene({"name": "b", "duration": 1.0,
                         "tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}],
                         "explosion": [{"position": [3.0, 0.0, 1.0], "time": 0.5,
                                        "charge": 50.0}]}, file="<b>")
    loads = SceneLoads(scene)
    com, axis, p = blast_bones()
    total, _, _ = loads.explosions[0].impulse(com, math.inf, axis, p.wood_area, p.leaf_area,
                                           p.diameter, p.cd_wood, p.cd_leaf)
    got = np.zeros_like(com)
    # the pulse and the capped push after it, which delivers the rest
    push = (np.linalg.norm(total, axis=1) / (p.mass * MAX_ACCELERATION)).max()
    for k in range(math.ceil((0.11 + push) / hold)):
        f = loads.forces(0.4 + k * hold, com, np.zeros_like(com), axis, p,
                         include_gravity=False, dt=hold)
        assert (np.linalg.norm(f, axis=1) <= MAX_ACCELERATION * p.mass * (1 + 1e-9)).all()
        got += f * hold
    assert np.allclose(got, total, rtol=1e-9, atol=1e-12)
    # the twigs were asked far more than the cap, the trunk piece was not
    assert (np.linalg.norm(total, axis=1) / p.mass)[1:].min() > 10 * MAX_ACCELERATION * 2e-3

"""The articulated tier (sim/articulated.py, sim/featherstone.py) against
independent truths: the linear tier's mass matrix and prestress (a separate
derivation), the conservation of energy and angular momentum of a double
pendulum swinging through large angles, the Euler-Bernoulli cantilever,
and the energy audit on the blast that the pymunk tier's one-way coupling
failed; and its place in the LOD: on to the pymunk tier as a joint nears
breaking or where it fails, the same bake twice."""

import math

import numpy as np
import pytest
from simkit import BARE
from treebake import stress
from treebake.library import grammars_folder
from treebake.pipeline import bake_scene, grow, prepare
from treebake.scene import parse_scene
from treebake.sim.articulated import ArticulatedTier
from treebake.sim.audit import summary
from treebake.sim.featherstone import accelerations
from treebake.sim.joint_space import JointSpace
from treebake.sim.layout import ChainLayout
from treebake.sim.loads import SceneLoads
from treebake.sim.quality import QUALITIES
from treebake.sway import frequency

E, RHO = 8.0e9, 800.0  # green wood, Pa and kg/m^3
BRANCHED = (f"density: {RHO}\nmodulus: {E}\n{BARE}"
            "axiom: !(0.3)F(2)F(2)[&(70)!(0.1)F(1)F(1)[+(40)!(0.04)F(0.5)]F(1)]"
            "[^(60)/(90)!(0.08)F(1)F(1)]F(2)\n")


def tier_of(tmp_path, grammar: str, quality: str = "default", **scene) -> ArticulatedTier:
    """An articulated tier for the one tree `grammar` grows in a scene of
    the keyword arguments (TOML keys of docs/scenes.md)."""
    path = tmp_path / "g.lsys"
    path.write_text(grammar)
    raw = {"tree": [{"grammar": str(path)}], "ground": False, "duration": 1.0, "fps": 24.0}
    raw.update(scene)
    sc = parse_scene(raw, file="<test>")
    grown = grow(sc)
    loads = SceneLoads(sc, np.array([[-50.0, -50.0], [50.0, 50.0]]))
    trees, _, _, _ = prepare(sc, grown, loads, QUALITIES[quality])
    return ArticulatedTier(trees[:1], sc, QUALITIES[quality], loads)


def test_its_mass_matrix_and_prestress_are_the_linear_tiers(tmp_path):
    """Solving for hinge accelerations under unit torques, at rest in the
    grown shape, inverts the joint-space mass matrix that joint_space.py
    assembles from its own closed-form entries; and the prestress is the
    same gravity torque."""
    tier = tier_of(tmp_path, BRANCHED)
    b = tier.bones
    nd = 2 * b.n
    js = JointSpace(b, ChainLayout.of(tier.trees, b.offsets, b.pivot0, b.tip0), tier.loads.g,
                    0.0, 0.0)
    mass = js.dense()[0]
    zero3, zero = np.zeros((b.n, 3)), np.zeros(nd)
    solved = np.empty((nd, nd))
    for k in range(nd):
        tau = np.zeros(nd)
        tau[k] = 1.0
        accelerations(tier.dof_parent, tier.frame_dof, tier.same_limb, b.mass, tier.com,
                      tier.inertia, tier.axis, tier.vel, tier.bias, zero3, zero3, tau,
                      zero.copy(), zero, np.zeros(3), zero, zero, 0.0, 0.0, 0.0, zero.copy(),
                      *tier.work_arrays, tier.qdd, tier.floating, tier.base_acc,
                      tier.base_inertia)
        solved[:, k] = tier.qdd
    assert mass @ solved == pytest.approx(np.eye(nd), abs=1e-9)
    assert tier.hold == pytest.approx(js.tau_g0, rel=1e-10, abs=1e-9)


def test_a_double_pendulum_swinging_through_large_angles_keeps_its_energy(tmp_path):
    """Two 1 m bones, limp joints and no air, released level: they fall and
    swing through more than a right angle, chaotic. Without springs or
    damping only gravity acts, so kinetic plus gravitational energy stays
    what it was (until a hinge meets its cone at 180 degrees, whose damping
    takes energy); the velocity-product terms (centrifugal, Coriolis,
    gyroscopic) are where a wrong sign or a missed term would show. The
    step's own error is first order: 1.2e-2 J here at 1e-4 s, 1.2e-3 J at
    1e-5 s."""
    grammar = (f"density: {RHO}\ndamping: 0\n{BARE}"
               "axiom: @stiffness(1e-6)@cone(180)&(90)!(0.05)F(1)!(0.04)F(1)\n")
    tier = tier_of(tmp_path, grammar, prestress=False)
    b = tier.bones
    assert b.n == 2
    force = np.zeros((b.n, 3))
    e0 = tier.energy().sum()
    scale = float((b.mass * 9.81).sum() * 2.0)  # J: the weights over the chain's length
    h, turned, drift = 1e-4, 0.0, 0.0
    for _ in range(int(1.5 / h)):
        tier.step(h, force)
        if np.any(np.abs(tier.q) > tier.cone):
            break
        drift = max(drift, abs(tier.energy().sum() - e0))
        turned = max(turned, float(np.abs(tier.q).max()))
    assert turned > math.pi / 2
    assert drift < 5e-4 * scale


def test_a_spinning_double_pendulum_keeps_its_angular_momentum(tmp_path):
    """The same pendulum without gravity, both joints set spinning: the root
    hinge is limp, so nothing turns the pair about its axis (world x, through
    the pivot) and their angular momentum about it stays what it was. The
    gyroscopic forces, v x* I v, do no work (the energy test cannot see
    them) but they do turn momentum between the two bones."""
    grammar = (f"density: {RHO}\ndamping: 0\n{BARE}"
               "axiom: @stiffness(1e-6)@cone(180)&(90)!(0.05)F(1)!(0.04)F(1)\n")
    tier = tier_of(tmp_path, grammar, prestress=False, gravity=0.0)
    b = tier.bones
    tier.qd = np.array([3.0, 0.0, -5.0, 0.0])
    tier._kinematics()

    def momentum() -> float:
        spin = np.einsum("bij,bj->bi", tier.inertia, tier.omega())
        return float((spin + b.mass[:, None] * np.cross(tier.com, tier.vcom())).sum(0)[0])

    l0 = momentum()
    h, worst, swung = 1e-4, 0.0, 0.0
    for _ in range(int(1.0 / h)):
        tier.step(h, np.zeros((b.n, 3)))
        if np.any(np.abs(tier.q) > tier.cone):
            break
        worst = max(worst, abs(momentum() - l0))
        swung = max(swung, abs(tier.q[2]))
    assert swung > 1.0  # the second bone swung about the first
    assert worst < 1e-3 * abs(l0)


def test_a_cantilever_rings_at_the_euler_bernoulli_frequency(tmp_path):
    """The 10 m x 0.2 m green-wood stem in 20 bones, gravity off, pulled
    at the top and released, on the articulated tier's own step."""
    n, length, diameter = 20, 10.0, 0.2
    grammar = (f"density: {RHO}\nmodulus: {E}\ndamping: 0\n{BARE}iterations: {n}\n"
               f"axiom: !({diameter})A({n})\nA(n) : n > 0 -> F({length}/{n})A(n-1)\n")
    tier = tier_of(tmp_path, grammar, gravity=0.0, duration=6.0,
                   pull=[{"tree": 0, "force": [100.0, 0, 0], "release": 1.0, "at": 1.0}])
    nd = 2 * tier.n
    result = tier.run(0.0, (np.zeros(nd), np.zeros(nd)))
    motion = result.motions[tier.trees[0].name]
    t = np.arange(len(motion.pivots)) / 24.0
    x = motion.pivots[:, -1, 0]
    free = t > 1.05
    ei = E * math.pi * diameter**4 / 64
    f1 = 0.5596 * math.sqrt(ei / (RHO * math.pi * diameter**2 / 4 * length**4))
    assert frequency(t[free], x[free]) == pytest.approx(f1, rel=0.02)
    assert np.ptp(x[free]) > 0.01  # it rang


@pytest.mark.parametrize("level", ["draft", "default", "final"])
def test_a_sapling_blasted_into_the_ground_gains_no_energy(level):
    """The stress case the pymunk tier failed: 50 kg of TNT 5 m from a
    standing sapling (no breaking), bent into the ground. Its chains gained
    0.69 / 3.94 / 2.07 % of the tree's energy at draft / default / final,
    none of it supplied by a load (the one-way coupling). Here the sapling
    leaves the linear tier for the articulated tier, which holds its tips
    on the ground itself, and comes back."""
    case = next(c for c in stress.cases(True) if c.name == "blast 50 kg at 5 m")
    r = stress.run(case, "planar", level, engine="articulated")
    assert r.error == ""
    assert r.gain < 0.005
    assert r.passed
    assert any("articulated tier" in n for n in r.notes)
    assert any("came back to the linear tier" in n for n in r.notes)


def test_the_articulated_tier_bakes_the_same_twice(tmp_path):
    """Deterministic: the same scene twice gives the same motion, to the bit."""
    bakes = []
    for _ in range(2):
        tier = tier_of(tmp_path, BRANCHED, duration=1.0,
                       explosion=[{"position": [4.0, 0.0, 1.0], "time": 0.1, "charge": 5.0}])
        nd = 2 * tier.n
        r = tier.run(0.0, (np.zeros(nd), np.zeros(nd)))
        bakes.append(r.motions[tier.trees[0].name])
    assert np.array_equal(bakes[0].quaternions, bakes[1].quaternions)
    assert np.array_equal(bakes[0].energy, bakes[1].energy)
    a = summary(["t"], bakes[0].energy[:, None], bakes[0].work[:, None], 24.0, [])["t"]
    assert a["max_gain_fraction"] < 0.005
    assert np.ptp(bakes[0].pivots[:, -1, 0]) > 0.01  # the blast moved it


@pytest.mark.parametrize("gravity, spin", [(0.0, 6.0), (9.81, 6.0), (0.0, 20.0)])
def test_an_uprooted_tree_flies_as_newton_has_it(tmp_path, gravity, spin):
    """A branched tree thrown free (its root turning at `spin` rad/s as it
    lets go), for 0.5 s without air: its momentum changes only by its
    weight, its centre of mass flies on a line (a parabola under gravity),
    its angular momentum about that centre holds, and no energy is made.
    The base's own equation integrated as it turned gained 10 % of the
    energy at 6 rad/s; a velocity taken at the wrong point put the centre
    7 cm off its line and lost 4 % of the energy."""
    tier = tier_of(tmp_path, BRANCHED, gravity=gravity)
    nd = 2 * tier.n
    tier.q, tier.qd = np.zeros(nd), np.zeros(nd)
    tier.qd[0], tier.qd[1] = spin, 0.5 * spin
    tier._kinematics()
    tier._uproot(0)
    mass = tier.mass.sum()
    weight = np.array([0.0, 0.0, -gravity])

    def state():  # momentum (N s), COM (m), angular momentum about it (N m s), energy (J)
        m, v, c = tier.mass, tier.vcom(), tier.com
        com = m @ c / mass
        spin_l = np.einsum("bij,bj->bi", tier.inertia, tier.omega()) \
            + m[:, None] * np.cross(c - com, v)
        return m @ v, com, spin_l.sum(0), tier.energy().sum()

    p0, c0, l0, e0 = state()
    assert np.linalg.norm(l0) > 100.0  # it spins
    energy = []
    for k in range(1, round(0.5 / tier.h) + 1):
        tier.step(tier.h, np.zeros((tier.n, 3)))
        t = k * tier.h
        p, c, spin_l, e = state()
        energy.append(e / e0)
        assert p == pytest.approx(p0 + mass * weight * t, abs=1e-9 * np.linalg.norm(p0))
        # within 2e-4 of the way flown (semi-implicit in gravity, as the
        # hinges: 1/2 g h t behind)
        line = c0 + p0 / mass * t + 0.5 * weight * t * t
        flown = np.linalg.norm(line - c0)
        assert np.abs(c - line).max() < 2e-4 * flown + 0.6 * gravity * tier.h * t, (t, c, line)
        assert np.abs(spin_l - l0).max() < 5e-3 * np.linalg.norm(l0), (t, spin_l, l0)
    assert max(energy) < 1.0 + 1e-4, max(energy)
    assert energy[-1] > 0.98, energy[-1]  # (the implicit springs' damping of the step)


def test_a_tree_cut_after_parts_broke_here_is_replayed_whole_by_the_pymunk_tier():
    """2 kg of TNT 4 m from a sapling at 0.3 s, its felling cut at 0.6 s: the
    articulated tier takes the tree as the blast reaches it and breaks its
    twigs (13 joints within 0.1 s); the cut, which only the pymunk tier
    handles, comes while it still holds the tree. That tier takes the tree
    from where the articulated tier took it, broken limbs whole, and replays
    what broke: no break is lost (a start at 0.6 s would have put the limbs
    back on) or counted twice."""
    scene = parse_scene({
        "duration": 2.0, "fps": 24, "quality": {"nonlinear": "articulated"},
        "tree": [{"grammar": str(grammars_folder() / "sapling.lsys")}],
        "explosion": [{"position": [4.0, 0.0, 1.0], "time": 0.3, "charge": 2.0}],
        "cut": [{"tree": 0, "time": 0.6, "direction": 0.0}]}, file="<test>")
    bake = bake_scene(scene)
    (tree,) = bake.trees
    assert "then articulated, then pymunk" in tree.info["solver"], tree.info["solver"]
    switches = [e for e in tree.info["events"] if e["kind"] == "tier"]
    assert [e["detail"].split(":")[0] for e in switches] == ["to articulated", "to pymunk"]
    assert "felling cut" in switches[1]["detail"]
    assert switches[1]["time"] == switches[0]["time"], switches  # replayed from the take
    assert any(e["kind"] == "cut" for e in tree.info["events"])
    broken = [e["segment"] for e in tree.info["events"] if e["kind"] in ("broke", "uprooted")]
    assert len(broken) >= 10 and len(set(broken)) == len(broken), broken
    assert bake.meta["stats"]["broken"] == len(broken), (bake.meta["stats"], len(broken))
    assert bake.meta["energy"][tree.name]["max_gain_fraction"] < 0.02, bake.meta["energy"]


def test_where_the_articulated_tier_fails_the_pymunk_tier_takes_the_tree(tmp_path, monkeypatch):
    """A non-finite state (forced here) stops the articulated tier with a
    SimulationError naming tree, segment and time, and the pymunk tier
    takes the tree from the linear tier's hand-over: the bake completes."""
    case = next(c for c in stress.cases(True) if c.name == "blast 50 kg at 5 m")
    path = tmp_path / "sapling.lsys"
    path.write_text(case.grammar)
    scene = parse_scene({"name": "blast", "duration": 1.5, "fps": 24,
                         "quality": {"nonlinear": "articulated"},
                         "tree": [{"grammar": str(path)}], **case.scene}, file="<test>")
    step = ArticulatedTier.step

    def failing(self, h, force):
        step(self, h, force)
        if self.stats.steps > 20:
            self.q[3] = np.nan
            self._kinematics()

    monkeypatch.setattr(ArticulatedTier, "step", failing)
    logged = []
    bake = bake_scene(scene, log=logged.append)
    (tree,) = bake.trees
    assert tree.info["solver"].startswith("linear, then pymunk at ")
    assert "the articulated tier failed" in tree.info["solver"]
    switches = [e["detail"] for e in tree.info["events"] if e["kind"] == "tier"]
    # (both tiers start where the blast found the tree, in the order they took it)
    assert [d.split(":")[0] for d in switches] == ["to articulated", "to pymunk"]
    assert switches[1].startswith("to pymunk: the articulated tier failed (non-finite")
    failed = [m for m in logged if "the articulated tier failed" in m]
    assert failed and "non-finite state in the articulated tier" in failed[0]
    assert np.isfinite(tree.positions).all()

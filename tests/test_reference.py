"""The full-3D MuJoCo reference against independent truths: the spring
pendulum, the Euler-Bernoulli cantilever, static equilibrium under gravity,
bit-for-bit repeatability, felling, breaking, projectiles and the
stability guard."""

import math

import numpy as np
import pytest
from simkit import BARE, bake_text, tip
from treebake.bake_file import save_bake
from treebake.errors import SimulationError
from treebake.lsystem import derive, load_grammar
from treebake.pipeline import bake_scene
from treebake.rig import build_rig
from treebake.scene import parse_scene
from treebake.sim import reference
from treebake.stress import kinetic_energy
from treebake.sway import damping_ratio, frequency, segment_ends
from treebake.turtle import interpret

E, RHO, G = 8.0e9, 800.0, 9.81  # green wood (Pa, kg/m^3), gravity (m/s^2)


def rig_of(path):
    g = load_grammar(path)
    return build_rig(interpret(derive(g, g.seed, g.iterations).modules, g, seed=g.seed))


@pytest.mark.parametrize("hanging", [False, True])
def test_single_bone_matches_spring_pendulum(tmp_path, hanging):
    """omega^2 = (k -+ m g d) / I_pivot, upright (gravity destabilises) and
    hanging, with m, d and I_pivot of a solid cylinder (diameter 0.05 m,
    length 1 m) worked out here, not taken from the rig under test."""
    k = 50.0
    turn = "&(180)" if hanging else ""
    grammar = f"density: {RHO}\ndamping: 0\n{BARE}axiom: @stiffness({k}){turn}!(0.05)F(1)\n"
    radius, length = 0.025, 1.0
    m = RHO * math.pi * radius**2 * length
    i_pivot = m * (radius**2 / 4 + length**2 / 3)  # transverse axis through one end
    torque = m * G * length / 2  # centre of mass halfway up
    expected = math.sqrt((k + (torque if hanging else -torque)) / i_pivot) / (2 * math.pi)
    bake = bake_text(tmp_path, grammar, solver="full", duration=6.0, fps=240,
                     pull=[{"tree": 0, "force": [2.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    assert frequency(t[free], x[free]) == pytest.approx(expected, rel=0.02)
    assert abs(x[np.searchsorted(t, 1.0)]) > 0.01  # the pull really moved it


def cantilever_grammar(n: int) -> str:
    return (f"density: {RHO}\nmodulus: {E}\ndamping: 0\n{BARE}iterations: {n}\n"
            f"axiom: !(0.2)A({n})\nA(n) : n > 0 -> F(10/{n})A(n-1)\n")


@pytest.mark.parametrize("n", [10, 30])
def test_chain_matches_cantilever_first_frequency(tmp_path, n):
    """10 m x 0.2 m stem at real green-wood stiffness, gravity off, pulled
    at the top and released: f1 = 0.5596 sqrt(E I / (rho A L^4))."""
    ei = E * math.pi * 0.2**4 / 64
    beam = 0.5596 * math.sqrt(ei / (RHO * math.pi * 0.2**2 / 4 * 10.0**4))
    (tmp_path / "g.lsys").write_text(cantilever_grammar(n))
    raw = {"tree": [{"grammar": str(tmp_path / "g.lsys")}], "ground": False, "gravity": 0.0,
           "duration": 7.0, "fps": 120,
           "pull": [{"tree": 0, "force": [100.0, 0, 0], "release": 1.0, "at": 1.0}]}
    bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
    tree = bake.trees[0]
    top = segment_ends(tree, [tree.n_segments - 1])[:, 0, 0]
    free = bake.times > 1.02
    assert frequency(bake.times[free], top[free]) == pytest.approx(beam, rel=0.02)
    assert bake.meta["solver"] == "full" and bake.meta["integrator"] == "discrete"


def calm(grammar: str, prestress: bool = True, duration: float = 1.0) -> dict:
    """A still scene that the pipeline must simulate (a zero pull makes the
    tree active): ground on, gravity on."""
    return {"tree": [{"grammar": grammar}], "duration": duration, "fps": 24,
            "prestress": prestress,
            "pull": [{"tree": 0, "force": [0.0, 0.0, 0.0], "release": duration}]}


@pytest.mark.parametrize("species", ["sapling", "oak"])
def test_prestressed_tree_stays_still_in_calm_air(root, species):
    bake = bake_scene(parse_scene(calm(str(root / "grammars" / f"{species}.lsys")),
                                  file="<test>"), solver="full")
    tree = bake.trees[0]
    assert not tree.static and tree.positions.shape[0] == 25
    assert np.abs(tree.positions - tree.positions[0]).max() < 1e-6  # m
    angle = 2 * np.arccos(np.clip(np.abs(tree.rotations[..., 3].astype(float)), 0, 1))
    assert angle.max() < 1e-3  # rad (float32 quaternions resolve about 5e-4)
    assert not tree.info["events"]


def test_without_prestress_the_tree_sags(root):
    """The control: the same scene without prestress does move."""
    bake = bake_scene(parse_scene(calm(str(root / "grammars" / "sapling.lsys"), False),
                                  file="<test>"), solver="full")
    tree = bake.trees[0]
    assert np.abs(tree.positions - tree.positions[0]).max() > 1e-3


def test_same_inputs_give_identical_bakes(root, tmp_path):
    """Gusty wind on a sapling, twice: the saved bakes are byte-identical."""
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 1.5,
           "fps": 24, "seed": 7,
           "wind": {"speed": 12.0, "turbulence": 0.3, "ramp": 0.5, "direction": 30.0}}
    files = []
    for k in range(2):
        bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
        files.append(save_bake(bake, tmp_path / f"b{k}.npz").read_bytes())
        assert np.abs(bake.trees[0].positions[-1] - bake.trees[0].positions[0]).max() > 0.01
    assert files[0] == files[1]


def test_felled_sapling_hinges_falls_and_comes_to_rest(root):
    # 9 s: turning about its rim (the hinge wood), the stem leaves slower
    # than about its centre (hinge snapped at 2.1 s) and rests at 7.8 s
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 9.0,
           "fps": 24, "cut": [{"tree": 0, "time": 0.2, "direction": 90.0, "hinge": 30.0}]}
    bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
    tree = bake.trees[0]
    events = tree.info["events"]
    order = [next(i for i, e in enumerate(events) if e["kind"] == kind)
             for kind in ("cut", "hinge snapped", "at rest")]
    assert order == sorted(order)
    ends = segment_ends(tree, np.arange(tree.n_segments))
    # lying down on its branches (it stood 3 m tall), which their leaves
    # hold out of the ground (its highest point: 0.78 m)
    assert ends[-1, :, 2].max() < 0.3 * tree.height
    assert ends[-1, :, 2].min() > -0.05  # on the ground, not through it
    top = ends[-1, -1] - tree.points[0]
    assert top[1] > 1.5 and abs(top[0]) < 1.0  # it fell toward +y (90 degrees)


def test_overloaded_root_breaks_and_the_tree_falls(tmp_path):
    """A 3 m pole anchored for 500 N m, pulled with 300 N at its top: the
    root joint breaks (uprooting) and the pole lands on the ground."""
    grammar = (f"density: {RHO}\nmodulus: {E}\ndamping: 0.05\n{BARE}anchor: 500\n"
               "iterations: 6\naxiom: !(0.1)A(6)\nA(n) : n > 0 -> F(0.5)A(n-1)\n")
    bake = bake_text(tmp_path, grammar, solver="full", duration=3.0, fps=24, ground=True,
                     pull=[{"tree": 0, "force": [300.0, 0, 0], "release": 3.0, "at": 1.0,
                            "ramp": 1.0}])
    events = bake.trees[0].info["events"]
    assert any(e["segment"] == "trunk:0" and e["kind"] == "uprooted" for e in events)
    t_break = events[0]["time"]
    assert 0.3 < t_break < 1.0  # 300 N x 3 m reaches 500 N m at 5/9 of the 1 s ramp
    assert bake.meta["stats"]["broken"] >= 1
    ends = segment_ends(bake.trees[0], np.arange(bake.trees[0].n_segments))
    assert ends[-1, :, 2].max() < 0.5


def test_projectile_flies_lands_and_is_tracked(root):
    """A sphere thrown at a sapling flies ballistically, hits it, lands and
    rests on the ground; its track is returned as objects."""
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 5.0,
           "fps": 24, "projectile": [{"shape": "sphere", "size": 0.4, "mass": 20.0,
                                       "position": [-4.0, 0.0, 2.0],
                                       "velocity": [3.0, 0.0, 2.0], "time": 0.5}]}
    bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
    obj = bake.objects
    assert obj is not None and obj.shapes == ["sphere"] and obj.positions.shape == (121, 1, 3)
    assert np.allclose(obj.positions[:12, 0], [-4.0, 0.0, 2.0])  # held until launched
    t = 0.25  # s after launch, in free flight
    f = 12 + 6
    expected = np.array([-4.0 + 3.0 * t, 0.0, 2.0 + 2.0 * t - 0.5 * G * t * t])
    assert obj.positions[f, 0] == pytest.approx(expected, abs=0.01)
    assert obj.positions[-1, 0, 2] == pytest.approx(0.2, abs=0.01)  # on the ground
    # at rest: it knocks the sapling over (uprooted at 2 s) and rolls on to about 4.5 s
    assert np.abs(obj.positions[-1, 0] - obj.positions[-2, 0]).max() < 0.01
    assert (obj.rotations.astype(float) ** 2).sum(-1) == pytest.approx(1.0, abs=1e-5)
    tree = bake.trees[0]
    assert np.abs(tree.positions[-1] - tree.positions[0]).max() > 0.05  # it hit the tree


def test_instability_is_reported_with_tree_segment_and_time(root, monkeypatch):
    """The guard: a bone faster than MAX_ANGULAR_SPEED stops the run with
    the tree, a segment of the offending bone and the time."""
    monkeypatch.setattr(reference.stepper, "MAX_ANGULAR_SPEED", 0.5)
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys"), "name": "shaky"}],
           "duration": 2.0, "fps": 24,
           "pull": [{"tree": 0, "force": [40.0, 0, 0], "release": 0.3, "at": 0.8,
                     "ramp": 0.0}]}
    with pytest.raises(SimulationError) as err:
        bake_scene(parse_scene(raw, file="<test>"), solver="full")
    e = err.value
    assert e.tree == "shaky" and 0.0 < e.time < 0.3 and "angular speed" in e.message
    rig = rig_of(root / "grammars" / "sapling.lsys")
    assert 0 <= e.segment < rig.model.n_segments


def test_non_finite_loads_are_reported(root, monkeypatch):
    """NaN from the loads (a broken force field) never reaches the bake."""
    from treebake.sim.loads import SceneLoads

    real = SceneLoads.forces

    def poisoned(self, t, com, *args, **kwargs):
        out = real(self, t, com, *args, **kwargs)
        if t > 0.5:
            out[7] = np.nan
        return out

    monkeypatch.setattr(SceneLoads, "forces", poisoned)
    raw = calm(str(root / "grammars" / "sapling.lsys"))
    with pytest.raises(SimulationError) as err:
        bake_scene(parse_scene(raw, file="<test>"), solver="full")
    assert err.value.time == pytest.approx(0.5, abs=0.01)
    rig = rig_of(root / "grammars" / "sapling.lsys")
    assert rig.seg_bone[err.value.segment] in range(rig.n_bones)


def test_timestep_and_force_rate_options(root):
    """Coarser steps for the accuracy report: whole force intervals per frame."""
    from treebake.grow import grow
    from treebake.sim.loads import SceneLoads
    from treebake.sim.rigging import rig_scene

    scene = parse_scene(calm(str(root / "grammars" / "sapling.lsys")), file="<test>")
    loads = SceneLoads(scene)
    trees = rig_scene(scene, grow(scene), None).trees
    for name, h in reference.TIMESTEPS.items():
        solver = reference.ReferenceEngine(trees, scene, scene.quality, loads, timestep=h,
                                           force_rate=240.0)
        # the nearest whole number of steps per force interval (1/240 s): 1/2000 s
        # becomes 1/1920, never 1/1600 (which a 30 % tolerance let through)
        steps = max(1, round(1 / (240.0 * h)))
        assert solver.h == pytest.approx(1 / (240.0 * steps), rel=1e-9), name
        assert solver.spf % solver.force_every == 0
        assert reference.solver.report(solver).stats["step"] == solver.h


def test_structural_damping_ratio_is_the_grammars(tmp_path):
    """Mass-proportional damping gives the first mode the grammar's ratio
    (the discrete integrator adds about pi f1 h = 0.001)."""
    grammar = cantilever_grammar(20).replace("damping: 0\n", "damping: 0.05\n")
    bake = bake_text(tmp_path, grammar, solver="full", duration=6.0, fps=120, gravity=0.0,
                     pull=[{"tree": 0, "force": [100.0, 0, 0], "release": 1.0, "at": 1.0}])
    t, x = bake.times, tip(bake.trees[0])[:, 0]
    free = t > 1.02
    assert damping_ratio(t[free], x[free]) == pytest.approx(0.05, abs=0.005)


def test_swaying_tree_comes_to_rest(root):
    """No perpetual motion: a sapling pulled and released in still air
    (damping, drag and limits all active) loses its motion."""
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 5.0,
           "fps": 24, "pull": [{"tree": 0, "force": [30.0, 0, 0], "release": 0.5, "at": 0.8}]}
    bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
    energy = kinetic_energy(bake)
    after = energy[13:]  # from the release on
    assert after[-24:].max() < 0.01 * after.max()


def test_broken_branch_falls_off_and_the_stem_stays(tmp_path):
    """A side branch weaker than its own weight's moment breaks at once,
    moves on in a model of its own, and lands; the stem it left stands."""
    grammar = (f"density: {RHO}\nmodulus: {E}\ndamping: 0.05\n{BARE}"
               "axiom: !(0.1)F(1)[&(90)@strength(2)!(0.03)F(0.5)F(0.5)]F(1)\n")
    bake = bake_text(tmp_path, grammar, solver="full", duration=1.5, fps=24, ground=True,
                     pull=[{"tree": 0, "force": [0.0, 0, 0], "release": 1.5}])
    tree = bake.trees[0]
    events = tree.info["events"]
    assert events and events[0]["segment"] == "trunk/1:0" and events[0]["kind"] == "broke"
    assert events[0]["time"] == 0.0
    assert bake.meta["stats"]["parts"] >= 1
    ends = segment_ends(tree, np.arange(tree.n_segments))
    branch = [i for i, p in enumerate(tree.paths) if p.startswith("trunk/1")]
    stem = [i for i, p in enumerate(tree.paths) if p.startswith("trunk:")]
    assert ends[-1, branch, 2].max() < 0.1  # on the ground
    assert np.abs(ends[-1, stem] - ends[0, stem]).max() < 0.01  # the stem stands


def test_detaching_keeps_every_body_s_pose_and_velocity(root, monkeypatch):
    """Breaking moves parts between MuJoCo models; no body may jump or
    change speed in the move (compared through MuJoCo's own kinematics)."""
    import mujoco

    def bodies(solver):
        out, res = {}, np.zeros(6)
        for g in solver.groups:
            mujoco.mj_forward(g.model, g.data)
            for b, body in zip(g.bones.tolist(), g.body.tolist()):
                mujoco.mj_objectVelocity(g.model, g.data, mujoco.mjtObj.mjOBJ_BODY, body, res, 0)
                out[b] = np.concatenate([g.data.xpos[body], g.data.xquat[body], res])
        return out

    worst = []
    detach = reference.ReferenceEngine._detach

    def checked(self, gi, freed):
        before = bodies(self)
        changed = detach(self, gi, freed)
        after = bodies(self)
        worst.append(max(np.abs(before[b] - after[b]).max() for b in before))
        return changed

    monkeypatch.setattr(reference.ReferenceEngine, "_detach", checked)
    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 0.5,
           "fps": 24, "pull": [{"tree": 0, "force": [400.0, 0, 0], "release": 0.5, "at": 0.9,
                                "ramp": 0.5}]}
    bake = bake_scene(parse_scene(raw, file="<test>"), solver="full")
    assert bake.meta["stats"]["parts"] >= 1 and bake.meta["stats"]["rebuilds"] >= 1
    assert len(worst) >= 2 and max(worst) < 1e-9


def test_damping_is_each_limbs_mass_matrix_block(root):
    """The sparse damping forces equal the dense formula -rate M_LL qdot_L
    per limb, on a bent, moving sapling in a model with a projectile (whose
    free joint changes MuJoCo's sparse layout)."""
    import mujoco
    from treebake.grow import grow
    from treebake.sim.loads import SceneLoads
    from treebake.sim.rigging import rig_scene

    raw = {"tree": [{"grammar": str(root / "grammars" / "sapling.lsys")}], "duration": 1.0,
           "projectile": [{"shape": "box", "size": 0.3, "mass": 5.0, "position": [-3.0, 0, 1.0],
                           "velocity": [3.0, 0, 1.0]}]}
    scene = parse_scene(raw, file="<test>")
    loads = SceneLoads(scene)
    trees = rig_scene(scene, grow(scene), None).trees
    solver = reference.ReferenceEngine(trees, scene, scene.quality, loads)
    (g,) = solver.groups
    m, d = g.model, g.data
    rng = np.random.default_rng(1)
    hinges = g.hinge_qpos[g.hinge_qpos >= 0]
    d.qpos[hinges] += 0.1 * rng.standard_normal(len(hinges))
    d.qvel[:] = rng.standard_normal(m.nv)
    mujoco.mj_forward(m, d)
    solver._damping(g)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    expected = np.zeros(m.nv)
    rig = trees[0].rig
    for limb in rig.limbs:
        dofs = g.hinge_dof[limb.bones].reshape(-1)
        rate = -np.expm1(-rig.alpha[limb.bones[0]] * solver.h) / solver.h
        expected[dofs] = -rate * full[np.ix_(dofs, dofs)] @ d.qvel[dofs]
    assert np.abs(expected).max() > 1.0
    assert np.abs(d.qfrc_applied - expected).max() < 1e-9 * np.abs(expected).max()

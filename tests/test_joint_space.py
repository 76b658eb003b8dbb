"""The linear tier's joint-space algebra against independent computations:
kinetic energy of the bones, virtual power of the loads, numerical
derivatives of the right-hand side, dense solves."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from treebake.grow import grow
from treebake.pipeline import bake_scene
from treebake.quality import QUALITIES
from treebake.scene import parse_scene
from treebake.sim.common import Bones
from treebake.sim.joint_space import JointSpace
from treebake.sim.layout import ChainLayout
from treebake.sim.loads import SceneLoads
from treebake.sim.rigging import rig_scene
from treebake.sim.treefactor import TreeFactor, ancestor_table, depths
from treebake.sim.treesums import ChainSums

ROOT = Path(__file__).resolve().parent.parent


def system(grammar: str | Path, count: int = 1) -> JointSpace:
    trees = [{"grammar": str(ROOT / "grammars" / grammar), "position": [10.0 * i, 0.0]}
             for i in range(count)]
    scene = parse_scene({"tree": trees, "wind": {"speed": 5.0}}, file="<test>")
    loads = SceneLoads(scene)
    sim = rig_scene(scene, grow(scene), QUALITIES["final"]).trees
    bones = Bones.of(sim)
    layout = ChainLayout.of(sim, bones.offsets, bones.pivot0, bones.tip0)
    return JointSpace(bones, layout, loads.g, 0.01, 1e-4)


@pytest.fixture(scope="module", params=["sapling.lsys", "forest/broadleaf.lsys"])
def js(request):
    return system(request.param, count=2)  # two trees: one block-diagonal system


def test_mass_matrix_is_the_bones_kinetic_energy(js):
    rng = np.random.default_rng(1)
    v = rng.normal(size=js.n)
    mass, _, _ = js.dense()
    kin = js.kinematics(np.zeros(js.n), v)
    pose = js.pose(kin, np.zeros(js.n))
    b = js.bones
    omega = kin[6:9].T
    energy = 0.5 * (b.mass * (pose.vcom**2).sum(0)).sum() + 0.5 * np.einsum(
        "bi,bij,bj->", omega, b.inertia, omega)
    assert 0.5 * v @ mass @ v == pytest.approx(energy, rel=1e-12)


def test_loads_do_the_work_of_the_forces(js):
    """At rest, J^T F . v = sum F . (velocity of each COM)."""
    rng = np.random.default_rng(2)
    v = rng.normal(size=js.n)
    force = rng.normal(size=(js.bones.n, 3))
    zero = np.zeros(js.n)
    kin = js.kinematics(zero, v)
    pose = js.pose(kin, zero)
    _, damping, _ = js.dense()
    tau = js.rhs(force.T, kin, pose, zero) + js.hold + damping @ v
    assert tau @ v == pytest.approx((force * pose.vcom.T).sum(), rel=1e-10)


def test_tip_shift_is_the_tips_first_order_motion(js):
    """tip_shift(dq) against the exact kinematics: central differences of
    every bone's tip (pivot + R (tip0 - pivot0)) about the grown shape."""
    rng = np.random.default_rng(8)
    dq = rng.normal(size=js.n) * 1e-6
    zero = np.zeros(js.n)
    b = js.bones

    def tips(q):
        pose = js.pose(js.kinematics(q, zero), q, loads=False)
        return pose.pivot + np.einsum("ijb,bj->ib", pose.rot, b.tip0 - b.pivot0)

    num = (tips(dq) - tips(-dq)) / 2
    assert np.allclose(js.tip_shift(dq), num, rtol=1e-5, atol=1e-6 * np.abs(num).max())


def test_damping_is_each_limbs_block_of_the_mass_matrix(js):
    rng = np.random.default_rng(3)
    v = rng.normal(size=js.n)
    mass, damping, _ = js.dense()
    limb = js.layout.bone_chain[js.dof_bone]
    block = np.where(limb[:, None] == limb[None, :], mass, 0.0) * js.alpha[:, None]
    assert np.allclose(damping, block)
    got = js.alpha * js.limb_momentum(js.kinematics(np.zeros(js.n), v))
    assert np.allclose(got, block @ v, rtol=1e-10, atol=1e-10 * np.abs(block @ v).max())


def test_tangent_stiffness_is_the_derivative_of_the_right_hand_side(js):
    """K_s + K_g (in the implicit matrix) = -d(rhs)/dq at rest, gravity and
    prestress included: central differences on the exact right-hand side."""
    b = js.bones
    gravity = b.mass[:, None] * np.array([0.0, 0.0, -9.81])
    zero = np.zeros(js.n)

    def rhs(q):
        kin = js.kinematics(q, zero)
        return js.rhs(gravity.T, kin, js.pose(kin, q), q)

    assert np.abs(rhs(zero)).max() < 1e-9 * np.abs(js.hold).max()  # prestress: at rest
    _, _, stiffness = js.dense()
    rng = np.random.default_rng(4)
    for _ in range(3):
        d = rng.normal(size=js.n) * 1e-6
        num = -(rhs(d) - rhs(-d)) / 2
        assert np.allclose(num, stiffness @ d, rtol=1e-4, atol=1e-5 * np.abs(stiffness @ d).max())


def test_energy_is_the_bones_and_the_springs(js):
    """JointSpace.energy against its parts computed here: the bones' kinetic
    energy (as above), their weight above z = 0 and (k q + hold)^2 / 2k."""
    rng = np.random.default_rng(7)
    q, v = rng.normal(size=js.n) * 1e-3, rng.normal(size=js.n)
    kin = js.kinematics(q, v)
    pose = js.pose(kin, q)
    b = js.bones
    mass, _, _ = js.dense()
    kinetic = 0.5 * v @ mass @ v  # first-order velocities: the mass matrix at rest
    weight = (b.mass * 9.81 * pose.com[2]).sum()
    springs = (0.5 * (js.k_spring * q + js.hold) ** 2 / js.k_spring).sum()
    got = js.energy(kin, pose, q, 9.81).sum()
    # the spin uses the turned inertia R I R^T, the mass matrix the rest one: q ~ 1e-3
    assert got == pytest.approx(kinetic + weight + springs, rel=1e-6)


def test_factor_solves_the_implicit_matrix(js):
    mass, damping, stiffness = js.dense()
    a = mass + 0.01 * damping + 1e-4 * stiffness
    b = np.random.default_rng(5).normal(size=js.n)
    assert np.allclose(js.factor.solve(b), np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    assert np.allclose(js.mass_factor.solve(b), np.linalg.solve(mass, b), rtol=1e-9,
                       atol=1e-12)


def test_tree_sums_and_factor_on_a_random_tree():
    rng = np.random.default_rng(6)
    parent, chains, level = [], [], []

    def chain(p, lev, length):
        out = []
        for _ in range(length):
            parent.append(p)
            p = len(parent) - 1
            out.append(p)
        chains.append(np.array(out))
        level.append(lev)
        return out

    trunk = chain(-1, 0, 9)
    for a in trunk[1::2]:
        for b in chain(a, 1, int(rng.integers(1, 6)))[::2]:
            chain(b, 2, int(rng.integers(1, 4)))
    # several chains on one bone: a whorl of five on the trunk (level 1),
    # two side chains on one branch bone (level 2)
    for _ in range(5):
        chain(trunk[3], 1, 2)
    twice = chain(trunk[6], 1, 3)[1]
    chain(twice, 2, 2)
    chain(twice, 2, 1)
    parent = np.array(parent)
    n = len(parent)
    chain_parent = np.array([parent[c[0]] for c in chains])
    sums = ChainSums(chains, chain_parent, np.array(level), n)
    x = rng.normal(size=(2, n))
    pre, suf = x.copy(), x.copy()
    for j in range(n):
        if parent[j] >= 0:
            pre[:, j] += pre[:, parent[j]]
    for j in range(n - 1, -1, -1):
        if parent[j] >= 0:
            suf[:, parent[j]] += suf[:, j]
    own = x.copy()  # within its own chain: the bones after it
    for c in chains:
        own[:, c] = np.cumsum(x[:, c][:, ::-1], axis=1)[:, ::-1]
    assert np.allclose(sums.prefix(x), pre)
    assert np.allclose(sums.suffix(x), suf)
    assert np.allclose(sums.chain_suffix(x), own)
    depth = depths(parent)
    anc = ancestor_table(parent, depth)
    a = 0.1 * np.eye(n)
    for j in range(n):  # SPD with entries only between ancestors
        path = [j, *anc[j, :depth[j]]]
        u = np.zeros(n)
        u[path] = rng.normal(size=len(path))
        a += np.outer(u, u)
    lower = np.zeros((n, max(depth.max(), 1)))
    for j in range(n):
        lower[j, :depth[j]] = a[j, anc[j, :depth[j]]]
    factor = TreeFactor(parent, np.diag(a).copy(), lower, chains, np.array(level))
    b = rng.normal(size=n)
    assert np.allclose(factor.solve(b), np.linalg.solve(a, b))


def test_tree_sums_add_a_bones_chains_in_np_add_at_order(monkeypatch):
    """Chains that hang on one bone add onto it in rounds of distinct bones;
    the sums are the bytes np.add.at gives, which adds them in the chains'
    order (a bake's bytes do not depend on which path ran)."""
    import treebake.sim.treesums as treesums

    rng = np.random.default_rng(8)
    parent = [-1, 0, 1, 2]  # a trunk of 4 bones; on bone 2, three twigs of 2 bones
    chains, level = [np.arange(4)], [0]
    for _ in range(3):
        chains.append(np.array([len(parent), len(parent) + 1]))
        level.append(1)
        parent += [2, len(parent)]
    chain_parent = np.array([-1, 2, 2, 2])
    x = rng.normal(size=(64, len(parent)))  # 64 draws: the order shows in the last bits
    rounds = ChainSums(chains, chain_parent, np.array(level), len(parent))
    assert rounds.levels[1].rounds is not None and len(rounds.levels[1].rounds) == 3
    monkeypatch.setattr(treesums, "MAX_ROUNDS", 0)
    at = ChainSums(chains, chain_parent, np.array(level), len(parent))
    assert at.levels[1].rounds is None
    assert rounds.suffix(x).tobytes() == at.suffix(x).tobytes()


def test_hinges_from_pose_inverts_the_exact_kinematics(js):
    """The pymunk tier hands a tree back as rotations and spins: the hinge
    angles and rates recovered from pose_frames' exact rotations (angles up
    to 1.2 rad) and from their finite-difference spins are the ones put in."""
    from treebake.rotations import matrices_from_quaternions
    from treebake.sim.hinges import hinges_from_pose, pose_frames

    rng = np.random.default_rng(5)
    b = js.bones
    q = rng.uniform(-1.2, 1.2, size=js.n)
    v = rng.normal(size=js.n)
    dt = 1e-6
    quats, _ = pose_frames(b, np.stack([q - dt * v, q, q + dt * v]))
    rots = matrices_from_quaternions(quats.reshape(-1, 4)).reshape(3, b.n, 3, 3)
    # world spin from the rotations' rate: (dR/dt) R^T is [omega]x
    skew = np.einsum("bij,bkj->bik", (rots[2] - rots[0]) / (2 * dt), rots[1])
    omega = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], 1)
    q_back, v_back = hinges_from_pose(b, rots[1], omega)
    assert np.abs(q_back - q).max() < 1e-9
    assert np.abs(v_back - v).max() < 1e-6


def test_linearised_at_a_bent_pose_the_system_is_that_poses(tmp_path):
    """A straight stem of 8 bones bent in one plane (its first hinges, all
    on one axis: there the exact kinematics are rotations about fixed axes)
    by 0.1 rad per joint, 0.8 rad at the top. Linearised at that pose, the
    rates move every COM as the exact kinematics' central differences do,
    the mass matrix is the kinetic energy of those velocities, and the
    tangent stiffness is the numerical derivative of the right-hand side
    (gravity and springs) within the plane. Linearised at rest instead,
    the mass matrix is off by 2 % at this pose."""
    stem = tmp_path / "stem.lsys"
    stem.write_text("drag: 0\nleaf drag: 0\niterations: 8\n"
                    "axiom: !(0.12)A(8)\nA(n) : n > 0 -> F(0.6)A(n-1)\n")
    js = system(stem)
    b = js.bones
    assert b.n == 8 and np.allclose(b.hinges[:, 0], b.hinges[0, 0])
    q = np.zeros(js.n)
    q[0::2] = 0.1
    rng = np.random.default_rng(9)
    v = np.zeros(js.n)
    v[0::2] = rng.normal(size=b.n)
    eps = 1e-6
    zero = np.zeros(js.n)

    def com(qq):
        return js.pose(js.kinematics(qq, zero), qq, loads=False).com

    vcom = (com(q + eps * v) - com(q - eps * v)) / (2 * eps)
    omega = np.outer(b.hinges[0, 0], v[0::2].cumsum())  # (3, B): planar, turns add up
    energy = 0.5 * (b.mass * (vcom**2).sum(0)).sum() + 0.5 * np.einsum(
        "ib,bij,jb->", omega, b.inertia, omega)  # a spin about a principal axis: R I R^T = I
    at_rest = 0.5 * v @ js.dense()[0] @ v
    assert abs(at_rest / energy - 1) > 0.01
    js.linearise_at(q)
    kin = js.kinematics(q, v)
    pose = js.pose(kin, q)
    assert np.allclose(pose.vcom, vcom, rtol=1e-6, atol=1e-8 * np.abs(vcom).max())
    mass, _, stiffness = js.dense()
    assert 0.5 * v @ mass @ v == pytest.approx(energy, rel=1e-8)
    gravity = (b.mass[:, None] * np.array([0.0, 0.0, -9.81])).T

    def rhs(qq):
        kk = js.kinematics(qq, zero)
        return js.rhs(gravity, kk, js.pose(kk, qq), qq)

    plane = np.arange(0, js.n, 2)
    for _ in range(3):
        d = np.zeros(js.n)
        d[plane] = rng.normal(size=b.n) * 1e-6
        num = -(rhs(q + d) - rhs(q - d)) / 2
        assert np.allclose(num[plane], (stiffness @ d)[plane], rtol=1e-5,
                           atol=1e-6 * np.abs(stiffness @ d).max())


def test_a_tree_that_stays_keeps_its_work_when_another_leaves():
    """Two saplings in one linear tier: one pulled hard leaves it at 0.73 s
    (the tier rebuilds its system without it), the other, pulled less,
    stays and is still being pulled through the rebuild. The pull's work on the
    one that stays goes on being counted: its energy never rises above its
    start plus the work done on it (structural damping only takes)."""
    g = str(ROOT / "grammars" / "sapling.lsys")
    scene = parse_scene({
        "name": "two", "duration": 2.5, "fps": 24,
        "tree": [{"grammar": g, "position": [0.0, 0.0]}, {"grammar": g, "position": [30.0, 0.0]}],
        "pull": [{"tree": 0, "force": [300.0, 0.0, 0.0], "ramp": 2.5, "release": 2.5, "at": 1.0},
                 {"tree": 1, "force": [60.0, 0.0, 0.0], "ramp": 2.5, "release": 2.5, "at": 1.0}]},
        file="<test>")
    bake = bake_scene(scene, quality=replace(QUALITIES["default"], nonlinear="pymunk"))
    left, stayed = bake.trees
    assert left.info["solver"].startswith("linear, then pymunk from ")
    assert stayed.info["solver"] == "linear"
    audit = bake.meta["energy"][stayed.name]
    assert audit["external_work_j"] > 20.0
    # the step of the rebuild (0.73 s) uncounted: 0.17 J, 2.5e-3 of its scale
    assert audit["max_gain_fraction"] < 2e-4, audit

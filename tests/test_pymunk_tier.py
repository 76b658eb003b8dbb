"""The pymunk tier's bookkeeping at events, checked on its bodies directly."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
from treebake.grow import grow
from treebake.quality import QUALITIES
from treebake.rotations import rotvecs_from_matrices
from treebake.scene import parse_scene
from treebake.sim.chains import PymunkTier
from treebake.sim.loads import SceneLoads
from treebake.sim.rigging import rig_scene

# a stem of four segments with a heavy side branch on its second
GRAMMAR = ("density: 800\nmodulus: 8e9\ndamping: 0.05\n"
           "axiom: !(0.2)F(1)F(1)[&(60)!(0.12)F(1.2)F(1)]F(1)F(1)\n")


def _tier(tmp_path, grammar: str) -> PymunkTier:
    """A pymunk tier, begun, for one tree of `grammar` in a 5 m/s wind."""
    path = tmp_path / "g.lsys"
    path.write_text(grammar)
    scene = parse_scene({"tree": [{"grammar": str(path)}], "ground": False, "duration": 1.0,
                         "wind": {"speed": 5.0}}, file="<test>")
    loads = SceneLoads(scene, np.array([[-20.0, -20.0], [20.0, 20.0]]))
    trees = rig_scene(scene, grow(scene), QUALITIES["default"]).trees
    tier = PymunkTier(trees, scene, QUALITIES["default"], loads)
    tier.begin()
    return tier


def test_a_part_breaking_off_a_spinning_body_leaves_its_wood_moving_as_before(tmp_path):
    """When a branch breaks off, the bodies that carried it lose its mass
    and their centres of gravity move within them. A body's wood must go on
    moving as before (a break releases no momentum into what stays): pymunk
    keeps a body's velocity at its centre of gravity, so that velocity must
    change by omega x the shift. Checked at every remaining body's pivot and
    tip, spinning at 3 rad/s."""
    tier = _tier(tmp_path, GRAMMAR)
    branch = int(np.nonzero(tier.bone_frame >= 0)[0][0])  # the side chain's first bone
    stays = [i for i in range(len(tier.bodies)) if tier.bone_frame[tier.body_bone[i]] < 0]
    for i, body in enumerate(tier.bodies):
        body.angular_velocity = 3.0
        body.velocity = (0.5 + 0.1 * i, -0.2)
    points = {i: [tier.bodies[i].local_to_world(p) for p in
                  ((0.0, 0.0), tuple(tier.bodies[i].center_of_gravity * 2))] for i in stays}
    before = {i: [tier.bodies[i].velocity_at_world_point(p) for p in points[i]] for i in stays}
    cog_before = {i: tier.bodies[i].center_of_gravity for i in stays}
    tier.read()
    tier.break_joint(branch, 0.0, tier.reconstruct(), 0.0)
    moved = [i for i in stays if (tier.bodies[i].center_of_gravity - cog_before[i]).length > 1e-3]
    assert moved, "no body that carried the branch changed its centre of gravity"
    for i in stays:
        after = [tier.bodies[i].velocity_at_world_point(p) for p in points[i]]
        for a, b in zip(after, before[i], strict=True):
            assert (a - b).length < 1e-9, (i, a, b)


def test_a_bake_that_stays_linear_never_loads_pymunk(tmp_path):
    """The pymunk tier (and pymunk) loads only when a tree leaves the linear
    tier: a breeze on a small tree is baked in a fresh interpreter, which
    must finish with every tree linear and pymunk never imported."""
    path = tmp_path / "g.lsys"
    path.write_text(GRAMMAR)
    code = (
        "import sys, json\n"
        "from treebake.pipeline import bake_scene\n"
        "from treebake.scene import parse_scene\n"
        f"scene = parse_scene({{'tree': [{{'grammar': {str(path)!r}}}], 'duration': 1.0,\n"
        "                      'wind': {'speed': 5.0}}, file='<test>')\n"
        "bake = bake_scene(scene, solver='planar')\n"
        "solvers = [t.info.get('solver') for t in bake.trees]\n"
        "print(json.dumps([solvers, 'pymunk' in sys.modules]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    solvers, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert solvers == ["linear"]
    assert not loaded


def test_a_break_does_not_jolt_the_chains_that_stay_on_the_body(tmp_path):
    """A child chain rides in the frame of the bone it hangs on, and feels
    that frame's acceleration as d'Alembert forces. When another branch
    breaks off that bone, the bone's lumped centre of gravity moves within
    it, and its velocity jumps by omega x the shift: that is no
    acceleration of the wood. The frame forces on the branch that stays
    must be the same whether the last pose was taken before or after the
    break (the same instant). Measured from the pose of the bone's own COM,
    they are; from the lumped COG's, the branch got 1,300 m/s^2 for a
    substep when an oak's twig broke in a blast (docs/physics.md)."""
    tier = _tier(tmp_path, "density: 800\nmodulus: 8e9\ndamping: 0.05\n"
                 "axiom: !(0.2)F(1)F(1)[&(60)!(0.12)F(1.2)F(1)][/(180)&(45)!(0.04)F(0.6)]"
                 "F(1)F(1)\n")
    children = np.nonzero(tier.bone_frame >= 0)[0]
    heavy = int(children[np.argmax(tier.mass[children])])  # the thick branch's first bone
    light = [i for i in range(len(tier.bodies))
             if tier.bone_chain[tier.body_bone[i]] != tier.bone_chain[heavy]
             and tier.bone_frame[tier.body_bone[i]] >= 0]
    assert light and tier.bone_frame[heavy] == tier.bone_frame[tier.body_bone[light[0]]]
    for i, body in enumerate(tier.bodies):
        body.angular_velocity = 3.0
        body.velocity = (0.5 + 0.1 * i, -0.2)
    tier.read()
    before = tier.reconstruct()
    tier.break_joint(heavy, 0.0, before, 0.0)
    after = tier.reconstruct()
    since = 1e-3  # s
    rows = tier.row_of_body[light]
    tier.forces(0.0, after, before, since, since)
    across = tier.force_rows[rows].copy()
    tier.forces(0.0, after, after, since, since)
    still = tier.force_rows[rows].copy()
    scale = tier.lump_mass[tier.body_bone[light]] * 9.81  # the branch's weight, N
    assert np.abs(across - still)[:, :2].max() < 1e-6 * scale.max(), (across, still)


def test_the_velocities_rebuilt_are_the_rate_of_the_pose_rebuilt(tmp_path):
    """A bone bending in two planes turns by exp(theta_0 n_0 + theta_1 n_1)
    in its frame. Its angular velocity is then not theta_0' n_0 +
    theta_1' n_1 (the two only agree while one plane turns): the rotation
    vector's rate must go through the exponential map's Jacobian. Checked
    against a central finite difference of the rebuilt poses, every bone
    of a stem and the branch riding on it bent 0.5-0.9 rad in both planes
    and turning at 2-4 rad/s: the rotations' rate and every COM's velocity.
    (With theta' n summed, a child's frame turned at the wrong rate: the
    energy audit charged a 70 m/s gale on a sapling with 4.9 % of its energy
    as made from nothing, 3.1 % with the Jacobian.) Checked again after
    breaks: a body whose lumped COG moved must be rebuilt from pymunk's
    COG, not the one it was built with (a stale one made a broken bamboo
    culm's head 8 % slow in the `hurricane` preset)."""
    tier = _tier(tmp_path, GRAMMAR)
    assert (tier.planes_of_bone == 2).all()
    _check_rebuilt_velocities(tier)
    # the same after the branch breaks off the second bone (whose lumped
    # COG moves within it) and that bone's joint breaks too (it becomes the
    # head of a falling stem's row, its velocity taken from its origin)
    branch = int(np.nonzero(tier.bone_frame >= 0)[0][0])
    carrier = int(tier.bone_frame[branch])
    tier.read()
    tier.break_joint(branch, 0.0, tier.reconstruct(), 0.0)
    tier.read()
    tier.break_joint(carrier, 0.0, tier.reconstruct(), 0.0)
    tier.read()
    for i in range(len(tier.bodies)):  # the tier's COGs are pymunk's
        if tier.in_space[i]:
            body = tier.bodies[i]
            cog = body.local_to_world(body.center_of_gravity)
            assert np.allclose(tier._cogs(np.array([i]))[0], (cog.x, cog.y), atol=1e-9), i
    _check_rebuilt_velocities(tier)


def _check_rebuilt_velocities(tier) -> None:
    rng = np.random.default_rng(3)
    nb = len(tier.bodies)
    state = tier.state.copy()
    state[:, 2] = rng.uniform(0.5, 0.9, nb) * rng.choice([-1.0, 1.0], nb)
    state[:, 3:5] = rng.uniform(-1.0, 1.0, (nb, 2))
    state[:, 5] = rng.uniform(2.0, 4.0, nb) * rng.choice([-1.0, 1.0], nb)
    dt = 1e-6  # s

    # pymunk's position is a body's origin (its pivot), its velocity the
    # centre of gravity's: the origin moves at v - w x (cog - origin)
    tier.state[:] = state
    arm = tier._cogs(np.arange(nb)) - state[:, 0:2]
    origin_rate = state[:, 3:5] - state[:, 5:6] * np.stack([-arm[:, 1], arm[:, 0]], 1)

    def pose_at(offset: float) -> dict:
        tier.state[:] = state
        tier.state[:, 0:2] += offset * origin_rate
        tier.state[:, 2] += offset * state[:, 5]
        return tier.reconstruct()

    now, ahead, behind = pose_at(0.0), pose_at(dt), pose_at(-dt)
    turn = rotvecs_from_matrices(np.einsum("nij,nkj->nik", ahead["rot"], behind["rot"]))
    rate = turn / (2 * dt)
    assert np.abs(now["omega"] - rate).max() < 1e-5 * np.abs(rate).max(), (now["omega"], rate)
    vcom = (ahead["com"] - behind["com"]) / (2 * dt)
    assert np.abs(now["vcom"] - vcom).max() < 1e-5 * np.abs(vcom).max(), (now["vcom"], vcom)


def test_the_loads_do_the_same_work_on_the_two_planes_as_on_the_pose(tmp_path):
    """A bone bent in two planes turns by exp(theta_0 n_0 + theta_1 n_1):
    what a load does on the two planes' angles must be what it does on the
    3D pose rebuilt from them, or the planes gain energy the load never
    gave. With every bone of a stem and its branch bent 0.5-0.9 rad in
    both planes and turning at 2-4 rad/s, and an arbitrary force and torque
    on every bone, the power pymunk's bodies receive (the force at each
    COG, the torque on its turn, in both planes) must equal the power on
    the rebuilt bones, relative to each chain's frame. (Each plane given
    the torque about its own normal, a 70 m/s gust on the stress suite's
    sapling gained 3.1 % of its energy.)"""
    tier = _tier(tmp_path, GRAMMAR)
    assert (tier.planes_of_bone == 2).all()
    rng = np.random.default_rng(5)
    nb = len(tier.bodies)
    angle = rng.uniform(0.5, 0.9, nb) * rng.choice([-1.0, 1.0], nb)
    rate = rng.uniform(2.0, 4.0, nb) * rng.choice([-1.0, 1.0], nb)
    # each plane's chain as pymunk would hold it: its head pinned at rest,
    # every pivot at the tip of the body before it
    for i, body in enumerate(tier.bodies):
        body.angle = angle[i]
        j = tier.prev_body[i]
        if j < 0:
            origin, v_origin = tuple(tier.q0[i]), (0.0, 0.0)
        else:
            joint = tier.bodies[j].local_to_world(tuple(tier.q0[i] - tier.q0[j]))
            origin, v_origin = joint, tier.bodies[j].velocity_at_world_point(joint)
        body.position = origin
        body.velocity = (0.0, 0.0)
        body.angular_velocity = rate[i]
        back = body.velocity_at_world_point(origin)  # pymunk's velocity is the COG's
        body.velocity = (v_origin[0] - back[0], v_origin[1] - back[1])
    tier.read()
    assert tier.joint_gap() < 1e-12
    pose = tier.reconstruct()
    force = rng.normal(0.0, 100.0, (tier.n, 3))  # N, on each bone's lumped COG
    torque = rng.normal(0.0, 100.0, (tier.n, 3))  # N m
    bone = tier.body_bone
    f_loc = np.einsum("nji,nj->ni", pose["frame_rot"][bone], force[bone])
    t_loc = np.einsum("nji,nj->ni", pose["frame_rot"][bone], torque[bone])
    turn = tier._turning(pose, force[bone], torque[bone], f_loc, t_loc)
    v = tier.state[:, 3:5]
    planes = ((f_loc * tier.body_e).sum(1) * v[:, 0] + (f_loc * tier.body_d).sum(1) * v[:, 1]
              + turn * tier.state[:, 5]).sum()
    # on the pose: relative to the frame each chain moves in (its parent bone)
    frame = tier.bone_frame
    v_rel, w_rel = pose["vcog"].copy(), pose["omega"].copy()
    held = frame >= 0
    p = frame[held]
    w_rel[held] -= pose["omega"][p]
    v_rel[held] -= pose["vcom"][p] + np.cross(pose["omega"][p],
                                              pose["cog"][held] - pose["com"][p])
    rebuilt = (force * v_rel).sum() + (torque * w_rel).sum()
    assert abs(planes - rebuilt) < 1e-9 * np.abs(force * v_rel).sum(), (planes, rebuilt)


def test_a_stems_light_top_breaks_off_as_debris_and_a_heavy_one_as_a_chain(tmp_path):
    """A stem snapped near its top frees a piece of well under 1 % of the
    tree: it flies on as rigid debris, out of pymunk's space, with the
    momentum it had; snapped at its second bone, the part above (most of
    the tree) falls on as a free planar chain."""
    widths = [0.3, 0.26, 0.22, 0.18, 0.14, 0.1, 0.07, 0.05, 0.03, 0.015]
    axiom = "".join(f"!({w})F(1)" for w in widths)
    grammar = f"density: 800\nmodulus: 8e9\ndamping: 0.05\naxiom: {axiom}\n"
    tier = _tier(tmp_path, grammar)
    for i, body in enumerate(tier.bodies):
        body.angular_velocity = 1.0
        body.velocity = (0.3 + 0.05 * i, -0.1)
    tier.read()
    pose = tier.reconstruct()
    top = tier.n - 1
    assert tier.mass[top] < 0.01 * tier.mass.sum()  # the light piece: the top bone alone
    momentum = tier.mass[top] * pose["vcom"][top]
    tier.break_joint(top, 0.0, pose, 0.0)
    assert tier.in_debris[top] and not tier.in_debris[:top].any()
    assert not any(tier.in_space[tier.body_of[(top, k)]] for k in range(tier.planes_of_bone[top]))
    after = tier.reconstruct()
    assert np.allclose(tier.mass[top] * after["vcom"][top], momentum, atol=1e-12)
    tier.break_joint(1, 0.0, after, 0.0)  # above it, two thirds of the tree
    assert not tier.in_debris[1:top].any()
    assert all(tier.in_space[tier.body_of[(b, 0)]] for b in range(1, top))

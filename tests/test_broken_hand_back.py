"""A tree that lost parts comes back to the linear tier once they lie still
(sim/pruning.py): its standing part runs on there, keeping its springs'
set; what broke off stays where it came to rest. Against the truth of the
same shot with the tree kept in the MuJoCo reference to the end
(`hand_back = false`): the same motion until the return, no jump at it,
the reference's motion after within the linear tier's accuracy, and the
audit's energy carried across."""

from dataclasses import replace

import numpy as np
import pytest
from treebake.grow import grow
from treebake.library import grammars_folder
from treebake.pipeline import bake_scene
from treebake.rig import build_rig
from treebake.scene import parse_scene
from treebake.sim.pruning import pruned_rig
from treebake.sim.rigging import rig_scene
from treebake.sim.run import simulate, solver_kind
from treebake.sway import segment_ends


def blast_scene():
    """The explosion preset's sapling alone: 10 kg of TNT 9 m away breaks
    ten of its joints at 0.53 s; the parts fall and lie still by 2.75 s."""
    return parse_scene({
        "name": "sapling-blast", "duration": 4.0, "fps": 24,
        "tree": [{"grammar": str(grammars_folder() / "sapling.lsys"), "position": [9.0, 2.0]}],
        "explosion": [{"position": [0.0, 0.0, 1.0], "time": 0.5, "charge": 10.0}]},
        file="<broken hand-back>")


def motion(scene, hand_back: bool):
    """The sapling's motion (per bone, with the audit's energy per frame)."""
    scene = replace(scene, quality=replace(scene.quality, hand_back=hand_back))
    rigged = rig_scene(scene, grow(scene), None, None)
    got = {}
    simulate(solver_kind("planar"), rigged, scene, on_tree=lambda i, m, e: got.update({i: m}))
    return got[0]


@pytest.fixture(scope="module")
def runs():
    scene = blast_scene()
    bake = bake_scene(scene)
    back, stay = motion(scene, True), motion(scene, False)
    (came,) = [e for e in bake.trees[0].info["events"]
               if e["kind"] == "tier" and e["detail"].startswith("to linear")]
    return bake, back, stay, round(came["time"] * bake.fps)


def test_the_broken_tree_comes_back(runs):
    bake, back, stay, f_back = runs
    solver = bake.trees[0].info["solver"]
    assert solver.startswith("linear, then reference from ") and \
        solver.endswith("then linear from 3.250 s (back in the linear range)"), solver
    assert bake.meta["stats"]["broken"] == 10 and bake.meta["stats"]["returned"] == 1
    assert bake.meta["stats"]["reference"]["returned_broken"] == 1
    assert any(n.endswith("1 of them without the parts that broke off, which lie where they "
                          "came to rest") for n in bake.meta["notes"]), bake.meta["notes"]
    assert 0.6 < f_back / bake.fps < bake.times[-1] - 0.3


def test_what_broke_off_stays_where_it_lay(runs):
    _bake, back, stay, f_back = runs
    rest = stay.pivots[f_back]
    still = np.all(back.pivots[f_back:] == back.pivots[f_back], axis=(0, 2)) & np.all(
        back.quaternions[f_back:] == back.quaternions[f_back], axis=(0, 2))
    fallen = np.nonzero(still)[0]
    assert len(fallen) >= 10  # the ten broken joints and what hung on them
    # exactly the reference's pose at the return, and it was lying still there
    assert np.array_equal(back.pivots[f_back:, fallen], np.broadcast_to(
        rest[fallen], back.pivots[f_back:, fallen].shape))
    assert np.abs(stay.pivots[f_back:, fallen] - rest[fallen]).max() < 0.01  # m
    assert np.array_equal(back.quaternions[f_back:, fallen],
                          np.broadcast_to(stay.quaternions[f_back, fallen],
                                          back.quaternions[f_back:, fallen].shape))


def test_the_standing_part_goes_on_as_the_reference_would(runs):
    bake, back, stay, f_back = runs
    height = bake.trees[0].height
    off = np.linalg.norm(back.pivots - stay.pivots, axis=-1).max(1) / height
    assert off[:f_back].max() == 0.0  # the reference's frames
    assert off[f_back] < 1e-9  # its state at the return (the same hinge angles)
    # no jump: one linear step from the reference's state
    assert off[f_back + 1] < 2e-4, off[f_back + 1]
    # then the linear tier at 1/24 s against the reference at 1/480 s
    # (0.06 % of the height measured); a wrong prestress would sag or lift
    # the standing tree by centimetres
    assert off.max() < 2e-3, off.max()


def test_the_audit_carries_the_fallen_parts_energy(runs):
    bake, back, stay, f_back = runs
    # the fallen parts' energy stays in the tree's record: no step at the return
    assert abs(back.energy[f_back] - stay.energy[f_back]) < 1e-4 * stay.energy[f_back]
    assert np.abs(back.energy[f_back:] - stay.energy[f_back:]).max() < 1e-3 * stay.energy.max()
    assert abs(back.work[-1] - stay.work[-1]) < 1e-3 * stay.work[-1]
    assert bake.meta["energy"]["sapling"]["max_gain_fraction"] < 0.02


def test_a_pruned_rig_keeps_its_standing_bones_as_they_were():
    scene = blast_scene()
    (tree,) = grow(scene)
    rig = build_rig(tree.model)
    standing = np.ones(rig.n_bones, dtype=bool)
    gone = rig.n_bones - 3  # a bone near the top and all it carries
    for b in range(gone, rig.n_bones):
        if b == gone or not standing[rig.bone_parent[b]]:
            standing[b] = False
    part = pruned_rig(rig, standing)
    keep = np.nonzero(standing)[0]
    assert part.n_bones == len(keep)
    assert np.array_equal(part.mass, rig.mass[keep]) and np.array_equal(part.k, rig.k[keep])
    assert np.array_equal(keep[part.bone_parent[part.bone_parent >= 0]],
                          rig.bone_parent[keep][part.bone_parent >= 0])
    assert (part.bone_parent < np.arange(part.n_bones)).all()  # parents first
    # every segment of a standing bone keeps its bone; the others have none
    assert np.array_equal(part.seg_bone >= 0, standing[rig.seg_bone])
    assert np.array_equal(keep[part.seg_bone[part.seg_bone >= 0]],
                          rig.seg_bone[part.seg_bone >= 0])
    assert sorted(b for limb in part.limbs for b in limb.bones) == list(range(part.n_bones))


def test_the_set_a_standing_part_keeps_is_the_same_on_both_engines():
    """The prestress handed over (-k x the reference's spring reference) is
    the linear tier's own for a whole tree (two derivations of gravity's
    torques on the grown shape: MuJoCo's bias forces and the joint-space
    sums), and the reference starts a tree that keeps a set from it."""
    from treebake.sim import reference
    from treebake.sim.linear import LinearTier
    from treebake.sim.loads import SceneLoads

    scene = blast_scene()
    loads = SceneLoads(scene)
    (tree,) = rig_scene(scene, grow(scene), None).trees
    engine = reference.ReferenceEngine([tree], scene, scene.quality, loads)
    handed = -(engine.k * engine.springref).reshape(-1)
    linear = LinearTier([tree], scene, scene.quality, loads, 1)
    own = linear.model.tau_g0
    assert np.abs(own).max() > 0.1  # N m: gravity loads the sapling's joints (0.39 at most)
    assert np.abs(handed - own).max() < 1e-6 * np.abs(own).max()
    kept = replace(tree, hold=0.5 * own)
    again = reference.ReferenceEngine([kept], scene, scene.quality, loads)
    assert np.allclose(-(again.k * again.springref).reshape(-1), 0.5 * own, rtol=1e-12,
                       atol=1e-12)
    assert np.array_equal(LinearTier([kept], scene, scene.quality, loads, 1).model.hold,
                          0.5 * own)


def test_a_standing_part_can_leave_again_and_break_on():
    """After the return, a 45 m/s gust sends the standing sapling back to
    the reference (its own rig and set): it breaks on there, only joints
    that still stood break, and what fell first stays where it lay."""
    scene = parse_scene({
        "name": "blast-then-gust", "duration": 6.0, "fps": 24,
        "tree": [{"grammar": str(grammars_folder() / "sapling.lsys"), "position": [9.0, 2.0]}],
        "explosion": [{"position": [0.0, 0.0, 1.0], "time": 0.5, "charge": 10.0}],
        "gust": [{"position": [{"time": 4.0, "value": [0.0, 2.0, 1.5]},
                               {"time": 6.0, "value": [18.0, 2.0, 1.5]}],
                  "speed": 45.0, "radius": 4.0, "profile": "bump"}]},
        file="<broken hand-back, then a gust>")
    bake = bake_scene(scene)
    (tree,) = bake.trees
    tiers = [e for e in tree.info["events"] if e["kind"] == "tier"]
    assert [e["detail"][:12] for e in tiers] == ["to reference", "to linear: b", "to reference"]
    back, left = tiers[1]["time"], tiers[2]["time"]
    assert back < left
    broke = [e for e in tree.info["events"] if e["kind"] == "broke"]
    first = [e["segment"] for e in broke if e["time"] < back]
    later = [e["segment"] for e in broke if e["time"] > left]
    assert len(first) == 10 and later  # it broke on in the reference
    assert len(set(first + later)) == len(first) + len(later)  # no joint broke twice
    # what fell first (every segment outboard of a first break) lies still to the end
    f_back = round(back * bake.fps)
    ends = segment_ends(tree, np.arange(tree.n_segments))
    still = np.all(ends[f_back:] == ends[f_back], axis=(0, 2))
    assert still.sum() >= 10
    assert bake.meta["energy"]["sapling"]["max_gain_fraction"] < 0.02

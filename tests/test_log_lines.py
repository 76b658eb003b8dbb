"""What a bake's log says (issue 38 item 6: logs a person reads): the
reference's description of its model stays in the bake's notes, not in every
log; an uprooting says it is the root joint that the count of broken joints
includes."""

from treebake.pipeline import bake_scene
from treebake.scene import load_scene
from treebake.sim.notes import DESCRIPTIONS


def test_the_log_leaves_the_models_description_to_the_bakes_notes(root):
    scene = load_scene(root / "presets" / "boxes.toml", {"duration": 1.5})
    lines: list[str] = []
    bake = bake_scene(scene, log=lines.append)
    notes = bake.meta["notes"]
    described = [n for n in notes if n.startswith(DESCRIPTIONS)]
    # both descriptions the reference writes (engine_notes) are still in the bake
    assert len(described) == 2 and described[0].startswith("reference: MuJoCo ")
    assert "no twist" in described[1]
    assert not [x for x in lines if x.startswith(DESCRIPTIONS)], lines
    assert [n for n in notes if n not in described and n in lines]  # the others are logged
    uprooted = [x for x in lines if "uprooted" in x]
    assert uprooted and all("(its root joint broke)" in x for x in uprooted), lines

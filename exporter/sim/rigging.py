"""The rig stage: every grown tree rigged at its quality level, with what
the scene does to it, and whether it needs simulating at all."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..grow import GrownTree
from ..quality import QUALITIES, Quality
from ..rig import RigOptions, build_rig
from ..scene import Scene
from .common import SimTree
from .loads import SceneLoads
from .projectiles import projectile_reaches


@dataclass
class RiggedScene:
    """The scene's trees as the simulation takes them (in scene order), each
    tree's quality level, why each static one is left out (by name), and how
    many trees each rule left out or coarsened ("unseen", "far",
    "no_force")."""

    trees: list[SimTree]
    qualities: list[Quality]
    static: dict[str, str]
    culled: dict[str, int]

    @property
    def active(self) -> list[SimTree]:
        return [t for t in self.trees if t.active]


def rig_scene(scene: Scene, grown: list[GrownTree], loads: SceneLoads,
              quality: Quality | None = None, log=None) -> RiggedScene:
    """Rig every tree, give it its quality (`quality` overrides every
    tree's), and decide which need simulating. Static: trees the camera
    never sees (culling.py) and trees that no force reaches and start at
    rest (the prestress balances gravity). Trees the camera only ever sees
    from beyond `far` m get its `far_quality`."""
    log = log or (lambda msg: None)
    cuts = {c.tree: c for c in scene.cuts}
    pulls: dict[int, list] = {}
    for p in scene.pulls:
        pulls.setdefault(p.tree, []).append(p)
    bounds = [g.model.bounds() for g in grown]
    centres = np.array([0.5 * (lo + hi) for lo, hi in bounds])
    radii = np.array([0.5 * float(np.linalg.norm(hi - lo)) for lo, hi in bounds])
    seen = np.ones(len(grown), dtype=bool)
    far = np.zeros(len(grown), dtype=bool)
    if scene.camera is not None:
        from ..culling import cull

        c = cull(scene.camera, scene.duration, centres, radii)
        seen, far = c.seen, c.nearest > scene.camera.far
    out = RiggedScene([], [], {}, {"unseen": 0, "far": 0, "no_force": 0})
    for i, g in enumerate(grown):
        m = g.model
        q = quality or (QUALITIES[g.spec.quality] if g.spec.quality else scene.quality)
        if far[i] and quality is None and g.spec.quality is None and not scene.projectiles:
            q = QUALITIES[scene.camera.far_quality]
            out.culled["far"] += int(seen[i])
        lo, hi = bounds[i]
        reached = (not scene.prestress or i in cuts or i in pulls
                   or loads.quiet_after(centres[i], 0.5 * float(np.linalg.norm(hi[:2] - lo[:2])),
                                        float(hi[2])) > 0
                   or (scene.projectiles and projectile_reaches(scene, m)))
        if not seen[i]:
            out.static[m.name] = "outside the camera's view for the whole shot"
            out.culled["unseen"] += 1
        elif not reached:
            out.static[m.name] = "no force reaches it (gravity is balanced by the prestress)"
            out.culled["no_force"] += 1
        rig = build_rig(m, RigOptions(min_bone_length=q.bone_length * max(m.height, 1e-3)))
        out.trees.append(SimTree(m.name, rig, q.planes,
                                 loads.dominant_direction(m.points[0], cuts.get(i),
                                                          pulls.get(i, [])),
                                 cuts.get(i), pulls.get(i, []), active=bool(reached and seen[i])))
        out.qualities.append(q)
    if scene.camera is not None:
        c = out.culled
        log(f"culling: {c['unseen']} trees never in view, {c['far']} far "
            f"({scene.camera.far_quality}), {c['no_force']} reached by no force")
    return out

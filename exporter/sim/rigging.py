"""The rig stage: every grown tree rigged at its quality level, with what
the scene does to it, and whether it needs simulating at all."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..forked import forked_map
from ..grow import GrownTree
from ..quality import QUALITIES, Quality
from ..rig import Rig, RigOptions, build_rig
from ..scene import Scene
from .common import SimTree
from .loads import SceneLoads
from .projectiles import projectile_reaches


@dataclass
class RiggedScene:
    """The scene's trees as the simulation takes them (in scene order), each
    tree's quality level, why each static one is left out (by name), how
    many trees each rule left out or coarsened ("unseen", "far",
    "no_force"), and the scene's loads (its wind synthesised over the box
    the trees stand in, widened by MARGIN)."""

    trees: list[SimTree]
    qualities: list[Quality]
    static: dict[str, str]
    culled: dict[str, int]
    loads: SceneLoads


MARGIN = 20.0  # m around the trees where the wind's turbulence is synthesised


def rig_scene(scene: Scene, grown: list[GrownTree], quality: Quality | None = None,
              log=None, workers: int = 1) -> RiggedScene:
    """Rig every tree, give it its quality (`quality` overrides every
    tree's), and decide which need simulating. Static: trees the camera
    never sees (culling.py) and trees that no force reaches and start at
    rest (the prestress balances gravity). Trees the camera only ever sees
    from beyond `far` m get its `far_quality`. `workers` processes share
    the rigging (forked.py); the rigs are the same with any number."""
    box = [g.bounds for g in grown]  # (lo, hi) m per tree
    height = [max(g.height, 1e-3) for g in grown]
    seen, far = np.ones(len(grown), dtype=bool), np.zeros(len(grown), dtype=bool)
    if scene.camera is not None:  # which trees it ever sees, and only from afar (culling.py)
        from ..culling import cull

        drawn = [g.model.drawn_bounds() for g in grown]  # twigs are seen too
        c = cull(scene.camera, scene.duration, np.array([0.5 * (lo + hi) for lo, hi in drawn]),
                 np.array([0.5 * float(np.linalg.norm(hi - lo)) for lo, hi in drawn]))
        seen, far = c.seen, c.nearest > scene.camera.far
    lo, hi = np.min([b[0] for b in box], axis=0), np.max([b[1] for b in box], axis=0)
    loads = SceneLoads(scene, np.array([lo[:2] - MARGIN, hi[:2] + MARGIN]))
    cuts = {c.tree: c for c in scene.cuts}
    pulls: dict[int, list] = {}
    for p in scene.pulls:
        pulls.setdefault(p.tree, []).append(p)
    reached = [not scene.prestress or i in cuts or i in pulls
               or loads.quiet_after(0.5 * (b[0] + b[1]), 0.5 * float(np.linalg.norm(
                   b[1][:2] - b[0][:2])), float(b[1][2])) > 0
               or (bool(scene.projectiles) and projectile_reaches(scene, g.model))
               for i, (g, b) in enumerate(zip(grown, box))]
    direction = [loads.dominant_direction(g.model.points[0], cuts.get(i), pulls.get(i, []))
                 for i, g in enumerate(grown)]
    out = RiggedScene([], [], {}, {"unseen": 0, "far": 0, "no_force": 0}, loads)
    for i, g in enumerate(grown):
        q = quality or (QUALITIES[g.spec.quality] if g.spec.quality else scene.quality)
        if far[i] and quality is None and g.spec.quality is None and not scene.projectiles:
            q = QUALITIES[scene.camera.far_quality]
            out.culled["far"] += int(seen[i])
        if not seen[i]:
            out.static[g.model.name] = "outside the camera's view for the whole shot"
            out.culled["unseen"] += 1
        elif not reached[i]:
            out.static[g.model.name] = "no force reaches it (gravity is balanced by the prestress)"
            out.culled["no_force"] += 1
        out.qualities.append(q)

    def rigged(i: int) -> Rig:
        try:
            rig = build_rig(grown[i].model, RigOptions(
                min_bone_length=out.qualities[i].bone_length * height[i]))
        except InputError as exc:  # a tree the rig cannot take: say whose grammar it is
            raise InputError(f"{grown[i].spec.grammar}: {exc}") from None
        rig.model = None  # the grown tree's, put back below: not sent back from a worker
        return rig

    for i, (g, rig) in enumerate(zip(grown, forked_map(rigged, range(len(grown)), workers))):
        rig.model = g.model
        out.trees.append(SimTree(g.model.name, rig, out.qualities[i].planes, direction[i],
                                 cuts.get(i), pulls.get(i, []),
                                 active=bool(reached[i] and seen[i])))
    if log is None:
        return out
    if scene.camera is not None:
        c = out.culled
        log(f"culling: {c['unseen']} trees never in view, {c['far']} far "
            f"({scene.camera.far_quality}), {c['no_force']} reached by no force")
    active = [t for t in out.trees if t.active]
    log(f"{len(grown):,} tree{'' if len(grown) == 1 else 's'}, {len(active):,} simulated, "
        f"{sum(t.rig.n_bones for t in active):,} bones, quality {scene.quality.name}")
    return out

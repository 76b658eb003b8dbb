"""The linear tier's tree factorization (sim/lowrank.py) against dense
numpy solves on random tree-structured systems: long chains (many solve
blocks), branched trees with limbs (the masked couplings across them) and
several trees at once."""

from __future__ import annotations

import numpy as np
import pytest
from treebake.sim.lowrank import BLOCK, LowRankFactor, TreeMatrix

R = 5  # generator rank; the first KEEP components couple across limbs
KEEP = 3


def random_tree(rng, trunks: int, trunk_length: int, branching: bool):
    """Parents (parents first), limbs (dof lists, base first) and each
    dof's limb: `trunks` root limbs of `trunk_length` dofs, with branches
    (and twigs on them) if `branching`."""
    parent, limbs, limb_of = [], [], []

    def limb(p, length):
        out = []
        for _ in range(length):
            parent.append(p)
            limb_of.append(len(limbs))
            p = len(parent) - 1
            out.append(p)
        limbs.append(np.array(out))
        return out

    for _ in range(trunks):
        trunk = limb(-1, trunk_length)
        if branching:
            for a in trunk[1::max(1, trunk_length // 6)]:
                for b in limb(a, int(rng.integers(1, 2 * BLOCK)))[::7]:
                    limb(b, int(rng.integers(1, 5)))
    return np.array(parent), limbs, np.array(limb_of)


def dense_of(parent, limb_of, u, v, rng):
    """The matrix the generators stand for, built entry by entry along each
    dof's path to its root (independently of TreeMatrix.dense), with a
    diagonal that makes it strictly diagonally dominant (so SPD)."""
    n = len(parent)
    a = np.zeros((n, n))
    for j in range(n):
        i = parent[j]
        while i >= 0:
            vj = v[j] if limb_of[i] == limb_of[j] else np.where(np.arange(R) < KEEP, v[j], 0)
            a[i, j] = a[j, i] = u[i] @ vj
            i = parent[i]
    diag = np.abs(a).sum(1) + rng.uniform(0.05, 1.0, size=n)
    return a + np.diag(diag), diag


@pytest.mark.parametrize("trunks, length, branching", [
    (1, 3 * BLOCK + 17, False),  # one long chain: several blocks in a row
    (1, BLOCK, False),  # exactly one block
    (1, 40, True),  # a branched tree: limbs of up to 2 blocks, twigs
    (3, 2 * BLOCK + 5, True),  # several trees, long trunks, branches
])
def test_solve_matches_a_dense_solve(trunks, length, branching):
    rng = np.random.default_rng(trunks * 1000 + length)
    parent, limbs, limb_of = random_tree(rng, trunks, length, branching)
    n = len(parent)
    # entries small against the diagonal's dominance margin keep A well
    # conditioned; the dense solve is then a truth to 1e-10
    u = rng.normal(size=(n, R)) / np.sqrt(n)
    v = rng.normal(size=(n, R)) / np.sqrt(n)
    a, diag = dense_of(parent, limb_of, u, v, rng)
    cut = np.array([p < 0 or limb_of[p] != limb_of[j] for j, p in enumerate(parent)])
    matrix = TreeMatrix(parent, diag, u, v, cut, np.arange(R) < KEEP, limbs)
    assert np.allclose(matrix.dense(), a, rtol=0, atol=1e-14)
    factor = LowRankFactor(matrix)
    for _ in range(2):
        b = rng.normal(size=n)
        assert np.allclose(factor.solve(b), np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)


def test_an_indefinite_matrix_is_refused():
    parent = np.array([-1, 0, 1])
    u = np.eye(3)[:, :R] if R <= 3 else np.pad(np.eye(3), ((0, 0), (0, R - 3)))
    v = 2.0 * u[[1, 2, 0]]  # u_0 . v_1 = 2 against a diagonal of 1
    matrix = TreeMatrix(parent, np.ones(3), u, v, np.array([True, False, False]),
                        np.arange(R) < KEEP, [np.arange(3)])
    with pytest.raises(np.linalg.LinAlgError):
        LowRankFactor(matrix)


def deep_system(tmp_path, segments: int, count: int = 2):
    """JointSpace of `count` trees (10 m apart) of a stem of `segments`
    segments with a twig every 10: deeper than EXPLICIT_DEPTH."""
    from treebake.grow import grow
    from treebake.quality import QUALITIES
    from treebake.scene import parse_scene
    from treebake.sim.common import Bones
    from treebake.sim.joint_space import JointSpace
    from treebake.sim.layout import ChainLayout
    from treebake.sim.loads import SceneLoads
    from treebake.sim.rigging import rig_scene

    path = tmp_path / "deep.lsys"
    steps = segments // 10
    path.write_text(f"iterations: {steps}\naxiom: !(0.05)A({steps})\n"
                    f"A(n) : n > 0 -> F(0.02)F(0.02)[+(40)!(0.01)F(0.05)F(0.05)]"
                    f"{'F(0.02)' * 8}A(n-1)\n")
    trees = [{"grammar": str(path), "position": [10.0 * i, 0.0]} for i in range(count)]
    scene = parse_scene({"tree": trees, "wind": {"speed": 5.0}}, file="<test>")
    sim = rig_scene(scene, grow(scene), QUALITIES["final"]).trees
    bones = Bones.of(sim)
    layout = ChainLayout.of(sim, bones.offsets, bones.pivot0, bones.tip0)
    return JointSpace(bones, layout, SceneLoads(scene).g, 0.01, 1e-4)


def test_joint_space_of_a_deep_tree_solves_as_its_dense_matrix(tmp_path):
    """A stem of 300 bones with twigs, two trees: the low-rank path, against
    np.linalg.solve of the matrices written entry by entry (JointSpace.dense)."""
    from treebake.sim.joint_space import EXPLICIT_DEPTH

    js = deep_system(tmp_path, 300)
    assert js.deep and 2 * 300 > EXPLICIT_DEPTH
    mass, damping, stiffness = js.dense()
    a = mass + 0.01 * damping + 1e-4 * stiffness
    b = np.random.default_rng(5).normal(size=js.n)
    assert isinstance(js.factor, LowRankFactor)
    assert np.allclose(js.factor.solve(b), np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    # M alone (no stiffness) of a thin 300-bone stem has a condition number
    # near 2e10: as backward-stable as numpy's LU (residuals alike), and the
    # two solutions as close as that condition allows
    x, ref = js.mass_factor.solve(b), np.linalg.solve(mass, b)
    assert np.abs(mass @ x - b).max() <= 4 * max(np.abs(mass @ ref - b).max(), 1e-12)
    assert np.abs(x - ref).max() <= 1e-6 * np.abs(ref).max()


def test_both_factors_bake_the_same_motion(tmp_path, monkeypatch):
    """A 120-bone pole pulled and released: the explicit factor and the
    low-rank one (forced by lowering EXPLICIT_DEPTH) give the same motion to
    rounding."""
    from simkit import bake_text
    from treebake.sim import joint_space

    grammar = ("density: 800\nmodulus: 8e9\ndamping: 0.01\ndrag: 0\nleaf drag: 0\n"
               "iterations: 12\naxiom: !(0.05)A(12)\n"
               f"A(n) : n > 0 -> {'F(0.2/12)' * 10}A(n-1)\n")
    pull = [{"tree": 0, "force": [40.0, 0, 0], "release": 0.5, "at": 0.6}]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    explicit = bake_text(tmp_path / "a", grammar, duration=1.0, fps=60, pull=pull)
    monkeypatch.setattr(joint_space, "EXPLICIT_DEPTH", 10)
    low_rank = bake_text(tmp_path / "b", grammar, duration=1.0, fps=60, pull=pull)
    p, q = explicit.trees[0].positions, low_rank.trees[0].positions
    assert np.abs(p - p[0]).max() > 5e-3  # it moved
    assert np.abs(p - q).max() < 1e-7

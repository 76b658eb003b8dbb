"""forked.py: the stages before the simulation spread over forked workers
give the same results, in the same order, as one process; a bake grown
and rigged in workers is the same bytes."""

import os

import pytest
from test_streaming import forest

from treebake import forked, grow
from treebake.bake_file import save_bake
from treebake.pipeline import bake_scene
from treebake.sim import rigging


def _square_and_pid(x):
    return x * x, os.getpid()


def test_results_come_in_order_from_other_processes():
    out = forked.forked_map(_square_and_pid, range(300), workers=2)
    assert [v for v, _ in out] == [x * x for x in range(300)]
    assert os.getpid() not in {p for _, p in out}  # the workers computed them


def test_few_items_stay_in_this_process():
    assert {p for _, p in forked.forked_map(_square_and_pid, range(10), workers=2)} \
        == {os.getpid()}


def test_the_first_error_in_the_items_order_is_raised():
    def fails(x):
        if x in (170, 260):
            raise ValueError(f"item {x}")
        return x

    with pytest.raises(ValueError, match="item 170"):
        forked.forked_map(fails, range(300), workers=2)


def test_a_forest_grown_and_rigged_in_workers_bakes_the_same_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(forked, "PER_TASK", 8)  # 31 trees: four tasks, both workers
    calls = []
    real = forked.forked_map

    def spy(fn, items, workers):
        calls.append((len(items), workers))
        return real(fn, items, workers)

    for module in (grow, rigging):
        monkeypatch.setattr(module, "forked_map", spy)
    scene = forest(count=30, duration=0.3)
    one = save_bake(bake_scene(scene, workers=1), tmp_path / "one.npz")
    two = save_bake(bake_scene(scene, workers=2), tmp_path / "two.npz")
    assert one.read_bytes() == two.read_bytes()
    assert calls.count((31, 2)) == 2  # grown and rigged by the workers

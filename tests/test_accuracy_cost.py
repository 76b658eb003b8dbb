"""How `treebake accuracy` charges a setting's cost: one-off costs (the
first import of an engine) must not land on whichever setting runs first."""

from treebake import accuracy


def test_a_cheap_bake_is_charged_its_least_run_not_its_first(monkeypatch):
    costs = iter([0.30, 0.10, 0.12, 0.11, 0.13, 0.10])  # CPU s of each run
    now = [0.0]
    calls = []

    def fake_bake_scene(scene, **kw):
        calls.append(kw)
        now[0] += next(costs)
        return f"bake {len(calls)}"

    monkeypatch.setattr(accuracy, "bake_scene", fake_bake_scene)
    bake, cpu = accuracy._bake(None, accuracy.SETTINGS["draft"], clock=lambda: now[0])
    assert abs(cpu - 0.10) < 1e-12  # not the first run's 0.30
    assert bake == "bake 2"  # the bake that the cost belongs to
    assert len(calls) == accuracy.MAX_REPEATS  # 0.76 s spent: still under REPEAT_BELOW


def test_a_dear_bake_runs_once(monkeypatch):
    now = [0.0]
    calls = []

    def fake_bake_scene(scene, **kw):
        calls.append(kw)
        now[0] += 2.5
        return "bake"

    monkeypatch.setattr(accuracy, "bake_scene", fake_bake_scene)
    _bake, cpu = accuracy._bake(None, accuracy.SETTINGS["final"], clock=lambda: now[0])
    assert cpu == 2.5 and len(calls) == 1  # a long bake's one-off costs are noise

"""tests/golden/regenerate.py: one golden at a time, `treebake diff` shown,
nothing overwritten without a yes."""

import sys

import numpy as np
from conftest import ROOT

sys.path.insert(0, str(ROOT / "tests" / "golden"))
import regenerate  # noqa: E402


def test_regenerate_shows_the_diff_and_asks_before_replacing(tmp_path, monkeypatch, capsys):
    from treebake.bake_file import load_bake, save_bake

    monkeypatch.setattr(regenerate, "HERE", tmp_path)
    assert regenerate.regenerate("sapling-box", assume_yes=False) == "new"
    golden = tmp_path / "sapling-box.npz"
    assert regenerate.regenerate("sapling-box", assume_yes=False) == "unchanged"
    moved = load_bake(golden)  # as if the committed golden came from other physics
    moved.trees[0].positions[5:, 10] += np.float32(0.01)
    save_bake(moved, golden)
    before = golden.read_bytes()
    monkeypatch.setattr(sys.stdin, "isatty", lambda: True, raising=False)
    capsys.readouterr()
    assert regenerate.regenerate("sapling-box", False, ask=lambda q: "n") == "kept"
    out = capsys.readouterr().out
    assert "DIFFERENT" in out and "first frame past tolerance: 6" in out  # frame 5 (0-based): 6
    assert golden.read_bytes() == before  # not overwritten
    assert regenerate.regenerate("sapling-box", False, ask=lambda q: "y") == "replaced"
    assert golden.read_bytes() != before
    assert not list(tmp_path.glob(".*"))  # no temporaries left

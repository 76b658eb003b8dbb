"""Golden bakes: fresh bakes of tests/golden's scenes diff to within noise of
the committed ones (`treebake diff`). A failure here means motion changed:
if that was meant, regenerate (python tests/golden/regenerate.py) and say
why in the commit."""

import sys

import pytest
from conftest import ROOT
from treebake.bake_file import save_bake
from treebake.cli import main
from treebake.pipeline import bake_scene

sys.path.insert(0, str(ROOT / "tests" / "golden"))
from regenerate import GOLDEN, golden_scene


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_fresh_bake_matches_the_golden_one(name, tmp_path, capsys):
    fresh = save_bake(bake_scene(golden_scene(name)), tmp_path / f"{name}.npz")
    golden = ROOT / "tests" / "golden" / f"{name}.npz"
    code = main(["diff", str(golden), str(fresh), "--position-tolerance", "1e-4",
                 "--angle-tolerance", "0.01"])
    report = capsys.readouterr().out
    assert code == 0, report

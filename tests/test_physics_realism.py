"""Realism that can be measured: each species' first sway frequency, from a
pull-and-release test in the simulator (the field method), against
docs/physics-sources.md section 1.3. Only spruce's band rests on field data
(Milne 1991, scaled by DBH/H^2): that is the one realism test. The other
species' bands are cantilever estimates with published wood properties
(the document's "[D]", unverified): plausibility checks, named as such.

Damping is NOT tested for realism here: each grammar sets its own
first-mode damping ratio (`damping:`), and the field band's low end (0.08,
Moore & Maguire 2005) is the value several grammars set, so "the measured
ratio is inside the band" only says the solver reproduces its input. That
is what the damping test checks, and says: a solver check. Whether the
inputs are realistic is a data question, checked against the field band
without the simulator."""

import functools
import re

import pytest
from conftest import GRAMMARS
from treebake.sway import pull_release

FIELD_BANDS = {"spruce": (0.3, 0.7)}  # f1 Hz: Milne 1991 field data, scaled
ESTIMATE_BANDS = {  # f1 Hz: cantilever estimates ("[D]"), not measurements
    "oak": (0.3, 1.0),
    "willow": (0.3, 0.9),
    "palm": (0.15, 0.45),
    "bamboo": (0.15, 0.5),
    "sapling": (0.7, 2.0),
    "forest/conifer": (0.3, 0.7),  # as spruce (18 m, DBH 0.3 m)
    "forest/broadleaf": (0.3, 1.0),  # as oak (16 m, DBH 0.46 m)
    "forest/birch": (0.2, 0.7),  # slender birch (16 m, DBH 0.2 m), section 1.2
}
INTACT_CROWN_DAMPING = (0.08, 0.5)  # Moore & Maguire 2005, intact crowns (field data)
NO_DAMPING_DATA = {"palm", "bamboo"}  # no field data: the grammars take a low value
# measured ratio minus the grammar's: README's table (bench/sway.py) has it
# within 0.03 (bamboo: 0.05 set, 0.08 measured, the logarithmic decrement of
# a culm clump's beating modes); 0.04 leaves room for machine noise only
DAMPING_SOLVER_TOLERANCE = 0.04


@functools.cache
def measured(species: str):
    return pull_release(GRAMMARS / f"{species}.lsys")


def grammar_damping(species: str) -> float:
    text = (GRAMMARS / f"{species}.lsys").read_text()
    return float(re.search(r"^damping:\s*([0-9.eE+-]+)", text, re.M).group(1))


@pytest.mark.parametrize("species", sorted(FIELD_BANDS))
def test_first_sway_frequency_matches_field_data(species):
    lo, hi = FIELD_BANDS[species]
    r = measured(species)
    assert lo <= r.frequency <= hi, f"{species}: f1 = {r.frequency:.3f} Hz"
    assert 0.003 * r.height < r.deflection < 0.03 * r.height  # pulled ~1 %, as in the field
    # (no check against the rig's own Rayleigh estimate: 0.5x-2x could not fail,
    # and the estimate is the code under test, not an independent truth)


@pytest.mark.parametrize("species", sorted(ESTIMATE_BANDS))
def test_first_sway_frequency_is_plausible(species):
    """Plausibility, not realism: the bands are estimates (see module doc)."""
    lo, hi = ESTIMATE_BANDS[species]
    r = measured(species)
    assert lo <= r.frequency <= hi, f"{species}: f1 = {r.frequency:.3f} Hz"
    # the pull moved the stem top by about 1 % of the height, as in field tests
    assert 0.003 * r.height < r.deflection < 0.03 * r.height


@pytest.mark.parametrize("species", sorted({**FIELD_BANDS, **ESTIMATE_BANDS}))
def test_damping_ratio_is_the_grammars_solver_check(species):
    """A solver check, not realism: the measured first-mode damping ratio
    is the one the grammar asks for."""
    r = measured(species)
    assert r.damping == pytest.approx(grammar_damping(species), abs=DAMPING_SOLVER_TOLERANCE), \
        f"{species}: measured {r.damping:.3f}, grammar {grammar_damping(species)}"


@pytest.mark.parametrize("species", sorted(set(FIELD_BANDS) | set(ESTIMATE_BANDS)
                                           - NO_DAMPING_DATA))
def test_grammar_damping_inside_field_data(species):
    """Data, not code: the ratio a grammar sets lies in the intact-crown
    field band."""
    lo, hi = INTACT_CROWN_DAMPING
    assert lo <= grammar_damping(species) <= hi

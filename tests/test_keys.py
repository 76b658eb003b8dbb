"""Keyed curves (issue 41, item 1): step and linear exactly, smooth (the
monotone cubic) C1 and never past its keys, headings the short way round,
vectors per component, the integral and rate in closed form against
numerical truth, and the culling bound on a keyed path."""

import numpy as np
import pytest
from treebake.keys import Keyed, always_zero, largest, value_at

KEYS = ((0.0, 2.0, 4.0, 7.0), (0.0, 10.0, 4.0, 4.0))


def curve(how, times=KEYS[0], values=KEYS[1], **kw):
    return Keyed(times, values, how, **kw)


def test_step_holds_each_key_until_the_next():
    c = curve("step")
    t = np.array([-1.0, 0.0, 1.999, 2.0, 3.0, 4.0, 6.9, 7.0, 50.0])
    assert c.at(t).tolist() == [0.0, 0.0, 0.0, 10.0, 10.0, 4.0, 4.0, 4.0, 4.0]


def test_linear_is_exact_between_and_at_keys_and_holds_outside():
    c = curve("linear")
    t = np.array([-3.0, 0.0, 0.5, 1.0, 2.0, 3.0, 3.5, 4.0, 5.5, 7.0, 9.0])
    # by hand: 0 -> 10 over 2 s (5/s), 10 -> 4 over 2 s (-3/s), then flat
    assert c.at(t).tolist() == [0.0, 0.0, 2.5, 5.0, 10.0, 7.0, 5.5, 4.0, 4.0, 4.0, 4.0]
    assert c.at(3.0) == 7.0 and isinstance(c.at(3.0), float)
    assert c.derivative(np.array([-1.0, 1.0, 3.0, 5.0, 8.0])).tolist() == [0, 5, -3, 0, 0]


RISING = ((0.0, 1.0, 3.0, 4.0, 6.0), (0.0, 2.0, 10.0, 11.0, 20.0))  # slopes > 0 inside


@pytest.mark.parametrize("keys", [KEYS, RISING], ids=["turning", "rising"])
def test_smooth_passes_every_key_is_c1_and_never_overshoots(keys):
    c = curve("smooth", *keys)
    assert c.at(np.array(keys[0])).tolist() == list(keys[1])
    h = 1e-6
    for tk in keys[0]:
        left = (c.at(tk) - c.at(tk - h)) / h
        right = (c.at(tk + h) - c.at(tk)) / h
        assert left == pytest.approx(right, abs=1e-4), tk  # no kink at any key
        assert c.derivative(tk) == pytest.approx(right, abs=1e-4)
    # flat at both ends (the holds join without a kink)
    assert c.derivative(keys[0][0]) == 0.0 and c.derivative(keys[0][-1]) == 0.0
    if keys is KEYS:  # and at the peak key
        assert c.derivative(2.0) == 0.0
    else:  # the rising keys' inner slopes are not all zero: a real test of C1
        assert min(c.derivative(np.array(keys[0][1:-1]))) > 0.5
    # monotone between keys: inside the two keys' values, every interval
    for (t0, v0), (t1, v1) in zip(zip(*keys), list(zip(*keys))[1:]):
        inner = c.at(np.linspace(t0, t1, 501))
        assert inner.min() >= min(v0, v1) and inner.max() <= max(v0, v1)
        assert np.all(np.diff(inner) * np.sign(v1 - v0) >= 0)
    # two keys: the smoothstep 3s^2 - 2s^3 between them
    two = Keyed((1.0, 3.0), (2.0, 6.0), "smooth")
    s = 0.3
    assert two.at(1.0 + 2 * s) == pytest.approx(2.0 + 4.0 * (3 * s**2 - 2 * s**3), rel=1e-12)


def test_linear_is_not_c1_which_the_smooth_check_would_see():
    # the C1 check above is able to fail: the linear curve kinks at its keys
    c = curve("linear")
    h = 1e-6
    left = (c.at(2.0) - c.at(2.0 - h)) / h
    right = (c.at(2.0 + h) - c.at(2.0)) / h
    assert abs(left - right) > 1.0


@pytest.mark.parametrize("a, b, through", [(350.0, 10.0, 0.0), (10.0, 350.0, 0.0),
                                           (-170.0, 170.0, 180.0), (90.0, 300.0, 15.0)])
@pytest.mark.parametrize("how", ["linear", "smooth"])
def test_headings_turn_the_short_way_round(a, b, through, how):
    c = Keyed((0.0, 4.0), (a, b), how, angular=True)
    mid = c.at(2.0)
    assert (mid - through) % 360.0 == pytest.approx(0.0, abs=1e-9) or \
        (mid - through) % 360.0 == pytest.approx(360.0, abs=1e-9)
    turn = (b - a + 180.0) % 360.0 - 180.0  # the short way, signed
    path = c.at(np.linspace(0.0, 4.0, 401))
    assert abs(path[-1] - path[0]) == pytest.approx(abs(turn))  # never the long way
    assert np.all(np.abs(np.diff(path)) <= abs(turn) / 100 * 1.6)
    # the end key itself is the same direction as given
    assert np.cos(np.radians(c.at(4.0))) == pytest.approx(np.cos(np.radians(b)))
    assert np.sin(np.radians(c.at(4.0))) == pytest.approx(np.sin(np.radians(b)))


def test_vectors_interpolate_per_component():
    c = Keyed((0.0, 1.0, 3.0), ((0.0, 0.0, 5.0), (2.0, -4.0, 5.0), (2.0, 0.0, 1.0)))
    assert c.at(0.5).tolist() == [1.0, -2.0, 5.0]
    assert c.at(2.0).tolist() == [2.0, -2.0, 3.0]
    assert c.at(np.array([0.5, 2.0])).tolist() == [[1.0, -2.0, 5.0], [2.0, -2.0, 3.0]]
    assert c.largest().tolist() == [2.0, 0.0, 5.0] and c.smallest().tolist() == [0.0, -4.0, 1.0]


@pytest.mark.parametrize("how", ["linear", "smooth", "step"])
def test_vectorised_in_time_equals_one_time_at_a_time(how):
    c = curve(how)
    t = np.linspace(-1.0, 8.0, 97)
    assert c.at(t).tolist() == [c.at(x) for x in t]
    assert c.derivative(t).tolist() == [c.derivative(x) for x in t]


@pytest.mark.parametrize("how", ["linear", "smooth", "step"])
def test_integral_and_rate_match_numerical_truth(how):
    c = curve(how)
    t = np.linspace(-1.0, 9.0, 200_001)
    v = c.at(t)
    quad = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    quad -= np.interp(0.0, t, quad)  # from the first key
    for x in (-1.0, 0.7, 2.0, 3.3, 6.1, 9.0):
        assert c.integral(x) == pytest.approx(np.interp(x, t, quad), abs=2e-3), x
    if how != "step":
        mid = 0.5 * (t[1:] + t[:-1])
        rate = np.diff(v) / np.diff(t)
        away = np.all(np.abs(mid[:, None] - np.array(KEYS[0])[None]) > 1e-3, axis=1)
        assert np.allclose(c.derivative(mid[away]), rate[away], atol=1e-3)


def test_constant_and_plain_parameters():
    c = Keyed.constant(3.5)
    assert c.at(np.array([-5.0, 0.0, 1e4])).tolist() == [3.5, 3.5, 3.5]
    assert c.derivative(2.0) == 0.0 and c.integral(2.0) == 7.0
    assert value_at(2.0, 5.0) == 2.0 and value_at(curve("linear"), 3.0) == 7.0
    assert largest(2.0) == 2.0 and largest(curve("smooth")) == 10.0
    assert always_zero(0.0) and always_zero(Keyed((0.0, 1.0), (0.0, 0.0)))
    assert not always_zero(Keyed((0.0, 1.0), (0.0, -1.0)))


@pytest.mark.parametrize("bad", [dict(times=(), values=()), dict(times=(1.0, 1.0)),
                                 dict(times=(2.0, 1.0)), dict(interpolation="cubic")])
def test_malformed_curves_are_refused(bad):
    args = {"times": (0.0, 1.0), "values": (0.0, 1.0), **bad}
    with pytest.raises(ValueError):
        Keyed(**args)


@pytest.mark.parametrize("how", ["linear", "smooth", "step"])
def test_closest_distance_never_exceeds_the_truth_and_is_exact_where_it_says(how):
    path = Keyed((0.0, 2.0, 5.0, 6.0), ((-30.0, 0.0), (0.0, 20.0), (40.0, -10.0), (40.0, 5.0)),
                 how)
    rng = np.random.default_rng(3)
    points = rng.uniform(-60, 60, (300, 2))
    for t0, t1 in ((0.0, 6.0), (1.0, 4.5), (2.5, 2.5), (-1.0, 10.0)):
        dense = path.at(np.linspace(t0, t1, 20_001))
        truth = np.linalg.norm(points[:, None] - dense[None], axis=2).min(axis=1)
        bound = path.closest_distance(points, t0, t1)
        assert np.all(bound <= truth + 1e-9)
        if how != "smooth":
            assert np.allclose(bound, truth, atol=0.01)

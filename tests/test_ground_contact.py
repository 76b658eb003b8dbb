"""The ground's penalty contact (sim/contact.py) on rigid debris: its
springs' energy is counted, and a part that becomes debris already in the
soil is held there, not fired out. Truth: energy conservation of a rigid
body under gravity (nothing but the ground acts)."""

import numpy as np
from treebake.sim.contact import stored_energy
from treebake.sim.debris import Debris

G = np.array([0.0, 0.0, -9.81])
MASS, LENGTH, RADIUS = 10.0, 1.0, 0.05  # kg, m, m: a stick


def _stick(z: float, vz: float = 0.0) -> tuple[Debris, dict]:
    """A debris model of one horizontal stick (along x) whose axis is at
    height z (m), falling at vz (m/s); and the pose it is added from."""
    i_rod = MASS * LENGTH**2 / 12
    inertia = np.diag([0.5 * MASS * RADIUS**2, i_rod, i_rod])[None]
    pivot0 = np.array([[0.0, 0.0, z]])
    tip0 = pivot0 + [LENGTH, 0.0, 0.0]
    com0 = 0.5 * (pivot0 + tip0)
    debris = Debris(np.array([MASS]), inertia, com0, pivot0, tip0, np.array([RADIUS]), True, G)
    pose = {"rot": np.eye(3)[None], "com": com0.copy(), "pivot": pivot0.copy(),
            "vcom": np.array([[0.0, 0.0, vz]]), "omega": np.zeros((1, 3))}
    return debris, pose


def _gravity(com, vcom, axis, start, h):
    return MASS * G[None].repeat(len(com), 0)


def _energy(debris: Debris) -> tuple[float, float]:
    """Kinetic plus gravitational energy (J), and the ground springs' (J)."""
    kinetic = 0.5 * MASS * float(debris.v[0] @ debris.v[0]) + 0.5 * float(
        debris.w[0] @ debris.ang[0])
    return kinetic + MASS * 9.81 * float(debris.x[0, 2]), float(debris.contact_energy().sum())


def test_a_stick_added_in_the_soil_is_held_there_not_thrown_out():
    # the limb's chain let it sink 0.15 m (its contact acts at tips, with
    # the tip bone's own, soft spring); as debris both its ends touch with
    # the body's whole mass: the full depth's spring would hold
    # 1/2 k d^2 = 1/2 x 10 kg x (240/s)^2 x (0.2 m)^2 = 11.5 kJ
    debris, pose = _stick(-0.15)
    debris.add(np.array([0]), pose)
    top = debris.x[0, 2]
    for _ in range(480):
        debris.step(1 / 480, _gravity)
        top = max(top, debris.x[0, 2])
    assert top - (-0.15) < 1e-3  # m: not lifted (it may settle deeper)
    assert _energy(debris)[0] - MASS * 9.81 * -0.15 < 0.01  # J: no energy made


def test_the_ground_springs_energy_closes_a_bounce():
    # dropped 0.3 m onto the ground: kinetic + gravitational energy falls
    # into the contact spring and partly comes back; with the spring's
    # energy counted the total never rises, without it the rebound reads as
    # a gain (what the energy audit saw on felled trees: 2.4 %)
    debris, pose = _stick(0.35)
    debris.add(np.array([0]), pose)
    totals, bodies = [], []
    for _ in range(480):
        debris.step(1 / 960, _gravity)
        body, spring = _energy(debris)
        bodies.append(body)
        totals.append(body + spring)
    drop = MASS * 9.81 * 0.3
    rise = max(b - min(bodies[:i + 1]) for i, b in enumerate(bodies))
    assert rise > 0.05 * drop  # the spring's energy matters
    gain = max(t - min(totals[:i + 1]) for i, t in enumerate(totals))
    assert gain < 0.01 * drop, gain  # J


def test_stored_energy_is_what_an_explicit_springs_update_conserves():
    # k = m (0.5 / dt)^2 (contact.py): 2 kg, dt = 1/480 s, 1 cm deep and
    # sinking at 1 m/s, so 1/480 m shallower an update before; at 10 m/s
    # it was above the ground then, and its spring holds nothing yet
    dt = 1 / 480
    points = np.array([[0.0, 0.0, 0.04], [0.0, 0.0, 0.2], [0.0, 0.0, 0.04]])
    e = stored_energy(points, np.array([-1.0, 0.0, -10.0]), np.full(3, 0.05),
                      np.full(3, 2.0), dt)
    k = 2.0 * 240.0**2
    assert np.allclose(e, [0.5 * k * 0.01 * (0.01 - dt), 0.0, 0.0])
    # the truth: an undamped spring stepped as the solvers step it (velocity,
    # then position) keeps 1/2 m v^2 + stored_energy exactly while the point
    # is in the ground (entering included), 1/2 k d^2 not
    m, depth, v = 2.0, 0.0, -3.0  # kg, m, m/s (v the point's upward velocity)
    exact, squared = [], []
    while True:
        v += k * depth / m * dt
        depth -= v * dt
        if depth < 0.0:
            break
        point = np.array([[0.0, 0.0, 0.05 - depth]])
        kinetic = 0.5 * m * v * v
        exact.append(kinetic + stored_energy(point, np.array([v]), np.array([0.05]),
                                             np.array([m]), dt)[0])
        squared.append(kinetic + 0.5 * k * depth**2)
    assert np.ptp(exact) < 1e-9 * exact[0]  # J
    assert np.ptp(squared) > 0.1 * squared[0]


def test_a_long_limb_landing_flat_does_not_bounce_off_faster_than_it_landed():
    # a 5 m limb of 20 bones lands flat at 11 m/s (the felled willow's
    # 9.4 kg limb hit at 11 m/s): its 40 ends touch at once, each with a
    # spring stable alone; together they must be no stiffer than one
    # spring for the whole limb, or the explicit substep pumps it (that
    # limb left at 28 m/s). Truth: a passive contact only takes energy
    n, bone = 20, 0.25  # bones, m each
    m_bone = 10.0 / n
    i_rod = m_bone * bone**2 / 12
    inertia = np.tile(np.diag([0.5 * m_bone * RADIUS**2, i_rod, i_rod]), (n, 1, 1))
    pivot0 = np.array([[k * bone, 0.0, 0.1] for k in range(n)])
    tip0 = pivot0 + [bone, 0.0, 0.0]
    com0 = 0.5 * (pivot0 + tip0)
    debris = Debris(np.full(n, m_bone), inertia, com0, pivot0, tip0, np.full(n, RADIUS),
                    True, G)
    pose = {"rot": np.tile(np.eye(3), (n, 1, 1)), "com": com0.copy(), "pivot": pivot0.copy(),
            "vcom": np.tile([0.0, 0.0, -11.0], (n, 1)), "omega": np.zeros((n, 3))}
    debris.add(np.arange(n), pose)

    def gravity(com, vcom, axis, start, h):
        return m_bone * G[None].repeat(len(com), 0)

    def energy():
        kinetic = 0.5 * 10.0 * float(debris.v[0] @ debris.v[0]) + 0.5 * float(
            debris.w[0] @ debris.ang[0])
        return kinetic + 10.0 * 9.81 * float(debris.x[0, 2]) + float(
            debris.contact_energy().sum())

    start = energy()
    totals, up = [], []
    for _ in range(240):
        debris.step(1 / 480, gravity)
        totals.append(energy())
        up.append(float(debris.v[0, 2]))
    assert max(totals) <= start * 1.001, (max(totals), start)  # J
    assert max(up) < 11.0  # m/s upward, after landing at 11 m/s down

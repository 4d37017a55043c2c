"""Precision far from the world origin (the issue's criteria), CPU backend.

The peridynamic state is the displacement u from the rest configuration, rest positions are stored relative to the
scene's origin (the centre of its bodies, pdsim/kinematics.py), and the bond extension is evaluated from
displacement differences, e = (2 xi . du + du . du) / (|eta| + L) (kernels/peridynamics/step.py). So float32 resolves
a deformation to about 1e-7 of itself wherever the scene sits: a body at x = 100 m, where float32 positions are
spaced 7.6e-6 m apart (0.76 % of a 1 mm spacing, 7600 x the 1e-9 m bond stretch of a 1e-6 strain), must behave as at
the origin. Both tests build their solvers the way a Scene does (pdsim.Scene.build_solver: origin at the bodies'
centre).

Measured with origin = (0, 0, 0) instead (world coordinates in float32): at x = 100 m the crack count is still
identical (266; broken bonds 0.5 % apart) and the wave speeds 4e-5 apart; even at 1 km and 10 km the crack count is
off by only 0.8 % and 3 %. The displacement u stays relative to the rest position in any frame; only the rest lattice
is rounded (0.76 % of h at 100 m), which the model tolerates. So a world-coordinate origin is not a failing
counterpart of these criteria with the displacement formulation, and the tests do not assert one. What the criteria
can catch is shown inside each test: the crack count is taken while the crack runs (about 1 % per step), and the
wave's 1e-6 strain lies below what positions differenced in float32 would resolve even near the origin.
"""

import math

import numpy as np
import pytest

import pdsim

H = 1.0e-3  # particle spacing [m]
SHIFT = 100.0  # [m]


def _scene_solver(body, **scene_kwargs):
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), **scene_kwargs)
    scene.add_body(body)
    return scene.build_solver(device="cpu")


GLASS = pdsim.Material(density=2500.0, youngs_modulus=72.0e9, poisson_ratio=0.22, fracture_energy=3.8)


def _pulled_glass_plate(x0):
    """A 40 x 40 x 3 particle glass plate (40 x 40 x 3 mm) centred at (x0, 0, 0) with an edge notch a quarter of the
    width long on the plane y = 0 (between two particle layers), pulled apart along y by roller grips on its top and
    bottom 2 layers (unbreakable) at +-0.05 m/s, ramped up over 2 P-wave transits so no shock enters. The grips'
    stress wave carries a strain v / c_P = 9e-6, far below the critical stretch s_c = 1.2e-4 (G0 = 3.8 J/m^2,
    delta = 3 mm), so the crack runs straight from the notch without branching. Returns (body, solver, notch tip x
    relative to the centre)."""
    size, thick = 40 * H, 3 * H
    body = pdsim.PeridynamicBody(pdsim.box((size, size, thick), center=(x0, 0.0, 0.0)), GLASS, H, name="plate")
    tip = -0.25 * size
    body.add_notch(pdsim.BoxRegion(lo=(x0 - size, -1.0e-5, -1.0), hi=(x0 + tip, 1.0e-5, 1.0)))
    grip = 0.5 * size - 2.0 * H
    ramp = pdsim.TimeCurve.ramp(2.0 * size / GLASS.p_wave_speed)
    for sign, name in ((1.0, "top"), (-1.0, "bottom")):
        region = pdsim.HalfSpace((x0, sign * grip, 0.0), (0.0, sign, 0.0))
        body.set_velocity(region, (0.0, sign * 0.05, 0.0), axes="y", curve=ramp, name=name)
        body.set_unbreakable(region)
    return body, _scene_solver(body), tip


def test_glass_crack_grows_the_same_at_100_m():
    """The notched glass plate (see _pulled_glass_plate; 4800 particles, h = 1 mm, contact on as a Scene sets it
    for a breakable body) is pulled at the origin until its crack, grown from the notch, runs three quarters across
    (tip 10 mm past the centre, about 400 steps); the same plate centred at x = 100 m is run for the same steps.
    Damaged particles (damage > 0.2) must number the same within 2 % (the issue's criterion; measured: identical,
    266 and 266, with 60 cut by the notch; the crack tips agree too). The count is taken while the crack runs: it
    grows by about 1 % per step there (240 -> 266 over the last 10), so a crack starting or running 2 steps (0.2 us)
    early or late at 100 m would already fail; the test asserts the count is still moving (> 5 % over the last 10
    steps). The crack must also have grown well beyond the notch: more than 3 x its count. About 4 s per run."""
    body, solver, tip = _pulled_glass_plate(0.0)
    assert solver.origin.tolist() == [0.0, 0.0, 0.0]
    X = body.rest_positions
    on_line = np.abs(X[:, 1]) < 2.0 * H
    notch_count = int((solver.damage() > 0.2).sum())
    dt = 0.7 * solver.stable_time_step()
    counts, crack_tip = [notch_count], tip
    while crack_tip < 10.0 * H:  # three quarters across
        solver.simulate(dt, 10)
        damaged = solver.damage() > 0.2
        counts.append(int(damaged.sum()))
        crack_tip = X[damaged & on_line, 0].max()
        assert solver.step_count < 1000, "the crack did not run three quarters across"
    steps = solver.step_count
    assert counts[-1] > 3 * notch_count
    assert counts[-1] - counts[-2] > 0.05 * counts[-1]  # still running: a 4-step shift would break the 2 % criterion

    far_body, far, _ = _pulled_glass_plate(SHIFT)
    assert far.origin.tolist() == [SHIFT, 0.0, 0.0]
    far.simulate(dt, steps)
    far_damaged = far.damage() > 0.2
    assert int(far_damaged.sum()) == pytest.approx(counts[-1], rel=0.02)
    Xf = far_body.rest_positions
    assert Xf[far_damaged & (np.abs(Xf[:, 1]) < 2.0 * H), 0].max() - SHIFT == pytest.approx(crack_tip, abs=H)


def _bar_wave(x0, strain):
    """A free glass bar (nu = 0, so the bar speed sqrt(E / rho) is also the P-wave speed and lateral inertia plays no
    part), 150 x 5 x 5 particles (h = 1 mm) starting at x = x0, carrying a right-going Gaussian pulse u_x = A
    exp(-((x - x_p) / w)^2) of peak strain ``strain`` (w = 8 delta, x_p 40 mm from its left end; v = -c u'). Returns
    the solver and a function giving the pulse's position (peak of the cross-section mean of u_x, parabola-interpolated
    between layers) relative to x0."""
    mat = pdsim.Material(density=2500.0, youngs_modulus=72.0e9, poisson_ratio=0.0)
    length = 150 * H
    body = pdsim.PeridynamicBody(pdsim.box((length, 5 * H, 5 * H), center=(x0 + 0.5 * length, 0.0, 0.0)), mat, H)
    solver = _scene_solver(body)
    c = mat.bar_wave_speed
    X = body.rest_positions[:, 0] - x0
    xp, width = 40 * H, 8.0 * body.horizon
    amp = strain * width / math.sqrt(2.0 / math.e)  # max |u'| of the Gaussian is A sqrt(2/e) / w
    g = amp * np.exp(-(((X - xp) / width) ** 2))
    u = np.zeros_like(body.rest_positions)
    u[:, 0] = g
    v = np.zeros_like(u)
    v[:, 0] = -c * (-2.0 * (X - xp) / width**2) * g
    solver.set_displacements(u)
    solver.set_velocities(v)
    xs, layer = np.unique(np.round(X, 9), return_inverse=True)
    per_layer = np.bincount(layer)

    def profile():
        return np.bincount(layer, solver.displacements()[:, 0]) / per_layer / amp

    def position():
        p = profile()
        i = int(np.argmax(p))
        a, b, d = p[i - 1], p[i], p[i + 1]
        return xs[i] + 0.5 * H * (a - d) / (a - 2.0 * b + d)

    return solver, position, profile, c


def test_small_wave_at_100_m_travels_like_a_large_one_at_the_origin():
    """A longitudinal pulse of peak strain 1e-6 in a glass bar at x = 100 m must travel at the speed of one of strain
    1e-3 at the origin within 1 % (the issue's criterion; measured: 6e-7 apart, both at 1.011 sqrt(E / rho), the
    peridynamic bar being slightly stiff at 5 particles across) over 60 mm (140 steps). The 1e-6 pulse stretches a
    bond by ~1e-9 m: 7600 x below the float32 spacing of positions at 100 m, and still up to 7 x below it in the
    bar's own frame (|x| up to 75 mm), so it exists only through the displacement formulation and the
    cancellation-free extension. Also the two pulses' displacement profiles, each divided by its amplitude, agree
    within 1e-3 after the travel (measured 2.7e-4, the 1e-3 pulse's geometric nonlinearity): the small wave keeps its
    shape, not only its peak. 3750 particles, under 1 s per run."""
    big, big_position, big_profile, c = _bar_wave(0.0, 1.0e-3)
    small, small_position, small_profile, _ = _bar_wave(SHIFT, 1.0e-6)
    assert small.origin[0] == pytest.approx(SHIFT + 0.075)
    dt = 0.7 * big.stable_time_step()
    steps = round(60 * H / c / dt)
    speeds = []
    for solver, position in ((big, big_position), (small, small_position)):
        p0 = position()
        solver.simulate(dt, steps)
        speeds.append((position() - p0) / solver.time)
    assert speeds[1] == pytest.approx(speeds[0], rel=0.01)
    assert speeds[0] == pytest.approx(c, rel=0.05)  # and it is the bar wave (tests/test_pd_elastic.py: 5 %)
    assert np.abs(small_profile() - big_profile()).max() < 1.0e-3

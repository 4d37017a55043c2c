"""The position-based particle lattice reproduces the behaviour reported in dell'Erba 2018 (cases a-g,
propagation, pseudo-energy), CPU backend. Lengths are in lattice units (spacing 1, the paper's "units"); leader speeds
in units per step.

These tests build their specimens here, under Table 1's reading: the lattice's coordination neighbours (square: 4 +
8), 0.35 units/step and, for fracture, thresholds 2.0 / 2.5 units (docs/lattice.md, "Readings of the paper"). The
shipped case scenes (scenes/lattice_paper.py) take the readings that show more of the paper (Figure 3's Chebyshev
shells on the square lattice, case a's 1.2 units/step for cases a-d); tests/test_lattice_paper.py checks them."""

from __future__ import annotations

import numpy as np
import pytest

from pdsim.lattice import (
    Lattice,
    LatticeBody,
    LatticeFracture,
    LatticeKind,
    LatticeNeighbourhood,
    LatticeRuleMixedCoordinate,
    SolverLattice,
)

V_TABLE1 = 0.35  # Table 1: leader speed [units/step] for 10 steps
FRACTURE = (2.0, 2.5)  # per-shell link-loss thresholds [units] at 0.35 units/step (fracture starts at step 4-6)


def _tensile(
    lattice,
    counts,
    *,
    gradient=1,
    rule=None,
    fracture=None,
    frame_rule="average",
    frame_update="current",
    release=None,
    stop=10,
    velocity=V_TABLE1,
    axis=0,
):
    """The paper's tensile specimen: first layer (lowest along ``axis``) clamped, last layer pulled along ``axis`` at
    ``velocity`` until ``stop`` (None: for ever), released into followers at ``release``."""
    body = LatticeBody.block(
        lattice,
        counts,
        neighbourhood=LatticeNeighbourhood(gradient=gradient),
        rule=rule,
        fracture=fracture,
        frame_rule=frame_rule,
        frame_update=frame_update,
    )
    x = body.rest_positions[: body.body_count, axis]
    body.clamp(x < x.min() + 0.6 * lattice.spacing)  # 0.6: both row parities of the hexagonal lattice
    v = np.zeros(3)
    v[axis] = velocity
    body.add_leaders(x > x.max() - 0.6 * lattice.spacing, velocity=v, stop_step=stop, release_step=release)
    return body


def _run_tracked(body, index, steps):
    body.track([index])
    solver = SolverLattice([body])
    solver.run_steps(steps)
    _, x, pe1 = solver.trajectories()
    return solver, x[:, 0, :] - x[0, 0, :], pe1[:, 0]


def _sign_changes(series, *, tol=1.0e-7):
    """Number of direction reversals of a series (steps smaller than ``tol`` ignored)."""
    d = np.diff(series)
    d = d[np.abs(d) > tol]
    return int(np.count_nonzero(np.diff(np.sign(d))))


def _graph_layers(body, sources):
    """Graph distance (in links of the neighbourhood, all shells, between body points: frame points relay nothing,
    they copy) of every body point from ``sources`` (breadth-first search, numpy)."""
    n = body.particle_count
    owner = np.repeat(np.arange(n), np.diff(body.row_offsets))
    owner = np.where(body.link_neighbor < body.body_count, owner, n - 1)
    dist = np.full(n, -1)
    dist[sources] = 0
    frontier = np.zeros(n, dtype=bool)
    frontier[sources] = True
    layer = 0
    while frontier.any():
        layer += 1
        reach = np.zeros(n, dtype=bool)
        reach[body.link_neighbor[frontier[owner]]] = True
        reach[body.body_count :] = False
        new = reach & (dist < 0)
        dist[new] = layer
        frontier = new
    return dist


# ---------------------------------------------------------------------------------------------------- propagation
@pytest.mark.parametrize(
    ("lattice", "gradient"),
    [(Lattice.square(1.0), 1), (Lattice.square(1.0), 2), (Lattice.hexagonal(1.0), 1)],
    ids=["square-first", "square-second", "hexagonal-first"],
)
def test_disturbance_travels_one_layer_per_step(lattice, gradient):
    """Double-buffered rules: a follower k layers from the leaders (k = graph distance over its neighbour links, so
    two lattice rows per layer in second gradient) stays exactly at rest before step k and moves at step k."""
    body = LatticeBody.block(lattice, (12, 9), neighbourhood=LatticeNeighbourhood(gradient=gradient))
    x = body.rest_positions[: body.body_count, 0]
    leaders = body.add_leaders(x > x.max() - 0.5, velocity=(0.35, 0.0, 0.0))
    layers = _graph_layers(body, leaders)[: body.body_count]
    followers = np.setdiff1d(np.arange(body.body_count), leaders)
    body.track(followers)
    solver = SolverLattice([body])
    solver.run_steps(int(layers.max()) + 1)
    _, xt, _ = solver.trajectories()
    moved = np.linalg.norm(xt - xt[0], axis=2) > 0.0  # exact: a lattice at rest stays bit-exactly at rest
    first = np.argmax(moved, axis=0)
    assert moved.any(axis=0).all()
    np.testing.assert_array_equal(first, layers[followers])
    assert layers.max() >= (6 if gradient == 1 else 3)


# ---------------------------------------------------------------------------------------------------- case a
def test_case_a_tensile_test_with_release():
    """Case a (Table 1: square 10x10, coordination neighbours, centroid rule, left column clamped, right column
    pulled at 0.35 units/step for 10 steps, then released into followers, 401 steps). The central particle j = 67
    (index 66, 3 layers from the leaders) rests until step 3, rises at every step while the leaders move, reaches one
    maximum, then relaxes monotonically (no oscillation) towards rest without reaching it at step 401 (between 1 % and
    25 % of its peak displacement remains)."""
    body = _tensile(Lattice.square(1.0), (10, 10), release=11)
    assert np.allclose(body.rest_positions[66], [6.0, 6.0, 0.0])
    _, u, _ = _run_tracked(body, 66, 401)
    ux = u[:, 0]
    assert np.all(ux[:3] == 0.0) and ux[3] > 0.0
    assert np.all(np.diff(ux[3:11]) > 0.0)
    peak = int(np.argmax(ux))
    assert peak > 10
    assert np.all(np.diff(ux[3 : peak + 1]) >= 0.0)
    assert np.all(np.diff(ux[peak:]) <= 1.0e-7)
    assert _sign_changes(ux) == 1
    assert 0.01 * ux[peak] < ux[401] < 0.25 * ux[peak]
    assert np.abs(u[:, 1]).max() < 1.0e-6  # x pull only: the central particle moves along x


def test_case_a_rise_becomes_linear_under_a_sustained_pull():
    """Case a's linear rise: with the leaders kept moving, the central particle's x velocity settles (after the
    propagation transient) to the quasi-static value v * 6/9 of a linear profile between the clamp (column 0) and
    the leaders (column 9), within 2 %, and stays constant (x linear in the step) to 0.5 % over 100 steps."""
    body = _tensile(Lattice.square(1.0), (10, 10), stop=None)
    _, u, _ = _run_tracked(body, 66, 400)
    vel = np.diff(u[:, 0])
    assert vel[299:399] == pytest.approx(V_TABLE1 * 6.0 / 9.0, rel=0.02)
    assert np.ptp(vel[299:399]) < 0.005 * vel[299:399].mean()


# ---------------------------------------------------------------------------------------------------- cases b, c
def _poisson_central_dy(gradient):
    body = _tensile(Lattice.square(1.0), (10, 10), gradient=gradient, rule=LatticeRuleMixedCoordinate(k=0.01))
    _, u, _ = _run_tracked(body, 66, 100)
    return u


def test_cases_b_c_poisson_contraction_and_second_gradient():
    """Case b (mixed-coordinate rule, K = 0.01 /unit, leaders stop after 10 steps, 100 steps): the central particle
    j = 67, above the axis, moves down (lateral contraction) while it moves right. Case c (same with second gradient):
    it also moves down, but less: under 75 % of the first-gradient contraction at step 100."""
    ub = _poisson_central_dy(1)
    uc = _poisson_central_dy(2)
    assert ub[100, 0] > 1.0 and uc[100, 0] > 1.0
    assert ub[100, 1] < -0.1
    assert np.all(np.diff(ub[:, 1]) <= 1.0e-7)  # contraction grows monotonically
    assert uc[100, 1] < -0.05
    assert abs(uc[100, 1]) < 0.75 * abs(ub[100, 1])


# ---------------------------------------------------------------------------------------------------- case d
def _detach_steps(body, solver_steps):
    """Step at which each row's follower next to the pulled leaders loses its last intact link to a leader."""
    solver = SolverLattice([body])
    n = body.particle_count
    owner = np.repeat(np.arange(n), np.diff(body.row_offsets))
    lost = np.full(body.link_count, -1)
    for t in range(1, solver_steps + 1):
        solver.run_steps(1)
        lost[(~solver.link_alive()) & (lost < 0)] = t
    x = body.rest_positions
    pulled = (body.kind == LatticeKind.LEADER) & (x[:, 0] > x[: body.body_count, 0].max() - 0.6)
    col = x[: body.body_count, 0].max() - 1.0
    rows = np.unique(x[: body.body_count, 1])
    steps = []
    for y in rows:
        j = int(np.nonzero((x[:, 0] == col) & (x[:, 1] == y))[0][0])
        q = np.nonzero((owner == j) & pulled[body.link_neighbor])[0]
        assert np.all(lost[q] > 0), "a row never detached"
        steps.append(int(lost[q].max()))
    return solver, np.array(steps)


@pytest.mark.parametrize("gradient", [1, 2])
def test_case_d_fracture_line_crosses_the_specimen(gradient):
    """Case d (centroid rule, leaders at 0.35 units/step for 10 steps, thresholds 2.0 / 2.5 units, fictitious points
    at the rest offset): a crack crosses the whole specimen: after 100 steps the leaders and followers form exactly
    two pieces, the pulled column (with any followers torn off with it) on one side and the clamped column with the
    rest on the other, and every row has detached from the pulled leaders."""
    body = _tensile(Lattice.square(1.0), (15, 13), gradient=gradient, fracture=LatticeFracture(FRACTURE))
    solver, steps = _detach_steps(body, 100)
    frag = solver.fragments()[: body.body_count]
    x = body.rest_positions[: body.body_count, 0]
    assert len(np.unique(frag)) == 2
    assert len(np.unique(frag[x > x.max() - 0.5])) == 1 and len(np.unique(frag[x < 0.5])) == 1
    assert frag[np.argmax(x)] != frag[np.argmin(x)]
    assert steps.max() <= 10  # the crack forms while the leaders move


@pytest.mark.parametrize("frame_update", ["current", "previous"])
def test_case_d_second_gradient_detaches_near_the_frame_first(frame_update):
    """Case d, second gradient: the particles next to the frame (the outermost row at each edge) detach from the
    leaders at least one step before the central rows (the paper's Figure 15); with the lagging frame update
    ("previous") the three outermost rows at each edge do (measured: rows 0-2 and 10-12 at step 6, the rest at 7)."""
    body = _tensile(
        Lattice.square(1.0), (15, 13), gradient=2, fracture=LatticeFracture(FRACTURE), frame_update=frame_update
    )
    _, steps = _detach_steps(body, 20)
    depth = 1 if frame_update == "current" else 3
    edge = np.r_[steps[:depth], steps[-depth:]]
    centre = steps[depth:-depth]
    assert edge.max() < centre.min()


# ---------------------------------------------------------------------------------------------------- case e
def test_case_e_saint_venant_local_action():
    """Case e: four internal leaders (a 2x2 cluster at the centre of a 20x20 square) diverge along the bisectors at
    0.35 units/step. At step 9 (the paper's Figure 17) every particle more than 4 spacings from the nearest leader
    stays within 1 % of the leaders' displacement of rest, and those beyond 8 spacings within 1e-5 of it."""
    body = LatticeBody.block(Lattice.square(1.0), (20, 20))
    x = body.rest_positions[: body.body_count]
    centre = x.mean(axis=0)
    leaders = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            j = body.nearest_particle(centre + 0.5 * np.array([sx, sy, 0.0]))
            leaders.append(j)
            body.add_leaders([j], velocity=(sx * V_TABLE1 / np.sqrt(2), sy * V_TABLE1 / np.sqrt(2), 0.0))
    solver = SolverLattice([body])
    solver.run_steps(9)
    u = np.linalg.norm(solver.displacements()[: body.body_count], axis=1)
    lead_disp = 9 * V_TABLE1
    assert np.allclose(u[leaders], lead_disp, rtol=1e-5)
    dist = np.min(np.linalg.norm(x[:, None, :] - x[None, leaders, :], axis=2), axis=1)
    assert u[dist > 4.0].max() < 0.01 * lead_disp
    assert u[dist > 8.0].max() < 1.0e-5 * lead_disp
    assert u[dist < 1.5].min() > 0.1  # the neighbourhood of the leaders does move


# ---------------------------------------------------------------------------------------------------- cases f, g
def _fracture_specimen(lattice, gradient, frame_rule, steps):
    """Cases f and g: square 15x13 specimen (the size for which the paper's point 103 lies where its text puts it:
    mid-height, two columns left of the leaders) or hexagonal 15x17, fracture as in case d; tracks the particle two
    columns left of the leaders at mid-height (j = 103 in the square, j = 133 in the hexagonal specimen)."""
    ny = 13 if lattice.type.value == "square" else 17
    body = _tensile(lattice, (15, ny), gradient=gradient, fracture=LatticeFracture(FRACTURE), frame_rule=frame_rule)
    tracked = 15 * (ny // 2) + 12
    solver, u, _ = _run_tracked(body, tracked, steps)
    return body, solver, u[:, 0]


def test_case_f_hexagonal_rebounds_square_does_not():
    """Case f: after the fracture the tracked particle (j = 133 in the hexagonal 15x17 specimen, j = 103 in the
    square 15x13 one) rises and falls back; in the hexagonal lattice (averaging frame rule) its x then rises again
    (a rebound: two reversals, the late rise at least 0.05 units), in the square lattice it relaxes monotonically
    (one reversal). With second gradient the hexagonal rebound disappears (the paper's Figure 21)."""
    _, _, hex_x = _fracture_specimen(Lattice.hexagonal(1.0), 1, "average", 400)
    _, _, sq_x = _fracture_specimen(Lattice.square(1.0), 1, "average", 400)
    _, _, hex2_x = _fracture_specimen(Lattice.hexagonal(1.0), 2, "average", 400)
    assert _sign_changes(hex_x) == 2
    low = int(np.argmin(hex_x[20:])) + 20
    assert hex_x[400] - hex_x[low] > 0.05
    assert _sign_changes(sq_x) == 1
    assert _sign_changes(hex2_x) == 1


def _stranded_frame_points(body, solver):
    """Frame points farther than 1.5 times their rest distance from every body point (left between the pieces)."""
    nb = body.body_count
    x = solver.positions()
    x0 = body.rest_positions
    d = np.min(np.linalg.norm(x[nb:, None, :] - x[None, :nb, :], axis=2), axis=1)
    d0 = np.min(np.linalg.norm(x0[nb:, None, :] - x0[None, :nb, :], axis=2), axis=1)
    return np.nonzero(d > 1.5 * d0)[0] + nb


@pytest.mark.parametrize("gradient", [1, 2])
def test_case_g_frame_rule_strands_frame_points(gradient):
    """Case g: in the fractured hexagonal specimen, the averaging frame rule leaves frame points stranded between the
    two pieces (two, top and bottom, where the crack separates a frame point's two followers), while the
    single-follower rule leaves none."""
    body_avg, solver_avg, _ = _fracture_specimen(Lattice.hexagonal(1.0), gradient, "average", 100)
    body_one, solver_one, _ = _fracture_specimen(Lattice.hexagonal(1.0), gradient, "single", 100)
    stranded = _stranded_frame_points(body_avg, solver_avg)
    assert len(stranded) == 2
    y = body_avg.rest_positions[stranded, 1]
    assert y.min() < 0.0 and y.max() > body_avg.rest_positions[: body_avg.body_count, 1].max()
    assert len(_stranded_frame_points(body_one, solver_one)) == 0


# ---------------------------------------------------------------------------------------------------- pseudo-energy
@pytest.mark.parametrize("lattice", [Lattice.square(1.0), Lattice.hexagonal(1.0)], ids=["square", "hexagonal"])
def test_pe1_zero_at_rest_and_quadratic_in_stretch(lattice):
    """PE1 = sum over neighbours of (dis - dis0)^2 is exactly 0 at rest and, under a uniform stretch eps along x,
    equals eps^2 sum_k dx_k^4 / L_k^2 to first order for a particle with a full neighbourhood: doubling a small
    stretch multiplies it by 4 (to 0.5 %)."""
    body = LatticeBody.block(lattice, (8, 8))
    solver = SolverLattice([body])
    assert np.all(solver.pe1() == 0.0)
    x0 = body.rest_positions
    j = body.nearest_particle(x0[: body.body_count].mean(axis=0))
    offs = body.offset_delta
    expected = np.sum(offs[:, 0] ** 4 / np.sum(offs**2, axis=1))
    values = []
    for eps in (1.0e-3, 2.0e-3):
        u = np.zeros_like(x0)
        u[:, 0] = eps * x0[:, 0]
        solver.set_displacements(u)
        values.append(solver.pe1()[j])
        assert values[-1] == pytest.approx(expected * eps**2, rel=5e-3)
    assert values[1] / values[0] == pytest.approx(4.0, rel=5e-3)


def test_pe2_is_the_last_step_displacement():
    """PE2(t, j) = |C_t(j) - C_{t-1}(j)|: after a run it equals the distance each particle moved in the last step
    (compared with the tracked history, float32 round-off)."""
    body = _tensile(Lattice.square(1.0), (6, 6))
    body.track(np.arange(body.particle_count))
    solver = SolverLattice([body])
    solver.run_steps(7)
    _, x, _ = solver.trajectories()
    np.testing.assert_allclose(solver.pe2(), np.linalg.norm(x[7] - x[6], axis=1), atol=1e-6)


# ---------------------------------------------------------------------------------------------------- 3D
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_cubic_lattice_reproduces_case_a_along_each_axis(axis):
    """3D: a simple cubic 10x10x10 block, clamped on one face and pulled on the opposite one along ``axis`` as in
    Table 1 (10 steps at 0.35, then released), shows case a's behaviour along that axis: its central particle (3
    layers from the leaders) rests until step 3, rises while the leaders move, then relaxes monotonically without
    reaching rest at step 401; the transverse coordinates do not move."""
    body = _tensile(Lattice.simple_cubic(1.0), (10, 10, 10), release=11, axis=axis)
    p = np.full(3, 4.0)
    p[axis] = 6.0
    j = body.nearest_particle(p)
    _, u, _ = _run_tracked(body, j, 401)
    ua = u[:, axis]
    assert np.all(ua[:3] == 0.0) and ua[3] > 0.0
    assert np.all(np.diff(ua[3:11]) > 0.0)
    peak = int(np.argmax(ua))
    assert np.all(np.diff(ua[peak:]) <= 1.0e-7)
    assert _sign_changes(ua) == 1
    assert 0.01 * ua[peak] < ua[401] < 0.5 * ua[peak]
    assert np.abs(np.delete(u, axis, axis=1)).max() < 1.0e-6

"""Plasticity of the tetrahedral FEM solid: the slides' update rule (yield, creep, max) and a permanent bend."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, FemPlasticity, SolverFem
from pdsim.fem.mesh import box_tet_mesh

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def _apply_rule(total, plastic, params, dt, device):
    """Runs the plastic update kernel (the function the element force kernel calls) on arrays of 3x3 strains."""
    import warp as wp
    from pdsim.kernels.fem import elements as ke

    _, mat33, _ = ke.fem_types(wp.float64)
    t = wp.array(np.asarray(total, dtype=np.float64), dtype=mat33, device=device)
    p = wp.array(np.asarray(plastic, dtype=np.float64), dtype=mat33, device=device)
    pp = wp.array(np.asarray(params, dtype=np.float64), dtype=wp.vec3d, device=device)
    wp.launch(ke.plastic_update_kernel(wp.float64), dim=len(total), inputs=[t, pp, wp.float64(dt), p], device=device)
    return p.numpy()


def test_plastic_update_rule(device):
    """The slides' rule on the strain tensor (Frobenius norm), float64, exact to 1e-15:
    below yield nothing changes; above yield the plastic strain creeps towards the total strain by
    min(creep dt, 1) of the elastic strain; a plastic strain above max is scaled back to norm max."""
    yield_strain, creep, max_strain, dt = 0.01, 20.0, 0.05, 0.01  # creep dt = 0.2
    eye = np.eye(3)
    small = 0.004 * eye  # |eps| = 0.0069 < yield
    big = np.diag([0.03, -0.01, 0.0])  # |eps| = 0.0316 > yield
    huge = np.diag([0.2, 0.0, 0.0])
    ep0 = np.diag([0.001, 0.0, 0.0])
    total = np.stack([small, big, big, huge])
    plastic = np.stack([np.zeros((3, 3)), np.zeros((3, 3)), ep0, np.zeros((3, 3))])
    params = np.tile([yield_strain, creep, max_strain], (4, 1))
    out = _apply_rule(total, plastic, params, dt, device)
    np.testing.assert_allclose(out[0], 0.0, atol=1e-15)  # below yield: unchanged
    np.testing.assert_allclose(out[1], 0.2 * big, atol=1e-15)  # creeps by creep dt of the elastic strain
    np.testing.assert_allclose(out[2], ep0 + 0.2 * (big - ep0), atol=1e-15)
    # huge strain: 0.2 * huge has norm 0.04 < max; a second call passes max and is clamped to norm max
    np.testing.assert_allclose(out[3], 0.2 * huge, atol=1e-15)
    out2 = _apply_rule(total[3:], out[3:], params[3:], 1.0, device)  # creep dt >= 1: absorbs everything, clamped
    assert np.linalg.norm(out2[0]) == pytest.approx(max_strain, rel=1e-14)
    np.testing.assert_allclose(out2[0] / np.linalg.norm(out2[0]), huge / np.linalg.norm(huge), atol=1e-14)
    # repeated application converges to the total strain (below max): creep towards the total
    p = np.zeros((1, 3, 3))
    for _ in range(200):
        p = _apply_rule(big[None], p, params[:1], dt, device)
    assert np.linalg.norm(big - p[0]) <= yield_strain * (1.0 + 1e-12)


def _bend(plasticity, integrator, device):
    """A bar (1 m x 0.1 m x 0.1 m) clamped at x = 0, its free end pushed 0.3 m sideways at 0.5 m/s, released at
    t = 0.6 s and left to settle (damping 5 /s) until t = 3 s; returns (tip deflection [m], largest speed [m/s],
    largest plastic strain norm)."""
    mesh = box_tet_mesh((1.0, 0.1, 0.1), (20, 2, 2), center=(0.5, 0.0, 0.0))
    body = FemBody(mesh, MAT, integrator=integrator, plasticity=plasticity, damping=5.0)
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1e-6, 1, 1)))
    body.set_velocity(pdsim.BoxRegion(lo=(1.0 - 1e-6, -1, -1), hi=(2, 1, 1)), (0.0, 0.0, 0.5), release=0.6)
    solver = SolverFem([body], device=device)
    dt = solver.stable_time_step()
    solver.simulate(dt, round(3.0 / dt))
    tip = np.isclose(mesh.vertices[:, 0], 1.0)
    deflection = float((solver.positions() - mesh.vertices)[tip, 2].mean())
    return (
        deflection,
        float(np.abs(solver.velocities()).max()),
        float(np.linalg.norm(solver.plastic_strain(), axis=(1, 2)).max()),
    )


@pytest.mark.parametrize("integrator", ["explicit", "implicit"])
def test_bar_keeps_a_permanent_bend_after_unloading(integrator, device):
    """A bar bent 0.3 m and released springs back straight when elastic (|tip| < 2 mm at rest) but keeps a permanent
    bend when it yields (yield strain 0.005, creep 5 /s, max 0.2): the tip stays above 0.1 m (measured 0.32 m explicit,
    0.31 m implicit: released while moving, the yielding bar coasts on) with the bar at rest (speeds below 1 cm/s)
    and plastic strain below max."""
    plastic = FemPlasticity(yield_strain=0.005, creep=5.0, max_strain=0.2)
    d_el, v_el, ep_el = _bend(None, integrator, device)
    d_pl, v_pl, ep_pl = _bend(plastic, integrator, device)
    print(f"{integrator}: elastic tip {d_el:.4f} m, plastic tip {d_pl:.4f} m, max plastic strain {ep_pl:.4f}")
    assert abs(d_el) < 2.0e-3 and ep_el == 0.0
    assert d_pl > 0.1
    assert v_el < 1.0e-2 and v_pl < 1.0e-2
    assert 0.0 < ep_pl <= 0.2 * (1 + 1e-6)

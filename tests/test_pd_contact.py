"""Physics checks of contact (kernels/contact.py, pdsim/contact.py) on the CPU backend: particles with no live bond
repel at short range, colliders (static mesh, kinematic sphere / box / mesh projectiles) keep particles out."""

import math

import numpy as np
import pytest

import pdsim
from pdsim.colliders import BoxProjectile, MeshCollider, MeshProjectile, SphereProjectile
from pdsim.contact import ParticleContact, bond_stiffness_row_sum

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25)  # P-wave speed 34.6 m/s
H = 0.01


class ContactSolver(pdsim.SolverPeridynamics):
    """The peridynamic solver with contact and colliders (SolverPeridynamics applies them: colliders after the
    drift, particle contact after the bond force density) plus a total-energy diagnostic."""

    def __init__(self, bodies, *, contact: dict | None = None, colliders=(), **kwargs):
        super().__init__(bodies, contact=contact, colliders=colliders, **kwargs)

    def total_energy(self) -> float:
        """Kinetic + elastic + contact penalty energy [J]."""
        return self.kinetic_energy() + self.strain_energy() + self.contact_energy()


def _min_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance between a point of a [n, 3] and one of b [m, 3] (brute force; small sets)."""
    return float(np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2).min()))


def _cubes(speed: float, *, contact: dict | None, edge: int = 8, offset: float = 0.0, device="cpu"):
    """Two cubes of edge ``edge`` h, facing particles 1.5 h apart (just outside the default contact distance 1.35 h),
    flying at each other at +-speed along x; the second is shifted by ``offset`` h along y and z (0.5: its lattice
    sits over the hollows of the first)."""
    L = edge * H
    a = pdsim.PeridynamicBody(pdsim.box((L,) * 3, center=(-0.5 * L - 0.25 * H, 0.0, 0.0)), MAT, H, name="a")
    shift = offset * H
    b = pdsim.PeridynamicBody(pdsim.box((L,) * 3, center=(0.5 * L + 0.25 * H, shift, shift)), MAT, H, name="b")
    a.set_initial_velocity((speed, 0.0, 0.0))
    b.set_initial_velocity((-speed, 0.0, 0.0))
    solver = ContactSolver([a, b], contact=contact, device=device)
    return solver, solver.slice_of(a), solver.slice_of(b)


def _collide(solver, sa, sb, duration: float, stats: dict | None = None):
    """Steps ``duration`` [s] at 0.7 x the stable estimate; returns (min distance between the bodies over all steps,
    max energy / initial energy, final mean x velocities of a and b). ``stats`` receives the largest contact count
    and contact stiffness row sum [N/m^4] of any particle at any step."""
    dt = 0.7 * solver.stable_time_step()
    e0 = solver.total_energy()
    d_min, e_max = math.inf, e0
    for _ in range(int(duration / dt)):
        solver.step(dt)
        x = solver.positions().astype(np.float64)
        xa, xb = x[sa], x[sb]
        front_a = xa[xa[:, 0] > xa[:, 0].max() - 3.0 * H]  # the facing layers (the cubes hit along x)
        front_b = xb[xb[:, 0] < xb[:, 0].min() + 3.0 * H]
        d_min = min(d_min, _min_distance(front_a, front_b))
        e_max = max(e_max, solver.total_energy())
        if stats is not None:
            diag = solver.contact.diagnostics(solver._local_positions_wp())
            stats["count"] = max(stats.get("count", 0), int(diag.count.max()))
            stats["row_sum"] = max(stats.get("row_sum", 0.0), float(diag.row_sum.max()))
    v = solver.velocities()
    return d_min, e_max / e0, float(v[sa, 0].mean()), float(v[sb, 0].mean())


def test_bonded_body_at_rest_or_mildly_compressed_feels_no_contact_force():
    """Particles of one body repel only below 0.9 of their reference distance (LAMMPS PERI's rule), so a bonded body
    at rest, or uniformly compressed by 5 %, gets exactly zero contact force (no round-off: the pairs are not in
    range); compressed by 15 % its lattice neighbours repel (positive pressure: outward force on the surface)."""
    body = pdsim.PeridynamicBody(pdsim.box((0.08, 0.06, 0.05)), MAT, H)
    contact = ParticleContact.from_bodies([body])
    import warp as wp

    X = body.rest_positions
    c = X.mean(axis=0)
    for squeeze, expect_force in ((1.0, False), (0.95, False), (0.85, True)):
        y = wp.array((c + squeeze * (X - c)).astype(np.float32), dtype=wp.vec3)
        f = wp.zeros(body.particle_count, dtype=wp.vec3)
        contact.apply(y, wp.zeros_like(y), wp.zeros_like(y), f)
        f = f.numpy().astype(np.float64)
        if expect_force:
            outward = np.einsum("ij,ij->i", f, X - c)
            assert outward.sum() > 0.0 and np.abs(f).max() > 0.0
        else:
            assert np.abs(f).max() == 0.0
            assert contact.potential_energy(y) == 0.0


def test_two_cubes_bounce_apart_without_interpenetrating(device):
    """Two elastic cubes thrown at each other at 0.087 of the P-wave speed (relative): the closest pair of
    particles of different bodies stays above h/2 at every step (penalty alone, hard floor off), the total energy
    (kinetic + elastic + contact) never exceeds its initial value by more than 2 %, the cubes bounce apart (both mean
    velocities reverse, restitution > 0.5) and linear momentum is conserved to 1e-4 of its scale. The contact adds at
    most 2 neighbours' stiffness (S / 6, S the continuum bond row sum) to any particle, about the headroom between a
    facing particle's bond sum (0.94 S here) and the body's largest (1.13 S): measured, no particle's total exceeds
    the largest bond sum by more than 4 % (the Silling-Askari step would shrink by 2 %); a particle would need 12
    simultaneous contacts for the contact springs alone to need the bonds' step."""
    v0 = 1.5
    solver, sa, sb = _cubes(v0, contact={"floor_factor": 0.0}, device=device)
    p_scale = solver.masses().sum() * v0
    stats = {}
    d_min, e_ratio, va, vb = _collide(solver, sa, sb, duration=0.012, stats=stats)
    s_bond = bond_stiffness_row_sum(MAT.bulk_modulus, MAT.shear_modulus, 3.015 * H)
    assert stats["count"] <= 2 and stats["row_sum"] <= s_bond / 6.0 * (1.0 + 1e-5)
    assert solver.contact.stable_time_step() >= solver.stable_time_step()
    assert d_min > 0.5 * H
    assert d_min < 1.3 * H  # they came within the contact distance 1.35 h
    assert e_ratio < 1.02
    assert va < -0.5 * v0 and vb > 0.5 * v0
    assert np.abs(solver.linear_momentum()).max() < 1.0e-4 * p_scale


@pytest.mark.parametrize("distance_factor", [1.0, 1.35])
def test_offset_lattices_do_not_slip_into_each_other(distance_factor):
    """Cubes whose lattices are offset by half a spacing (each particle faces a hollow between four others) hit at
    0.29 of the P-wave speed (relative). With the default contact distance 1.35 h the second particle layer fills the
    hollows: no particle of either cube's central columns passes the other's first layer and they bounce apart. With
    1.0 h (cells just touching) the facing particles sink through the hollows and the cubes interpenetrate by more
    than a spacing: the reason for the default."""
    v0 = 5.0
    solver, sa, sb = _cubes(v0, contact={"distance_factor": distance_factor}, edge=8, offset=0.5)
    dt = 0.7 * solver.stable_time_step()
    inner = 4.0 * H - 2.0 * H  # central columns: 2 h away from the lateral faces of either cube
    gap = math.inf
    for _ in range(int(0.006 / dt)):
        solver.step(dt)
        x = solver.positions().astype(np.float64)
        xa, xb = x[sa], x[sb]
        ca = np.all(np.abs(xa[:, 1:]) < inner, axis=1)
        cb = np.all(np.abs(xb[:, 1:] - 0.5 * H) < inner, axis=1)
        gap = min(gap, float(xb[cb, 0].min() - xa[ca, 0].max()))
    v = solver.velocities()
    if distance_factor == 1.35:
        assert gap > 0.0
        assert v[sa, 0].mean() < -0.5 * v0 and v[sb, 0].mean() > 0.5 * v0
    else:
        assert gap < -H


def test_violent_impact_is_stopped_by_the_hard_floor():
    """At 0.52 of the P-wave speed (relative) the penalty alone lets the facing particles come closer than h/2; the
    hard floor (default 0.6 of the contact distance) keeps them above h/2 at every step, and the impact does not
    create energy (at most 2 % above the initial value: the floor is inelastic)."""
    v0 = 9.0
    solver, sa, sb = _cubes(v0, contact={"floor_factor": 0.0}, edge=6)
    d_soft, _, _, _ = _collide(solver, sa, sb, duration=0.004)
    assert d_soft < 0.5 * H
    solver, sa, sb = _cubes(v0, contact={}, edge=6)
    d_min, e_ratio, _, _ = _collide(solver, sa, sb, duration=0.004)
    assert d_min > 0.5 * H
    assert e_ratio < 1.02


def test_fragments_of_one_body_do_not_interpenetrate():
    """A bar cut in two by a notch (all bonds across the mid-plane start broken) whose halves are pushed into each
    other: without contact the halves pass through each other; with contact the closest pair across the crack stays
    above h/2 at every step (same-body pairs repel below 0.9 of their reference distance) and they bounce apart."""
    v0 = 1.5

    def run(contact):
        body = pdsim.PeridynamicBody(pdsim.box((0.16, 0.06, 0.06)), MAT, H)
        body.add_notch(pdsim.BoxRegion(lo=(-1.0e-4, -1.0, -1.0), hi=(1.0e-4, 1.0, 1.0)))
        left = body.rest_positions[:, 0] < 0.0
        v = np.zeros((body.particle_count, 3))
        v[:, 0] = np.where(left, v0, -v0)
        body.set_initial_velocity(v)
        solver = ContactSolver([body], contact=contact)
        dt = 0.7 * solver.stable_time_step()
        d_min = math.inf
        for _ in range(int(0.008 / dt)):
            solver.step(dt)
            x = solver.positions().astype(np.float64)
            a, b = x[left], x[~left]
            d_min = min(d_min, _min_distance(a[a[:, 0] > a[:, 0].max() - 3 * H], b[b[:, 0] < b[:, 0].min() + 3 * H]))
        v = solver.velocities()
        return d_min, float(v[left, 0].mean()), float(v[~left, 0].mean())

    d_none, _, _ = run(None)
    assert d_none < 0.3 * H  # no contact: the halves run into each other
    d_min, v_left, v_right = run({"floor_factor": 0.0})
    assert d_min > 0.5 * H
    assert v_left < 0.0 < v_right


@pytest.mark.parametrize("kind", ["sphere", "mesh"])
def test_projectile_hitting_a_block_never_ends_inside_it(kind, device):
    """A kinematic sphere (analytic, or an icosphere mesh) of radius 0.03 m flies at 3 m/s into a free block: after
    every step no particle centre lies inside the sphere by more than h/2 (the projection keeps them at least one
    radius h/2 outside the surface, the mesh up to its faceting), the block is pushed along (it gains forward
    momentum) and the projectile is not slowed down (kinematic)."""
    R, v = 0.03, np.array([3.0, 0.0, 0.0])
    block = pdsim.PeridynamicBody(pdsim.box((0.06, 0.08, 0.08)), MAT, H)
    c0 = np.array([-0.03 - R - 0.5 * H, 0.0, 0.0])
    if kind == "sphere":
        projectile = SphereProjectile(R, c0, velocity=v, device=device)
    else:
        projectile = MeshProjectile(pdsim.sphere(R, center=c0, subdivisions=3), velocity=v, device=device)
    solver = ContactSolver([block], contact={}, colliders=[projectile], device=device)
    dt = 0.7 * solver.stable_time_step()
    worst = -math.inf
    for _ in range(int(0.01 / dt)):
        solver.step(dt)
        centre, _ = projectile.pose(solver.time)
        np.testing.assert_allclose(centre, c0 + v * solver.time, rtol=0, atol=1e-9)
        depth = R - np.linalg.norm(solver.positions().astype(np.float64) - centre, axis=1)
        worst = max(worst, depth.max())
    assert worst < 0.5 * H
    assert worst > -H  # it did touch the block
    assert solver.linear_momentum()[0] > 0.1 * solver.masses().sum() * 3.0


def test_body_dropped_on_a_static_mesh_rests_on_it():
    """A damped block dropped from 2 cm onto a static box-shaped triangle mesh (a table top) comes to rest on it: no
    particle centre ever gets inside the mesh or closer to its top than r - 1 % of h, at the end the block's lowest
    particles sit one radius above the top (to 1 % of h) and over the last 0.05 s no particle moves more than 1 % of h
    (the reported velocities keep a residual a dt / 2 from the projection, as with the ground plane, so stillness is
    measured on positions)."""
    top = 0.0
    table = MeshCollider(pdsim.box((0.3, 0.3, 0.1), center=(0.0, 0.0, top - 0.05)), friction=0.5)
    soft = pdsim.Material(density=1000.0, youngs_modulus=2.0e5, poisson_ratio=0.25)
    block = pdsim.PeridynamicBody(pdsim.box((0.06, 0.06, 0.04), center=(0.0, 0.0, 0.04)), soft, H, damping=40.0)
    solver = ContactSolver([block], colliders=[table], gravity=(0.0, 0.0, -9.81))
    dt = 0.7 * solver.stable_time_step()
    r = 0.5 * H
    lowest = math.inf
    for _ in range(int(0.25 / dt)):
        solver.step(dt)
        lowest = min(lowest, float(solver.positions()[:, 2].min()))
    x_before = solver.positions().astype(np.float64)
    solver.simulate(dt, int(0.05 / dt))
    x = solver.positions().astype(np.float64)
    assert lowest > top + r - 0.01 * H
    assert abs(x[:, 2].min() - (top + r)) < 0.01 * H
    assert np.abs(x - x_before).max() < 0.01 * H
    assert x[:, 2].mean() < 0.03  # it did fall (the centre started at 0.04 m)


def test_scripted_box_projectile_follows_its_path_exactly():
    """A box projectile on a scripted path (translation along x while turning about z) sweeps through a free block:
    its pose at every step is the path's value, and after every step no particle is closer to the moving box's
    surface than its radius (signed distance of the oriented box evaluated in numpy at the path's pose)."""
    half = np.array([0.02, 0.03, 0.05])

    def path(t):
        angle = 20.0 * t
        rotation = np.array([0.0, 0.0, math.sin(0.5 * angle), math.cos(0.5 * angle)])
        return np.array([-0.06 + 2.0 * t, 0.0, 0.0]), rotation

    projectile = BoxProjectile(2.0 * half, path=path)
    block = pdsim.PeridynamicBody(pdsim.box((0.04, 0.08, 0.08), center=(0.02, 0.0, 0.0)), MAT, H)
    solver = ContactSolver([block], colliders=[projectile])
    dt = 0.7 * solver.stable_time_step()
    worst = -math.inf
    for _ in range(int(0.03 / dt)):
        solver.step(dt)
        p, q = projectile.pose(solver.time)
        p_ref, q_ref = path(solver.time)
        assert np.array_equal(p, p_ref) and np.allclose(q, q_ref / np.linalg.norm(q_ref), rtol=0, atol=1e-15)
        angle = 20.0 * solver.time
        rot = np.array([[math.cos(angle), -math.sin(angle), 0.0], [math.sin(angle), math.cos(angle), 0.0], [0, 0, 1]])
        local = (solver.positions().astype(np.float64) - p) @ rot  # R^T (x - p), row-wise
        qd = np.abs(local) - half
        sdf = np.linalg.norm(np.maximum(qd, 0.0), axis=1) + np.minimum(qd.max(axis=1), 0.0)
        worst = max(worst, (0.5 * H - sdf).max())
    assert worst < 1.0e-3 * H  # float32 positions
    assert np.abs(solver.velocities()).max() > 0.5  # the box did hit the block


def test_pair_force_damping_and_coulomb_friction():
    """Two particles of different bodies 0.8 h apart (contact distance R = 1.35 h): the normal force density is the
    penalty C V_j (R - r) (C = S / (12 (2 r)^3), S the continuum bond row sum); approaching at 1 m/s adds the dashpot
    zeta c_crit V_j |v_n|; sliding at 10 m/s gives a tangential force mu |f_n| opposing the slip (Coulomb), sliding at
    1 um/s the regularised viscous c_crit V_j |v_t| < mu |f_n|. The pair forces V_k f_k and V_j f_j cancel (to float32
    round-off)."""
    import warp as wp

    r, vol, rho = 0.5 * H, H**3, MAT.density
    mu_f, zeta = 0.3, 0.05
    contact = ParticleContact(
        np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]),
        [0, 1],
        r,
        vol,
        rho,
        MAT.bulk_modulus,
        MAT.shear_modulus,
        3.015 * H,
        friction=mu_f,
        damping_ratio=zeta,
        floor_factor=0.0,
    )
    C = bond_stiffness_row_sum(MAT.bulk_modulus, MAT.shear_modulus, 3.015 * H) / (12.0 * H**3)
    c_crit = 2.0 * math.sqrt(C * 0.5 * rho * vol / vol**2)
    x = wp.array(np.array([[0.0, 0.0, 0.0], [0.8 * H, 0.0, 0.0]], dtype=np.float32), dtype=wp.vec3)

    def force(v_k):
        v = wp.array(np.array([v_k, [0.0, 0.0, 0.0]], dtype=np.float32), dtype=wp.vec3)
        f = wp.zeros(2, dtype=wp.vec3)
        contact.apply(x, wp.zeros_like(x), v, f)
        f = f.numpy().astype(np.float64)
        np.testing.assert_allclose(f[0] * vol, -f[1] * vol, rtol=1e-6, atol=1e-6 * np.abs(f).max() * vol)
        return f[0]

    fn = C * vol * (1.35 - 0.8) * H
    np.testing.assert_allclose(force([0.0, 0.0, 0.0]), [-fn, 0.0, 0.0], rtol=1e-4)
    np.testing.assert_allclose(force([1.0, 0.0, 0.0]), [-fn - zeta * c_crit * vol * 1.0, 0.0, 0.0], rtol=1e-4)
    assert c_crit * vol * 10.0 > mu_f * fn  # sliding at 10 m/s: Coulomb regime
    np.testing.assert_allclose(force([0.0, 10.0, 0.0]), [-fn, -mu_f * fn, 0.0], rtol=1e-4)
    slow = force([0.0, 1.0e-6, 0.0])
    assert c_crit * vol * 1.0e-6 < mu_f * fn
    np.testing.assert_allclose(slow, [-fn, -c_crit * vol * 1.0e-6, 0.0], rtol=1e-3)


def test_stiffness_cap_holds_a_crowded_particle_to_twelve_contacts():
    """The stiffness cap (kernels/contact.py): a particle of one body with 18 particles of another on a sphere 0.9 h
    around it (18 contacts at R = 1.35 h; the 18 are one body at rest, so they do not repel each other). The first
    force pass applies the full stiffness, row sum 18 C V (C V = S / 12, S the continuum bond row sum), and sets the
    centre's scale for the next pass to the budget over its row sum, 12 / 18 (the others, one contact each, keep 1).
    The second pass scales every pair of the centre by 2/3: its row sum is then the budget 12 C V = S, each pair
    force 2/3 of the penalty C V (R - r), the pair energies 2/3 too, the pair forces still cancel (momentum exact), and
    the contact's stable step satisfies dt^2 S_contact <= 2 rho. Tolerances: float32 round-off (1e-5)."""
    import warp as wp

    n_out, r_shell = 18, 0.9 * H
    i = np.arange(n_out) + 0.5
    polar, azimuth = np.arccos(1.0 - 2.0 * i / n_out), math.pi * (1.0 + 5.0**0.5) * i  # Fibonacci sphere
    shell = r_shell * np.stack(
        [np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1
    )
    X = np.concatenate([np.zeros((1, 3)), shell])
    vol = H**3
    contact = ParticleContact(
        X, [0] + [1] * n_out, 0.5 * H, vol, MAT.density, MAT.bulk_modulus, MAT.shear_modulus, 3.015 * H
    )
    cv = bond_stiffness_row_sum(MAT.bulk_modulus, MAT.shear_modulus, 3.015 * H) / 12.0  # C V [N/m^4]
    x = wp.array(X.astype(np.float32), dtype=wp.vec3)
    zero = wp.zeros_like(x)
    penalty = cv * (1.35 * H - r_shell)

    def force_pass():
        f = wp.zeros(len(X), dtype=wp.vec3)
        contact.apply(x, wp.zeros_like(x), zero, f)
        return f.numpy().astype(np.float64)

    f1 = force_pass()
    d1 = contact.diagnostics(x)
    assert d1.count[0] == n_out and np.all(d1.count[1:] == 1)
    assert d1.row_sum[0] == pytest.approx(n_out * cv, rel=1e-5)
    np.testing.assert_allclose(np.linalg.norm(f1[1:], axis=1), penalty, rtol=1e-5)
    f2 = force_pass()
    d2 = contact.diagnostics(x)
    assert d2.row_sum[0] == pytest.approx(12.0 * cv, rel=1e-5)
    np.testing.assert_allclose(d2.row_sum[1:], cv * 12.0 / n_out, rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(f2[1:], axis=1), penalty * 12.0 / n_out, rtol=1e-5)
    assert d2.energy.sum() == pytest.approx(d1.energy.sum() * 12.0 / n_out, rel=1e-5)
    assert np.abs(f2.sum(axis=0)).max() < 1e-5 * penalty  # equal volumes: sum of V f is V sum f
    dt = contact.stable_time_step()
    assert dt**2 * d2.row_sum.max() <= 2.0 * MAT.density * (1.0 + 1e-5)
    assert dt**2 * d1.row_sum.max() > 2.0 * MAT.density  # uncapped, 18 contacts would need a smaller step


def test_exposure_marks_two_shells_and_crack_faces():
    """With shield_interior only particles within two lattice shells of a surface take part in contact: a cube of
    10^3 particles exposes 10^3 - 6^3 = 784. After a notch cuts it in two at x = 0 (bonds across start broken),
    update_exposure also exposes the two layers on each side of the cut: 784 + 6 * 6 * 4 = 928."""
    body = pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), MAT, H)
    contact = ParticleContact.from_bodies([body], shield_interior=True)
    assert contact.exposed_mask().sum() == 10**3 - 6**3
    body.add_notch(pdsim.BoxRegion(lo=(-1.0e-4, -1.0, -1.0), hi=(1.0e-4, 1.0, 1.0)))
    solver = pdsim.SolverPeridynamics([body])
    m = solver.model
    contact.update_exposure(m.family_offsets, m.family_neighbors, solver.state.bond_alive)
    exposed = contact.exposed_mask()
    assert exposed.sum() == 784 + 6 * 6 * 4
    near_cut = np.abs(body.rest_positions[:, 0]) < 2.0 * H
    assert exposed[near_cut].all()

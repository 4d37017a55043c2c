"""Bond kernels of the ordinary state-based peridynamic solid (the peridynamics supplement of the project
specification).

Notation: reference bond xi = X_j - X_k, L = |xi|, deformed eta = y_j - y_k, l = |eta|,
n = eta / l, extension e = l - L, weight w = delta / L, V_j the neighbour's volume and beta its
partial-volume factor. Per bond we store ``bond_geom = (xi / L, L)`` and ``bond_wv = w V_j beta``.

The supplement's model, with per-particle parameters a_k, b_k, d_k (the supplement's continuum values, or the same
matching conditions evaluated on each particle's discrete family, see pdsim/peridynamics/solver.py), without the
supplement's directional factor Lambda = n . xi / L (1 to first order in the strain, but not invariant under
rotation; pdsim/peridynamics/solver.py):

    theta_k = d_k sum_j w e V_j
    e^d_kj  = e - g_k theta_k,                     g_k = (5 mu / 6) d_k / b_k    (= delta / 4 for the continuum values)
    A_kj    = 4 w (a_k theta_k + b_k e^d_kj),      a_k = kappa d_k / 2           (= 9 kappa / (8 pi delta^4))
    f_k     = sum_j 1/2 (A_kj + A_jk) n V_j

Since a_k - b_k g_k = d_k (kappa / 2 - 5 mu / 6), A_kj / (4 w) = P_k + b_k e with P_k = d_k c0 theta_k and
c0 = kappa / 2 - 5 mu / 6. The dilatation kernel writes (b_k, P_k) per particle so the force kernel gathers one vec2
per neighbour. Both kernels are gathers over a CSR list (one thread per particle, no atomics); on the CPU the pair
form of the two passes runs instead (kernels/peridynamics/pairs.py: each bond pair once, the same per-bond
arithmetic and return mapping, the sums in another order).
"""

import numpy as np
import warp as wp

from ..launch import launch


@wp.kernel
def compute_family_moments(
    family_offsets: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_wv: wp.array(dtype=float),
    horizon: wp.array(dtype=float),
    volume_sum: wp.array(dtype=float),
    weighted_volume: wp.array(dtype=float),
):
    """Discrete family integrals used to calibrate d_k and b_k: volume_sum = sum_j V_j beta and
    weighted_volume m_k = sum_j w L^2 V_j beta (continuum values 4/3 pi delta^3 and pi delta^5)."""
    k = wp.tid()
    vs = float(0.0)
    m = float(0.0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        L = bond_geom[q][3]
        wv = bond_wv[q]
        vs += wv * L / horizon[k]
        m += wv * L * L
    volume_sum[k] = vs
    weighted_volume[k] = m


@wp.kernel
def compute_stiffness_row_sum(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_wv_dil: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
    dev_b: wp.array(dtype=float),
    dil_d: wp.array(dtype=float),
    dil_c0: wp.array(dtype=float),
    row_sum: wp.array(dtype=float),
):
    """Silling-Askari stiffness sum S_k = sum_j V_j C_kj [N/m^4] with the bond's effective spring constant
    C_kj = 2 w G^dev (b_k + b_j) for the deviatoric part, plus a Gershgorin bound |c0| d_k^2 (sum_j w V_j G^dil)^2
    for the dilatational coupling. The stable step is dt_k = sqrt(2 rho_k / S_k)."""
    k = wp.tid()
    dev = float(0.0)
    sw = float(0.0)
    bk = dev_b[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        dev += 2.0 * bond_wv_dev[q] * (bk + dev_b[family_neighbors[q]])
        sw += bond_wv_dil[q]
    d = dil_d[k]
    row_sum[k] = dev + wp.abs(dil_c0[k]) * d * d * sw * sw


@wp.kernel
def compute_bond_geometry(
    rest_positions: wp.array(dtype=wp.vec3),
    volumes: wp.array(dtype=float),
    horizon: wp.array(dtype=float),
    spacing: wp.array(dtype=float),
    partial_volumes: wp.array(dtype=wp.int32),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_wv: wp.array(dtype=float),
):
    """Per-bond constants: bond_geom = (xi / L, L) and bond_wv = w V_j beta with w = delta / L. With partial volumes
    the neighbour's volume counts by the fraction of its cell inside the horizon, beta = clamp((delta + h/2 - L) / h,
    0, 1) (linear approximation); otherwise beta = 1 and the family is cut at delta."""
    k = wp.tid()
    xk = rest_positions[k]
    delta = horizon[k]
    h = spacing[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        xi = rest_positions[j] - xk
        L = wp.length(xi)
        beta = float(1.0)
        if partial_volumes[k] != 0:
            beta = wp.clamp((delta + 0.5 * h - L) / h, 0.0, 1.0)
        bond_geom[q] = wp.vec4(xi[0] / L, xi[1] / L, xi[2] / L, L)
        bond_wv[q] = delta / L * volumes[j] * beta


@wp.kernel
def compute_directional_bond_factors(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_wv: wp.array(dtype=float),
    factor_dil: wp.array(dtype=wp.vec3),
    factor_dev: wp.array(dtype=wp.vec3),
    bond_wv_dil: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
):
    """Madenci-Oterkus surface correction. factor_*[k] holds particle k's correction for a uniaxial stretch along
    x, y, z (continuum value / discrete value). A bond uses the mean of its two particles' factors along each axis,
    interpolated over the ellipsoid G = (n_x^2 / Gx^2 + n_y^2 / Gy^2 + n_z^2 / Gz^2)^(-1/2) with n the reference bond
    direction; G is the same for bond kj and jk, so forces stay pairwise equal and opposite."""
    k = wp.tid()
    fdk = factor_dil[k]
    fbk = factor_dev[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        g = bond_geom[q]
        gd = 0.5 * (fdk + factor_dil[j])
        gb = 0.5 * (fbk + factor_dev[j])
        nx2 = g[0] * g[0]
        ny2 = g[1] * g[1]
        nz2 = g[2] * g[2]
        Gd = 1.0 / wp.sqrt(nx2 / (gd[0] * gd[0]) + ny2 / (gd[1] * gd[1]) + nz2 / (gd[2] * gd[2]))
        Gb = 1.0 / wp.sqrt(nx2 / (gb[0] * gb[0]) + ny2 / (gb[1] * gb[1]) + nz2 / (gb[2] * gb[2]))
        bond_wv_dil[q] = bond_wv[q] * Gd
        bond_wv_dev[q] = bond_wv[q] * Gb


@wp.func
def deformed_bond(xi: wp.vec3, du: wp.vec3, L: float):
    """The deformed bond of reference bond ``xi`` (|xi| = L [m]) whose ends moved apart by ``du`` [m]: its unit
    direction n = eta / |eta| (eta = xi + du) and its extension e = |eta| - L [m], evaluated as
    (2 xi . du + du . du) / (|eta| + L), which keeps float32's relative precision at any strain (|eta| - L would lose
    it to cancellation below a strain of about 1e-5)."""
    eta = xi + du
    length = wp.length(eta)
    n = eta * (1.0 / length)
    e = (2.0 * wp.dot(xi, du) + wp.dot(du, du)) / (length + L)
    return n, e


@wp.func
def deviatoric_norm_term(two_b: float, wv_dev: float, wv: float, L: float, ed: float, ep: float):
    """One bond's term of a particle's squared trial deviatoric force norm before the factor delta,
    (2 b w V beta G^dev (e^d - e^p))^2 / (w V beta L) [m^2 Pa^2 ...]: ``two_b`` = 2 b_k, ``wv_dev`` = w V beta G^dev,
    ``wv`` = w V beta [m^3], ``L`` [m], the deviatoric and plastic extensions ``ed``, ``ep`` [m]
    (kernels/peridynamics/step.py gives the return mapping)."""
    a = two_b * wv_dev * (ed - ep)
    return a * a / (wv * L)


@wp.func
def yield_ratio(norm2: float, delta: float, sigma_y: float, psi_scale: float):
    """The return mapping's scale r = sqrt(2 psi0 / ||t||^2) of a yielding particle's trial deviatoric force state,
    or -1 where it does not yield (||t||^2 / 2 <= psi0): ``norm2`` = ||t||^2 (the family sum of deviatoric_norm_term
    times delta), psi0 = psi_scale 10 sigma_y^2 / (3 pi delta^5) with the current yield stress ``sigma_y`` [Pa] and
    the horizon ``delta`` [m]."""
    psi0 = psi_scale * 10.0 * sigma_y * sigma_y / (3.0 * wp.pi * wp.pow(delta, 5.0))
    r = float(-1.0)
    if 0.5 * norm2 > psi0:
        r = wp.sqrt(2.0 * psi0 / norm2)
    return r


@wp.func
def returned_plastic_extension(ed: float, ep: float, r: float):
    """The plastic extension [m] after the return mapping of scale ``r`` (yield_ratio): e^p <- e^d - r (e^d - e^p),
    which leaves the deviatoric force alpha (e^d - e^p) scaled by r."""
    return ed - r * (ed - ep)


@wp.func
def bond_strength_factor(a: int, b: int, seed: int, modulus: float):
    """Weibull variate of shape ``modulus`` and unit median, (-ln(1 - U) / ln 2)^(1 / m), for the undirected bond
    between the body-local particle indices a and b: U comes from a PCG hash chain of (seed, min(a, b), max(a, b)),
    so both directed copies of a bond draw the same factor and the same seed gives the same factors."""
    lo = wp.min(a, b)
    hi = wp.max(a, b)
    s0 = wp.rand_init(seed, lo)
    s1 = wp.rand_init(wp.randi(s0), hi)
    u = wp.randf(s1)  # [0, 1)
    return wp.pow(-wp.log(1.0 - u) / wp.log(2.0), 1.0 / modulus)


STRENGTH_FIELD_MODES = 64  # cosine modes of a strength field (its one-point marginal is Gaussian to about 1 / N)


def strength_field_modes(correlation_length: float, seed: int, count: int = STRENGTH_FIELD_MODES) -> np.ndarray:
    """The modes of a Gaussian random field g(x) = sqrt(2 / N) sum_i cos(k_i . x + phi_i) with mean 0, variance 1
    and correlation E[g(x) g(x + r)] = exp(-|r|^2 / (2 l^2)) (spectral synthesis: k_i ~ N(0, I / l^2), phi_i uniform
    in [0, 2 pi)), drawn from ``seed`` (numpy's PCG64): float32 [count, 4] rows (k_i [1/m], phi_i [rad]). The same
    (correlation_length [m], seed) gives the same field."""
    rng = np.random.default_rng(int(seed))
    k = rng.standard_normal((count, 3)) / float(correlation_length)
    phase = rng.uniform(0.0, 2.0 * np.pi, count)
    return np.concatenate([k, phase[:, None]], axis=1).astype(np.float32)


@wp.func
def weibull_from_gaussian(g: float, modulus: float):
    """The Weibull variate of shape ``modulus`` and unit median, F = (-ln(1 - Phi(g)) / ln 2)^(1 / m), that has the
    same probability as the standard normal value g (Phi its CDF); each tail computed where float32 resolves it."""
    t = float(0.0)
    if g < 0.0:
        p = 0.5 * wp.erfc(-g / wp.sqrt(2.0))  # Phi(g), small: -ln(1 - p) by its series
        t = p * (1.0 + p * (0.5 + p / 3.0))
        if p > 1.0e-3:
            t = -wp.log(1.0 - p)
    else:
        t = -wp.log(0.5 * wp.erfc(g / wp.sqrt(2.0)))  # -ln(1 - Phi(g)), the upper tail 1 - Phi(g) kept exact
    return wp.pow(t / wp.log(2.0), 1.0 / modulus)


@wp.func
def strength_field_factor(x: wp.vec3, modes: wp.array(dtype=wp.vec4), first: int, count: int, modulus: float):
    """The strength factor of a field at the body-local point x [m]: the Gaussian field
    g(x) = sqrt(2 / N) sum_i cos(k_i . x + phi_i) over the modes [first, first + count) (strength_field_modes)
    mapped to the Weibull marginal of shape ``modulus`` and unit median (weibull_from_gaussian)."""
    acc = float(0.0)
    for i in range(first, first + count):
        m = modes[i]
        acc += wp.cos(m[0] * x[0] + m[1] * x[1] + m[2] * x[2] + m[3])
    return weibull_from_gaussian(acc * wp.sqrt(2.0 / float(count)), modulus)


@wp.kernel
def sample_strength_field(
    points: wp.array(dtype=wp.vec3),
    modes: wp.array(dtype=wp.vec4),
    mode_count: int,
    modulus: float,
    factor: wp.array(dtype=float),
):
    """The strength factor of one field (modes [0, mode_count)) at each body-local point [m]."""
    i = wp.tid()
    factor[i] = strength_field_factor(points[i], modes, 0, mode_count, modulus)


@wp.kernel
def init_bond_fracture(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    critical_stretch: wp.array(dtype=float),
    unbreakable: wp.array(dtype=wp.int32),
    axis: wp.array(dtype=wp.vec3),
    strength_ratio: wp.array(dtype=float),
    local_index: wp.array(dtype=wp.int32),
    weibull_modulus: wp.array(dtype=float),
    strength_seed: wp.array(dtype=wp.int32),
    field_positions: wp.array(dtype=wp.vec3),
    field_first_mode: wp.array(dtype=wp.int32),
    field_modes: wp.array(dtype=wp.vec4),
    field_mode_count: int,
    bond_critical_stretch: wp.array(dtype=float),
):
    """Per-bond critical stretch: s_c of the particle scaled by 1 - (1 - strength_ratio) (n . a)^2 about the world
    material axis a and, where the particle's weibull_modulus m > 0, by a Weibull factor of shape m and unit median:
    where the particle's field_first_mode >= 0, the body's strength field (strength_field_factor) at the bond's
    midpoint in body-local coordinates (field_positions [m]); else the bond's own factor (bond_strength_factor, from
    the two particles' body-local indices and the body's strength seed); infinite when either particle lies in an
    unbreakable region. Symmetric in k and j (bonds never join two bodies; the midpoint's sum commutes)."""
    k = wp.tid()
    a = axis[k]
    m = weibull_modulus[k]
    first = field_first_mode[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        g = bond_geom[q]
        c = wp.dot(wp.vec3(g[0], g[1], g[2]), a)
        sc = critical_stretch[k] * (1.0 - (1.0 - strength_ratio[k]) * c * c)
        if m > 0.0:
            if first >= 0:
                mid = 0.5 * (field_positions[k] + field_positions[j])
                sc = sc * strength_field_factor(mid, field_modes, first, field_mode_count, m)
            else:
                sc = sc * bond_strength_factor(local_index[k], local_index[j], strength_seed[k], m)
        if unbreakable[k] != 0 or unbreakable[j] != 0:
            sc = 1.0e30
        bond_critical_stretch[q] = sc


@wp.kernel
def strengthen_cell_interiors(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    cell: wp.array(dtype=wp.int32),
    cell_ratio: wp.array(dtype=float),
    bond_critical_stretch: wp.array(dtype=float),
):
    """Multiplies the critical stretch of each bond of particle k whose two particles lie in the same cell
    (cell[k] == cell[j] >= 0; a particle of a body without cells has -1) by the body's cell_ratio[k] (both directed
    copies: the test is symmetric and the ratio is the body's)."""
    k = wp.tid()
    c = cell[k]
    if c < 0:
        return
    r = cell_ratio[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        if cell[family_neighbors[q]] == c:
            bond_critical_stretch[q] = bond_critical_stretch[q] * r


@wp.kernel
def scale_anisotropic_stiffness(
    family_offsets: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    axis: wp.array(dtype=wp.vec3),
    stiffness_ratio: wp.array(dtype=float),
    bond_wv_dil: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
):
    """Scales both bond weights by 1 - (1 - stiffness_ratio) (n . a)^2 (the same for bond kj and jk, so the forces
    stay pairwise balanced and derivable from the energy)."""
    k = wp.tid()
    a = axis[k]
    r = stiffness_ratio[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        g = bond_geom[q]
        c = wp.dot(wp.vec3(g[0], g[1], g[2]), a)
        f = 1.0 - (1.0 - r) * c * c
        bond_wv_dil[q] = bond_wv_dil[q] * f
        bond_wv_dev[q] = bond_wv_dev[q] * f


@wp.kernel
def compute_plastic_norm_scale(
    family_offsets: wp.array(dtype=wp.int32),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_wv: wp.array(dtype=float),
    bond_wv_dev: wp.array(dtype=float),
    horizon: wp.array(dtype=float),
    b_ratio: wp.array(dtype=float),
    psi_scale: wp.array(dtype=float),
):
    """The family's share of the continuum deviatoric-force norm, s_k = (b_k / b)^2 sum_j G^2 V_j beta_j /
    (4/3 pi delta^3), so that a particle with a truncated family yields at the same stress as one in the bulk."""
    k = wp.tid()
    delta = horizon[k]
    acc = float(0.0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        wv = bond_wv[q]
        G = bond_wv_dev[q] / wv
        acc += G * G * wv * bond_geom[q][3] / delta
    r = b_ratio[k]
    psi_scale[k] = r * r * acc / (4.0 / 3.0 * wp.pi * delta * delta * delta)


# ---------------------------------------------------------------------------------------------------- launches
# One launch per kernel above, each over the ``count`` particles of the model (one thread per particle).


def bond_geometry(count, *, device, **arguments):
    """Writes bond_geom = (xi / L, L) and bond_wv = w V_j beta [m^3] (compute_bond_geometry)."""
    launch(compute_bond_geometry, count, device=device, **arguments)


def family_moments(count, *, device, **arguments):
    """Writes volume_sum [m^3] and weighted_volume m_k [m^5] (compute_family_moments)."""
    launch(compute_family_moments, count, device=device, **arguments)


def stiffness_row_sum(count, *, device, **arguments):
    """Writes the Silling-Askari stiffness sum S_k [N/m^4] (compute_stiffness_row_sum)."""
    launch(compute_stiffness_row_sum, count, device=device, **arguments)


def directional_bond_weights(count, *, device, **arguments):
    """Writes the surface-corrected bond weights bond_wv_dil, bond_wv_dev [m^3] (compute_directional_bond_factors)."""
    launch(compute_directional_bond_factors, count, device=device, **arguments)


def bond_strengths(count, *, device, **arguments):
    """Writes the critical stretch of every bond [-] (init_bond_fracture)."""
    launch(init_bond_fracture, count, device=device, **arguments)


def cell_strengths(count, *, device, **arguments):
    """Strengthens the bonds inside each cell of ``count`` particles (strengthen_cell_interiors)."""
    launch(strengthen_cell_interiors, count, device=device, **arguments)


def strength_field(count, *, device, **arguments):
    """Writes the strength factor of one field at ``count`` body-local points [-] (sample_strength_field)."""
    launch(sample_strength_field, count, device=device, **arguments)


def anisotropic_stiffness(count, *, device, **arguments):
    """Scales bond_wv_dil and bond_wv_dev in place by the anisotropy factor (scale_anisotropic_stiffness)."""
    launch(scale_anisotropic_stiffness, count, device=device, **arguments)


def plastic_norm_scale(count, *, device, **arguments):
    """Writes the family's share s_k of the continuum deviatoric-force norm [-] (compute_plastic_norm_scale)."""
    launch(compute_plastic_norm_scale, count, device=device, **arguments)

"""Peridynamic step kernels with optional plasticity and fracture, compiled per feature set.

``make_step_kernels(fracture, plastic)`` returns kernels in which the branches of features a scene does not use are
removed at code generation (``wp.static``), so an elastic scene runs exactly the elastic arithmetic. The kernels'
signatures are the same for every variant; arrays of dead features are passed as length-1 placeholders.

Formulas (kernels/peridynamics/bonds.py gives the notation and the elastic model):

- Elastic + plastic force: A_kj / (4 w) = Lambda P_k + b_k (e - e^p_kj), so
  f_k = sum_j 2 (w V beta G^dil Lambda (P_k + P_j) + w V beta G^dev (b_k (e - e^p_kj) + b_j (e - e^p_jk))) n,
  the derivative of W_k = c0 theta_k^2 + b_k sum_j w V beta G^dev (e - e^p_kj)^2 (e^p_kj: plastic extension).
- Plasticity (ordinary state-based, Mitchell 2011): per bond the deviatoric extension e^d = e - Lambda theta_p L / 3
  with theta_p = 3 sum_live w L e Lambda V beta / sum_live w L^2 V beta, which vanishes bond by bond under any
  isotropic expansion for every particle (the supplement's e - (delta/4) Lambda theta does so only on average over a
  full family, so a yield check on it would yield under pure hydrostatic load). Trial deviatoric
  force t_j = alpha_j (e^d_j - e^p_j), alpha_j = 2 w b_k G^dev; ||t||^2 = sum_j t_j^2 V_j beta_j;
  yield when ||t||^2 / 2 > psi0_k = s_k 10 sigma_Y(eps_p)^2 / (3 pi delta^5) (s_k: the family's share of the
  continuum norm, 1 in the bulk); then t <- t sqrt(2 psi0) / ||t|| and e^p_j = e^d_j - t_j / alpha_j.
  Linear hardening sigma_Y = sigma_Y0 + H eps_p with the equivalent plastic strain
  eps_p = sqrt(5 sum_j w (e^p_j)^2 V_j beta_j / m_k) (equal to the uniaxial plastic strain for isochoric flow).
- Fracture: a live bond breaks for good when its stretch (its elastic stretch, s - (e^p_kj + e^p_jk) / (2 L), for
  a yielding material) exceeds s_c,kj - alpha min(s_min,k, s_min,j) (Silling-Askari compressive bonus, s_min the
  particle's most compressive live stretch, <= 0, from this step's dilatation pass), or, for a ductile material,
  when the larger equivalent plastic strain of its two particles exceeds the failure plastic strain. The test runs
  at the end of the force pass, which already holds both directions' plastic extensions; both directed copies of a
  bond see the same quantities, so they break in the same step without communication.
"""

import warp as wp

_cache = {}


def make_step_kernels(fracture: bool, plastic: bool):
    """Kernels (dilatation, plastic_update, force, energy) for the given feature set, built once and cached."""
    key = (bool(fracture), bool(plastic))
    if key in _cache:
        return _cache[key]
    FRACTURE = key[0]
    PLASTIC = key[1]

    @wp.kernel(module="unique")
    def dilatation(
        displacements: wp.array(dtype=wp.vec3),
        family_offsets: wp.array(dtype=wp.int32),
        family_neighbors: wp.array(dtype=wp.int32),
        bond_geom: wp.array(dtype=wp.vec4),
        bond_wv_dil: wp.array(dtype=float),
        dil_d: wp.array(dtype=float),
        dil_coef: wp.array(dtype=float),
        dev_b: wp.array(dtype=float),
        bond_alive: wp.array(dtype=wp.uint8),
        theta: wp.array(dtype=float),
        bp: wp.array(dtype=wp.vec2),
        bond_ne: wp.array(dtype=wp.vec4),
        bond_lambda: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
    ):
        """theta_k = d_k sum_live w e Lambda V beta G^dil; caches each bond's (n, e) and Lambda for the later passes
        and, with fracture, the particle's most compressive live stretch (for the compressive bonus).

        The deformed bond is eta = xi + (u_j - u_k) with xi the reference bond, and the extension is evaluated as
        e = |eta| - L = (2 xi . du + du . du) / (|eta| + L), which keeps float32's relative precision at any strain
        (|eta| - L would lose it to cancellation below a strain of about 1e-5)."""
        k = wp.tid()
        uk = displacements[k]
        acc = float(0.0)
        smin = float(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            g = bond_geom[q]
            L = g[3]
            xi = wp.vec3(g[0], g[1], g[2]) * L
            du = displacements[family_neighbors[q]] - uk
            eta = xi + du
            length = wp.length(eta)
            n = eta / length
            lam = wp.dot(n, wp.vec3(g[0], g[1], g[2]))
            e = (2.0 * wp.dot(xi, du) + wp.dot(du, du)) / (length + L)
            bond_ne[q] = wp.vec4(n[0], n[1], n[2], e)
            bond_lambda[q] = lam
            live = int(1)
            if wp.static(FRACTURE):
                live = int(bond_alive[q])
                if live != 0:
                    smin = wp.min(smin, e / g[3])
            if live != 0:
                acc += bond_wv_dil[q] * e * lam
        th = dil_d[k] * acc
        theta[k] = th
        bp[k] = wp.vec2(dev_b[k], dil_coef[k] * th)
        if wp.static(FRACTURE):
            stretch_min[k] = smin

    @wp.kernel(module="unique")
    def plastic_update(
        family_offsets: wp.array(dtype=wp.int32),
        bond_geom: wp.array(dtype=wp.vec4),
        bond_wv: wp.array(dtype=float),
        bond_wv_dev: wp.array(dtype=float),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_ne: wp.array(dtype=wp.vec4),
        bond_lambda: wp.array(dtype=float),
        theta: wp.array(dtype=float),
        dev_b: wp.array(dtype=float),
        horizon: wp.array(dtype=float),
        weighted_volume: wp.array(dtype=float),
        yield_stress: wp.array(dtype=float),
        hardening: wp.array(dtype=float),
        psi_scale: wp.array(dtype=float),
        bond_plastic: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
    ):
        """Return mapping of the deviatoric force state at particle k (launched over yielding particles only)."""
        k = wp.tid()
        delta = horizon[k]
        bk = dev_b[k]
        sigma_y = yield_stress[k] + hardening[k] * eqps[k]
        psi0 = psi_scale[k] * 10.0 * sigma_y * sigma_y / (3.0 * wp.pi * wp.pow(delta, 5.0))
        # volumetric strain of the live family, theta_p = 3 sum w L e Lambda V beta / sum w L^2 V beta: exactly
        # 3 zeta under any isotropic expansion zeta, for every particle (surface or cracked), so the deviatoric part
        # below vanishes bond by bond and hydrostatic load never yields
        num = float(0.0)
        den = float(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            live = int(1)
            if wp.static(FRACTURE):
                live = int(bond_alive[q])
            if live != 0:
                L = bond_geom[q][3]
                num += bond_wv[q] * L * bond_ne[q][3] * bond_lambda[q]
                den += bond_wv[q] * L * L
        th = float(0.0)
        if den > 0.0:
            th = 3.0 * num / den
        norm2 = float(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            live = int(1)
            if wp.static(FRACTURE):
                live = int(bond_alive[q])
            if live != 0:
                L = bond_geom[q][3]
                vb = bond_wv[q] * L / delta  # V_j beta_j
                alpha = 2.0 * bk * bond_wv_dev[q] / vb  # 2 w b G
                ed = bond_ne[q][3] - bond_lambda[q] * th * L / 3.0
                t = alpha * (ed - bond_plastic[q])
                norm2 += t * t * vb
        if 0.5 * norm2 > psi0:
            r = wp.sqrt(2.0 * psi0 / norm2)
            acc = float(0.0)
            for q in range(family_offsets[k], family_offsets[k + 1]):
                live = int(1)
                if wp.static(FRACTURE):
                    live = int(bond_alive[q])
                if live != 0:
                    L = bond_geom[q][3]
                    ed = bond_ne[q][3] - bond_lambda[q] * th * L / 3.0
                    ep = ed - r * (ed - bond_plastic[q])
                    bond_plastic[q] = ep
                acc += bond_wv[q] * bond_plastic[q] * bond_plastic[q]
            m = weighted_volume[k]
            if m > 0.0:
                eqps[k] = wp.sqrt(5.0 * acc / m)

    @wp.kernel(module="unique")
    def force(
        family_offsets: wp.array(dtype=wp.int32),
        family_neighbors: wp.array(dtype=wp.int32),
        bond_geom: wp.array(dtype=wp.vec4),
        bond_ne: wp.array(dtype=wp.vec4),
        bond_lambda: wp.array(dtype=float),
        bond_wv_dil: wp.array(dtype=float),
        bond_wv_dev: wp.array(dtype=float),
        bp: wp.array(dtype=wp.vec2),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_critical_stretch: wp.array(dtype=float),
        bonus_alpha: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
        failure_eqps: wp.array(dtype=float),
        plastic_bond_count: int,
        bond_plastic: wp.array(dtype=float),
        bond_reverse: wp.array(dtype=wp.int32),
        force_density: wp.array(dtype=wp.vec3),
    ):
        """Force density [N/m^3] over live bonds, with plastic extensions where the material yields; then, with
        fracture, the breaking test of each live bond (it takes effect from the next pass). The test reads only
        quantities both directed copies of a bond share, so both break in the same step."""
        k = wp.tid()
        bpk = bp[k]
        f = wp.vec3(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            live = int(1)
            if wp.static(FRACTURE):
                live = int(bond_alive[q])
            if live != 0:
                j = family_neighbors[q]
                c = bond_ne[q]
                bpj = bp[j]
                dev = (bpk[0] + bpj[0]) * c[3]
                ep_sum = float(0.0)
                if wp.static(PLASTIC):
                    if q < plastic_bond_count:
                        ep_k = bond_plastic[q]
                        ep_j = bond_plastic[bond_reverse[q]]
                        dev = dev - bpk[0] * ep_k - bpj[0] * ep_j
                        ep_sum = ep_k + ep_j
                s = bond_wv_dil[q] * bond_lambda[q] * (bpk[1] + bpj[1]) + bond_wv_dev[q] * dev
                f += (2.0 * s) * wp.vec3(c[0], c[1], c[2])
                if wp.static(FRACTURE):
                    L = bond_geom[q][3]
                    stretch = c[3] / L
                    broke = int(0)
                    if wp.static(PLASTIC):
                        if q < plastic_bond_count:
                            if stretch > 0.0 and wp.max(eqps[k], eqps[j]) > failure_eqps[k]:
                                broke = 1
                    sc = bond_critical_stretch[q] - bonus_alpha[k] * wp.min(stretch_min[k], stretch_min[j])
                    if stretch - 0.5 * ep_sum / L > sc:
                        broke = 1
                    if broke != 0:
                        bond_alive[q] = wp.uint8(0)
        force_density[k] = f

    @wp.kernel(module="unique")
    def energy(
        family_offsets: wp.array(dtype=wp.int32),
        bond_ne: wp.array(dtype=wp.vec4),
        bond_wv_dev: wp.array(dtype=float),
        bond_alive: wp.array(dtype=wp.uint8),
        plastic_bond_count: int,
        bond_plastic: wp.array(dtype=float),
        theta: wp.array(dtype=float),
        dev_b: wp.array(dtype=float),
        dil_c0: wp.array(dtype=float),
        energy_density: wp.array(dtype=float),
    ):
        """Elastic energy density W_k = c0 theta_k^2 + b_k sum_live w V beta G^dev (e - e^p)^2 [J/m^3]."""
        k = wp.tid()
        acc = float(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            live = int(1)
            if wp.static(FRACTURE):
                live = int(bond_alive[q])
            if live != 0:
                e = bond_ne[q][3]
                if wp.static(PLASTIC):
                    if q < plastic_bond_count:
                        e = e - bond_plastic[q]
                acc += bond_wv_dev[q] * e * e
        th = theta[k]
        energy_density[k] = dil_c0[k] * th * th + dev_b[k] * acc

    class StepKernels:
        pass

    ks = StepKernels()
    ks.dilatation, ks.plastic_update, ks.force, ks.energy = dilatation, plastic_update, force, energy
    _cache[key] = ks
    return ks


@wp.kernel
def compose_positions(
    rest_positions: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    positions: wp.array(dtype=wp.vec3),
):
    """positions = rest + u [m] in the solver's local frame (for the contact pass's hash grid)."""
    i = wp.tid()
    positions[i] = rest_positions[i] + displacements[i]


@wp.kernel
def compute_damage(
    family_offsets: wp.array(dtype=wp.int32),
    bond_wv: wp.array(dtype=float),
    bond_alive: wp.array(dtype=wp.uint8),
    damage: wp.array(dtype=float),
):
    """phi_k = 1 - (sum_live w V beta) / (sum_all w V beta), in [0, 1]."""
    k = wp.tid()
    total = float(0.0)
    live = float(0.0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        wv = bond_wv[q]
        total += wv
        if bond_alive[q] != wp.uint8(0):
            live += wv
    d = float(0.0)
    if total > 0.0:
        d = 1.0 - live / total
    damage[k] = d


@wp.kernel
def find_reverse_bonds(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_reverse: wp.array(dtype=wp.int32),
):
    """bond_reverse[q] = index of bond j -> k for bond q = k -> j (launched over the particles whose bonds need it)."""
    k = wp.tid()
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        r = int(-1)
        for p in range(family_offsets[j], family_offsets[j + 1]):
            if family_neighbors[p] == k:
                r = p
        bond_reverse[q] = r


@wp.kernel
def break_bonds_crossing_box(
    first: int,
    rest_positions: wp.array(dtype=wp.vec3),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    lo: wp.vec3,
    hi: wp.vec3,
    bond_alive: wp.array(dtype=wp.uint8),
):
    """Pre-cut notch: breaks every bond whose reference segment X_k -> X_j passes through the box [lo, hi]
    (slab test), for the particles first + tid. Symmetric: bond k -> j and j -> k test the same segment."""
    k = first + wp.tid()
    a = rest_positions[k]
    for q in range(family_offsets[k], family_offsets[k + 1]):
        d = rest_positions[family_neighbors[q]] - a
        t0 = float(0.0)
        t1 = float(1.0)
        hit = int(1)
        for ax in range(3):
            if wp.abs(d[ax]) < 1.0e-12:
                if a[ax] < lo[ax] or a[ax] > hi[ax]:
                    hit = 0
            else:
                ta = (lo[ax] - a[ax]) / d[ax]
                tb = (hi[ax] - a[ax]) / d[ax]
                t0 = wp.max(t0, wp.min(ta, tb))
                t1 = wp.min(t1, wp.max(ta, tb))
        if hit != 0 and t0 <= t1:
            bond_alive[q] = wp.uint8(0)


@wp.kernel
def break_bonds_crossing_mesh(
    first: int,
    mesh: wp.uint64,
    rest_positions: wp.array(dtype=wp.vec3),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_alive: wp.array(dtype=wp.uint8),
):
    """Pre-cut notch: breaks every bond whose reference segment crosses the triangle surface ``mesh``. The ray is cast
    from the lower-indexed particle so both directed copies get the same answer (particles first + tid)."""
    k = first + wp.tid()
    for q in range(family_offsets[k], family_offsets[k + 1]):
        j = family_neighbors[q]
        a = rest_positions[wp.min(k, j)]
        b = rest_positions[wp.max(k, j)]
        d = b - a
        L = wp.length(d)
        hit = wp.mesh_query_ray(mesh, a, d / L, L)
        if hit.result:
            bond_alive[q] = wp.uint8(0)

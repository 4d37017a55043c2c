"""Peridynamic step kernels with optional plasticity and fracture, compiled per feature set.

``make_step_kernels(fracture, plastic)`` returns kernels in which the branches of features a scene does not use are
removed at code generation (``wp.static``), so an elastic scene runs exactly the elastic arithmetic. The kernels'
signatures are the same for every variant; arrays of dead features are passed as length-1 placeholders.

Formulas (kernels/peridynamics/bonds.py gives the notation and the elastic model):

- Elastic + plastic force: A_kj / (4 w) = Lambda P_k + b_k (e - e^p_kj), so
  f_k = sum_j 2 (w V beta G^dil Lambda (P_k + P_j) + w V beta G^dev (b_k (e - e^p_kj) + b_j (e - e^p_jk))) n,
  the derivative of W_k = c0 theta_k^2 + b_k sum_j w V beta G^dev (e - e^p_kj)^2 (e^p_kj: plastic extension) with
  theta_k = d_k sum_j w V beta G^dil (e - e^p_kj) Lambda, the dilatation of the elastic extensions: W_k depends on
  e - e^p only, so plastic flow leaves no stress behind.
- Plasticity (ordinary state-based after Mitchell 2011, with a finite-strain volumetric split): the deviatoric part
  of a bond's elastic extension is e^d - e^p = e - e^p - Lambda L theta_p / 3 with theta_p / 3 = J^(1/3) - 1 and
  J = det F the volume ratio of the family's deformation F = I + G K^-1, G = sum_live w V beta du xi^T,
  K = sum_live w V beta xi xi^T (the shape tensor), all from the dilatation loop. J is exact for every affine
  deformation of any family (surface or cracked), so e^d - e^p vanishes bond by bond under an isotropic expansion
  (hydrostatic load never yields) and an isochoric stretch of any size (J = 1) counts as deviatoric in full. The
  family's mean extension, 3 sum w L e Lambda V beta / sum w L^2 V beta, is exact only for the isotropic expansion:
  it reads 0.086 for the isochoric stretch diag(l, l^-1/2, l^-1/2) at l = 1.3 (0.011 at l = 1.1), which as a
  volumetric split held that much of a pulled bar's plastic stretch elastic, as a spurious pressure of kappa theta or
  a loss of volume (docs/accuracy.md). Where the live family does not span space (det K < 1e-2 (tr K / 3)^3, a
  particle left with a sheet or a line of bonds), theta_p = 0. Trial deviatoric force t_j = alpha_j (e^d_j - e^p_j),
  alpha_j = 2 w b_k G^dev; ||t||^2 = sum_j t_j^2 V_j beta_j, accumulated in the dilatation loop as a quadratic in
  theta_p / 3 (no second pass over the family);
  yield when ||t||^2 / 2 > psi0_k = s_k 10 sigma_Y(eps_p)^2 / (3 pi delta^5) (s_k: the family's share of the
  continuum norm, 1 in the bulk); then t <- t sqrt(2 psi0) / ||t|| and e^p_j = e^d_j - t_j / alpha_j.
  Linear hardening sigma_Y = sigma_Y0 + H eps_p with the equivalent plastic strain
  eps_p = sqrt(5 sum_j w (e^p_j)^2 V_j beta_j / m_k) (equal to the uniaxial plastic strain for isochoric flow).
  The return mapping runs in the dilatation kernel, right after a yielding particle's family sums (its bonds'
  (n, e, Lambda) are then still in cache), and recomputes theta_k from the new plastic extensions.
- Fracture: a live bond breaks for good when its stretch (its elastic stretch, s - (e^p_kj + e^p_jk) / (2 L), for
  a yielding material) exceeds s_c,kj - alpha min(s_min,k, s_min,j) (Silling-Askari compressive bonus, s_min the
  particle's most compressive live stretch, <= 0, from this step's dilatation pass), or, for a ductile material,
  when the larger equivalent plastic strain of its two particles exceeds the failure plastic strain. The test runs
  at the end of the force pass, which already holds both directions' plastic extensions; both directed copies of a
  bond see the same quantities, so they break in the same step without communication. Broken bonds are skipped by
  every pass after the flag (their cached (n, e) is left as it was).

A step is two passes over the particles, dilatation (with the plastic update) then force, each launched over
contiguous particle ranges (pdsim/peridynamics/solver.py, ParticleRanges): a kernel writes only its particles' rows
and their own bonds' rows (and, for the mirror of the plastic extensions, the one slot each of its bonds owns at the
reverse bond, read only by the next pass), and reads other particles' rows only from what an earlier pass wrote.
"""

import warp as wp

_cache = {}


def make_step_kernels(fracture: bool, plastic: bool):
    """Kernels (dilatation with the fused plastic update, force, energy) for the given feature set, built once and
    cached. Every kernel takes the first particle of its launch (``first``): a launch covers the particles
    first .. first + dim - 1, and each writes only its particles' rows and their bonds' rows (bonds are stored per
    particle family; the plastic mirror is the one exception, module docstring), so launches over disjoint particle
    ranges of one pass can run at the same time."""
    key = (bool(fracture), bool(plastic))
    if key in _cache:
        return _cache[key]
    FRACTURE = key[0]
    PLASTIC = key[1]

    @wp.kernel(module="unique")
    def dilatation(
        first: int,
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
        plastic_particle_count: int,
        bond_wv: wp.array(dtype=float),
        bond_wv_dev: wp.array(dtype=float),
        horizon: wp.array(dtype=float),
        weighted_volume: wp.array(dtype=float),
        yield_stress: wp.array(dtype=float),
        hardening: wp.array(dtype=float),
        psi_scale: wp.array(dtype=float),
        bond_plastic: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
        bond_reverse: wp.array(dtype=wp.int32),
        bond_plastic_reverse: wp.array(dtype=float),
    ):
        """theta_k = d_k sum_live w (e - e^p) Lambda V beta G^dil for particle k = first + tid (e^p = 0 where the
        material does not yield); caches each live bond's (n, e) and Lambda for the later passes and, with fracture,
        the particle's most compressive live stretch (for the compressive bonus). With plasticity, a yielding particle
        (k < plastic_particle_count) also sums its family's deformation (G, K) and the trial norm's terms in the same
        loop, then runs the return mapping on the bonds it just cached (the plastic update: it writes its own bonds'
        plastic extensions and its own equivalent plastic strain, mirrors each new extension e^p_kj into
        ``bond_plastic_reverse`` at the reverse bond j -> k, the one slot of that array bond k -> j owns, which no
        kernel reads before the force pass, and recomputes theta_k with the new extensions).

        The deformed bond is eta = xi + (u_j - u_k) with xi the reference bond, and the extension is evaluated as
        e = |eta| - L = (2 xi . du + du . du) / (|eta| + L), which keeps float32's relative precision at any strain
        (|eta| - L would lose it to cancellation below a strain of about 1e-5). A broken bond is skipped: no later pass
        reads its cache."""
        k = first + wp.tid()
        uk = displacements[k]
        acc = float(0.0)
        smin = float(0.0)
        yields = int(0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                yields = 1
        # yielding particles: rows of G = sum w V beta du xi^T and K = sum w V beta xi xi^T over the live family, and
        # the trial norm ||t||^2 / (4 b^2 delta) = sum c (x - u y)^2 = na - 2 nb y + nc y^2 with x = e - e^p,
        # u = Lambda L, y = theta_p / 3 and c = (w V beta G^dev)^2 / (w V beta L) (V beta = w V beta L / delta)
        gx = wp.vec3(0.0)
        gy = wp.vec3(0.0)
        gz = wp.vec3(0.0)
        kx = wp.vec3(0.0)
        ky = wp.vec3(0.0)
        kz = wp.vec3(0.0)
        na = float(0.0)
        nb = float(0.0)
        nc = float(0.0)
        for q in range(family_offsets[k], family_offsets[k + 1]):
            if wp.static(FRACTURE):
                if bond_alive[q] == wp.uint8(0):
                    continue
            g = bond_geom[q]
            L = g[3]
            xh = wp.vec3(g[0], g[1], g[2])
            xi = xh * L
            du = displacements[family_neighbors[q]] - uk
            eta = xi + du
            length = wp.length(eta)
            inv = 1.0 / length
            n = eta * inv
            lam = wp.dot(n, xh)
            e = (2.0 * wp.dot(xi, du) + wp.dot(du, du)) / (length + L)
            bond_ne[q] = wp.vec4(n[0], n[1], n[2], e)
            bond_lambda[q] = lam
            if wp.static(FRACTURE):
                smin = wp.min(smin, e / L)
            x = e
            if wp.static(PLASTIC):
                if yields != 0:
                    x = e - bond_plastic[q]
                    wv = bond_wv[q]
                    wx = xi * wv
                    gx += du[0] * wx
                    gy += du[1] * wx
                    gz += du[2] * wx
                    kx += xi[0] * wx
                    ky += xi[1] * wx
                    kz += xi[2] * wx
                    wd = bond_wv_dev[q]
                    c = wd * wd / (wv * L)
                    u = lam * L
                    cx = c * x
                    na += cx * x
                    nb += cx * u
                    nc += c * u * u
            acc += bond_wv_dil[q] * x * lam
        bk = dev_b[k]
        if wp.static(FRACTURE):
            stretch_min[k] = smin
        if wp.static(PLASTIC):
            if yields != 0:
                # Return mapping (module docstring). K is scaled to a unit mean eigenvalue before the determinant
                # test and the inverse (its entries scale as h^5: float32 would underflow in det K at mm spacings);
                # J - 1 = tr H + (tr^2 H - tr H^2) / 2 + det H and J^(1/3) - 1 = (J - 1) / (j^2 + j + 1),
                # j = J^(1/3), keep the relative precision of small strains.
                delta = horizon[k]
                sigma_y = yield_stress[k] + hardening[k] * eqps[k]
                psi0 = psi_scale[k] * 10.0 * sigma_y * sigma_y / (3.0 * wp.pi * wp.pow(delta, 5.0))
                th3 = float(0.0)  # theta_p / 3 = J^(1/3) - 1
                tk = kx[0] + ky[1] + kz[2]
                if tk > 0.0:  # some live bond
                    sk = 3.0 / tk
                    km = wp.matrix_from_rows(kx, ky, kz) * sk
                    if wp.determinant(km) > 1.0e-2:
                        hm = wp.matrix_from_rows(gx, gy, gz) * sk * wp.inverse(km)
                        tr = wp.trace(hm)
                        jm1 = tr + 0.5 * (tr * tr - wp.trace(hm * hm)) + wp.determinant(hm)
                        jc = 1.0 + jm1
                        cb = wp.sign(jc) * wp.pow(wp.abs(jc), 1.0 / 3.0)
                        th3 = jm1 / (cb * cb + cb + 1.0)
                # ||t||^2 / 2 > psi0 as quad > psi0 / (2 b^2 delta) (b^2 alone would overflow float32 at mm horizons)
                quad = na - 2.0 * nb * th3 + nc * th3 * th3
                q_yield = psi0 / bk / bk / (2.0 * delta)
                if quad > q_yield:
                    r = wp.sqrt(q_yield / quad)
                    ep2 = float(0.0)
                    acc_new = float(0.0)
                    for q in range(family_offsets[k], family_offsets[k + 1]):
                        live = int(1)
                        if wp.static(FRACTURE):
                            live = int(bond_alive[q])
                        ep = bond_plastic[q]
                        if live != 0:
                            eq = bond_ne[q][3]
                            lq = bond_lambda[q]
                            ed = eq - lq * th3 * bond_geom[q][3]
                            ep = ed - r * (ed - ep)
                            bond_plastic[q] = ep
                            bond_plastic_reverse[bond_reverse[q]] = ep
                            acc_new += bond_wv_dil[q] * (eq - ep) * lq
                        ep2 += bond_wv[q] * ep * ep
                    acc = acc_new
                    m = weighted_volume[k]
                    if m > 0.0:
                        eqps[k] = wp.sqrt(5.0 * ep2 / m)
        th = dil_d[k] * acc
        theta[k] = th
        bp[k] = wp.vec2(bk, dil_coef[k] * th)

    @wp.kernel(module="unique")
    def force(
        first: int,
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
        bond_plastic_reverse: wp.array(dtype=float),
        force_density: wp.array(dtype=wp.vec3),
    ):
        """Force density [N/m^3] at particle k = first + tid over live bonds, with plastic extensions where the
        material yields; then, with fracture, the breaking test of each live bond (it takes effect from the next
        pass). The test reads only quantities both directed copies of a bond share, so both break in the same step.
        It compares extensions, e - (e^p_kj + e^p_jk) / 2 > s_c L, rather than stretches (no division per bond)."""
        k = first + wp.tid()
        bpk = bp[k]
        f = wp.vec3(0.0)
        smin_k = float(0.0)
        alpha_k = float(0.0)
        eqps_k = float(0.0)
        fail_k = float(0.0)
        if wp.static(FRACTURE):
            smin_k = stretch_min[k]
            alpha_k = bonus_alpha[k]
            if wp.static(PLASTIC):
                eqps_k = eqps[k]
                fail_k = failure_eqps[k]
        for q in range(family_offsets[k], family_offsets[k + 1]):
            if wp.static(FRACTURE):
                if bond_alive[q] == wp.uint8(0):
                    continue
            j = family_neighbors[q]
            c = bond_ne[q]
            bpj = bp[j]
            dev = (bpk[0] + bpj[0]) * c[3]
            ep_sum = float(0.0)
            if wp.static(PLASTIC):
                if q < plastic_bond_count:
                    ep_k = bond_plastic[q]
                    ep_j = bond_plastic_reverse[q]  # e^p_jk, kept beside bond q (no gather)
                    dev = dev - bpk[0] * ep_k - bpj[0] * ep_j
                    ep_sum = ep_k + ep_j
            s = bond_wv_dil[q] * bond_lambda[q] * (bpk[1] + bpj[1]) + bond_wv_dev[q] * dev
            f += (2.0 * s) * wp.vec3(c[0], c[1], c[2])
            if wp.static(FRACTURE):
                broke = int(0)
                if wp.static(PLASTIC):
                    if q < plastic_bond_count:
                        if c[3] > 0.0 and wp.max(eqps_k, eqps[j]) > fail_k:
                            broke = 1
                sc = bond_critical_stretch[q] - alpha_k * wp.min(smin_k, stretch_min[j])
                if c[3] - 0.5 * ep_sum > sc * bond_geom[q][3]:
                    broke = 1
                if broke != 0:
                    bond_alive[q] = wp.uint8(0)
        force_density[k] = f

    @wp.kernel(module="unique")
    def energy(
        first: int,
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
        """Elastic energy density W_k = c0 theta_k^2 + b_k sum_live w V beta G^dev (e - e^p)^2 [J/m^3] at particle
        k = first + tid (theta_k: the dilatation pass's, of the elastic extensions e - e^p)."""
        k = first + wp.tid()
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
    ks.dilatation, ks.force, ks.energy = dilatation, force, energy
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
    first: int,
    family_offsets: wp.array(dtype=wp.int32),
    bond_wv: wp.array(dtype=float),
    bond_alive: wp.array(dtype=wp.uint8),
    damage: wp.array(dtype=float),
):
    """phi_k = 1 - (sum_live w V beta) / (sum_all w V beta), in [0, 1], at particle k = first + tid."""
    k = first + wp.tid()
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
def mirror_plastic_extensions(
    bond_reverse: wp.array(dtype=wp.int32),
    bond_plastic: wp.array(dtype=float),
    bond_plastic_reverse: wp.array(dtype=float),
):
    """bond_plastic_reverse[q] = bond_plastic[reverse of q] for every plastic bond q (after a state is restored)."""
    q = wp.tid()
    bond_plastic_reverse[q] = bond_plastic[bond_reverse[q]]


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

"""Peridynamic step kernels with optional plasticity and fracture, compiled per feature set.

``make_step_kernels(fracture, plastic)`` returns kernels in which the branches of features a scene does not use are
removed at code generation (``wp.static``), so an elastic scene runs exactly the elastic arithmetic. The kernels'
signatures are the same for every variant; arrays of dead features are passed as length-1 placeholders.

Formulas (kernels/peridynamics/bonds.py gives the notation and the elastic model):

- Elastic + plastic force: A_kj / (4 w) = P_k + b_k (e - e^p_kj), so
  f_k = sum_j 2 (w V beta G^dil (P_k + P_j) + w V beta G^dev (b_k (e - e^p_kj) + b_j (e - e^p_jk))) n,
  the derivative of W_k = c0 theta_k^2 + b_k sum_j w V beta G^dev (e - e^p_kj)^2 (e^p_kj: plastic extension).
- Plasticity (ordinary state-based, Mitchell 2011): per bond the deviatoric extension e^d = e - theta_p L / 3
  with theta_p = 3 sum_live w L e V beta / sum_live w L^2 V beta, which vanishes bond by bond under any
  isotropic expansion for every particle (the supplement's e - (delta/4) theta does so only on average over a
  full family, so a yield check on it would yield under pure hydrostatic load). Trial deviatoric
  force t_j = alpha_j (e^d_j - e^p_j), alpha_j = 2 w b_k G^dev; ||t||^2 = sum_j t_j^2 V_j beta_j;
  yield when ||t||^2 / 2 > psi0_k = s_k 10 sigma_Y(eps_p)^2 / (3 pi delta^5) (s_k: the family's share of the
  continuum norm, 1 in the bulk); then t <- t sqrt(2 psi0) / ||t|| and e^p_j = e^d_j - t_j / alpha_j.
  Linear hardening sigma_Y = sigma_Y0 + H eps_p with the equivalent plastic strain
  eps_p = sqrt(5 sum_j w (e^p_j)^2 V_j beta_j / m_k) (equal to the uniaxial plastic strain for isochoric flow).
  The return mapping runs in the dilatation kernel, right after a yielding particle's family sums (its bonds'
  (n, e) are then still in cache, and the volumetric sums of theta_p come with the dilatation's loop); the CPU's pair
  form runs the same arithmetic in pair passes (kernels/peridynamics/pairs.py).
- Internal damping (Material.retardation_time tau, a Kelvin-Voigt solid): each live bond's deviatoric term also
  carries (tau_k b_k + tau_j b_j) e_dot, e_dot = (v_j - v_k) . n its extension rate (``damping_b`` = tau_k b_k per
  particle), so f_k += sum_j 2 w V beta G^dev (tau_k b_k + tau_j b_j) e_dot n: tau times the b term of the elastic
  force evaluated on the velocities. Where the elastic model has no c0 term (Poisson's ratio 1/4) the damping is
  exactly stiffness-proportional: a linear vibration of angular frequency omega has the damping ratio omega tau / 2,
  and the continuum limit is a solid whose viscous stress is tau times the elastic stress of the strain rate; at
  another Poisson's ratio the shear viscosity is tau mu and the bulk viscosity 5 tau mu / 3 (tau kappa at 1/4). The
  force is central and equal and opposite on a bond's two ends (momentum and angular momentum are kept) and vanishes
  under any rigid motion. It is not part of the breaking test (the stretch is).
- Fracture: a live bond breaks for good when its stretch (its elastic stretch, s - (e^p_kj + e^p_jk) / (2 L), for
  a yielding material) exceeds s_c,kj - alpha min(s_min,k, s_min,j) (Silling-Askari compressive bonus, s_min the
  particle's most compressive live stretch, <= 0, from this step's dilatation pass; alpha is
  Material.compressive_bonus; with Material.compressive_bonus_cap k the min is floored at -(k / alpha) s_c,kj, the
  model's compressive_stretch_floor k / alpha, so the bonus is at most k s_c,kj), or, for a ductile material,
  when the larger equivalent plastic strain of its two particles exceeds the failure plastic strain. The test runs
  at the end of the force pass, which already holds both directions' plastic extensions; both directed copies of a
  bond see the same quantities, so they break in the same step without communication. Broken bonds are skipped by
  every pass after the flag (their cached (n, e) is left as it was).

A step is two passes over the particles, dilatation (with the plastic update) then force, each launched over
contiguous particle ranges (pdsim/peridynamics/ranges.py, ParticleRanges): a kernel writes only its particles' rows
and their own bonds' rows (and, for the mirror of the plastic extensions, the one slot each of its bonds owns at the
reverse bond, read only by the next pass), and reads other particles' rows only from what an earlier pass wrote.
"""

import warp as wp

from ..launch import range_inputs
from .bonds import deformed_bond, deviatoric_norm_term, returned_plastic_extension, yield_ratio

_cache = {}


def make_step_kernels(fracture: bool, plastic: bool, handoff: bool = False, damped: bool = False):
    """Kernels (dilatation with the fused plastic update, force, energy) for the given feature set, built once and
    cached. With ``handoff`` the dilatation and force passes run over a compacted list of particles,
    ``live_particles`` (ascending indices): thread t of a launch computes particle live_particles[first + t], so the
    particles of rigid fragments (collision proxies, pdsim/peridynamics/handoff.py), which the list leaves out, cost
    nothing: none of their bonds is visited and their dilatation, bond cache and force density are not written
    (kernels/peridynamics/handoff.py clears their force density); without it ``live_particles`` is a placeholder
    the kernels never read and thread t computes particle first + t. Every kernel takes the first entry of its launch
    (``first``): a launch covers the particles (or list entries) first .. first + dim - 1, and each writes only its
    particles' rows and their bonds' rows (bonds are stored per particle family; the plastic mirror is the one
    exception, module docstring), so launches over disjoint ranges of one pass can run at the same time. With
    ``damped`` the force pass adds the internal damping (module docstring; ``velocities`` and ``damping_b``, else
    placeholders it never reads)."""
    key = (bool(fracture), bool(plastic), bool(handoff), bool(damped))
    if key in _cache:
        return _cache[key]
    FRACTURE = key[0]
    PLASTIC = key[1]
    HANDOFF = key[2]
    DAMPED = key[3]

    # tools/feature_cost.py holds a deliberate stripped copy of the elastic dilatation and force below (it measures
    # what the feature branches cost an elastic scene): keep it in step (tests/test_bench_tools.py checks the bits).
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
        live_particles: wp.array(dtype=wp.int32),
    ):
        """theta_k = d_k sum_live w e V beta G^dil for particle k = first + tid; caches each live bond's (n, e)
        for the later passes and, with fracture, the particle's most compressive live stretch (for the
        compressive bonus). With plasticity, a yielding particle (k < plastic_particle_count) then runs the return
        mapping of its deviatoric force state on the bonds it just cached (the plastic update: it writes its own
        bonds' plastic extensions and its own equivalent plastic strain, and mirrors each new extension e^p_kj into
        ``bond_plastic_reverse`` at the reverse bond j -> k, the one slot of that array bond k -> j owns, which no
        kernel reads before the force pass).

        The deformed bond is eta = xi + (u_j - u_k) with xi the reference bond, and the extension is evaluated as
        e = |eta| - L = (2 xi . du + du . du) / (|eta| + L), which keeps float32's relative precision at any strain
        (|eta| - L would lose it to cancellation below a strain of about 1e-5). A broken bond is skipped: no later pass
        reads its cache."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        uk = displacements[k]
        acc = float(0.0)
        smin = float(0.0)
        yields = int(0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                yields = 1
        num = float(0.0)  # plastic volumetric strain: sum w L e V beta over the live family
        den = float(0.0)  # and sum w L^2 V beta
        for q in range(family_offsets[k], family_offsets[k + 1]):
            if wp.static(FRACTURE):
                if bond_alive[q] == wp.uint8(0):
                    continue
            g = bond_geom[q]
            L = g[3]
            xh = wp.vec3(g[0], g[1], g[2])
            xi = xh * L
            du = displacements[family_neighbors[q]] - uk
            n, e = deformed_bond(xi, du, L)
            bond_ne[q] = wp.vec4(n[0], n[1], n[2], e)
            if wp.static(FRACTURE):
                smin = wp.min(smin, e / L)
            acc += bond_wv_dil[q] * e
            if wp.static(PLASTIC):
                if yields != 0:
                    wl = bond_wv[q] * L
                    num += wl * e
                    den += wl * L
        th = dil_d[k] * acc
        theta[k] = th
        bk = dev_b[k]
        bp[k] = wp.vec2(bk, dil_coef[k] * th)
        if wp.static(FRACTURE):
            stretch_min[k] = smin
        if wp.static(PLASTIC):
            if yields != 0:
                # Return mapping (module docstring). theta_p = 3 num / den is exactly 3 zeta under any isotropic
                # expansion zeta, for every particle (surface or cracked), so the deviatoric extension
                # e^d = e - theta_p L / 3 vanishes bond by bond and hydrostatic load never yields.
                # ||t||^2 = sum alpha^2 (e^d - e^p)^2 V beta with alpha = 2 b G^dev w and V beta = w V beta L / delta,
                # evaluated as delta sum (2 b w V beta G^dev (e^d - e^p))^2 / (w V beta L): one division per bond.
                delta = horizon[k]
                th3 = float(0.0)  # theta_p / 3
                if den > 0.0:
                    th3 = num / den
                two_b = 2.0 * bk
                norm2 = float(0.0)
                for q in range(family_offsets[k], family_offsets[k + 1]):
                    live = int(1)
                    if wp.static(FRACTURE):
                        live = int(bond_alive[q])
                    if live != 0:
                        L = bond_geom[q][3]
                        ed = bond_ne[q][3] - th3 * L
                        norm2 += deviatoric_norm_term(two_b, bond_wv_dev[q], bond_wv[q], L, ed, bond_plastic[q])
                norm2 = norm2 * delta
                r = yield_ratio(norm2, delta, yield_stress[k] + hardening[k] * eqps[k], psi_scale[k])
                if r >= 0.0:
                    ep2 = float(0.0)
                    for q in range(family_offsets[k], family_offsets[k + 1]):
                        live = int(1)
                        if wp.static(FRACTURE):
                            live = int(bond_alive[q])
                        ep = bond_plastic[q]
                        if live != 0:
                            ed = bond_ne[q][3] - th3 * bond_geom[q][3]
                            ep = returned_plastic_extension(ed, ep, r)
                            bond_plastic[q] = ep
                            bond_plastic_reverse[bond_reverse[q]] = ep
                        ep2 += bond_wv[q] * ep * ep
                    m = weighted_volume[k]
                    if m > 0.0:
                        eqps[k] = wp.sqrt(5.0 * ep2 / m)

    @wp.kernel(module="unique")
    def force(
        first: int,
        family_offsets: wp.array(dtype=wp.int32),
        family_neighbors: wp.array(dtype=wp.int32),
        bond_geom: wp.array(dtype=wp.vec4),
        bond_ne: wp.array(dtype=wp.vec4),
        bond_wv_dil: wp.array(dtype=float),
        bond_wv_dev: wp.array(dtype=float),
        bp: wp.array(dtype=wp.vec2),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_critical_stretch: wp.array(dtype=float),
        compressive_bonus: wp.array(dtype=float),
        compressive_stretch_floor: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
        failure_eqps: wp.array(dtype=float),
        plastic_bond_count: int,
        bond_plastic: wp.array(dtype=float),
        bond_plastic_reverse: wp.array(dtype=float),
        live_particles: wp.array(dtype=wp.int32),
        velocities: wp.array(dtype=wp.vec3),
        damping_b: wp.array(dtype=float),
        force_density: wp.array(dtype=wp.vec3),
    ):
        """Force density [N/m^3] at particle k = first + tid over live bonds, with plastic extensions where the material
        yields and, where compiled in, the internal damping; then, with fracture, the breaking test of each live bond
        (it takes effect from the next pass). The test reads only quantities both directed copies of a bond share, so
        both break in the same step. It compares extensions, e - (e^p_kj + e^p_jk) / 2 > s_c L, rather than stretches
        (no division per bond)."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        bpk = bp[k]
        f = wp.vec3(0.0)
        smin_k = float(0.0)
        bonus_k = float(0.0)
        floor_k = float(0.0)
        eqps_k = float(0.0)
        fail_k = float(0.0)
        vk = wp.vec3(0.0)
        tbk = float(0.0)
        if wp.static(DAMPED):
            vk = velocities[k]
            tbk = damping_b[k]
        if wp.static(FRACTURE):
            smin_k = stretch_min[k]
            bonus_k = compressive_bonus[k]
            floor_k = compressive_stretch_floor[k]
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
            n = wp.vec3(c[0], c[1], c[2])
            if wp.static(DAMPED):
                dev = dev + (tbk + damping_b[j]) * wp.dot(velocities[j] - vk, n)
            s = bond_wv_dil[q] * (bpk[1] + bpj[1]) + bond_wv_dev[q] * dev
            f += (2.0 * s) * n
            if wp.static(FRACTURE):
                broke = int(0)
                if wp.static(PLASTIC):
                    if q < plastic_bond_count:
                        if c[3] > 0.0 and wp.max(eqps_k, eqps[j]) > fail_k:
                            broke = 1
                sc0 = bond_critical_stretch[q]
                sc = sc0 - bonus_k * wp.max(wp.min(smin_k, stretch_min[j]), -floor_k * sc0)
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
        k = first + tid."""
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


# ---------------------------------------------------------------------------------------------------- launches
def launch_range(kernel, first: int, count: int, inputs: list, device, record_cmd: bool = False):
    """One launch of a range kernel (its first argument is the first particle of the launch) over the particles
    first .. first + count - 1 with the remaining arguments ``inputs``; returns what ``wp.launch`` returns (with
    ``record_cmd``, the recorded launch, to be run later)."""
    return wp.launch(kernel, dim=count, inputs=[first, *inputs], device=device, record_cmd=record_cmd)


def single_launch(count: int, device):
    """A ``launch(kernel, inputs)`` for the pass functions below that runs a range kernel as one launch over the
    particles 0 .. count - 1 (the solver passes its ParticleRanges' launch instead, which splits a pass into thread
    ranges)."""

    def launch(kernel, inputs: list) -> None:
        launch_range(kernel, 0, count, inputs, device)

    return launch


def placeholders(device):
    """Length-1 arrays (uint8, float, int32) passed for the arguments of features a kernel variant compiles out."""
    return (
        wp.zeros(1, dtype=wp.uint8, device=device),
        wp.zeros(1, dtype=float, device=device),
        wp.zeros(1, dtype=wp.int32, device=device),
    )


def plastic_placeholders(f1, i1) -> dict:
    """The dilatation pass's plasticity arguments for a variant without plasticity: length-1 placeholders ``f1``
    (float) and ``i1`` (int32), and no yielding particle."""
    return {
        "plastic_particle_count": 0,
        "bond_wv": f1,
        "bond_wv_dev": f1,
        "horizon": f1,
        "weighted_volume": f1,
        "yield_stress": f1,
        "hardening": f1,
        "psi_scale": f1,
        "bond_plastic": f1,
        "eqps": f1,
        "bond_reverse": i1,
        "bond_plastic_reverse": f1,
    }


def dilatation(launch, ks, **arguments):
    """The dilatation pass of the kernels ``ks`` (make_step_kernels) through ``launch(kernel, inputs)``: theta [-],
    (b_k, P_k), the bonds' (n, e) cache and, where compiled in, the most compressive stretch and the plastic update."""
    launch(ks.dilatation, range_inputs(ks.dilatation, arguments))


def bond_forces(launch, ks, **arguments):
    """The force pass of the kernels ``ks`` through ``launch(kernel, inputs)``: force density [N/m^3] and, where
    compiled in, the breaking test of every live bond."""
    launch(ks.force, range_inputs(ks.force, arguments))


def strain_energy_density(launch, ks, **arguments):
    """The energy pass of the kernels ``ks`` through ``launch(kernel, inputs)``: elastic energy density [J/m^3]."""
    launch(ks.energy, range_inputs(ks.energy, arguments))


def particle_damage(launch, family_offsets, bond_wv, bond_alive, damage):
    """Damage phi_k [-] of every particle through ``launch(kernel, inputs)`` (compute_damage)."""
    launch(compute_damage, [family_offsets, bond_wv, bond_alive, damage])


def deformed_positions(count, rest_positions, displacements, positions, device):
    """positions = rest + u [m] of the ``count`` particles (compose_positions)."""
    wp.launch(compose_positions, dim=count, inputs=[rest_positions, displacements, positions], device=device)


def mirror_plastic(count, bond_reverse, bond_plastic, bond_plastic_reverse, device):
    """bond_plastic_reverse from bond_plastic for the ``count`` plastic bonds (mirror_plastic_extensions)."""
    wp.launch(
        mirror_plastic_extensions, dim=count, inputs=[bond_reverse, bond_plastic, bond_plastic_reverse], device=device
    )


def reverse_bonds(count, family_offsets, family_neighbors, bond_reverse, device):
    """bond_reverse of the bonds of the first ``count`` particles (find_reverse_bonds)."""
    wp.launch(find_reverse_bonds, dim=count, inputs=[family_offsets, family_neighbors, bond_reverse], device=device)


def cut_bonds_by_box(first, count, rest_positions, family_offsets, family_neighbors, lo, hi, bond_alive, device):
    """Breaks the bonds of particles first .. first + count - 1 that cross the box [lo, hi] (break_bonds_crossing_box;
    lo, hi: wp.vec3 [m] in the frame of ``rest_positions``)."""
    wp.launch(
        break_bonds_crossing_box,
        dim=count,
        inputs=[first, rest_positions, family_offsets, family_neighbors, lo, hi, bond_alive],
        device=device,
    )


def cut_bonds_by_mesh(first, count, mesh, rest_positions, family_offsets, family_neighbors, bond_alive, device):
    """Breaks the bonds of particles first .. first + count - 1 that cross the triangle surface ``mesh`` (a wp.Mesh id;
    break_bonds_crossing_mesh)."""
    wp.launch(
        break_bonds_crossing_mesh,
        dim=count,
        inputs=[first, mesh, rest_positions, family_offsets, family_neighbors, bond_alive],
        device=device,
    )

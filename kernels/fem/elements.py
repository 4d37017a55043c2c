"""Element kernels of the linear tetrahedral finite element solid.

Notation: a tetrahedron has corners 0..3 with rest positions X_a and displacements u_a (current positions
x_a = X_a + u_a); Dm = [X1-X0, X2-X0, X3-X0] (positive determinant after loading; Dm^-1 is computed on the host in
float64 from rest differences), rest volume V = det(Dm) / 6, Du = [u1-u0, u2-u0, u3-u0], displacement gradient
G = Du Dm^-1 and deformation gradient F = I + G. The shape-function gradients are g_a = row a of Dm^-1 (a = 1..3) and
g_0 = -(g_1 + g_2 + g_3), so a displacement field u gives grad u = sum_a u_a g_a^T.

Precision: the kernels never see positions, only displacements (kernels/integration.py), and the strains are formed
from G without adding and subtracting the identity, so a float32 solver resolves a strain to about 1e-7 of itself
wherever the body sits in the world and however small the strain is.

Strain measures (the element's strain is constant, slides "Linear Displacement Tetrahedron"):

    linear      eps = sym(G)                          stress sigma = lambda tr(eps) I + 2 mu eps, P = sigma
    corotated   R = polar rotation of F, eps = sym(R^T F) - I = sym(R^T G) + sym(R) - I,  P = R sigma
                (stiffness warping, Mueller & Gross 2004); sym(R) - I = 2 (v v^T - |v|^2 I) from the rotation's unit
                quaternion (v, w), exact and free of cancellation for small rotations
    green       E = (F^T F - I) / 2 = (G + G^T + G^T G) / 2 (Green-Saint-Venant),  S = lambda tr(E) I + 2 mu E,
                P = F S

P is the first Piola-Kirchhoff stress; the nodal forces are f_a = -V P g_a (so f_0 = -(f_1 + f_2 + f_3) and every
element's forces sum to zero: linear momentum is conserved). For the corotated measure R^T F is symmetric, so P is the
gradient of the energy V (mu |eps|^2 + lambda/2 tr(eps)^2): all three measures derive from an energy. The linear measure
is not rotation invariant: a rigid rotation by 90 degrees gives eps = sym(R) - I != 0 and spurious forces.

Element stiffness (slides: K_e = V B^T E B), as 3x3 blocks between corners a and b:

    K_ab = V (lambda g_a g_b^T + mu (g_a . g_b) I + mu g_b g_a^T),   f = -K u;  corotated: R K_ab R^T (R frozen).

Plasticity (slides "Plastic Update Rules"), on the element's strain tensor in its material frame,
with |.| the Frobenius norm of the symmetric 3x3 tensor:

    eps_elastic = eps_total - eps_plastic
    if |eps_elastic| > yield:  eps_plastic += min(creep dt, 1) eps_elastic
    if |eps_plastic| > max:    eps_plastic *= max / |eps_plastic|

and the stress is computed from eps_total - eps_plastic (equivalent to the slides' plastic forces R V B^T E eps_plastic
added to the elastic ones).

Fracture (slides "Principal Stresses"): the element's material-frame stress (sigma, or S for Green) is
eigen-decomposed; its largest eigenvalue and eigenvector (a direction in the rest frame) are written per element, and a
counter is raised when the largest one exceeds the element's tensile strength.

Kernels are built by factories per scalar type (float32 by default, float64 for verification) and with the features a
scene does not use compiled out (``wp.static`` branches); each variant lives in its own Warp module.
"""

import functools

import warp as wp

from ..launch import launch

MEASURE_LINEAR = 0
MEASURE_COROTATED = 1
MEASURE_GREEN = 2
MEASURES = {"linear": MEASURE_LINEAR, "corotated": MEASURE_COROTATED, "green": MEASURE_GREEN}


@functools.cache
def fem_types(dtype):
    """(vec3, mat33, vec4) Warp types of scalar ``dtype``: Warp's own wp.vec3/wp.mat33/wp.vec4 for wp.float32 (so that
    the shared collider kernels accept the solver's arrays) and wp.vec3d/wp.mat33d/wp.vec4d for wp.float64."""
    if dtype == wp.float64:
        return wp.vec3d, wp.mat33d, wp.vec4d
    return wp.vec3, wp.mat33, wp.vec4


@functools.cache
def fem_funcs(dtype):
    """Warp functions shared by the element kernels, for scalar ``dtype``; returned as a namespace dict."""
    vec3, mat33, vec4 = fem_types(dtype)

    @wp.func
    def displacement_gradient(u0: vec3, u1: vec3, u2: vec3, u3: vec3, dm_inv: mat33):
        """G = Du Dm^-1 [-] of corner vectors u_a (displacements [m]; or any nodal vector field, e.g. velocities)."""
        du = mat33(u1[0] - u0[0], u2[0] - u0[0], u3[0] - u0[0],
                   u1[1] - u0[1], u2[1] - u0[1], u3[1] - u0[1],
                   u1[2] - u0[2], u2[2] - u0[2], u3[2] - u0[2])  # fmt: skip
        return du * dm_inv

    @wp.func
    def polar_rotation(f: mat33):
        """Rotation R of the polar decomposition F = R S (from the SVD; a proper rotation also for inverted F)."""
        u = mat33()
        s = vec3()
        v = mat33()
        wp.svd3(f, u, s, v)
        r = u * wp.transpose(v)
        if wp.determinant(r) < dtype(0.0):
            # Warp's svd3 already returns rotations with a signed smallest singular value; guard for round-off
            u[0, 2] = -u[0, 2]
            u[1, 2] = -u[1, 2]
            u[2, 2] = -u[2, 2]
            r = u * wp.transpose(v)
        return r

    quat = wp.types.quaternion(dtype)
    polar_tolerance = dtype(1.0e-12) if dtype == wp.float64 else dtype(1.0e-6)
    polar_tolerance_sq = polar_tolerance * polar_tolerance

    @wp.func
    def rotation_newton_step(a: mat33, r: mat33):
        """One step of rotation_iterative at R: (omega [rad], |omega|^2, newton, kappa^2). omega = H^-1 g (newton = 1,
        kappa^2 = (|H^-1|_F |B|_F)^2) where H is positive definite, else g / |tr(B)| (newton = 0, kappa^2 = 0)."""
        b = a * wp.transpose(r)
        g = vec3(b[2, 1] - b[1, 2], b[0, 2] - b[2, 0], b[1, 0] - b[0, 1])
        # H = tr(B) I - sym(B), symmetric: its six entries, their cofactors and determinant
        h00 = b[1, 1] + b[2, 2]
        h11 = b[0, 0] + b[2, 2]
        h22 = b[0, 0] + b[1, 1]
        h01 = dtype(-0.5) * (b[0, 1] + b[1, 0])
        h02 = dtype(-0.5) * (b[0, 2] + b[2, 0])
        h12 = dtype(-0.5) * (b[1, 2] + b[2, 1])
        c00 = h11 * h22 - h12 * h12
        c01 = h02 * h12 - h01 * h22
        c02 = h01 * h12 - h02 * h11
        c11 = h00 * h22 - h02 * h02
        c12 = h01 * h02 - h00 * h12
        c22 = h00 * h11 - h01 * h01
        det = h00 * c00 + h01 * c01 + h02 * c02
        if h00 > dtype(0.0) and c22 > dtype(0.0) and det > dtype(0.0):
            # H positive definite (Sylvester): the Newton step H^-1 g = adj(H) g / det(H)
            inv_det = dtype(1.0) / det
            omega = inv_det * vec3(
                c00 * g[0] + c01 * g[1] + c02 * g[2],
                c01 * g[0] + c11 * g[1] + c12 * g[2],
                c02 * g[0] + c12 * g[1] + c22 * g[2],
            )
            adj_sq = c00 * c00 + c11 * c11 + c22 * c22 + dtype(2.0) * (c01 * c01 + c02 * c02 + c12 * c12)
            return omega, wp.dot(omega, omega), int(1), adj_sq * inv_det * inv_det * wp.ddot(b, b)
        omega = g / (wp.abs(wp.trace(b)) + dtype(1.0e-20))
        return omega, wp.dot(omega, omega), int(0), dtype(0.0)

    @wp.func
    def quat_turned(q: quat, omega: vec3, w_sq: dtype):
        """rot(omega) q for a unit quaternion q and |omega|^2 = w_sq <= 1: the product dq q with
        dq = ((1 - w^2/24) omega / 2, 1 - w^2/8) written out, then rescaled to unit length (one Newton step of
        1 / sqrt(n) from 1 where |n - 1| < 1e-3, error below 1e-6 (n - 1)^2; else the square root)."""
        h = (dtype(0.5) - w_sq / dtype(48.0)) * omega
        c = dtype(1.0) - w_sq / dtype(8.0)
        qv = vec3(q[0], q[1], q[2])
        nv = c * qv + q[3] * h + wp.cross(h, qv)
        nw = c * q[3] - wp.dot(h, qv)
        n = wp.dot(nv, nv) + nw * nw
        scale = dtype(1.5) - dtype(0.5) * n
        if wp.abs(n - dtype(1.0)) > dtype(1.0e-3):
            scale = dtype(1.0) / wp.sqrt(n)
        return quat(scale * nv[0], scale * nv[1], scale * nv[2], scale * nw)

    @wp.func
    def rotation_iterative(a: mat33, q0: quat):
        """Rotation R maximising tr(R^T A) (the polar rotation of A, sign-fixed for inverted A), warm-started from q0.

        Each iteration rotates R by omega: R <- rot(omega) R, the quaternion q <- normalize(dq q) with
        dq = ((1 - w^2/24) omega / 2, 1 - w^2/8) (w = |omega|; the half-angle sine and cosine to the order whose error,
        w^5 / 3840 rad, is below every tolerance here). With B = A R^T, the gradient is g = axial(B - B^T) =
        sum_i r_i x a_i (r_i, a_i the columns; Mueller et al. 2016, "A Robust Method to Extract the Rotational Part of
        Deformations") and the Hessian H = tr(B) I - sym(B). Where H is positive definite, omega = H^-1 g (a Newton
        step, an ascent direction, at most 1 rad long); else the paper's damped step g / |tr(B)|.

        Stops when |omega| is below the tolerance (1e-6 rad in float32, 1e-12 rad in float64), or right after a Newton
        step of length w when |H^-1|_F |B|_F w^3 is below it. The Newton step converges cubically here: at the
        solution B is symmetric, so the odd terms of tr(rot(theta)^T B) in theta vanish, and the rotation after the
        step lies within about (2/9) |H^-1|_F |B|_F w^3 of the polar rotation (sampled over strains 1e-4 to 1 and
        stretches 0.05 to 5; tests/test_fem_rotation.py checks the result against the SVD's rotation). From the
        previous step's rotation an explicit step therefore takes one iteration wherever the element turned by less
        than about 1e-2 rad (float32).
        After 16 iterations without converging (cold starts near a half turn) it takes the SVD's rotation.
        Returns (R, q)."""
        r = wp.quat_to_matrix(q0)
        omega, w_sq, newton, kappa_sq = rotation_newton_step(a, r)
        if w_sq < polar_tolerance_sq:
            return r, q0
        if newton != 0 and w_sq <= dtype(1.0):
            # the common case, written without the loop: one Newton step from the previous rotation
            q = quat_turned(q0, omega, w_sq)
            r = wp.quat_to_matrix(q)
            if kappa_sq * w_sq * w_sq * w_sq < polar_tolerance_sq:
                return r, q
        else:
            q = q0
        it = int(0)
        while it < 16:  # a while loop: Warp would unroll a range of 16 into 16 copies of the step
            it += 1
            omega, w_sq, newton, kappa_sq = rotation_newton_step(a, r)
            if w_sq < polar_tolerance_sq:
                return r, q
            if w_sq > dtype(1.0):
                omega = omega / wp.sqrt(w_sq)  # at most 1 rad
                w_sq = dtype(1.0)
                newton = 0
            q = quat_turned(q, omega, w_sq)
            r = wp.quat_to_matrix(q)
            if newton != 0 and kappa_sq * w_sq * w_sq * w_sq < polar_tolerance_sq:
                return r, q
        # far from the previous rotation (a cold start near a half turn): the SVD
        rs = polar_rotation(a)
        return rs, wp.quat_from_matrix(rs)

    @wp.func
    def sym(a: mat33):
        return dtype(0.5) * (a + wp.transpose(a))

    @wp.func
    def corotated_strain(g: mat33, r: mat33, q: quat):
        """eps = sym(R^T F) - I = sym(R^T G) + 2 (v v^T - |v|^2 I) for F = I + G and R the rotation of the unit
        quaternion q = (v, w) (sym(R) - I written without cancellation)."""
        v = vec3(q[0], q[1], q[2])
        return sym(wp.transpose(r) * g) + dtype(2.0) * (wp.outer(v, v) - wp.dot(v, v) * wp.identity(3, dtype))

    @wp.func
    def green_strain(g: mat33):
        """E = (F^T F - I) / 2 = (G + G^T + G^T G) / 2 for F = I + G."""
        return dtype(0.5) * (g + wp.transpose(g) + wp.transpose(g) * g)

    @wp.func
    def hooke(eps: mat33, lam: dtype, mu: dtype):
        """Isotropic Hooke's law sigma = lambda tr(eps) I + 2 mu eps [Pa]."""
        return (lam * wp.trace(eps)) * wp.identity(3, dtype) + (dtype(2.0) * mu) * eps

    @wp.func
    def frobenius(a: mat33):
        return wp.sqrt(wp.ddot(a, a))

    @wp.func
    def plastic_update(eps_total: mat33, eps_plastic: mat33, yield_strain: dtype, creep_dt: dtype, max_strain: dtype):
        """The slides' plastic update rule; returns the new plastic strain. creep_dt = min(creep dt, 1)."""
        ep = eps_plastic
        eel = eps_total - ep
        if frobenius(eel) > yield_strain:
            ep = ep + creep_dt * eel
        n = frobenius(ep)
        if n > max_strain:
            ep = ep * (max_strain / n)
        return ep

    @wp.func
    def shape_gradient(dm_inv: mat33, corner: int):
        """g_a [1/m]: row a-1 of Dm^-1 for a = 1..3, minus their sum for a = 0."""
        g1 = vec3(dm_inv[0, 0], dm_inv[0, 1], dm_inv[0, 2])
        g2 = vec3(dm_inv[1, 0], dm_inv[1, 1], dm_inv[1, 2])
        g3 = vec3(dm_inv[2, 0], dm_inv[2, 1], dm_inv[2, 2])
        if corner == 1:
            return g1
        if corner == 2:
            return g2
        if corner == 3:
            return g3
        return -(g1 + g2 + g3)

    @wp.func
    def stiffness_block(ga: vec3, gb: vec3, vol: dtype, lam: dtype, mu: dtype):
        """K_ab = V (lambda g_a g_b^T + mu (g_a . g_b) I + mu g_b g_a^T) [N/m]."""
        return vol * (lam * wp.outer(ga, gb) + (mu * wp.dot(ga, gb)) * wp.identity(3, dtype) + mu * wp.outer(gb, ga))

    @wp.func
    def largest_eigen(s: mat33):
        """(largest eigenvalue, its unit eigenvector) of a symmetric 3x3 matrix."""
        q = mat33()
        d = vec3()
        q, d = wp.eig3(s)
        k = int(0)
        if d[1] > d[k]:
            k = 1
        if d[2] > d[k]:
            k = 2
        return d[k], vec3(q[0, k], q[1, k], q[2, k])

    @wp.func
    def store_corners(h: mat33, e: int, corners: wp.array(dtype=vec3)):
        """Writes the corner vectors of element e from the columns (f_1, f_2, f_3) of h: corners[4 e + a] = f_a for
        a = 1..3 and corners[4 e] = -(f_1 + f_2 + f_3) (the four sum to zero)."""
        f1 = vec3(h[0, 0], h[1, 0], h[2, 0])
        f2 = vec3(h[0, 1], h[1, 1], h[2, 1])
        f3 = vec3(h[0, 2], h[1, 2], h[2, 2])
        base = 4 * e
        corners[base] = -(f1 + f2 + f3)
        corners[base + 1] = f1
        corners[base + 2] = f2
        corners[base + 3] = f3

    return {
        "displacement_gradient": displacement_gradient,
        "corotated_strain": corotated_strain,
        "green_strain": green_strain,
        "polar_rotation": polar_rotation,
        "rotation_iterative": rotation_iterative,
        "hooke": hooke,
        "sym": sym,
        "frobenius": frobenius,
        "plastic_update": plastic_update,
        "shape_gradient": shape_gradient,
        "stiffness_block": stiffness_block,
        "largest_eigen": largest_eigen,
        "store_corners": store_corners,
    }


@functools.cache
def element_force_kernel(dtype, measure: int, plastic: bool, fracture: bool, store_rotation: bool, scatter: bool):
    """Kernel over elements: corner forces f_a = -V P g_a [N] into ``corner_forces[4 e + a]``, or with ``scatter``
    added onto ``forces[t_a]`` of the element's corners t_a instead (``corner_forces`` unused). Scatter is for the CPU
    only: there one thread walks the elements in order, so every vertex sums its corner forces in element order
    (deterministic, and Warp's atomic_add is a plain add there); on a GPU the additions would race in no fixed order,
    so the GPU writes corners and gathers them per vertex (kernels/fem/solver.py).

    Inputs: ``displacements`` [m] per vertex; per element ``tets`` (vec4i), ``dm_inv`` (Dm^-1 [1/m]), ``volume``
    [m^3], ``lame`` = (lambda, mu) [Pa].
    With ``plastic``: ``plastic_params`` = (yield [-], creep [1/s], max [-]) and ``plastic_strain`` (updated in place,
    once per call, with factor min(creep dt, 1); dt = 0 leaves it unchanged). With ``fracture``: ``strength`` [Pa],
    writes ``principal`` = (rest-frame unit direction, largest principal stress [Pa]; an upper bound and a zero
    direction where it cannot exceed the strength) and adds 1 to ``over_count[0]`` per element whose largest
    principal stress exceeds its strength. Corotated: the rotation is found iteratively from the element's previous
    one (``rotation_q``, updated in place); with ``store_rotation`` the matrix R is written to ``rotation`` for the
    implicit solver.
    """
    vec3, mat33, vec4 = fem_types(dtype)
    quat = wp.types.quaternion(dtype)
    fn = fem_funcs(dtype)
    displacement_gradient = fn["displacement_gradient"]
    rotation_iterative = fn["rotation_iterative"]
    corotated_strain = fn["corotated_strain"]
    green_strain = fn["green_strain"]
    hooke = fn["hooke"]
    sym = fn["sym"]
    frobenius = fn["frobenius"]
    plastic_update = fn["plastic_update"]
    largest_eigen = fn["largest_eigen"]
    store_corners = fn["store_corners"]
    sqrt_two_thirds = dtype(0.816496580927726)

    @wp.kernel(module="unique")
    def element_forces(
        displacements: wp.array(dtype=vec3),
        tets: wp.array(dtype=wp.vec4i),
        dm_inv: wp.array(dtype=mat33),
        volume: wp.array(dtype=dtype),
        lame: wp.array(dtype=wp.types.vector(2, dtype)),
        plastic_params: wp.array(dtype=vec3),
        plastic_strain: wp.array(dtype=mat33),
        dt: dtype,
        strength: wp.array(dtype=dtype),
        principal: wp.array(dtype=vec4),
        over_count: wp.array(dtype=wp.int32),
        rotation_q: wp.array(dtype=quat),
        rotation: wp.array(dtype=mat33),
        corner_forces: wp.array(dtype=vec3),
        forces: wp.array(dtype=vec3),
    ):
        e = wp.tid()
        t = tets[e]
        # Dm^-1 and the Lame constants are read where they are used, so that fewer values live across the rotation
        g = displacement_gradient(
            displacements[t[0]], displacements[t[1]], displacements[t[2]], displacements[t[3]], dm_inv[e]
        )
        r = wp.identity(3, dtype)
        if wp.static(measure == MEASURE_COROTATED):
            r, q = rotation_iterative(wp.identity(3, dtype) + g, rotation_q[e])
            rotation_q[e] = q
            eps = corotated_strain(g, r, q)
        elif wp.static(measure == MEASURE_GREEN):
            eps = green_strain(g)
        else:
            eps = sym(g)
        if wp.static(plastic):
            pp = plastic_params[e]
            ep = plastic_update(eps, plastic_strain[e], pp[0], wp.min(pp[1] * dt, dtype(1.0)), pp[2])
            plastic_strain[e] = ep
            eps = eps - ep
        dmi = dm_inv[e]
        sigma = hooke(eps, lame[e][0], lame[e][1])
        if wp.static(fracture):
            # Samuelson's bound max eig <= mean + sqrt(2/3) |deviator| spares the eigen-decomposition when no
            # principal stress can exceed the strength
            mean = wp.trace(sigma) / dtype(3.0)
            bound = mean + sqrt_two_thirds * frobenius(sigma - mean * wp.identity(3, dtype))
            if bound > strength[e]:
                smax, n = largest_eigen(sigma)
                principal[e] = vec4(n[0], n[1], n[2], smax)
                if smax > strength[e]:
                    wp.atomic_add(over_count, 0, 1)
            else:
                principal[e] = vec4(dtype(0.0), dtype(0.0), dtype(0.0), bound)
        if wp.static(measure == MEASURE_COROTATED):
            p = r * sigma
            if wp.static(store_rotation):
                rotation[e] = r
        elif wp.static(measure == MEASURE_GREEN):
            p = sigma + g * sigma  # F S
        else:
            p = sigma
        h = (-volume[e]) * (p * wp.transpose(dmi))  # columns are f_1, f_2, f_3
        if wp.static(scatter):
            f1 = vec3(h[0, 0], h[1, 0], h[2, 0])
            f2 = vec3(h[0, 1], h[1, 1], h[2, 1])
            f3 = vec3(h[0, 2], h[1, 2], h[2, 2])
            wp.atomic_add(forces, t[0], -(f1 + f2 + f3))
            wp.atomic_add(forces, t[1], f1)
            wp.atomic_add(forces, t[2], f2)
            wp.atomic_add(forces, t[3], f3)
        else:
            store_corners(h, e, corner_forces)

    return element_forces


@functools.cache
def rotation_matrices_kernel(dtype):
    """Kernel over elements: ``rotation[e]`` <- the matrix of the unit quaternion ``rotation_q[e]``."""
    _, mat33, _ = fem_types(dtype)
    quat = wp.types.quaternion(dtype)

    @wp.kernel(module="unique")
    def rotation_matrices(rotation_q: wp.array(dtype=quat), rotation: wp.array(dtype=mat33)):
        e = wp.tid()
        rotation[e] = wp.quat_to_matrix(rotation_q[e])

    return rotation_matrices


@functools.cache
def element_energy_kernel(dtype, measure: int, plastic: bool):
    """Kernel over elements: elastic energy V (mu |eps_el|^2 + lambda/2 tr(eps_el)^2) [J] into ``energy[e]`` at the
    vertex ``displacements`` [m], with eps_el = eps - eps_plastic in the element's strain measure (plastic strain read,
    not updated)."""
    vec3, mat33, _ = fem_types(dtype)
    fn = fem_funcs(dtype)
    displacement_gradient = fn["displacement_gradient"]
    polar_rotation = fn["polar_rotation"]
    corotated_strain = fn["corotated_strain"]
    green_strain = fn["green_strain"]
    sym = fn["sym"]

    @wp.kernel(module="unique")
    def element_energy(
        displacements: wp.array(dtype=vec3),
        tets: wp.array(dtype=wp.vec4i),
        dm_inv: wp.array(dtype=mat33),
        volume: wp.array(dtype=dtype),
        lame: wp.array(dtype=wp.types.vector(2, dtype)),
        plastic_strain: wp.array(dtype=mat33),
        energy: wp.array(dtype=dtype),
    ):
        e = wp.tid()
        t = tets[e]
        g = displacement_gradient(
            displacements[t[0]], displacements[t[1]], displacements[t[2]], displacements[t[3]], dm_inv[e]
        )
        if wp.static(measure == MEASURE_COROTATED):
            r = polar_rotation(wp.identity(3, dtype) + g)
            eps = corotated_strain(g, r, wp.quat_from_matrix(r))
        elif wp.static(measure == MEASURE_GREEN):
            eps = green_strain(g)
        else:
            eps = sym(g)
        if wp.static(plastic):
            eps = eps - plastic_strain[e]
        tr = wp.trace(eps)
        energy[e] = volume[e] * (lame[e][1] * wp.ddot(eps, eps) + dtype(0.5) * lame[e][0] * tr * tr)

    return element_energy


@functools.cache
def element_stiffness_product_kernel(dtype, rotated: bool):
    """Kernel over elements: corner products (K_e u)_a = sum_b R K_ab R^T u_b [N] into ``corner_out[4 e + a]`` for a
    vector field u [m] (or [m/s]); R is the element's frozen rotation (identity when not ``rotated``). Evaluated without
    assembling K_e: G = R^T Du Dm^-1, sigma = hooke(sym(G)), (K u)_a = V R sigma g_a."""
    vec3, mat33, _ = fem_types(dtype)
    fn = fem_funcs(dtype)
    displacement_gradient = fn["displacement_gradient"]
    hooke = fn["hooke"]
    sym = fn["sym"]
    store_corners = fn["store_corners"]

    # the same element prologue as element_energy (corners, displacement gradient) on another field: the kernels
    # differ in what they form from G, and Warp kernels cannot take a function argument
    @wp.kernel(module="unique")
    def element_stiffness_product(
        u: wp.array(dtype=vec3),
        tets: wp.array(dtype=wp.vec4i),
        dm_inv: wp.array(dtype=mat33),
        volume: wp.array(dtype=dtype),
        lame: wp.array(dtype=wp.types.vector(2, dtype)),
        rotation: wp.array(dtype=mat33),
        corner_out: wp.array(dtype=vec3),
    ):
        e = wp.tid()
        t = tets[e]
        dmi = dm_inv[e]
        g = displacement_gradient(u[t[0]], u[t[1]], u[t[2]], u[t[3]], dmi)
        if wp.static(rotated):
            r = rotation[e]
            sigma = hooke(sym(wp.transpose(r) * g), lame[e][0], lame[e][1])
            h = volume[e] * ((r * sigma) * wp.transpose(dmi))
        else:
            sigma = hooke(sym(g), lame[e][0], lame[e][1])
            h = volume[e] * (sigma * wp.transpose(dmi))
        store_corners(h, e, corner_out)

    return element_stiffness_product


@functools.cache
def element_stiffness_blocks_kernel(dtype, rotated: bool):
    """Kernel over elements: the 16 blocks R K_ab R^T [N/m] of the element stiffness into ``blocks[16 e + 4 a + b]``
    (the assembled path of the implicit solver and the tests' finite-difference check)."""
    _, mat33, _ = fem_types(dtype)
    fn = fem_funcs(dtype)
    shape_gradient = fn["shape_gradient"]
    stiffness_block = fn["stiffness_block"]

    @wp.kernel(module="unique")
    def element_stiffness_blocks(
        dm_inv: wp.array(dtype=mat33),
        volume: wp.array(dtype=dtype),
        lame: wp.array(dtype=wp.types.vector(2, dtype)),
        rotation: wp.array(dtype=mat33),
        blocks: wp.array(dtype=mat33),
    ):
        e = wp.tid()
        dmi = dm_inv[e]
        vol = volume[e]
        lam = lame[e][0]
        mu = lame[e][1]
        for a in range(4):
            ga = shape_gradient(dmi, a)
            for b in range(4):
                k = stiffness_block(ga, shape_gradient(dmi, b), vol, lam, mu)
                if wp.static(rotated):
                    r = rotation[e]
                    k = r * k * wp.transpose(r)
                blocks[16 * e + 4 * a + b] = k

    return element_stiffness_blocks


@functools.cache
def plastic_update_kernel(dtype):
    """Kernel applying the plastic update rule to arrays (the solver applies the same function inside the element force
    kernel): ``plastic_strain[i]`` <- rule(``total_strain[i]``, ``plastic_strain[i]``, yield, min(creep dt, 1), max)."""
    vec3, mat33, _ = fem_types(dtype)
    plastic_update = fem_funcs(dtype)["plastic_update"]

    @wp.kernel(module="unique")
    def apply_plastic_update(
        total_strain: wp.array(dtype=mat33),
        plastic_params: wp.array(dtype=vec3),
        dt: dtype,
        plastic_strain: wp.array(dtype=mat33),
    ):
        i = wp.tid()
        pp = plastic_params[i]
        plastic_strain[i] = plastic_update(
            total_strain[i], plastic_strain[i], pp[0], wp.min(pp[1] * dt, dtype(1.0)), pp[2]
        )

    return apply_plastic_update


@functools.cache
def embed_points_kernel(dtype):
    """Kernel over embedded points (barycentric render-mesh embedding): the displacement u_p = sum_a w_pa u[t_a] [m]
    and the velocity v_p = sum_a w_pa v[t_a] [m/s] of point p in element ``element[p]`` (t = its corners)."""
    vec3, _, vec4 = fem_types(dtype)

    @wp.kernel(module="unique")
    def embed_points(
        displacements: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        tets: wp.array(dtype=wp.vec4i),
        element: wp.array(dtype=wp.int32),
        weights: wp.array(dtype=vec4),
        out_displacement: wp.array(dtype=vec3),
        out_velocity: wp.array(dtype=vec3),
    ):
        p = wp.tid()
        t = tets[element[p]]
        w = weights[p]
        u = w[0] * displacements[t[0]] + w[1] * displacements[t[1]]
        u = u + w[2] * displacements[t[2]] + w[3] * displacements[t[3]]
        v = w[0] * velocities[t[0]] + w[1] * velocities[t[1]] + w[2] * velocities[t[2]] + w[3] * velocities[t[3]]
        out_displacement[p] = u
        out_velocity[p] = v

    return embed_points


# -- launches ----------------------------------------------------------------------------------------------------------
# One function per kernel, its arguments given by the kernel's parameter names (kernels/launch.py); ``dtype`` is the
# solver's scalar type (wp.float32 or wp.float64), one thread per element (per embedded point for embed_points).


def element_forces(
    *,
    dtype,
    measure: int,
    plastic: bool,
    fracture: bool,
    device,
    scatter: bool = False,
    store_rotation: bool = True,
    **arguments,
):
    """Corner forces [N] of every element into ``corner_forces`` (``scatter``, CPU only: added onto ``forces`` per
    vertex instead) at ``displacements`` [m], with the plastic update of step ``dt`` [s], the principal stresses and
    the over-strength count (fracture) and the rotations (corotated) as element_force_kernel documents (the rotation
    matrix stored into ``rotation`` with ``store_rotation``; the quaternions always)."""
    if scatter and not wp.get_device(device).is_cpu:
        raise ValueError("element_forces: scatter=True adds in a fixed order only on the CPU")
    kernel = element_force_kernel(dtype, measure, plastic, fracture, bool(store_rotation), bool(scatter))
    launch(kernel, arguments["tets"].shape[0], device=device, **arguments)


def rotation_matrices(*, dtype, device, **arguments):
    """The rotation matrices of the elements' quaternions ``rotation_q`` into ``rotation``
    (rotation_matrices_kernel)."""
    launch(rotation_matrices_kernel(dtype), arguments["rotation"].shape[0], device=device, **arguments)


def element_energy(*, dtype, measure: int, plastic: bool, device, **arguments):
    """Elastic energy [J] of every element into ``energy`` at ``displacements`` [m] (element_energy_kernel)."""
    launch(element_energy_kernel(dtype, measure, plastic), arguments["tets"].shape[0], device=device, **arguments)


def element_stiffness_product(*, dtype, rotated: bool, device, **arguments):
    """Corner products (K_e u)_a [N] of every element into ``corner_out`` for a vector field ``u`` [m]
    (element_stiffness_product_kernel: the matrix-free stiffness)."""
    launch(element_stiffness_product_kernel(dtype, rotated), arguments["tets"].shape[0], device=device, **arguments)


def element_stiffness_blocks(*, dtype, rotated: bool, device, **arguments):
    """The 16 stiffness blocks R K_ab R^T [N/m] of every element into ``blocks[16 e + 4 a + b]``
    (element_stiffness_blocks_kernel)."""
    launch(element_stiffness_blocks_kernel(dtype, rotated), arguments["volume"].shape[0], device=device, **arguments)


def embed_points(*, dtype, device, **arguments):
    """Displacements [m] and velocities [m/s] of the barycentrically embedded points (embed_points_kernel)."""
    launch(embed_points_kernel(dtype), arguments["weights"].shape[0], device=device, **arguments)

"""Tetrahedral finite element solid with plasticity and fracture (shared/seeds/fem_slides.txt, DESIGN.md section 3).

A :class:`FemBody` is a linear-tetrahedron mesh of a solid (meshed from a closed surface by fTetWild, or loaded ready)
with a :class:`pdsim.Material`, a strain measure ("linear", "corotated" or "green", see kernels/fem/elements.py), an
integrator ("explicit" or "implicit"), and optional plasticity (:class:`FemPlasticity`) and fracture
(``tensile_strength``). :class:`SolverFem` steps all FEM bodies of a scene together; the scene layer, colliders and USD
output are shared with the peridynamic solid (``Scene.add_body(FemBody(...))``).

Integrators:

- explicit: velocity Verlet with lumped masses m_i = sum over the vertex's elements of rho V / 4. The stable step is
  dt_stable = 0.5 h_min / c_p with h_min the smallest element height (3 V / largest face area) and
  c_p = sqrt((lambda + 2 mu) / rho) the dilatational wave speed. The factor 0.5 makes the estimate safe: the
  element-by-element bound 2 / sqrt(max eig(M_e^-1 K_e)), a lower bound of the true critical step, measured at least
  0.50 h / c_p over 15,000 random tetrahedra (flat ones included, nu from -0.5 to 0.499), and the true critical step
  of whole meshes (largest eigenvalue of M^-1 K) measured 0.88-0.95 h_min / c_p on structured box meshes and
  1.4-3.0 h_min / c_p on fTetWild and jittered meshes (tests/test_fem_dynamics.py: 1.8-1.9 and 5.0-5.2 times the
  automatic step). :meth:`SolverFem.step` refuses a larger step (ParameterError);
  :meth:`SolverFem.simulate` (what the Scene calls) splits each requested step into equal substeps no longer than
  dt_stable instead (automatic substepping).
- implicit: linearly implicit backward Euler with the corotated stiffness (kernels/fem/solver.py), one CG solve per
  step, at any step size; :meth:`SolverFem.stable_time_step` then reports ``implicit_step_ratio`` (default 10) times the
  explicit limit as the step the scene should use. The linear measure uses the constant stiffness, the Green measure
  has no implicit integrator here (ParameterError).

A quasi-static solve (:meth:`SolverFem.solve_static`, Newton iterations with the same CG) verifies the elements
(patch test, cantilever).

Plasticity is compiled into the element force kernel and its state (a plastic strain tensor per element) allocated
only when some body yields. Fracture (pdsim/fem/fracture.py) costs one eigen-decomposition per element whose
Samuelson bound exceeds its strength, a counter read per step, and host topology work (vectorised numpy/scipy, local to
the split vertices) only on steps where some element exceeded its strength; vertex arrays are then reallocated.

Colliders: the ground plane and the scene's colliders (pdsim/contact.py) act on the free vertices with zero radius.
Contact between FEM pieces or bodies is not implemented: pieces of a cracked body pass through each other.

Output: per body one ``UsdGeom.Mesh`` holding the boundary surface of every piece (each a closed shell with its own
vertices), topology time-sampled on frames where fracture changed it; optionally an embedded render mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InstabilityError, ParameterError
from ..validate import check_range
from .body import PRECISIONS, STIFFNESS_MODES, FemBody
from .mesh import boundary_faces, element_heights

EXPLICIT_STEP_FACTOR = 0.5  # dt_stable = 0.5 h_min / c_p (see the module docstring)
CG_CHUNK = 256  # vertices per partial sum of the CG reductions


@dataclass
class CgReport:
    """Outcome of one CG solve: iterations, final relative residual |r| / |b|, and whether it reached the tolerance."""

    iterations: int
    relative_residual: float
    converged: bool


@dataclass
class StaticSolveReport:
    """Outcome of :meth:`SolverFem.solve_static`: Newton iterations, CG iterations in total, the final equilibrium
    residual |f_int + f_ext| over free vertices [N] and relative to the external load."""

    newton_iterations: int
    cg_iterations: int
    residual: float
    relative_residual: float


def _embed(rest: np.ndarray, tets: np.ndarray, points: np.ndarray, *, candidates: int = 16):
    """Barycentric embedding of ``points`` [p, 3] in a tet mesh: (element [p], weights [p, 4]); each point takes, among
    the ``candidates`` elements with the nearest centroids, the one it is deepest inside (largest smallest weight);
    points slightly outside the mesh (fTetWild's envelope) get slightly negative weights (linear extrapolation)."""
    from scipy.spatial import cKDTree

    cent = rest[tets].mean(axis=1)
    k = min(candidates, len(tets))
    _, idx = cKDTree(cent).query(points, k=k)
    idx = idx.reshape(len(points), k)
    x = rest[tets[idx]]  # [p, k, 4, 3]
    dm = np.stack([x[..., 1, :] - x[..., 0, :], x[..., 2, :] - x[..., 0, :], x[..., 3, :] - x[..., 0, :]], axis=-1)
    lam = np.linalg.solve(dm, (points[:, None, :] - x[..., 0, :])[..., None])[..., 0]  # [p, k, 3]
    w = np.concatenate([1.0 - lam.sum(axis=-1, keepdims=True), lam], axis=-1)
    best = np.argmax(w.min(axis=-1), axis=1)
    rows = np.arange(len(points))
    return idx[rows, best], w[rows, best]


class SolverFem:
    """Solver for the FEM bodies of a scene (concatenated into one mesh; elements never join two bodies).

    Args:
        bodies: the FEM bodies; they must share the strain measure and the integrator.
        device: Warp device ("cpu", "cuda", ...).
        gravity: acceleration [m/s^2], 3 numbers.
        ground: optional :class:`pdsim.GroundPlane` collider (applied to free vertices).
        colliders: pdsim colliders (MeshCollider, SphereProjectile, ...; pdsim/contact.py) applied to the free vertices
            after each step's drift with zero collision radius (float32 only).
        precision: "float32" (default) or "float64" (verification).
        cg_tolerance: relative residual |r| / |b| at which CG stops; default 1e-5 (float32) or 1e-10 (float64).
        cg_max_iterations: CG iterations per solve, >= 1 (default 2000).
        stiffness: how CG applies K_R: "matrix_free" (the element kernels with the frozen rotations, per
            iteration) or "assembled" (default; a 3x3-block sparse matrix filled once per solve from the element
            stiffness blocks: about 2x faster per implicit step on the CPU, docs/benchmarks.md).

    ``features`` lists the live optional parts (plasticity, fracture, gravity, ground_plane, damping, render_mesh);
    kernels are compiled with the dead ones removed, and no state is allocated for them.
    """

    def __init__(
        self,
        bodies: list[FemBody],
        *,
        device="cpu",
        gravity=(0.0, 0.0, 0.0),
        ground=None,
        colliders=(),
        precision: str = "float32",
        cg_tolerance: float | None = None,
        cg_max_iterations: int = 2000,
        stiffness: str = "assembled",
    ):
        import warp as wp

        from ..kernels.fem import elements as ke

        bodies = list(bodies)
        if not bodies or not all(isinstance(b, FemBody) for b in bodies):
            raise ParameterError("bodies", bodies, "a non-empty list of pdsim.fem.FemBody")
        for attr in ("measure", "integrator"):
            values = sorted({getattr(b, attr) for b in bodies})
            if len(values) > 1:
                raise ParameterError(attr, values, f"one {attr} shared by all FEM bodies of a scene")
        if precision not in PRECISIONS:
            raise ParameterError("precision", precision, " or ".join(map(repr, PRECISIONS)))
        g = np.asarray(gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ParameterError("gravity", gravity, "3 finite numbers [m/s^2]")
        if stiffness not in STIFFNESS_MODES:
            raise ParameterError("stiffness", stiffness, " or ".join(map(repr, STIFFNESS_MODES)))
        self.stiffness = stiffness
        if int(cg_max_iterations) != cg_max_iterations or cg_max_iterations < 1:
            raise ParameterError("cg_max_iterations", cg_max_iterations, "an integer >= 1")
        self.bodies = bodies
        self.device = wp.get_device(device)
        self.precision = precision
        self.dtype = wp.float64 if precision == "float64" else wp.float32
        self.np_dtype = np.float64 if precision == "float64" else np.float32
        self.vec3, self.mat33, self.vec4 = ke.fem_types(self.dtype)
        self.vec2 = wp.types.vector(2, self.dtype)
        self.gravity_host = g
        self.gravity = self.vec3(*g)
        self.ground = ground
        self.colliders = list(colliders)
        if self.colliders and precision != "float32":
            raise ParameterError("precision", precision, "'float32' in a scene with colliders")
        self.measure = bodies[0].measure
        self.integrator = bodies[0].integrator
        default_tol = 1.0e-10 if precision == "float64" else 1.0e-5
        self.cg_tolerance = check_range("cg_tolerance", default_tol if cg_tolerance is None else cg_tolerance, 0, 1)
        self.cg_max_iterations = int(cg_max_iterations)
        self.cg_reports: list[CgReport] = []  # of the last step / static solve
        self.time = 0.0
        self.step_count = 0
        self.topology_version = 0
        self.split_count = 0  # vertex splits performed by fracture
        self.last_splits = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # (vertices, rest-frame normals)

        self._build_model()
        self.features = {"elastic"}
        if self.plastic:
            self.features.add("plasticity")
        if self.fracture:
            self.features.add("fracture")
        if np.any(g != 0.0):
            self.features.add("gravity")
        if ground is not None:
            self.features.add("ground_plane")
        if self.colliders:
            self.features.add("colliders")
        if np.any(self._vertex_damping_h > 0.0):
            self.features.add("damping")
        if self._render:
            self.features.add("render_mesh")
        self._handles = []
        self._collision_radius = None
        self._written_version: dict[int, int] = {}
        if self.integrator == "explicit":
            self._update_accelerations()

    # -- model ----------------------------------------------------------------------------------------------------
    def _build_model(self):
        import warp as wp

        from ..kernels.fem import elements as ke

        bodies = self.bodies
        v_counts = [b.vertex_count for b in bodies]
        e_counts = [b.element_count for b in bodies]
        v_off = np.concatenate([[0], np.cumsum(v_counts)]).astype(np.int64)
        self.element_offsets = np.concatenate([[0], np.cumsum(e_counts)]).astype(np.int64)
        rest = np.concatenate([b.mesh.vertices for b in bodies])
        tets = np.concatenate([b.mesh.tets.astype(np.int64) + v_off[i] for i, b in enumerate(bodies)])
        self.element_body = np.repeat(np.arange(len(bodies)), e_counts)
        mats = [b.material for b in bodies]

        def per_element(values):
            return np.asarray(values, dtype=np.float64)[self.element_body]

        x = rest[tets]
        dm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=-1)  # columns
        self._volume_h = np.linalg.det(dm) / 6.0
        dm_inv = np.linalg.inv(dm)
        self._density_h = per_element([m.density for m in mats])
        lam = per_element([m.lame_lambda for m in mats])
        mu = per_element([m.shear_modulus for m in mats])
        cp = per_element([m.p_wave_speed for m in mats])
        heights = element_heights(rest, tets)
        self._explicit_dt = float(EXPLICIT_STEP_FACTOR * np.min(heights / cp))
        self._centroids_h = x.mean(axis=1)
        self.plastic = any(b.plasticity is not None for b in bodies)
        self.fracture = any(b.tensile_strength is not None for b in bodies)
        dev, f = self.device, self.np_dtype
        m = len(tets)
        self.element_count = m
        self._dm_inv = wp.array(dm_inv.astype(f), dtype=self.mat33, device=dev)
        self._volume = wp.array(self._volume_h.astype(f), dtype=self.dtype, device=dev)
        self._lame = wp.array(np.stack([lam, mu], axis=1).astype(f), dtype=self.vec2, device=dev)
        self._corner = wp.zeros(4 * m, dtype=self.vec3, device=dev)
        self._corner_product = wp.zeros(4 * m, dtype=self.vec3, device=dev)
        self._rotation = wp.array(np.tile(np.eye(3), (m, 1, 1)).astype(f), dtype=self.mat33, device=dev)
        self._rotation_q = wp.array(
            np.tile([0.0, 0.0, 0.0, 1.0], (m, 1)).astype(f), dtype=wp.types.quaternion(self.dtype), device=dev
        )
        self._energy = wp.zeros(m, dtype=self.dtype, device=dev)
        self._plastic_params = self._plastic_strain = None
        if self.plastic:
            inf = np.inf
            pp = np.array(
                [
                    (b.plasticity.yield_strain, b.plasticity.creep, b.plasticity.max_strain)
                    if b.plasticity is not None
                    else (inf, 0.0, inf)
                    for b in bodies
                ],
                dtype=np.float64,
            )[self.element_body]
            self._plastic_params = wp.array(pp.astype(f), dtype=self.vec3, device=dev)
            self._plastic_strain = wp.zeros(m, dtype=self.mat33, device=dev)
        self._strength = self._principal = self._over_count = None
        if self.fracture:
            self._strength_h = per_element(
                [np.inf if b.tensile_strength is None else b.tensile_strength for b in bodies]
            )
            self._strength = wp.array(self._strength_h.astype(f), dtype=self.dtype, device=dev)
            self._principal = wp.zeros(m, dtype=self.vec4, device=dev)
            self._over_count = wp.zeros(1, dtype=wp.int32, device=dev)
        self._measure_id = ke.MEASURES[self.measure]
        self._rotated = self.measure == "corotated"
        self._force_kernel = ke.element_force_kernel(self.dtype, self._measure_id, self.plastic, self.fracture, True)
        self._check = wp.zeros(2, dtype=float, device=dev)

        # render meshes: barycentric embedding in the body's own elements (global element ids)
        self._render = []
        for i, b in enumerate(bodies):
            if b.render_mesh is None:
                continue
            lo, hi = self.element_offsets[i], self.element_offsets[i + 1]
            elem, w = _embed(rest, tets[lo:hi], np.asarray(b.render_mesh.vertices, dtype=np.float64))
            self._render.append(
                (
                    i,
                    wp.array((elem + lo).astype(np.int32), dtype=wp.int32, device=dev),
                    wp.array(w.astype(f), dtype=self.vec4, device=dev),
                    np.asarray(b.render_mesh.faces, dtype=np.int32),
                    wp.zeros(len(w), dtype=wp.vec3, device=dev),
                )
            )

        # vertex data (rebuilt when fracture changes the topology)
        self._rest_h = rest
        self._tets_h = tets
        self._kind_h = np.concatenate([b.kind for b in bodies]).astype(np.int32)
        self._presc_h = np.concatenate([b.prescribed_velocity for b in bodies])
        self._release_h = np.concatenate([b.release_time for b in bodies])
        self._vertex_body_h = np.repeat(np.arange(len(bodies)), v_counts)
        self._vertex_damping_h = np.asarray([b.damping for b in bodies], dtype=np.float64)[self._vertex_body_h]
        self._crack_vertex_h = np.zeros(len(rest), dtype=bool)
        init_v = np.concatenate([b.initial_velocity for b in bodies])
        self._upload_vertices(rest, init_v, np.zeros_like(rest))

    def _upload_vertices(self, positions, velocities, accelerations):
        """(Re)allocates every per-vertex array from host data and the current topology ``self._tets_h``."""
        import warp as wp

        from .fracture import vertex_incidence

        dev, f = self.device, self.np_dtype
        n = len(self._rest_h)
        self.vertex_count = n
        tets = self._tets_h
        self._tets = wp.array(tets.astype(np.int32), dtype=wp.vec4i, device=dev)
        offsets, slots = vertex_incidence(tets, n)
        self._vertex_offsets = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=dev)
        self._vertex_slots = wp.array(slots.astype(np.int32), dtype=wp.int32, device=dev)
        mass = np.bincount(tets.ravel(), weights=np.repeat(self._density_h * self._volume_h / 4.0, 4), minlength=n)
        self._mass_h = mass

        def vec(a):
            return wp.array(np.asarray(a, dtype=f), dtype=self.vec3, device=dev)

        def scal(a):
            return wp.array(np.asarray(a, dtype=f), dtype=self.dtype, device=dev)

        self.positions_wp = vec(positions)
        self.velocities_wp = vec(velocities)
        self._accelerations = vec(accelerations)
        self._forces = wp.zeros(n, dtype=self.vec3, device=dev)
        self._rest = vec(self._rest_h)
        self._kind = wp.array(self._kind_h, dtype=wp.int32, device=dev)
        self._prescribed = vec(self._presc_h)
        self._mass = scal(mass)
        self._inv_mass = scal(1.0 / mass)
        self._damping = scal(self._vertex_damping_h)
        self._op_mass = None
        self._op_mass_dt = None
        # CG work arrays
        self._chunk = CG_CHUNK
        chunks = max(1, math.ceil(n / CG_CHUNK))
        self._cg_rhs = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_x = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_r = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_z = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_p = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_q = wp.zeros(n, dtype=self.vec3, device=dev)
        self._cg_precond = wp.zeros(n, dtype=self.mat33, device=dev)
        self._constrained = wp.array((self._kind_h != 0).astype(np.int32), dtype=wp.int32, device=dev)
        self._cg_partial = wp.zeros(chunks, dtype=self.dtype, device=dev)
        self._cg_partial2 = wp.zeros(chunks, dtype=self.vec2, device=dev)
        self._cg_partial3 = wp.zeros(chunks, dtype=self.vec3, device=dev)
        self._cg_scalars = wp.zeros(8, dtype=self.dtype, device=dev)
        self._cg_chunks = chunks
        self._next_release = float(self._release_h[self._kind_h == 2].min(initial=np.inf))
        self._surfaces = None  # per body (vertex ids, faces), rebuilt lazily
        self._bsr = None  # assembled stiffness pattern, rebuilt lazily

    # -- time step ------------------------------------------------------------------------------------------------
    def explicit_time_step(self) -> float:
        """Stable explicit step 0.5 h_min / c_p [s] (see the module docstring)."""
        return self._explicit_dt

    def stable_time_step(self) -> float:
        """The step the scene should use [s]: the explicit limit, or ``implicit_step_ratio`` times it (implicit)."""
        if self.integrator == "implicit":
            return min(b.implicit_step_ratio for b in self.bodies) * self._explicit_dt
        return self._explicit_dt

    # -- kernels ----------------------------------------------------------------------------------------------------
    def _compute_element_forces(self, dt: float, positions=None):
        """Corner forces of every element at ``positions`` (default: current), with the plastic update of step dt."""
        import warp as wp

        if self.fracture:
            self._over_count.zero_()
        wp.launch(
            self._force_kernel,
            dim=self.element_count,
            inputs=[
                self.positions_wp if positions is None else positions,
                self._tets,
                self._dm_inv,
                self._volume,
                self._lame,
                self._plastic_params,
                self._plastic_strain,
                self.dtype(dt),
                self._strength,
                self._principal,
                self._over_count,
                self._rotation_q,
                self._rotation,
                self._corner,
            ],
            device=self.device,
        )

    def _update_accelerations(self):
        """a = f / m + g - c v at the current state, without a kick or a plastic update (after init and splits)."""
        self._compute_element_forces(0.0)
        self._gather_kick(0.0)
        if self.fracture:
            self._over_count.zero_()

    def _collide(self, dt: float):
        """Ground plane, then the scene's colliders, on the positions at the end of the step (time + dt), as the
        peridynamic solver does."""
        import warp as wp

        from ..kernels.fem import solver as ks

        if self.ground is not None:
            g = self.ground
            wp.launch(
                ks.vertex_kernels(self.dtype)["collide_ground_plane"],
                dim=self.vertex_count,
                inputs=[
                    self.positions_wp,
                    self.velocities_wp,
                    self._kind,
                    self.vec3(*g.normal),
                    self.dtype(g.offset),
                    self.dtype(g.friction),
                ],
                device=self.device,
            )
        if self.colliders:
            if self._collision_radius is None or self._collision_radius.shape[0] != self.vertex_count:
                self._collision_radius = wp.zeros(self.vertex_count, dtype=float, device=self.device)
            for c in self.colliders:
                c.apply(self.positions_wp, self.velocities_wp, self._collision_radius, self._kind, self.time + dt, dt)

    # -- stepping ---------------------------------------------------------------------------------------------------
    def step(self, dt: float):
        """Advances all bodies by one step of ``dt`` [s]. The explicit integrator refuses dt above its stable limit
        (ParameterError); use :meth:`simulate` for automatic substepping."""
        dt = check_range("dt", dt, 0.0, None)
        if self.integrator == "explicit":
            limit = self._explicit_dt
            if dt > limit * (1.0 + 1.0e-9):
                raise ParameterError(
                    "dt", dt, f"(0, {limit:.6g}] s: the explicit stable limit 0.5 h_min / c_p (simulate() substeps)"
                )
            self._step_explicit(dt)
        else:
            self._step_implicit(dt)
        self.time += dt
        self.step_count += 1
        if self.fracture:
            self._fracture_event()
        if self.time >= self._next_release:
            self._release_vertices()

    def _release_vertices(self):
        """Prescribed vertices whose release time has passed become free (they keep their current velocity)."""
        import warp as wp

        due = (self._kind_h == 2) & (self._release_h <= self.time)
        self._kind_h = np.where(due, 0, self._kind_h).astype(np.int32)
        self._release_h = np.where(due, np.inf, self._release_h)
        self._next_release = float(self._release_h[self._kind_h == 2].min(initial=np.inf))
        self._kind = wp.array(self._kind_h, dtype=wp.int32, device=self.device)
        self._constrained = wp.array((self._kind_h != 0).astype(np.int32), dtype=wp.int32, device=self.device)
        if self.integrator == "explicit":
            self._update_accelerations()

    def simulate(self, dt: float, steps: int):
        """Runs ``steps`` steps of ``dt`` [s]; the explicit integrator splits each into ceil(dt / dt_stable) equal
        substeps when dt exceeds its stable limit."""
        dt = check_range("dt", dt, 0.0, None)
        sub = 1
        if self.integrator == "explicit":
            sub = max(1, math.ceil(dt / self._explicit_dt - 1.0e-9))
        for _ in range(int(steps) * sub):
            self.step(dt / sub)

    def _step_explicit(self, dt: float):
        import warp as wp

        from ..kernels.fem import solver as ks

        kick_drift, _ = ks.explicit_kernels(self.dtype)
        d = self.device
        wp.launch(
            kick_drift,
            dim=self.vertex_count,
            inputs=[
                self.positions_wp,
                self.velocities_wp,
                self._accelerations,
                self._rest,
                self._kind,
                self._prescribed,
                self.dtype(dt),
            ],
            device=d,
        )
        self._collide(dt)
        self._compute_element_forces(dt)
        self._gather_kick(dt)

    def _gather_kick(self, dt: float):
        """Gathers the element corner forces into vertex forces, a = f / m + g - c v, and kicks free vertices by
        dt / 2 (dt = 0: accelerations only)."""
        import warp as wp

        from ..kernels.fem import solver as ks

        _, gather_kick = ks.explicit_kernels(self.dtype)
        wp.launch(
            gather_kick,
            dim=self.vertex_count,
            inputs=[
                self._vertex_offsets,
                self._vertex_slots,
                self._corner,
                self._inv_mass,
                self._kind,
                self.gravity,
                self._damping,
                self.dtype(dt),
                self.velocities_wp,
                self._accelerations,
                self._forces,
            ],
            device=self.device,
        )

    def _operator_mass(self, dt: float):
        """(1 + dt c) m per vertex (the mass term of the backward-Euler operator), cached per dt and topology."""
        import warp as wp

        if self._op_mass is None or self._op_mass_dt != dt:
            om = self._mass_h * (1.0 + dt * self._vertex_damping_h)
            self._op_mass = wp.array(om.astype(self.np_dtype), dtype=self.dtype, device=self.device)
            self._op_mass_dt = dt
        return self._op_mass

    def _step_implicit(self, dt: float):
        import warp as wp

        from ..kernels.fem import solver as ks

        d = self.device
        self._compute_element_forces(dt)
        wp.launch(
            ks.implicit_rhs_kernel(self.dtype),
            dim=self.vertex_count,
            inputs=[
                self._vertex_offsets,
                self._vertex_slots,
                self._corner,
                self._mass,
                self.velocities_wp,
                self._kind,
                self._prescribed,
                self.gravity,
                self.dtype(dt),
                self._forces,
                self._cg_rhs,
                self._cg_x,
                self._constrained,
            ],
            device=d,
        )
        report = self._cg_solve(self._operator_mass(dt), 1.0, dt * dt)
        self.cg_reports = [report]
        wp.copy(self.velocities_wp, self._cg_x)
        wp.launch(
            ks.vertex_kernels(self.dtype)["advance_positions"],
            dim=self.vertex_count,
            inputs=[self.positions_wp, self.velocities_wp, self._rest, self._kind, self.dtype(dt)],
            device=d,
        )
        self._collide(dt)

    def _apply_stiffness(self, u, out_corner):
        import warp as wp

        from ..kernels.fem import elements as ke

        wp.launch(
            ke.element_stiffness_product_kernel(self.dtype, self._rotated),
            dim=self.element_count,
            inputs=[u, self._tets, self._dm_inv, self._volume, self._lame, self._rotation, out_corner],
            device=self.device,
        )

    def _cg_solve(self, op_mass, c_mass: float, c_stiff: float, *, tolerance=None, max_iterations=None) -> CgReport:
        """Solves (c_mass diag(op_mass) + c_stiff K_R) x = rhs on the unconstrained vertices by block-Jacobi
        preconditioned CG; ``self._cg_x`` holds the initial guess (kept on constrained vertices) and the result."""
        import warp as wp

        from ..kernels.fem import solver as ks

        k = ks.cg_kernels(self.dtype, self._rotated)
        d, n, ch, chunks = self.device, self.vertex_count, self._chunk, self._cg_chunks
        tol = self.cg_tolerance if tolerance is None else tolerance
        max_it = self.cg_max_iterations if max_iterations is None else int(max_iterations)
        c_mass, c_stiff = self.dtype(c_mass), self.dtype(c_stiff)
        assembled = self.stiffness == "assembled"
        if assembled:
            ka = ks.assembled_kernels(self.dtype)
            bsr = self._assemble_stiffness()
            wp.launch(
                ka["bsr_block_jacobi"],
                dim=n,
                inputs=[bsr["diagonal"], bsr["values"], op_mass, c_mass, c_stiff, self._constrained, self._cg_precond],
                device=d,
            )
            op_kernel = ka["bsr_operator_gather"]
            op_inputs = [bsr["row_offsets"], bsr["columns"], bsr["values"], op_mass, c_mass, c_stiff]
        else:
            wp.launch(
                k["block_jacobi"],
                dim=n,
                inputs=[
                    self._vertex_offsets,
                    self._vertex_slots,
                    self._dm_inv,
                    self._volume,
                    self._lame,
                    self._rotation,
                    op_mass,
                    c_mass,
                    c_stiff,
                    self._constrained,
                    self._cg_precond,
                ],
                device=d,
            )
            op_kernel = k["operator_gather"]
            op_inputs = [self._vertex_offsets, self._vertex_slots, self._corner_product, op_mass, c_mass, c_stiff]
        # q = A x0 (constrained rows zeroed), r = b - q, z = P r, p = z
        if not assembled:
            self._apply_stiffness(self._cg_x, self._corner_product)
        wp.launch(
            op_kernel,
            dim=chunks,
            inputs=[*op_inputs, self._constrained, self._cg_x, ch, self._cg_q, self._cg_partial],
            device=d,
        )
        wp.launch(
            k["residual_init"],
            dim=chunks,
            inputs=[
                self._cg_rhs,
                self._cg_q,
                self._constrained,
                self._cg_precond,
                ch,
                self._cg_r,
                self._cg_z,
                self._cg_p,
                self._cg_partial3,
            ],
            device=d,
        )
        wp.launch(k["reduce_init"], dim=1, inputs=[self._cg_partial3, self._cg_scalars], device=d)
        s = self._cg_scalars.numpy()
        bb = float(s[5])
        if bb == 0.0:
            return CgReport(0, 0.0, True)
        target = tol * tol * bb
        it = 0
        rr = float(s[4])
        while rr > target and it < max_it:
            if not assembled:
                self._apply_stiffness(self._cg_p, self._corner_product)
            wp.launch(
                op_kernel,
                dim=chunks,
                inputs=[*op_inputs, self._constrained, self._cg_p, ch, self._cg_q, self._cg_partial],
                device=d,
            )
            wp.launch(k["reduce_alpha"], dim=1, inputs=[self._cg_partial, self._cg_scalars], device=d)
            wp.launch(
                k["update_xr"],
                dim=chunks,
                inputs=[
                    self._cg_p,
                    self._cg_q,
                    self._cg_precond,
                    self._cg_scalars,
                    ch,
                    self._cg_x,
                    self._cg_r,
                    self._cg_z,
                    self._cg_partial2,
                ],
                device=d,
            )
            wp.launch(k["reduce_beta"], dim=1, inputs=[self._cg_partial2, self._cg_scalars], device=d)
            wp.launch(k["update_p"], dim=chunks, inputs=[self._cg_z, self._cg_scalars, ch, self._cg_p], device=d)
            it += 1
            rr = float(self._cg_scalars.numpy()[4])
        rel = math.sqrt(max(rr, 0.0) / bb)
        return CgReport(it, rel, rr <= target)

    def _assemble_stiffness(self) -> dict:
        """The assembled K_R as 3x3 blocks in CSR order (pattern cached per topology; values filled per call from the
        element blocks by a gather over the precomputed contribution lists)."""
        import warp as wp

        from ..kernels.fem import elements as ke
        from ..kernels.fem import solver as ks

        d = self.device
        if self._bsr is None:
            n, m = self.vertex_count, self.element_count
            tets = self._tets_h
            rows = np.repeat(tets, 4, axis=1).ravel()  # (e, a, b) in 16 e + 4 a + b order
            cols = np.tile(tets, (1, 4)).ravel()
            key = rows * n + cols
            uniq, block_of = np.unique(key, return_inverse=True)
            row_of_block = uniq // n
            row_offsets = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(np.bincount(row_of_block, minlength=n), out=row_offsets[1:])
            order = np.argsort(block_of, kind="stable")
            contrib_offsets = np.zeros(len(uniq) + 1, dtype=np.int64)
            np.cumsum(np.bincount(block_of, minlength=len(uniq)), out=contrib_offsets[1:])
            diagonal = np.searchsorted(uniq, np.arange(n) * n + np.arange(n))

            def i32(a):
                return wp.array(np.asarray(a, dtype=np.int32), dtype=wp.int32, device=d)

            self._bsr = {
                "row_offsets": i32(row_offsets),
                "columns": i32(uniq % n),
                "diagonal": i32(diagonal),
                "contrib_offsets": i32(contrib_offsets),
                "contrib_ids": i32(order),
                "values": wp.zeros(len(uniq), dtype=self.mat33, device=d),
                "element_blocks": wp.zeros(16 * m, dtype=self.mat33, device=d),
            }
        bsr = self._bsr
        wp.launch(
            ke.element_stiffness_blocks_kernel(self.dtype, self._rotated),
            dim=self.element_count,
            inputs=[self._dm_inv, self._volume, self._lame, self._rotation, bsr["element_blocks"]],
            device=d,
        )
        wp.launch(
            ks.assembled_kernels(self.dtype)["assemble_blocks"],
            dim=bsr["values"].shape[0],
            inputs=[bsr["contrib_offsets"], bsr["contrib_ids"], bsr["element_blocks"], bsr["values"]],
            device=d,
        )
        return bsr

    def solve_static(
        self,
        *,
        constrained=None,
        tolerance: float = 1.0e-6,
        max_newton_iterations: int = 30,
        cg_tolerance: float | None = None,
        cg_max_iterations: int = 20000,
    ) -> StaticSolveReport:
        """Quasi-static equilibrium f_int(x) + M g = 0 on the unconstrained vertices, by Newton iterations with the
        tangent K_R (rotations frozen per iteration; the constant K for the linear and the Green measure), each solved
        by CG. Constrained vertices keep their current positions. The plastic strain is not updated.

        Args:
            constrained: bool mask [vertex_count] of vertices held in place; default: the fixed and prescribed ones.
            tolerance: stop when |residual| <= tolerance * |M g| (or * the first residual without gravity), or when a
                Newton update is below max(tolerance, 1000 eps) times the displacement so far (the float32 floor).
            max_newton_iterations: Newton iterations at most (the linear measure needs one).
            cg_tolerance: relative CG residual per Newton iteration (default: the solver's).
            cg_max_iterations: CG iterations per Newton iteration.
        """
        import warp as wp

        from ..kernels.fem import solver as ks

        n = self.vertex_count
        mask = self._kind_h != 0 if constrained is None else np.asarray(constrained)
        if mask.shape != (n,) or mask.dtype != np.bool_:
            raise ParameterError("constrained", constrained, f"a bool mask of shape ({n},) or None")
        tolerance = check_range("tolerance", tolerance, 0.0, None)
        vk = ks.vertex_kernels(self.dtype)
        d = self.device
        constrained_wp = wp.array(mask.astype(np.int32), dtype=wp.int32, device=d)
        saved = self._constrained
        self._constrained = constrained_wp
        zero_mass = wp.zeros(n, dtype=self.dtype, device=d)
        free = ~mask
        load = float(np.linalg.norm(self._mass_h[free]) * np.linalg.norm(self.gravity_host))
        reports = []
        x_start = self.positions()
        step_tol = max(tolerance, 1000.0 * float(np.finfo(self.np_dtype).eps))

        def residual_norm() -> float:
            self._compute_element_forces(0.0)
            wp.launch(
                vk["gather_forces"],
                dim=n,
                inputs=[self._vertex_offsets, self._vertex_slots, self._corner, self._forces],
                device=d,
            )
            wp.launch(
                vk["residual_forces"],
                dim=n,
                inputs=[self._forces, self._mass, self.gravity, constrained_wp, self._cg_rhs],
                device=d,
            )
            return float(np.linalg.norm(self._cg_rhs.numpy().astype(np.float64)))

        try:
            res = residual_norm()
            ref = load if load > 0.0 else max(res, 1.0e-300)
            for newton in range(int(max_newton_iterations)):
                if res <= tolerance * ref:
                    break
                self._cg_x.zero_()
                reports.append(
                    self._cg_solve(zero_mass, 0.0, 1.0, tolerance=cg_tolerance, max_iterations=cg_max_iterations)
                )
                wp.launch(vk["apply_displacement"], dim=n, inputs=[self.positions_wp, self._cg_x], device=d)
                du = float(np.linalg.norm(self._cg_x.numpy().astype(np.float64)))
                u = float(np.linalg.norm(self.positions() - x_start))
                res = residual_norm()
                if self.measure == "linear":
                    break  # the linear problem is solved by one iteration (to the CG tolerance)
                if newton > 0 and du <= step_tol * u:
                    break  # converged in the increment (float32 round-off bounds the residual)
        finally:
            self._constrained = saved
            if self.fracture:
                self._over_count.zero_()
        self.cg_reports = reports
        if self.integrator == "explicit":
            self._update_accelerations()
        return StaticSolveReport(
            newton_iterations=len(reports),
            cg_iterations=sum(r.iterations for r in reports),
            residual=res,
            relative_residual=res / ref if ref else 0.0,
        )

    # -- fracture -----------------------------------------------------------------------------------------------
    def apply_fracture(self) -> int:
        """Evaluates the stresses at the current positions (no plastic update) and performs the crack splits of
        every element over its strength, as a step does; returns the number of vertex splits."""
        if not self.fracture:
            raise ParameterError("tensile_strength", None, "a value > 0 on some body to use fracture")
        before = self.split_count
        self._compute_element_forces(0.0)
        self._fracture_event()
        return self.split_count - before

    def _fracture_event(self) -> bool:
        """Splits vertices where elements exceed their strength (only when the kernel counted one); True if the
        topology changed."""
        import warp as wp

        from .fracture import choose_splits, make_manifold, split_vertices

        if int(self._over_count.numpy()[0]) == 0:
            return False
        principal = self._principal.numpy().astype(np.float64)
        over = np.flatnonzero(principal[:, 3] > self._strength_h)
        if over.size == 0:
            return False
        nv = self.vertex_count
        verts, normals, sources = choose_splits(
            self._tets_h,
            self._rest_h,
            self._centroids_h,
            over,
            principal[over, :3],
            principal[over, 3],
            self._crack_vertex_h,
        )
        if len(verts) == 0:
            return False
        tets1, parent1 = split_vertices(self._tets_h, self._rest_h, self._centroids_h, verts, normals)
        copies = np.arange(nv, len(parent1))
        tets2, parent2 = make_manifold(tets1, len(parent1), np.concatenate([verts, copies]))
        parent = parent1[parent2]
        crack = self._crack_vertex_h[parent]
        crack[verts] = True
        crack[nv:] = True
        self.split_count += len(verts)
        self.last_splits = (verts.copy(), normals.copy())
        # an element splits at most once (pdsim/fem/fracture.py): retire the sources from the strength test
        self._strength_h[sources] = np.inf
        self._strength = wp.array(self._strength_h.astype(self.np_dtype), dtype=self.dtype, device=self.device)
        self._apply_topology(tets2, parent, crack)
        return True

    def _apply_topology(self, tets: np.ndarray, parent: np.ndarray, crack: np.ndarray):
        """Installs new element corners; vertex i of the new numbering copies the state of old vertex parent[i]."""
        x = self.positions_wp.numpy()[parent]
        v = self.velocities_wp.numpy()[parent]
        a = self._accelerations.numpy()[parent]
        self._rest_h = self._rest_h[parent]
        self._kind_h = self._kind_h[parent]
        self._presc_h = self._presc_h[parent]
        self._release_h = self._release_h[parent]
        self._vertex_body_h = self._vertex_body_h[parent]
        self._vertex_damping_h = self._vertex_damping_h[parent]
        self._crack_vertex_h = crack
        self._tets_h = np.asarray(tets, dtype=np.int64)
        self._upload_vertices(x, v, a)
        self.topology_version += 1
        if self.integrator == "explicit":
            self._update_accelerations()

    # -- checks ---------------------------------------------------------------------------------------------------
    def check_state(self, speed_limit: float):
        """Raises InstabilityError if a position or velocity is not finite or a speed exceeds ``speed_limit`` [m/s]."""
        import warp as wp

        from ..kernels.fem import solver as ks

        self._check.zero_()
        wp.launch(
            ks.vertex_kernels(self.dtype)["max_speed_and_finite"],
            dim=self.vertex_count,
            inputs=[self.positions_wp, self.velocities_wp, self._check],
            device=self.device,
        )
        vmax, bad = self._check.numpy()
        if bad > 0 or vmax > speed_limit:
            what = "non-finite positions or velocities" if bad > 0 else f"a vertex speed of {vmax:.3g} m/s"
            raise InstabilityError(
                f"the FEM simulation diverged at t={self.time:.6g} s (step {self.step_count}): {what}; "
                f"explicit stable limit {self._explicit_dt:.3g} s"
            )

    # -- scene integration ------------------------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        """Vertex count (the Scene's report calls it particle_count)."""
        return self.vertex_count

    @property
    def bond_count(self) -> int:
        """Element count (the Scene's report calls it bond_count)."""
        return self.element_count

    def speed_scale(self) -> float:
        """Largest of the bodies' P-wave speeds, initial speeds and prescribed speeds [m/s]."""
        return max(
            max(
                b.material.p_wave_speed,
                float(np.abs(b.initial_velocity).max(initial=0.0)),
                float(np.abs(b.prescribed_velocity).max(initial=0.0)),
            )
            for b in self.bodies
        )

    def surfaces(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per body: (vertex ids [k] into the solver's vertices, outward triangles [f, 3] indexing those ids). Each
        connected piece of a body is a closed surface with its own vertices."""
        return [(ids, faces) for ids, faces, _ in self._surface_data()]

    def _surface_data(self):
        """Per body: (vertex ids, triangles, piece label per triangle), rebuilt when the topology changed."""
        from .fracture import element_pieces

        if self._surfaces is None:
            faces, elem = boundary_faces(self._tets_h, return_elements=True)
            face_body = self.element_body[elem]
            piece_of_element = element_pieces(self._tets_h)[1]
            out = []
            for i in range(len(self.bodies)):
                mine = face_body == i
                ids, local = np.unique(faces[mine], return_inverse=True)
                out.append((ids, local.reshape(-1, 3).astype(np.int32), piece_of_element[elem[mine]].astype(np.int32)))
            self._surfaces = out
        return self._surfaces

    def add_outputs(self, cache):
        """Declares one UsdGeom.Mesh per body (its boundary surface: one closed shell per piece, with the per-face
        int primvar ``piece``) and one per render mesh ("<name>_render")."""
        self._handles = [cache.add_mesh(b.name, face_primvars={"piece": "int"}) for b in self.bodies]
        self._render_handles = [cache.add_mesh(f"{self.bodies[r[0]].name}_render") for r in self._render]
        self._written_version = {}

    def write_outputs(self, cache, frame: int):
        """Writes each body's boundary surface at ``frame`` (topology only on frames where it changed) and the render
        meshes (topology on their first frame)."""
        import warp as wp

        from ..kernels.fem import elements as ke

        x = self.positions()
        for i, (handle, (ids, faces, piece)) in enumerate(zip(self._handles, self._surface_data(), strict=True)):
            if self._written_version.get(i) != self.topology_version:
                cache.write_mesh(handle, frame, x[ids], faces, face_primvars={"piece": piece})
            else:
                cache.write_mesh(handle, frame, x[ids])
            self._written_version[i] = self.topology_version
        for handle, (_, elem, w, faces, out) in zip(self._render_handles, self._render, strict=True):
            wp.launch(
                ke.embed_points_kernel(self.dtype),
                dim=len(w),
                inputs=[self.positions_wp, self._tets, elem, w, out],
                device=self.device,
            )
            cache.write_mesh(handle, frame, out.numpy(), faces if not handle._has_topology else None)

    def render_points(self, index: int = 0) -> np.ndarray:
        """Current vertices of the ``index``-th render mesh [m], shape [render_vertex_count, 3]."""
        import warp as wp

        from ..kernels.fem import elements as ke

        _, elem, w, _, out = self._render[index]
        wp.launch(
            ke.embed_points_kernel(self.dtype),
            dim=len(w),
            inputs=[self.positions_wp, self._tets, elem, w, out],
            device=self.device,
        )
        return out.numpy().astype(np.float64)

    # -- host-side views and diagnostics (vectorised numpy) -----------------------------------------------------
    @property
    def tets(self) -> np.ndarray:
        """Current element corners (after fracture splits), shape [element_count, 4]."""
        return self._tets_h

    @property
    def rest_positions(self) -> np.ndarray:
        """Rest positions of the current vertices [m], shape [vertex_count, 3]."""
        return self._rest_h

    @property
    def vertex_body(self) -> np.ndarray:
        """Body index of each vertex, shape [vertex_count]."""
        return self._vertex_body_h

    def positions(self) -> np.ndarray:
        """Current positions [m], shape [vertex_count, 3], float64."""
        return self.positions_wp.numpy().astype(np.float64)

    def velocities(self) -> np.ndarray:
        """Current velocities [m/s], shape [vertex_count, 3], float64."""
        return self.velocities_wp.numpy().astype(np.float64)

    def set_positions(self, positions):
        """Overwrites positions [m] (shape [vertex_count, 3]); recomputes the accelerations (explicit)."""
        import warp as wp

        p = np.asarray(positions, dtype=self.np_dtype)
        if p.shape != (self.vertex_count, 3):
            raise ParameterError("positions", p.shape, f"shape ({self.vertex_count}, 3)")
        wp.copy(self.positions_wp, wp.array(p, dtype=self.vec3, device=self.device))
        if self.integrator == "explicit":
            self._update_accelerations()

    def set_velocities(self, velocities):
        """Overwrites velocities [m/s], shape [vertex_count, 3]."""
        import warp as wp

        v = np.asarray(velocities, dtype=self.np_dtype)
        if v.shape != (self.vertex_count, 3):
            raise ParameterError("velocities", v.shape, f"shape ({self.vertex_count}, 3)")
        wp.copy(self.velocities_wp, wp.array(v, dtype=self.vec3, device=self.device))
        if self.integrator == "explicit":
            self._update_accelerations()

    def nodal_forces(self, positions=None) -> np.ndarray:
        """Internal elastic forces [N] at the current (or given) positions, shape [vertex_count, 3] (no plastic
        update)."""
        import warp as wp

        from ..kernels.fem import solver as ks

        pos = None
        if positions is not None:
            p = np.asarray(positions, dtype=self.np_dtype)
            if p.shape != (self.vertex_count, 3):
                raise ParameterError("positions", p.shape, f"shape ({self.vertex_count}, 3)")
            pos = wp.array(p, dtype=self.vec3, device=self.device)
        self._compute_element_forces(0.0, pos)
        out = wp.zeros(self.vertex_count, dtype=self.vec3, device=self.device)
        wp.launch(
            ks.vertex_kernels(self.dtype)["gather_forces"],
            dim=self.vertex_count,
            inputs=[self._vertex_offsets, self._vertex_slots, self._corner, out],
            device=self.device,
        )
        if self.fracture:
            self._over_count.zero_()
        return out.numpy().astype(np.float64)

    def element_stiffness(self) -> np.ndarray:
        """Element stiffness matrices K_e = V B^T E B (rotated R K_e R^T with the last stored rotations for the
        corotated measure) [N/m], shape [element_count, 12, 12] (rows/cols: corner-major, xyz-minor)."""
        import warp as wp

        from ..kernels.fem import elements as ke

        blocks = wp.zeros(16 * self.element_count, dtype=self.mat33, device=self.device)
        wp.launch(
            ke.element_stiffness_blocks_kernel(self.dtype, self._rotated),
            dim=self.element_count,
            inputs=[self._dm_inv, self._volume, self._lame, self._rotation, blocks],
            device=self.device,
        )
        b = blocks.numpy().astype(np.float64).reshape(self.element_count, 4, 4, 3, 3)
        return b.transpose(0, 1, 3, 2, 4).reshape(self.element_count, 12, 12)

    def principal_stresses(self) -> np.ndarray:
        """(rest-frame direction, largest principal stress [Pa]) per element from the last force evaluation,
        shape [element_count, 4] (fracture bodies only)."""
        if not self.fracture:
            raise ParameterError("tensile_strength", None, "a value > 0 on some body to track principal stresses")
        return self._principal.numpy().astype(np.float64)

    def plastic_strain(self) -> np.ndarray:
        """Plastic strain tensor per element [-], shape [element_count, 3, 3] (zeros without plasticity)."""
        if not self.plastic:
            return np.zeros((self.element_count, 3, 3))
        return self._plastic_strain.numpy().astype(np.float64)

    def strain_energy(self) -> float:
        """Elastic energy sum_e V (mu |eps_el|^2 + lambda/2 tr(eps_el)^2) [J] at the current positions."""
        import warp as wp

        from ..kernels.fem import elements as ke

        wp.launch(
            ke.element_energy_kernel(self.dtype, self._measure_id, self.plastic),
            dim=self.element_count,
            inputs=[
                self.positions_wp,
                self._tets,
                self._dm_inv,
                self._volume,
                self._lame,
                self._plastic_strain,
                self._energy,
            ],
            device=self.device,
        )
        return float(self._energy.numpy().astype(np.float64).sum())

    def masses(self) -> np.ndarray:
        """Lumped vertex masses [kg], shape [vertex_count]."""
        return self._mass_h

    def kinetic_energy(self) -> float:
        """1/2 sum m v^2 [J]."""
        v = self.velocities()
        return float(0.5 * np.dot(self._mass_h, np.einsum("ij,ij->i", v, v)))

    def gravity_potential(self) -> float:
        """-sum m g . x [J]."""
        return float(-np.dot(self._mass_h, self.positions() @ self.gravity_host))

    def linear_momentum(self) -> np.ndarray:
        """sum m v [kg m/s]."""
        return self._mass_h @ self.velocities()

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """sum m (x - origin) x v [kg m^2/s]."""
        x = self.positions() - np.asarray(origin, dtype=np.float64)
        return self._mass_h @ np.cross(x, self.velocities())

    def summary(self) -> str:
        """One line for run reports: vertices and elements simulated."""
        return f"{self.particle_count} FEM vertices, {self.bond_count} tetrahedra"

    def piece_count(self) -> int:
        """Number of face-connected pieces of all bodies together."""
        from .fracture import element_pieces

        return int(element_pieces(self._tets_h)[0])


__all__ = ["CgReport", "SolverFem", "StaticSolveReport"]

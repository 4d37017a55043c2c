"""Tetrahedral finite element solid with plasticity and fracture.

A :class:`FemBody` is a linear-tetrahedron mesh of a solid (meshed from a closed surface by fTetWild, or loaded ready)
with a :class:`pdsim.Material`, a strain measure ("linear", "corotated" or "green", see kernels/fem/elements.py), an
integrator ("explicit" or "implicit"), and optional plasticity (:class:`FemPlasticity`) and fracture
(``tensile_strength``). :class:`SolverFem` steps all FEM bodies of a scene together on the method-neutral core
(pdsim/solver.py): its state is the shared :class:`pdsim.kinematics.PointKinematics` on the mesh vertices
(displacements u from the rest positions, velocities, accelerations; boundary conditions per axis with time windows
and curves; loads; reactions; the watchdog), the rest positions stored relative to the scene's origin.

The solver is split by concern: this module holds :class:`SolverFem` (construction, features, the vertex data of a
topology, scene integration, host state and diagnostics), built from one class per concern:

- pdsim/fem/step.py (:class:`FemStep`): the stable steps, element forces, loads and gathers, the explicit step, the
  colliders and the calls into the implicit step and the static solve;
- pdsim/fem/fracture_events.py (:class:`FemFractureEvents`): the crack splits after a step and the rebuilt topology;
- pdsim/fem/views.py (:class:`FemViews`): the output views, the drawn surfaces and the contact mesh;
- pdsim/fem/checkpoint.py (:class:`FemCheckpoint`): checkpoint and restore;

and delegates to

- pdsim/fem/model.py: the element data built once (rest geometry, Dm^-1, volumes, materials, the explicit stable step,
  render-mesh embeddings), and the precision argument: element strains come from displacement differences with Dm^-1
  computed on the host in float64, so a float32 solver gives the same answer wherever the scene sits in the world;
- pdsim/fem/cg.py: the block-Jacobi preconditioned conjugate gradient on the stiffness (matrix-free or assembled);
- pdsim/fem/implicit.py: the backward-Euler step, and pdsim/fem/static.py: the quasi-static solve, both through the
  operators of pdsim/fem/operators.py (they do not import this module).

Integrators:

- explicit: velocity Verlet (kernels/integration.py's kick-drift, then the element forces and the shared second half
  kick: on the CPU the element pass adds its forces onto the vertices in element order, on a GPU the corner forces
  are gathered per vertex fused with the kick) with lumped masses m_i = sum over the vertex's elements of rho V / 4.
  The stable step is dt_stable = 0.5 h_min / c_p with h_min the smallest element height (3 V / largest face area) and
  c_p = sqrt((lambda + 2 mu) / rho) the dilatational wave speed. The factor 0.5 keeps the step below the
  element-by-element bound 2 / sqrt(max eig(M_e^-1 K_e)), a lower bound of the true critical step (largest eigenvalue
  of M^-1 K; tests/test_fem_dynamics.py checks the margin). :meth:`SolverFem.step` refuses a larger step
  (ParameterError); :meth:`SolverFem.simulate` splits each requested step into equal substeps no longer than
  dt_stable instead.
- implicit (pdsim/fem/implicit.py): linearly implicit backward Euler with the corotated stiffness, one CG solve per
  step, at any step size; :meth:`SolverFem.stable_time_step` then reports ``implicit_step_ratio`` (default 10) times
  the explicit limit as the step the scene should use.

A quasi-static solve (:meth:`SolverFem.solve_static`, pdsim/fem/static.py: Newton iterations with the same CG) takes
the same loads (gravity, body forces, tractions, pressures, forces) and the per-axis boundary conditions.

Plasticity is compiled into the element force kernel and its state (a plastic strain tensor per element) allocated
only when some body yields. Fracture (pdsim/fem/fracture.py) costs one eigen-decomposition per element whose
Samuelson bound exceeds its strength, a counter read per step, and host topology work (vectorised numpy/scipy, local to
the split vertices) only on steps where some element exceeded its strength; the vertex arrays and the kinematics are
then rebuilt from host arrays (displacements, velocities, accelerations and boundary conditions carried over to the
new vertex numbering, copies inheriting their parent's; loads resolved again on the split mesh). With a fracture
energy, the steps that follow a split also read and write the velocities on the host until the energy owed is paid.

Colliders: the ground plane and the scene's colliders (pdsim/colliders.py) act on the free vertices with zero radius
(float32 only). Contact between FEM bodies and between the pieces of a cracked body (surface vertices against the
faces of other pieces) is pdsim.contact.MethodContact's, on unless the scene switches contact off.

Output (:meth:`SolverFem.views`): per body a PointsView of its vertices and a MeshView "<name>_surface", whose
topology version changes when its faces change; optionally an embedded render mesh "<name>_render". The surface of a
body that cannot fracture, or of one with ``crack_surfaces="elements"``, is the boundary of its tetrahedra (each piece
a closed shell with its own vertices). A body that can fracture draws by default (``crack_surfaces="smooth"``) its
input surface closed by smooth crack surfaces: pdsim/fragment_surfaces.py's FragmentSurfaces over the body's current
vertices (the copies fracture adds included; spacing the mean edge length; every vertex labelled by its piece),
rebuilt when fracture changed the body's vertices (docs/fem_fracture.md).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import warp as wp

from ..checks import check_range
from ..errors import FeatureNotAvailableError, ParameterError
from ..kernels.fem import elements as ke
from ..kernels.fem import solver as ks
from ..kinematics import PointKinematics, scene_origin
from ..solver import PointSolver, SolverContext, register_solver
from .body import PRECISIONS, STIFFNESS_MODES, FemBody, lumped_masses
from .cg import CgReport, FemCg
from .checkpoint import FemCheckpoint
from .fracture import element_pieces, vertex_incidence
from .fracture_events import FemFractureEvents
from .implicit import BackwardEuler
from .model import FemModel
from .static import StaticSolveReport
from .step import FemStep
from .views import FemViews

RUBBLE_ELEMENTS = 2  # a piece of at most this many elements is rubble (chip_shares: the crumbled report)


@register_solver
class SolverFem(FemStep, FemFractureEvents, FemViews, FemCheckpoint, PointSolver):
    """Solver for the FEM bodies of a scene (concatenated into one mesh; elements never join two bodies).

    Args:
        bodies: the FEM bodies; they must share the strain measure and the integrator.
        context: the scene's SolverContext (device, gravity [m/s^2], ground plane, colliders, origin [m] of the local
            frame; the ground plane and the colliders are bound to it). None: built from ``device``, ``gravity``,
            ``ground`` and ``colliders`` with the origin at the centre of the bodies' bounding box.
        device, gravity, ground, colliders: shortcuts for a solver built without a context (ParameterError with one).
        precision: "float32" (default) or "float64" (verification; no colliders or ground plane).
        cg_tolerance: relative residual |r| / |b| at which CG stops; default 1e-5 (float32) or 1e-10 (float64).
        cg_max_iterations: CG iterations per solve, >= 1 (default 2000).
        stiffness: how CG applies K_R: "matrix_free" (the element kernels with the frozen rotations, per
            iteration) or "assembled" (default; a 3x3-block sparse matrix filled once per solve from the element
            stiffness blocks: about 2x faster per implicit step on the CPU, docs/benchmarks.md).

    State: ``kin`` (the shared PointKinematics on the vertices), ``force`` (nodal forces [N]: internal plus loads at
    the last evaluation), ``inv_mass`` (1 / lumped mass [1/kg]); fracture: ``split_count``, ``crack_area`` (crack
    surface opened, one side [m^2]) and ``fracture_dissipated`` (fracture energy taken from the motion so far [J];
    G_c times ``crack_area`` once the energy owed is paid). ``features`` lists the live optional parts
    (plasticity, fracture, gravity, ground_plane, colliders, damping, render_mesh, boundary_conditions, loads,
    velocity_kicks); kernels are compiled with the dead ones removed, and no state is allocated for them.
    """

    method: ClassVar[str] = "fem"
    supported_features: ClassVar[frozenset] = frozenset(
        {"gravity", "ground_plane", "colliders", "loads", "plasticity", "fracture"}
    )

    def __init__(
        self,
        bodies: list[FemBody],
        context: SolverContext | None = None,
        *,
        device=None,
        gravity=None,
        ground=None,
        colliders=None,
        precision: str = "float32",
        cg_tolerance: float | None = None,
        cg_max_iterations: int = 2000,
        stiffness: str = "assembled",
    ):
        bodies = list(bodies)
        if not bodies or not all(isinstance(b, FemBody) for b in bodies):
            raise ParameterError("bodies", bodies, "a non-empty list of pdsim.fem.FemBody")
        context = self._context(bodies, context, device, gravity, ground, colliders)
        for attr in ("measure", "integrator"):
            values = sorted({getattr(b, attr) for b in bodies})
            if len(values) > 1:
                raise ParameterError(attr, values, f"one {attr} shared by all FEM bodies of a scene")
        if precision not in PRECISIONS:
            raise ParameterError("precision", precision, " or ".join(map(repr, PRECISIONS)))
        g = np.asarray(context.gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ParameterError("gravity", context.gravity, "3 finite numbers [m/s^2]")
        if stiffness not in STIFFNESS_MODES:
            raise ParameterError("stiffness", stiffness, " or ".join(map(repr, STIFFNESS_MODES)))
        if int(cg_max_iterations) != cg_max_iterations or cg_max_iterations < 1:
            raise ParameterError("cg_max_iterations", cg_max_iterations, "an integer >= 1")
        self.check_features(bodies, context)
        self.colliders = [c for c in [context.ground, *list(context.colliders)] if c is not None]
        if self.colliders and precision != "float32":
            names = ", ".join(f"'{b.name}'" for b in bodies)
            raise FeatureNotAvailableError(
                f"fem bodies ({names}) with precision={precision!r} cannot use the scene's ground plane or colliders "
                "(their kernels are float32 only); use precision='float32'"
            )
        self.context = context
        self.stiffness = stiffness
        self.bodies = bodies
        self.device = wp.get_device(context.device)
        self.origin = np.asarray(context.origin, dtype=np.float64).reshape(3)
        for c in self.colliders:
            c.bind(self.origin, self.device)  # the colliders act in this solver's local frame, on its device
        self.precision = precision
        self.dtype = wp.float64 if precision == "float64" else wp.float32
        self.np_dtype = np.float64 if precision == "float64" else np.float32
        self.vec3, self.mat33, self.vec4 = ke.fem_types(self.dtype)
        self.vec2 = wp.types.vector(2, self.dtype)
        self.gravity_host = g
        self.gravity = self.vec3(*g)
        self.measure = bodies[0].measure
        self.integrator = bodies[0].integrator
        default_tol = 1.0e-10 if precision == "float64" else 1.0e-5
        self.cg_tolerance = check_range("cg_tolerance", default_tol if cg_tolerance is None else cg_tolerance, 0, 1)
        self.cg_max_iterations = int(cg_max_iterations)
        self.cg_reports: list[CgReport] = []  # of the last step / static solve
        self.time = 0.0
        self.step_count = 0
        self._dt = 0.0
        self._force_time = 0.0
        self.topology_version = 0
        self.split_count = 0  # vertex splits performed by fracture
        self.last_splits = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))  # (vertices, rest-frame normals)

        self._build_model()
        self.features = {"elastic"}
        if self.plastic:
            self.features.add("plasticity")
        if self.fracture:
            self.features.add("fracture")
        if context.ground is not None:
            self.features.add("ground_plane")
        if context.colliders:
            self.features.add("colliders")
        if self.model.render:
            self.features.add("render_mesh")
        self.features |= self.kin.features
        if self.integrator == "explicit":
            self.update_accelerations()

    @staticmethod
    def _context(bodies, context, device, gravity, ground, colliders) -> SolverContext:
        """The given context, or one built from the shortcuts (origin: the bodies' bounding-box centre)."""
        shortcuts = {"device": device, "gravity": gravity, "ground": ground, "colliders": colliders}
        if context is not None:
            for name, value in shortcuts.items():
                if value is not None:
                    raise ParameterError(name, value, "None when a SolverContext is given (set it in the context)")
            if not isinstance(context, SolverContext):
                raise ParameterError("context", context, "a pdsim.solver.SolverContext or None")
            return context
        origin = scene_origin([b.bounds() for b in bodies])
        colliders = list(colliders or [])
        return SolverContext(
            device="cpu" if device is None else device,
            gravity=(0.0, 0.0, 0.0) if gravity is None else tuple(np.asarray(gravity, dtype=np.float64).ravel()),
            ground=ground,
            colliders=colliders,
            origin=origin,
        )

    # -- features -------------------------------------------------------------------------------------------------
    @classmethod
    def requested_features(cls, bodies, context: SolverContext) -> dict:
        """The scene-level requests, plus per body: plasticity (FemPlasticity), fracture (tensile_strength), loads,
        and the Material fields the FEM does not read (yield_stress, hardening_modulus, failure_plastic_strain,
        fracture_energy, critical_stretch, compressive_bonus, compressive_bonus_cap, strength_weibull_modulus,
        debris_damping, anisotropy, retardation_time, rigid_handoff:
        peridynamic settings with FEM counterparts named by :meth:`instead`)."""
        asked = super().requested_features(bodies, context)
        for b in bodies:
            m = b.material
            if getattr(b, "plasticity", None) is not None:
                asked.setdefault("plasticity", f"body '{b.name}' plasticity")
            if getattr(b, "tensile_strength", None) is not None:
                asked.setdefault("fracture", f"body '{b.name}' tensile_strength")
            if getattr(b, "loads", None):
                asked.setdefault("loads", f"body '{b.name}' loads")
            for field in ("yield_stress", "failure_plastic_strain"):
                if getattr(m, field, None) is not None:
                    asked.setdefault("material_plasticity", f"body '{b.name}': Material.{field}={getattr(m, field)!r}")
            if getattr(m, "hardening_modulus", 0.0):
                asked.setdefault("material_plasticity", f"body '{b.name}': Material.hardening_modulus")
            for field in ("fracture_energy", "critical_stretch", "compressive_bonus_cap", "strength_weibull_modulus"):
                if getattr(m, field, None) is not None:
                    asked.setdefault("material_fracture", f"body '{b.name}': Material.{field}={getattr(m, field)!r}")
            for field in ("compressive_bonus", "debris_damping"):
                if getattr(m, field, 0.0):
                    asked.setdefault("material_fracture", f"body '{b.name}': Material.{field}={getattr(m, field)!r}")
            if getattr(m, "anisotropy", None) is not None:
                asked.setdefault("anisotropy", f"body '{b.name}': Material.anisotropy")
            if getattr(m, "retardation_time", 0.0):
                asked.setdefault(
                    "material_damping", f"body '{b.name}': Material.retardation_time={m.retardation_time!r}"
                )
            if getattr(m, "rigid_handoff", False):
                asked.setdefault("rigid_handoff", f"body '{b.name}': Material.rigid_handoff=True")
        if getattr(context.ground, "restitution", None) is not None:
            asked["ground_restitution"] = f"the ground plane's restitution={context.ground.restitution!r}"
        return asked

    def surfaces_could_meet(self) -> bool:
        """Several FEM bodies, or one that cracks into pieces: surfaces that contact between FEM surfaces
        (pdsim.contact.MethodContact) keeps apart. False for the implicit integrator, which solves before contact
        forces are known: the pieces of one cracking implicit body do not collide (as documented in docs/guide.md,
        section 3); several implicit bodies are refused by :meth:`check_method_contact`."""
        if self.integrator != "explicit":
            return False
        return len(self.bodies) > 1 or any(getattr(b, "tensile_strength", None) is not None for b in self.bodies)

    @classmethod
    def instead(cls, feature: str) -> str:
        return {
            "material_plasticity": "FEM plasticity is set on the body: FemBody(..., plasticity=FemPlasticity("
            "yield_strain=..., creep=..., max_strain=...)); remove the Material field",
            "material_fracture": "FEM fracture is set on the body: FemBody(..., tensile_strength=... [Pa], "
            "fracture_energy=... [J/m^2]); remove the Material field",
            "anisotropy": "the FEM material is isotropic; remove Material.anisotropy or use a PeridynamicBody",
            "material_damping": "the FEM's damping is set on the body, FemBody(..., damping=... [1/s], "
            "mass-proportional); remove Material.retardation_time or use a PeridynamicBody",
            "rigid_handoff": "FEM pieces stay deformable (the rigid hand-off is peridynamic): set "
            "Material.rigid_handoff=False (dataclasses.replace(material, rigid_handoff=False)) or use a "
            "PeridynamicBody",
            "ground_restitution": "FEM vertices meet the ground by inelastic projection (they have no radius for the "
            "ground's penalty contact): add the ground plane without restitution, or use a PeridynamicBody",
        }.get(feature, super().instead(feature))

    # -- model ----------------------------------------------------------------------------------------------------
    def _build_model(self):
        """The element data (pdsim/fem/model.py), the element state (rotations, corner forces, plastic strains,
        fracture's strengths and principal stresses) and the vertex data of the input meshes."""
        bodies = self.bodies
        model = self.model = FemModel(bodies, self.origin, self.dtype, self.np_dtype, self.device)
        self.element_offsets = model.element_offsets
        self.element_body = model.element_body
        self.plastic = model.plastic
        self.fracture = model.fracture
        dev, f = self.device, self.np_dtype
        m = model.element_count
        self.element_count = m
        self._corner = wp.zeros(4 * m, dtype=self.vec3, device=dev)
        self._rotation_matrix = wp.array(np.tile(np.eye(3), (m, 1, 1)).astype(f), dtype=self.mat33, device=dev)
        self._rotation_stale = False  # the explicit step updates the quaternions only (see _rotation)
        self._rotation_q = wp.array(
            np.tile([0.0, 0.0, 0.0, 1.0], (m, 1)).astype(f), dtype=wp.types.quaternion(self.dtype), device=dev
        )
        self._energy = wp.zeros(m, dtype=self.dtype, device=dev)
        self._plastic_strain = None
        if self.plastic:
            self._plastic_strain = wp.zeros(m, dtype=self.mat33, device=dev)
        self._strength = self._principal = self._over_count = None
        if self.fracture:
            self._strength_h = model.strength_h.copy()  # fracture retires the elements it split
            self._strength = wp.array(self._strength_h.astype(f), dtype=self.dtype, device=dev)
            self._principal = wp.zeros(m, dtype=self.vec4, device=dev)
            self._over_count = wp.zeros(1, dtype=wp.int32, device=dev)
        self._measure_id = ke.MEASURES[self.measure]
        self._rotated = self.measure == "corotated"
        self._body_topology_version = [0] * len(bodies)
        self._smooth_surfaces = self._new_smooth_surfaces()

        # vertex data (rebuilt when fracture changes the topology)
        self._rest_h = model.rest
        self._rest_local_h = model.rest_local
        self._rest_local64_h = model.rest_local64
        self._tets_h = model.tets
        self._vertex_body_h = model.vertex_body
        self._point_condition_h = model.point_condition  # body-local
        self._crack_vertex_h = np.zeros(len(model.rest), dtype=bool)
        # fracture (pdsim/fem/fracture.py): per vertex, the crack plane it was split on (point in the rest local
        # frame, unit normal; NaN off cracks) and the fracture energy it still owes [J]; totals of the crack area
        # opened [m^2] and of the fracture energy taken from the motion [J]
        self._crack_plane_h = np.full((len(model.rest), 6), np.nan)
        self._debt_h = np.zeros(len(model.rest))
        self.crack_area = 0.0
        self.fracture_dissipated = 0.0
        self._build_vertex_data(bodies)

    @property
    def _rotation(self):
        """Each element's rotation matrix (Warp mat33, the last force evaluation's), formed from its quaternion first
        where the explicit step left it out of date."""
        if self._rotation_stale:
            ke.rotation_matrices(
                rotation_q=self._rotation_q, rotation=self._rotation_matrix, dtype=self.dtype, device=self.device
            )
            self._rotation_stale = False
        return self._rotation_matrix

    @property
    def _dm_inv(self):
        """Dm^-1 per element (the model's Warp array)."""
        return self.model.dm_inv

    def _build_vertex_data(self, kin_bodies, state=None):
        """(Re)allocates every per-vertex array and the kinematics from the host arrays and the current topology
        ``self._tets_h``; ``state`` = (u, v, a) [n, 3] to carry over (None: rest, initial velocities)."""
        dev, f = self.device, self.np_dtype
        n = len(self._rest_h)
        tets = self._tets_h
        self._tets = wp.array(tets.astype(np.int32), dtype=wp.vec4i, device=dev)
        offsets, slots = vertex_incidence(tets, n)
        self._vertex_offsets = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=dev)
        self._vertex_slots = wp.array(slots.astype(np.int32), dtype=wp.int32, device=dev)
        # the CSR incidence list under the vertex kernels' parameter names (kernels/fem/solver.py)
        self._incidence = {"vertex_offsets": self._vertex_offsets, "vertex_slots": self._vertex_slots}
        mass = lumped_masses(self._rest_local64_h, tets, self.model.density_h)
        self.lumped_mass_host = mass
        self.vertex_damping_host = np.asarray([b.damping for b in self.bodies], dtype=np.float64)[self._vertex_body_h]
        body_offsets = np.concatenate([[0], np.cumsum(np.bincount(self._vertex_body_h, minlength=len(self.bodies)))])
        self.body_offsets = body_offsets.astype(np.int64)
        old = getattr(self, "kin", None)
        self.kin = PointKinematics(
            kin_bodies,
            self.body_offsets,
            self._rest_h,
            self.origin,
            mass,
            np.ones(n),
            self.vertex_damping_host,
            self.gravity_host,
            dev,
            self.dtype,
        )
        if old is not None:
            self.kin.next_kick = old.next_kick
            self.kin.time = old.time
        if state is not None:
            u, v, a = state
            self.kin.set_displacements(u)
            self.kin.set_velocities(v)
            wp.copy(self.kin.a, wp.array(np.asarray(a, dtype=f), dtype=self.vec3, device=dev))

        self.lumped_mass = wp.array(mass.astype(f), dtype=self.dtype, device=dev)
        self.inv_mass = wp.array((1.0 / mass).astype(f), dtype=self.dtype, device=dev)
        self.force = wp.zeros(n, dtype=self.vec3, device=dev)
        self._zero_radius = wp.zeros(n, dtype=float, device=dev)
        self.cg = FemCg(
            self.model,
            self._rotation,
            self._rotated,
            tets,
            self._tets,
            self._vertex_offsets,
            self._vertex_slots,
            n,
        )  # CG work arrays and the assembled stiffness pattern
        self._implicit = BackwardEuler(self)  # its operator mass is cached per topology
        self._surfaces = None  # per body (vertex ids, faces, fragment, crack), rebuilt lazily
        self._contact_mesh = None  # (vertex ids, triangles) Warp arrays for MethodContact, rebuilt lazily
        self._contact_pieces = None  # (topology version, vertex labels, face labels, piece count) of the contact mesh
        self._contact_steps = None  # stable step of each vertex's smallest element (Warp array), rebuilt lazily
        self._fragments = None

    # -- scene integration ------------------------------------------------------------------------------------------
    @property
    def vertex_count(self) -> int:
        """Current vertex count (grows when fracture splits vertices)."""
        return self.kin.point_count

    def speed_scale(self) -> float:
        """Largest of the bodies' P-wave speeds and the speeds their initial velocities, boundary conditions and
        velocity kicks give [m/s]."""
        return max(max(b.material.p_wave_speed, b.prescribed_speed()) for b in self.bodies)

    def check_state(self, speed_limit: float) -> None:
        """Raises InstabilityError when a displacement or velocity is not finite or a speed exceeds ``speed_limit``
        [m/s]; with a watchdog attached (pdsim.kinematics.Watchdog, as Scene.run does) also when the energy exceeds
        what the run started with plus the work put in, or an element's volume ratio leaves its bounds."""
        where = f"at t={self.time:.6g} s (step {self.step_count}) in {self.summary()}"
        hint = f"explicit stable limit {self.model.explicit_dt:.3g} s (0.5 h_min / c_p)"
        if self.watchdog is not None:
            self.watchdog.check(speed_limit, where, hint)
        else:
            self.kin.check(speed_limit, where, hint=hint)

    def check_method_contact(self) -> None:
        """Raises FeatureNotAvailableError when these bodies cannot take part in contact between methods (the
        implicit step solves before contact forces are known)."""
        if self.integrator != "explicit":
            names = ", ".join(f"'{b.name}'" for b in self.bodies)
            raise FeatureNotAvailableError(
                f"fem bodies ({names}) with integrator={self.integrator!r} cannot take part in contact between methods "
                "(the implicit step solves before contact forces are known); use integrator='explicit' or "
                "scene.enable_contact(False)"
            )

    CHIP_MEANING = f"lies in pieces of at most {RUBBLE_ELEMENTS} elements"  # what chip_shares counts (run reports)

    def chip_shares(self) -> dict[str, float]:
        """Per body that can break (name -> share): the share of its mass (its material's density, without mass
        scaling) in face-connected pieces of at most RUBBLE_ELEMENTS elements, which the artist sees as rubble;
        empty when no body can break."""
        if not self.fracture:
            return {}
        m = self.model
        _, labels = element_pieces(self._tets_h)
        rubble = np.bincount(labels)[labels] <= RUBBLE_ELEMENTS
        mass = np.array([b.material.density for b in self.bodies])[m.element_body] * np.abs(m.volume_h)
        crushed = np.bincount(m.element_body, weights=mass * rubble, minlength=len(self.bodies))
        return {
            b.name: float(crushed[i] / m.body_mass[i])
            for i, b in enumerate(self.bodies)
            if b.tensile_strength is not None
        }

    def summary(self) -> str:
        """One line for run reports: vertices and elements simulated, and what the mass scaling added (FemBody
        ``mass_scaling``) where it scaled some element."""
        line = f"{self.point_count} FEM vertices, {self.element_count} tetrahedra"
        m = self.model
        for body, count, added, mass in zip(self.bodies, m.scaled_elements, m.added_mass, m.body_mass):
            if count > 0:
                line += (
                    f"; '{body.name}': mass scaling gave {int(count)} elements under {body.mass_scaling:g} of the "
                    f"median element height {100.0 * added / mass:.2g} % more mass"
                )
        if m.explicit_dt > m.unscaled_dt:
            line += f" (explicit step {m.explicit_dt:.3g} s instead of {m.unscaled_dt:.3g} s)"
        return line

    # -- host-side state and diagnostics (vectorised numpy) -----------------------------------------------------------
    @property
    def tets(self) -> np.ndarray:
        """Current element corners (after fracture splits), shape [element_count, 4]."""
        return self._tets_h

    @property
    def rest_positions(self) -> np.ndarray:
        """World rest positions of the current vertices [m], float64 [vertex_count, 3]."""
        return self._rest_h

    @property
    def vertex_body(self) -> np.ndarray:
        """Body index of each vertex, shape [vertex_count]."""
        return self._vertex_body_h

    def _vertex_array(self, values, name: str) -> np.ndarray:
        """``values`` as float64 [vertex_count, 3] (ParameterError ``name`` with another shape)."""
        a = np.asarray(values, dtype=np.float64)
        if a.shape != (self.point_count, 3):
            raise ParameterError(name, a.shape, f"shape ({self.point_count}, 3)")
        return a

    def _host_displacements(self, positions, name: str):
        """World positions [m] [vertex_count, 3] -> displacements (float64 difference, then the solver's dtype)."""
        return self._vertex_array(positions, name) - self._rest_h

    def _state_changed(self) -> None:
        """Recomputes the accelerations after the state was overwritten (explicit integrator)."""
        if self.integrator == "explicit":
            self.update_accelerations()

    def set_positions(self, positions):
        """Sets the displacements so that the vertices are at world ``positions`` [m] (shape [vertex_count, 3]);
        recomputes the accelerations (explicit)."""
        self.kin.set_displacements(self._host_displacements(positions, "positions"))
        self._state_changed()

    def set_displacements(self, displacements):
        """Overwrites the displacements [m] (shape [vertex_count, 3]); recomputes the accelerations (explicit)."""
        self.kin.set_displacements(self._vertex_array(displacements, "displacements"))
        self._state_changed()

    def set_velocities(self, velocities):
        """Overwrites velocities [m/s], shape [vertex_count, 3]; recomputes the accelerations (explicit)."""
        self.kin.set_velocities(self._vertex_array(velocities, "velocities"))
        self._state_changed()

    def nodal_forces(self, positions=None) -> np.ndarray:
        """Internal elastic forces [N] at the current (or given world) positions, shape [vertex_count, 3] (no loads,
        no plastic update)."""
        u = None
        if positions is not None:
            u = wp.array(
                self._host_displacements(positions, "positions").astype(self.np_dtype),
                dtype=self.vec3,
                device=self.device,
            )
        self.element_forces(0.0, u)
        out = wp.zeros(self.point_count, dtype=self.vec3, device=self.device)
        ks.gather_forces(
            **self._incidence,
            corner_forces=self._corner,
            forces=out,
            dtype=self.dtype,
            device=self.device,
        )
        self.reset_over_count()
        return out.numpy().astype(np.float64)

    def element_stiffness(self) -> np.ndarray:
        """Element stiffness matrices K_e = V B^T E B (rotated R K_e R^T with the last stored rotations for the
        corotated measure) [N/m], shape [element_count, 12, 12] (rows/cols: corner-major, xyz-minor)."""
        m = self.model
        blocks = wp.zeros(16 * self.element_count, dtype=self.mat33, device=self.device)
        ke.element_stiffness_blocks(
            **m.element_arrays,
            rotation=self._rotation,
            blocks=blocks,
            dtype=self.dtype,
            rotated=self._rotated,
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
        """Elastic energy sum_e V (mu |eps_el|^2 + lambda/2 tr(eps_el)^2) [J] at the current displacements."""
        m = self.model
        ke.element_energy(
            displacements=self.kin.u,
            tets=self._tets,
            **m.element_arrays,
            plastic_strain=self._plastic_strain,
            energy=self._energy,
            dtype=self.dtype,
            measure=self._measure_id,
            plastic=self.plastic,
            device=self.device,
        )
        return float(self._energy.numpy().astype(np.float64).sum())

    def gravity_potential(self) -> float:
        """-sum m g . x [J] (world positions)."""
        return float(-np.dot(self.lumped_mass_host, self.positions() @ self.gravity_host))


__all__ = ["CgReport", "SolverFem", "StaticSolveReport"]

"""Tetrahedral finite element solid with plasticity and fracture (shared/seeds/fem_slides.txt, DESIGN.md section 3).

A :class:`FemBody` is a linear-tetrahedron mesh of a solid (meshed from a closed surface by fTetWild, or loaded ready)
with a :class:`pdsim.Material`, a strain measure ("linear", "corotated" or "green", see kernels/fem/elements.py), an
integrator ("explicit" or "implicit"), and optional plasticity (:class:`FemPlasticity`) and fracture
(``tensile_strength``). :class:`SolverFem` steps all FEM bodies of a scene together on the method-neutral core
(pdsim/solver.py): its state is the shared :class:`pdsim.kinematics.PointKinematics` on the mesh vertices
(displacements u from the rest positions, velocities, accelerations; boundary conditions per axis with time windows
and curves; loads; reactions; the watchdog), the rest positions stored relative to the scene's origin.

The solver is split by concern: this module holds :class:`SolverFem` (construction, the explicit step, fracture
events, views and diagnostics) and delegates to

- pdsim/fem/model.py: the element data built once (rest geometry, Dm^-1, volumes, materials, the explicit stable step,
  render-mesh embeddings), and the precision argument: element strains come from displacement differences with Dm^-1
  computed on the host in float64, so a float32 solver gives the same answer wherever the scene sits in the world;
- pdsim/fem/cg.py: the block-Jacobi preconditioned conjugate gradient on the stiffness (matrix-free or assembled);
- pdsim/fem/implicit.py: the backward-Euler step;
- pdsim/fem/static.py: the quasi-static solve.

Integrators:

- explicit: velocity Verlet (kernels/integration.py's kick-drift, then a fused gather of the element forces and the
  shared second half kick) with lumped masses m_i = sum over the vertex's elements of rho V / 4. The stable step is
  dt_stable = 0.5 h_min / c_p with h_min the smallest element height (3 V / largest face area) and
  c_p = sqrt((lambda + 2 mu) / rho) the dilatational wave speed. The factor 0.5 makes the estimate safe: the
  element-by-element bound 2 / sqrt(max eig(M_e^-1 K_e)), a lower bound of the true critical step, measured at least
  0.50 h / c_p over 15,000 random tetrahedra (flat ones included, nu from -0.5 to 0.499), and the true critical step
  of whole meshes (largest eigenvalue of M^-1 K) measured 0.88-0.95 h_min / c_p on structured box meshes and
  1.4-3.0 h_min / c_p on fTetWild and jittered meshes (tests/test_fem_dynamics.py: 1.8-1.9 and 5.0-5.2 times the
  automatic step). :meth:`SolverFem.step` refuses a larger step (ParameterError);
  :meth:`SolverFem.simulate` splits each requested step into equal substeps no longer than dt_stable instead.
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
(float32 only). Contact between FEM pieces or bodies is not implemented: pieces of a cracked body pass through each
other. Asking for it (Scene.enable_contact with several FEM bodies or a cracking one) raises
FeatureNotAvailableError; with automatic contact the scene warns once when the FEM bodies are built.

Output (:meth:`SolverFem.views`): per body a PointsView of its vertices and a MeshView "<name>_surface", whose
topology version changes when its faces change; optionally an embedded render mesh "<name>_render". The surface of a
body that cannot fracture, or of one with ``crack_surfaces="elements"``, is the boundary of its tetrahedra (each piece
a closed shell with its own vertices). A body that can fracture draws by default (``crack_surfaces="smooth"``) its
input surface closed by smooth crack surfaces: pdsim/fragment_surfaces.py's FragmentSurfaces over the body's current
vertices (the copies fracture adds included; spacing the mean edge length; every vertex labelled by its piece),
rebuilt when fracture changed the body's vertices (docs/fem_fracture.md).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..errors import FeatureNotAvailableError, ParameterError
from ..loads import PointLoads
from ..regions import region_mask
from ..solver import PointSolver, SolverContext, register_solver
from ..validate import check_range
from .body import PRECISIONS, STIFFNESS_MODES, FemBody, face_point_forces, lumped_masses
from .cg import CgReport, FemCg
from .implicit import BackwardEuler
from .mesh import boundary_faces
from .model import FemModel
from .static import StaticSolveReport, solve_static


GRIFFITH_ROUNDS = 4  # fracture: rounds of the Griffith test before a step's remaining splits are made untested


class _SmoothSurface:
    """The drawn surface "<name>_surface" of a body that can fracture, with ``crack_surfaces="smooth"``.

    A :class:`pdsim.fragment_surfaces.FragmentSurfaces` over the body's vertices (rest positions, the copies fracture
    adds included) with the spacing of the mesh (its mean edge length) and every vertex labelled by its piece: the
    input surface (``FemBody.surface_shape``) cut by crack surfaces fitted to the element faces the cracks opened, and
    moved by the vertices of its own piece. The vertex copies coincide with their parents and are no lattice, so
    every grid vertex is labelled by the vote of its nearest vertices (``on_lattice=False``).

    It is built again from the current vertices and pieces whenever fracture changed the body's vertices (the body's
    topology version), so the drawn surface is a function of the topology alone: a resumed run draws the same. A
    piece that holds no vertex of the label grid (an element or a few that chipped off, smaller than a grid cell)
    gets no region there and is drawn as the boundary faces of its elements instead (crack = 1 on the faces fracture
    opened). The view's topology version changes exactly when its vertex count, faces or face attributes change.
    """

    def __init__(self, body: FemBody, spacing: float, device: str):
        self.body = body
        self.spacing = float(spacing)
        self.device = device
        self.surfaces = None  # FragmentSurfaces of the topology ``built_for``
        self.built_for = None  # the body's topology version the surfaces were built for
        self.rebuilds = 0  # builds so far, and the wall time of the last one [s]
        self.rebuild_seconds = 0.0
        self._used = None  # the body's vertices (local ids) that belong to an element, or None for all
        self._version = -1
        self._last = None  # (vertex count, faces, fragment, crack) of the last view

    def _build(self, topology: int, rest: np.ndarray, fragment: np.ndarray, used: np.ndarray) -> None:
        import time

        from ..fragment_surfaces import FragmentSurfaces

        t0 = time.perf_counter()
        self._used = None if used.all() else np.flatnonzero(used)
        sel = slice(None) if self._used is None else self._used
        surfaces = FragmentSurfaces(
            self.body.surface_shape, rest[sel], self.spacing, self.body.name, on_lattice=False, device=self.device
        )
        surfaces.update_topology(fragment[sel])
        self.surfaces = surfaces
        self.built_for = topology
        self.rebuilds += 1
        self.rebuild_seconds = time.perf_counter() - t0

    def view(self, topology, rest, fragment, used, positions, velocities, element_surface):
        """The MeshView at the body's current vertex ``positions`` [m] and ``velocities`` [m/s] (world, [n, 3]).

        Args:
            topology: the body's topology version (a rebuild when it changed).
            rest: world rest positions of the body's vertices [m], float64 [n, 3].
            fragment: piece id of each vertex, int [n]; used: whether each vertex belongs to an element, bool [n].
            element_surface: (vertex ids [k] into the body's vertices, triangles [f, 3] into those ids, piece per
                face [f], crack flag per face [f]) of the boundary faces of the body's elements.
        """
        from ..output.views import MeshView

        if self.surfaces is None or self.built_for != topology:
            self._build(topology, rest, fragment, used)
        sel = slice(None) if self._used is None else self._used
        drawn = self.surfaces.view(positions[sel], velocities[sel])
        points, vel, faces = drawn.points, drawn.velocities, drawn.faces
        frag_f = np.asarray(drawn.face_attributes["fragment"], dtype=np.int32)
        crack_f = np.asarray(drawn.face_attributes["crack"], dtype=np.int32)
        ids, e_faces, e_frag, e_crack = element_surface
        chips = ~np.isin(e_frag, self.surfaces.fragment_ids)  # pieces without a region: their element faces
        if chips.any():
            verts, local = np.unique(e_faces[chips], return_inverse=True)
            chip_ids = ids[verts]
            faces = np.concatenate([faces, local.reshape(-1, 3).astype(faces.dtype) + len(points)])
            points = np.concatenate([points, positions[chip_ids]])
            vel = np.concatenate([vel, velocities[chip_ids]])
            frag_f = np.concatenate([frag_f, e_frag[chips].astype(np.int32)])
            crack_f = np.concatenate([crack_f, e_crack[chips].astype(np.int32)])
        last = self._last
        if (
            last is None
            or last[0] != len(points)
            or not np.array_equal(last[1], faces)
            or not np.array_equal(last[2], frag_f)
            or not np.array_equal(last[3], crack_f)
        ):
            self._version += 1
            self._last = (len(points), faces, frag_f, crack_f)
        return MeshView(
            name=f"{self.body.name}_surface",
            points=points,
            velocities=vel,
            topology_version=self._version,
            faces=faces,
            face_attributes={"fragment": frag_f, "crack": crack_f},
        )


class _SplitBody(PointLoads):
    """A FemBody's boundary conditions, loads and kicks on its vertices after fracture split them (what
    PointKinematics reads from a body): ``point_condition`` carried to the new numbering, regions selected on the split
    vertices, surface loads resolved on the faces of the original surface (crack faces carry none)."""

    def __init__(self, body: FemBody, rest: np.ndarray, faces: np.ndarray, point_condition: np.ndarray):
        self.name = body.name
        self.conditions = body.conditions
        self.loads = body.loads
        self.kicks = body.kicks
        self.point_condition = point_condition
        self.point_count = len(rest)
        self.initial_velocity = np.zeros((len(rest), 3))
        self._rest = rest
        self._faces = faces

    def _select(self, region) -> np.ndarray:
        mask = region_mask(region, self._rest, field="region")
        if not mask.any():
            raise ParameterError("region", region, f"a region containing at least one vertex of '{self.name}'")
        return mask

    def surface_point_forces(self, region, traction, pressure: float):
        return face_point_forces(self._rest, self._faces, region, traction, pressure)


@register_solver
class SolverFem(PointSolver):
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
        import warp as wp

        from ..kernels.fem import elements as ke

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
            c.bind(self.origin)  # the colliders act in this solver's local frame (world = origin + local)
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
            self._update_accelerations()

    @staticmethod
    def _context(bodies, context, device, gravity, ground, colliders) -> SolverContext:
        """The given context, or one built from the shortcuts (origin: the bodies' bounding-box centre)."""
        from ..kinematics import scene_origin

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
        debris_damping, anisotropy:
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
        if context.contact and not context.contact_is_default and cls._surfaces_could_meet(bodies):
            asked["contact_between_fem"] = "the scene's contact (Scene.enable_contact) between FEM surfaces"
        return asked

    @staticmethod
    def _surfaces_could_meet(bodies) -> bool:
        """Several FEM bodies, or one that cracks into pieces: surfaces that contact between FEM surfaces would
        keep apart."""
        return len(bodies) > 1 or any(getattr(b, "tensile_strength", None) is not None for b in bodies)

    @classmethod
    def check_features(cls, bodies, context: SolverContext) -> None:
        """As Solver.check_features; with automatic contact, a warning that FEM surfaces do not collide with each
        other (several FEM bodies, or the pieces of a cracking one), so that it is never silent."""
        super().check_features(bodies, context)
        if context.contact and context.contact_is_default and cls._surfaces_could_meet(bodies):
            import warnings

            names = ", ".join(f"'{b.name}'" for b in bodies)
            warnings.warn(
                f"fem bodies ({names}): contact between FEM surfaces is not simulated, so separate FEM bodies and the "
                "pieces of a cracked FEM body pass through each other (FEM bodies do collide with peridynamic bodies, "
                "the ground and colliders); use PeridynamicBody for bodies that must collide with each other",
                stacklevel=2,
            )

    @classmethod
    def instead(cls, feature: str) -> str:
        return {
            "material_plasticity": "FEM plasticity is set on the body: FemBody(..., plasticity=FemPlasticity("
            "yield_strain=..., creep=..., max_strain=...)); remove the Material field",
            "material_fracture": "FEM fracture is set on the body: FemBody(..., tensile_strength=... [Pa], "
            "fracture_energy=... [J/m^2]); remove the Material field",
            "anisotropy": "the FEM material is isotropic; remove Material.anisotropy or use a PeridynamicBody",
            "contact_between_fem": "contact between FEM surfaces is not simulated (FEM bodies do collide with "
            "peridynamic bodies, the ground and colliders): use PeridynamicBody for bodies that must collide with each "
            "other, or scene.enable_contact(False) to let separate FEM bodies and cracked pieces pass through each "
            "other",
        }.get(feature, super().instead(feature))

    # -- model ----------------------------------------------------------------------------------------------------
    def _build_model(self):
        """The element data (pdsim/fem/model.py), the element state (rotations, corner forces, plastic strains,
        fracture's strengths and principal stresses) and the vertex data of the input meshes."""
        import warp as wp

        from ..kernels.fem import elements as ke

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
        self._rotation = wp.array(np.tile(np.eye(3), (m, 1, 1)).astype(f), dtype=self.mat33, device=dev)
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
        self._force_kernel = ke.element_force_kernel(self.dtype, self._measure_id, self.plastic, self.fracture, True)
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

    def _new_smooth_surfaces(self) -> list:
        """Per body: its :class:`_SmoothSurface` (a body that can fracture, with crack_surfaces="smooth"), else None;
        the spacing is the mesh's mean edge length."""
        return [
            None if b.surface_shape is None else _SmoothSurface(b, 2.0 * self.model.widths[i], str(self.device))
            for i, b in enumerate(self.bodies)
        ]

    @property
    def _dm_inv(self):
        """Dm^-1 per element (the model's Warp array)."""
        return self.model.dm_inv

    def _build_vertex_data(self, kin_bodies, state=None):
        """(Re)allocates every per-vertex array and the kinematics from the host arrays and the current topology
        ``self._tets_h``; ``state`` = (u, v, a) [n, 3] to carry over (None: rest, initial velocities)."""
        import warp as wp

        from ..kinematics import PointKinematics
        from .fracture import vertex_incidence

        dev, f = self.device, self.np_dtype
        n = len(self._rest_h)
        tets = self._tets_h
        self._tets = wp.array(tets.astype(np.int32), dtype=wp.vec4i, device=dev)
        offsets, slots = vertex_incidence(tets, n)
        self._vertex_offsets = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=dev)
        self._vertex_slots = wp.array(slots.astype(np.int32), dtype=wp.int32, device=dev)
        mass = lumped_masses(self._rest_local64_h, tets, self.model.density_h)
        self._mass_h = mass
        self._vertex_damping_h = np.asarray([b.damping for b in self.bodies], dtype=np.float64)[self._vertex_body_h]
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
            self._vertex_damping_h,
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

        self._mass = wp.array(mass.astype(f), dtype=self.dtype, device=dev)
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
        self._fragments = None

    # -- time step ------------------------------------------------------------------------------------------------
    def explicit_time_step(self) -> float:
        """Stable explicit step 0.5 h_min / c_p [s] (see the module docstring)."""
        return self.model.explicit_dt

    def stable_time_step(self) -> float:
        """The step the scene should use [s]: the explicit limit, or ``implicit_step_ratio`` times it (implicit)."""
        if self.integrator == "implicit":
            return min(b.implicit_step_ratio for b in self.bodies) * self.model.explicit_dt
        return self.model.explicit_dt

    # -- kernels ----------------------------------------------------------------------------------------------------
    def _compute_element_forces(self, dt: float, displacements=None):
        """Corner forces of every element at ``displacements`` (default: the current ones), with the plastic update
        of step dt."""
        import warp as wp

        m = self.model
        if self.fracture:
            self._over_count.zero_()
        wp.launch(
            self._force_kernel,
            dim=self.element_count,
            inputs=[
                self.kin.u if displacements is None else displacements,
                self._tets,
                m.dm_inv,
                m.volume,
                m.lame,
                m.plastic_params,
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

    def _loads_into_force(self, t: float):
        """``force`` <- the loads at time ``t`` [s] (zero without loads); the gathers add the element forces."""
        self.force.zero_()
        self.kin.add_loads(self.force, t)

    def _gather(self, kernel: str, dt: float = 0.0):
        import warp as wp

        from ..kernels.fem import solver as ks

        vk = ks.vertex_kernels(self.dtype)
        if kernel == "gather_add":
            inputs = [self._vertex_offsets, self._vertex_slots, self._corner, self.force]
        else:
            kin = self.kin
            inputs = [
                self._vertex_offsets,
                self._vertex_slots,
                self._corner,
                self.inv_mass,
                self.gravity,
                kin.damping,
                self.dtype(dt),
                kin.point_condition,
                kin.point_kind,
                kin.cond_axes,
                self.force,
                kin.v,
                kin.a,
            ]
        wp.launch(vk[kernel], dim=self.point_count, inputs=inputs, device=self.device)

    def _update_accelerations(self):
        """a = f / m + g - c v at the current state, without a kick or a plastic update (after init, splits and
        state changes)."""
        self._compute_element_forces(0.0)
        self._loads_into_force(self.time)
        self._gather("gather_kick", 0.0)
        if self.fracture:
            self._over_count.zero_()

    def apply_colliders(self, time: float, dt: float) -> None:
        """Ground plane, then the scene's colliders, on the free vertices (zero radius) at ``time`` [s]."""
        kin = self.kin
        for c in self.colliders:
            c.apply(kin.rest, kin.u, kin.v, self._zero_radius, kin.point_kind, time, dt, mass=kin.mass)

    # -- stepping ---------------------------------------------------------------------------------------------------
    def begin_step(self, dt: float) -> None:
        """Explicit: the shared kick-drift and the colliders (PointSolver). Implicit: the whole backward-Euler step
        (forces at the start of the step, CG solve, displacement update, colliders); forces added to ``force`` after
        it are not used."""
        self._dt = float(dt)
        if self.integrator == "implicit":
            self._force_time = self.time + dt
            self._implicit.step(dt)
        else:
            super().begin_step(dt)

    def compute_forces(self) -> None:
        """Explicit: element forces at the current displacements (plastic update of the step begun) plus the loads at
        the end of the step into ``force``. Implicit: nothing (``force`` holds the forces the step used)."""
        if self.integrator == "implicit":
            return
        self._compute_element_forces(self._dt)
        self._loads_into_force(self._force_time)
        self._gather("gather_add")

    def end_step(self, dt: float) -> None:
        """Explicit: the shared second half kick. Both: time advances, then fracture splits over-stressed elements."""
        if self.integrator == "implicit":
            self.time += dt
            self.step_count += 1
        else:
            super().end_step(dt)
        if self.fracture:
            self._fracture_event()

    def step(self, dt: float):
        """Advances all bodies by one step of ``dt`` [s]. The explicit integrator refuses dt above its stable limit
        (ParameterError); use :meth:`simulate` for automatic substepping."""
        dt = check_range("dt", dt, 0.0, None)
        if self.integrator == "implicit":
            self.begin_step(dt)
            self.end_step(dt)
            return
        limit = self.model.explicit_dt
        if dt > limit * (1.0 + 1.0e-9):
            raise ParameterError(
                "dt", dt, f"(0, {limit:.6g}] s: the explicit stable limit 0.5 h_min / c_p (simulate() substeps)"
            )
        self.begin_step(dt)
        # compute_forces and the kick fused: one gather-and-kick launch
        self._compute_element_forces(dt)
        self._loads_into_force(self._force_time)
        self._gather("gather_kick", dt)
        self.kin.end_clock_step()
        self.time += dt
        self.step_count += 1
        if self.fracture:
            self._fracture_event()

    def graph_capture_blocker(self, dt: float) -> str | None:
        """Why a frame of steps of ``dt`` [s] cannot be replayed as a graph (docs/architecture.md, GPU path), or
        None: fracture splits elements on the host (a read of the over-strength count every step, then a new
        topology); the implicit integrator's conjugate-gradient solve tests its convergence on the host; a scene
        step above the explicit limit is split into a number of steps of the solver's own."""
        if self.fracture:
            return "FEM fracture (the over-strength count is read every step and splits rebuild the mesh on the host)"
        if self.integrator == "implicit":
            return "the implicit FEM integrator (its conjugate-gradient solve tests convergence on the host)"
        if dt > self.model.explicit_dt * (1.0 + 1.0e-9):
            return "an FEM body stepping alone above its explicit limit (simulate() splits each step)"
        return None

    def simulate(self, dt: float, steps: int):
        """Runs ``steps`` steps of ``dt`` [s]; the explicit integrator splits each into ceil(dt / dt_stable) equal
        substeps when dt exceeds its stable limit."""
        dt = check_range("dt", dt, 0.0, None)
        sub = 1
        if self.integrator == "explicit":
            sub = max(1, math.ceil(dt / self.model.explicit_dt - 1.0e-9))
        for _ in range(int(steps) * sub):
            self.step(dt / sub)

    # -- implicit and static solves (pdsim/fem/implicit.py, pdsim/fem/static.py, pdsim/fem/cg.py) ------------------
    def _cg_solve(self, op_mass, c_mass: float, c_stiff: float, *, tolerance=None, max_iterations=None) -> CgReport:
        """Solves (c_mass diag(op_mass) + c_stiff K_R) x = rhs on the free components with the CG of the current
        topology (``self.cg``: its ``constrained`` bit masks, ``x`` the initial guess and the result), to the solver's
        ``cg_tolerance`` and ``cg_max_iterations`` unless given, the stiffness as set by ``stiffness``."""
        return self.cg.solve(
            op_mass,
            c_mass,
            c_stiff,
            tolerance=self.cg_tolerance if tolerance is None else tolerance,
            max_iterations=self.cg_max_iterations if max_iterations is None else int(max_iterations),
            assembled=self.stiffness == "assembled",
        )

    def solve_static(
        self,
        *,
        constrained=None,
        time: float | None = None,
        tolerance: float = 1.0e-6,
        max_newton_iterations: int = 30,
        cg_tolerance: float | None = None,
        cg_max_iterations: int = 20000,
    ) -> StaticSolveReport:
        """Quasi-static equilibrium f_int(u) + f_ext(t) + M g = 0 on the free components, by Newton iterations with
        the tangent K_R (rotations frozen per iteration; the constant K for the linear and the Green measure), each
        solved by CG. The loads are those of the bodies (body forces, tractions, pressures, forces) scaled by their
        curves at ``time``; the constrained components keep their current displacement. The plastic strain is not
        updated. Afterwards ``force`` holds the internal forces plus the loads at the solution (reaction_forces()).

        Args:
            constrained: bool mask [vertex_count] of vertices held in place on all axes; default: the boundary
                conditions active at ``time``, each on its own axes (a roller holds only its axes).
            time: the time [s] of the loads' curves and of the conditions' windows; default: the solver's time.
            tolerance: stop when |residual| <= tolerance * |f_ext + M g| over the free components (or * the first
                residual without external load), or when a Newton update is below max(tolerance, 1000 eps) times the
                displacement change so far (the float32 floor).
            max_newton_iterations: Newton iterations at most (the linear measure needs one).
            cg_tolerance: relative CG residual per Newton iteration (default: the solver's).
            cg_max_iterations: CG iterations per Newton iteration.
        """
        return solve_static(
            self,
            constrained=constrained,
            time=time,
            tolerance=tolerance,
            max_newton_iterations=max_newton_iterations,
            cg_tolerance=cg_tolerance,
            cg_max_iterations=cg_max_iterations,
        )

    # -- fracture -----------------------------------------------------------------------------------------------
    def apply_fracture(self) -> int:
        """Evaluates the stresses at the current displacements (no plastic update) and performs the crack splits of
        every element over its strength, as a step does; returns the number of vertex splits."""
        if not self.fracture:
            raise ParameterError("tensile_strength", None, "a value > 0 on some body to use fracture")
        before = self.split_count
        self._compute_element_forces(0.0)
        self._fracture_event()
        return self.split_count - before

    def _fracture_event(self) -> bool:
        """Pays fracture energy still owed, then splits vertices where elements exceed their strength (only when the
        kernel counted one) and the Griffith test passes (pdsim/fem/fracture.py); True if the topology changed."""
        import warp as wp

        from .fracture import (
            best_offsets,
            choose_splits,
            griffith_filter,
            make_manifold,
            opened_faces,
            separation_directions,
            split_vertices,
            triangle_areas,
        )

        if self._debt_h.any():
            self._pay_fracture_energy()
        if int(self._over_count.numpy()[0]) == 0:
            return False
        principal = self._principal.numpy().astype(np.float64)
        over = np.flatnonzero(principal[:, 3] > self._strength_h)
        if over.size == 0:
            return False
        nv = self.point_count
        rest, centroids = self._rest_local_h, self.model.centroids_h
        directions = separation_directions(
            self._tets_h, over, self._element_stresses, self.model.volume_h, principal[over, :3]
        )
        verts, normals, sources, anchors, new_crack = choose_splits(
            self._tets_h,
            rest,
            centroids,
            over,
            directions,
            principal[over, 3],
            self._crack_vertex_h,
            self._crack_plane_h,
        )
        if len(verts) == 0:
            return False
        origins, fits = best_offsets(self._tets_h, rest, centroids, verts, normals, anchors, new_crack)
        if not fits.all():
            verts, normals, sources, anchors, origins = (a[fits] for a in (verts, normals, sources, anchors, origins))
            if len(verts) == 0:
                return False
        gc = self.model.fracture_energy_h
        energy = None
        for round_ in range(GRIFFITH_ROUNDS + 1):
            tets1, parent1 = split_vertices(self._tets_h, rest, centroids, verts, normals, origins)
            copies = np.arange(nv, len(parent1))
            tets2, parent2 = make_manifold(tets1, len(parent1), np.concatenate([verts, copies]))
            if round_ == GRIFFITH_ROUNDS or not gc[sources].any():
                break
            if energy is None:
                self.strain_energy()  # fills self._energy
                energy = self._energy.numpy().astype(np.float64)
            # Griffith on the whole topology change (the splits and the separations they cause)
            keep, _, _ = griffith_filter(
                self._tets_h, rest, verts, tets2, parent1[parent2], energy, gc, sources, self._debt_h
            )
            if keep.all():
                break
            verts, normals, sources, anchors, origins = (a[keep] for a in (verts, normals, sources, anchors, origins))
            if len(verts) == 0:
                return False
        parent = parent1[parent2]
        crack = self._crack_vertex_h[parent]
        crack[verts] = True
        crack[nv:] = True
        # crack planes: the split vertex and its copies keep their split's plane, with its point moved to their
        # projection onto it
        crack_plane = self._crack_plane_h[parent]
        x = rest[verts]
        on_plane = x - np.einsum("sj,sj->s", x - origins, normals)[:, None] * normals
        split_of = np.full(nv, -1, dtype=np.int64)
        split_of[verts] = np.arange(len(verts))
        mine = split_of[parent] >= 0
        crack_plane[mine] = np.concatenate([on_plane, normals], axis=1)[split_of[parent[mine]]]
        # the crack area opened, with its fracture energy owed by the vertices of the opened faces (a third each)
        faces, elem = opened_faces(self._tets_h, tets2)
        area = 0.5 * triangle_areas(rest[parent], faces)  # each opened face appears once per side
        self.crack_area += float(area.sum())
        debt = np.zeros(len(parent))
        debt[:nv] = self._debt_h
        debt += np.bincount(faces.ravel(), weights=np.repeat(gc[elem] * area / 3.0, 3), minlength=len(parent))
        self.split_count += len(verts)
        self.last_splits = (verts.copy(), normals.copy())
        for b in np.unique(self._vertex_body_h[verts]):
            self._body_topology_version[int(b)] += 1
        # an element splits at most once (pdsim/fem/fracture.py): retire the sources from the strength test
        self._strength_h[sources] = np.inf
        self._strength = wp.array(self._strength_h.astype(self.np_dtype), dtype=self.dtype, device=self.device)
        self._apply_topology(tets2, parent, crack, crack_plane, debt)
        return True

    def _element_stresses(self, elements: np.ndarray) -> np.ndarray:
        """Stresses of ``elements`` at the current displacements in the rest frame [Pa], float64 [r, 3, 3] (host;
        the strain of the solver's measure, the corotated one with the rotations of the last force evaluation, less
        the plastic strain; the directions of fracture's crack planes)."""
        m = self.model
        t = self._tets_h[elements]
        u = self.kin.displacements()
        du = np.stack([u[t[:, a]] - u[t[:, 0]] for a in (1, 2, 3)], axis=-1)  # columns
        g = du @ m.dm_inv.numpy().astype(np.float64)[elements]
        eye = np.eye(3)
        if self.measure == "corotated":
            r = self._rotation.numpy().astype(np.float64)[elements]
            rf = np.swapaxes(r, 1, 2) @ (eye + g)
            eps = 0.5 * (rf + np.swapaxes(rf, 1, 2)) - eye
        elif self.measure == "green":
            eps = 0.5 * (g + np.swapaxes(g, 1, 2) + np.swapaxes(g, 1, 2) @ g)
        else:
            eps = 0.5 * (g + np.swapaxes(g, 1, 2))
        if self.plastic:
            eps = eps - self._plastic_strain.numpy().astype(np.float64)[elements]
        lame = m.lame.numpy().astype(np.float64)[elements]
        tr = np.trace(eps, axis1=1, axis2=2)
        return lame[:, 0, None, None] * tr[:, None, None] * eye + 2.0 * lame[:, 1, None, None] * eps

    def _pay_fracture_energy(self):
        """Takes the fracture energy owed from the relative motion around the cracks (pdsim/fem/fracture.py:
        pay_fracture_energy; momentum conserving, never adding energy)."""
        from .fracture import pay_fracture_energy

        free = self.kin.point_condition_host < 0
        v, self._debt_h, paid = pay_fracture_energy(
            self._tets_h, self._mass_h, self.kin.velocities(), self._debt_h, free
        )
        if paid > 0.0:
            self.kin.set_velocities(v)
            self.fracture_dissipated += paid

    def _apply_topology(self, tets: np.ndarray, parent: np.ndarray, crack: np.ndarray, crack_plane, debt):
        """Installs new element corners; vertex i of the new numbering copies the state of old vertex parent[i]
        (displacement, velocity, acceleration, boundary condition). Vertices are then renumbered body by body (stable:
        a single body keeps the numbering of the split), and the kinematics rebuilt from host arrays. The split keeps
        the old numbering as a prefix and appends the copies, so each body's first vertex_count vertices remain its
        input vertices (views() relies on it)."""
        body = self._vertex_body_h[parent]
        perm = np.argsort(body, kind="stable")  # new vertex k is the split's vertex perm[k]
        inverse = np.empty_like(perm)
        inverse[perm] = np.arange(len(perm))
        source = parent[perm]
        kin = self.kin
        state = (kin.u.numpy()[source], kin.v.numpy()[source], kin.a.numpy()[source])
        self._rest_h = self._rest_h[source]
        self._rest_local_h = self._rest_local_h[source]
        self._rest_local64_h = self._rest_local64_h[source]
        self._vertex_body_h = self._vertex_body_h[source]
        self._point_condition_h = self._point_condition_h[source]
        self._crack_vertex_h = crack[perm]
        self._crack_plane_h = crack_plane[perm]
        self._debt_h = debt[perm]
        self._tets_h = inverse[np.asarray(tets, dtype=np.int64)]
        faces, fid = boundary_faces(self._tets_h, return_face_ids=True)
        original = np.isin(fid, self.model.surface_face_ids)
        face_body = self.element_body[fid // 4]
        proxies = []
        for i, b in enumerate(self.bodies):
            lo, hi = np.searchsorted(self._vertex_body_h, [i, i + 1])
            mine = original & (face_body == i)
            proxies.append(_SplitBody(b, self._rest_h[lo:hi], faces[mine] - lo, self._point_condition_h[lo:hi].copy()))
        self._build_vertex_data(proxies, state)
        self.topology_version += 1
        if self.integrator == "explicit":
            self._update_accelerations()

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

    def checkpoint(self) -> dict:
        """The state to continue this run exactly (pdsim.solver.Solver.checkpoint): the shared kinematics, the element
        state (rotations, plastic strains, principal stresses) and, after fracture, the topology (split vertices,
        element corners, retired strengths, versions)."""
        from ..solver import array_state

        topology = {
            "rest": self._rest_h,
            "rest_local": self._rest_local_h,
            "rest_local64": self._rest_local64_h,
            "vertex_body": self._vertex_body_h,
            "point_condition": self._point_condition_h,
            "crack_vertex": self._crack_vertex_h,
            "crack_plane": self._crack_plane_h,
            "fracture_debt": self._debt_h,
            "crack_area": float(self.crack_area),
            "fracture_dissipated": float(self.fracture_dissipated),
            "tets": self._tets_h,
            "strength": self._strength_h if self.fracture else None,
            "body_topology_version": np.asarray(self._body_topology_version, dtype=np.int64),
            "topology_version": int(self.topology_version),
            "split_count": int(self.split_count),
            "last_split_vertices": self.last_splits[0],
            "last_split_normals": self.last_splits[1],
        }
        elements = {
            "rotation": array_state(self._rotation),
            "rotation_q": array_state(self._rotation_q),
            "plastic_strain": array_state(self._plastic_strain),
            "principal": array_state(self._principal),
        }
        return {
            "kinematics": self.kinematics_checkpoint(),
            "topology": {k: (np.array(v, copy=True) if isinstance(v, np.ndarray) else v) for k, v in topology.items()},
            "elements": elements,
            "dt": float(self._dt),
        }

    def restore(self, state: dict) -> None:
        """Puts a :meth:`checkpoint` of a solver built from the same bodies back, rebuilding the vertex data when
        fracture had split the mesh."""
        import warp as wp

        from ..errors import ParameterError
        from ..solver import assign_state

        topo = state["topology"]
        tets = np.asarray(topo["tets"], dtype=np.int64)
        if tets.shape != self._tets_h.shape:
            raise ParameterError("checkpoint", f"{len(tets)} tetrahedra", f"{len(self._tets_h)} (the same scene)")
        if len(topo["rest"]) != len(self._rest_h) or not np.array_equal(tets, self._tets_h):
            self._rest_h = np.asarray(topo["rest"], dtype=np.float64)
            self._rest_local_h = np.asarray(topo["rest_local"])
            self._rest_local64_h = np.asarray(topo["rest_local64"], dtype=np.float64)
            self._vertex_body_h = np.asarray(topo["vertex_body"])
            self._point_condition_h = np.asarray(topo["point_condition"])
            self._crack_vertex_h = np.asarray(topo["crack_vertex"], dtype=bool)
            self._tets_h = tets
            faces, fid = boundary_faces(self._tets_h, return_face_ids=True)
            original = np.isin(fid, self.model.surface_face_ids)
            face_body = self.element_body[fid // 4]
            proxies = []
            for i, b in enumerate(self.bodies):
                lo, hi = np.searchsorted(self._vertex_body_h, [i, i + 1])
                mine = original & (face_body == i)
                proxies.append(
                    _SplitBody(b, self._rest_h[lo:hi], faces[mine] - lo, self._point_condition_h[lo:hi].copy())
                )
            self._build_vertex_data(proxies)
        if self.fracture:
            self._strength_h = np.asarray(topo["strength"], dtype=np.float64).copy()
            self._strength = wp.array(self._strength_h.astype(self.np_dtype), dtype=self.dtype, device=self.device)
        self._body_topology_version = [int(x) for x in np.asarray(topo["body_topology_version"])]
        self.topology_version = int(topo["topology_version"])
        self.split_count = int(topo["split_count"])
        self.crack_area = float(topo["crack_area"])
        self._crack_plane_h = np.asarray(topo["crack_plane"], dtype=np.float64).copy()
        self._debt_h = np.asarray(topo["fracture_debt"], dtype=np.float64).copy()
        self.fracture_dissipated = float(topo["fracture_dissipated"])
        self.last_splits = (np.asarray(topo["last_split_vertices"]), np.asarray(topo["last_split_normals"]))
        self.kinematics_restore(state["kinematics"])
        e = state["elements"]
        assign_state(self._rotation, e["rotation"], "rotation")
        assign_state(self._rotation_q, e["rotation_q"], "rotation_q")
        assign_state(self._plastic_strain, e["plastic_strain"], "plastic_strain")
        assign_state(self._principal, e["principal"], "principal")
        self._dt = float(state["dt"])
        self._fragments = None
        self._surfaces = None
        self._contact_mesh = None
        self._smooth_surfaces = self._new_smooth_surfaces()  # drawn again from the restored topology

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

    def contact_mesh(self):
        """The closed surface of every piece of every body, for contact with particle methods
        (pdsim.contact.MethodContact): (vertex ids int32 [v], triangles int32 [3 f] indexing those ids, both Warp
        arrays; topology version, which changes when fracture changes the surface). float32 solvers only."""
        import warp as wp

        if self.precision != "float32":
            names = ", ".join(f"'{b.name}'" for b in self.bodies)
            raise FeatureNotAvailableError(
                f"fem bodies ({names}) with precision={self.precision!r} cannot take part in contact between methods "
                "(its kernels are float32 only); use precision='float32'"
            )
        if self._contact_mesh is None:
            faces = boundary_faces(self._tets_h)
            ids, local = np.unique(faces, return_inverse=True)
            self._contact_mesh = (
                wp.array(ids.astype(np.int32), dtype=wp.int32, device=self.device),
                wp.array(local.ravel().astype(np.int32), dtype=wp.int32, device=self.device),
            )
        return (*self._contact_mesh, self.topology_version)

    def summary(self) -> str:
        """One line for run reports: vertices and elements simulated."""
        return f"{self.point_count} FEM vertices, {self.element_count} tetrahedra"

    def _element_fragments(self) -> np.ndarray:
        """Piece id of every element, int64 [element_count]: the body-local index of the smallest element of its
        face-connected piece (0 for an intact body; a piece keeps its id when another splits off it)."""
        from .fracture import element_pieces

        if self._fragments is None:
            _, labels = element_pieces(self._tets_h)
            _, first = np.unique(labels, return_index=True)
            self._fragments = first[labels] - self.element_offsets[self.element_body]
        return self._fragments

    def _surface_data(self):
        """Per body: (vertex ids [k], triangles [f, 3] into those ids, fragment per face, crack flag per face),
        rebuilt when the topology changed."""
        if self._surfaces is None:
            faces, fid = boundary_faces(self._tets_h, return_face_ids=True)
            elem = fid // 4
            face_body = self.element_body[elem]
            fragment = self._element_fragments()[elem]
            crack = (~np.isin(fid, self.model.surface_face_ids)).astype(np.int32)
            out = []
            for i in range(len(self.bodies)):
                mine = face_body == i
                ids, local = np.unique(faces[mine], return_inverse=True)
                out.append((ids, local.reshape(-1, 3).astype(np.int32), fragment[mine], crack[mine]))
            self._surfaces = out
        return self._surfaces

    def surfaces(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per body: the boundary faces of its elements, (vertex ids [k] into the solver's vertices, outward
        triangles [f, 3] indexing those ids). Each connected piece of a body is a closed surface with its own
        vertices. (The drawn surface of a body with smooth crack surfaces is its MeshView in :meth:`views`.)"""
        return [(ids, faces) for ids, faces, _, _ in self._surface_data()]

    def views(self) -> list:
        """Per body: a PointsView of its input mesh vertices (a fixed count over an animation: the copies that
        fracture adds along cracks appear only in the surface; world positions [m], velocities [m/s], widths = half
        the mean edge length [m]; attributes displacement [m], fragment, plastic_strain when plastic; the reactions
        [N] of its boundary conditions) and a MeshView "<name>_surface" of its pieces (face attributes fragment,
        crack): the boundary faces of its elements, or for a body that can fracture with crack_surfaces="smooth" its
        input surface with smooth crack surfaces (:class:`_SmoothSurface`); a MeshView "<name>_render" per embedded
        render mesh."""
        import warp as wp

        from ..kernels.fem import elements as ke
        from ..output.views import MeshView, PointsView

        u = self.kin.displacements()
        x = self._rest_h + u
        v = self.kin.velocities()
        frag_e = self._element_fragments()
        frag_v = np.zeros(self.point_count, dtype=np.int64)
        frag_v[self._tets_h.ravel()] = np.repeat(frag_e, 4)
        used = np.zeros(self.point_count, dtype=bool)
        used[self._tets_h.ravel()] = True
        eq_v = None
        if self.plastic:
            ep = self._plastic_strain.numpy().astype(np.float64)
            eq = np.sqrt(2.0 / 3.0 * np.einsum("eij,eij->e", ep, ep))  # equivalent plastic strain per element
            vol = np.repeat(np.abs(self.model.volume_h), 4)
            flat = self._tets_h.ravel()
            eq_v = np.bincount(flat, weights=np.repeat(eq, 4) * vol, minlength=self.point_count) / np.maximum(
                np.bincount(flat, weights=vol, minlength=self.point_count), 1.0e-300
            )
        reactions = self.reaction_forces()
        out = []
        for i, (b, (ids, faces, frag_f, crack_f)) in enumerate(zip(self.bodies, self._surface_data(), strict=True)):
            # the body's input vertices: always the first vertex_count of its range (fracture appends the copies,
            # _apply_topology), so the points keep their count and identity over an animation
            lo = int(self.body_offsets[i])
            hi = lo + b.vertex_count
            attributes = {"displacement": u[lo:hi], "fragment": frag_v[lo:hi]}
            if eq_v is not None:
                attributes["plastic_strain"] = eq_v[lo:hi]
            out.append(
                PointsView(
                    name=b.name,
                    positions=x[lo:hi],
                    velocities=v[lo:hi],
                    widths=np.full(hi - lo, self.model.widths[i]),
                    attributes=attributes,
                    reactions={cond: r for (body, cond), r in reactions.items() if body == b.name},
                )
            )
            smooth = self._smooth_surfaces[i]
            if smooth is not None:
                end = int(self.body_offsets[i + 1])
                out.append(
                    smooth.view(
                        self._body_topology_version[i],
                        self._rest_h[lo:end],
                        frag_v[lo:end],
                        used[lo:end],
                        x[lo:end],
                        v[lo:end],
                        (ids - lo, faces, frag_f, crack_f),
                    )
                )
                continue
            out.append(
                MeshView(
                    name=f"{b.name}_surface",
                    points=x[ids],
                    velocities=v[ids],
                    topology_version=self._body_topology_version[i],
                    faces=faces,
                    face_attributes={"fragment": frag_f, "crack": crack_f},
                )
            )
        for body_index, elem, w, faces, rest_points, out_u, out_v in self.model.render:
            wp.launch(
                ke.embed_points_kernel(self.dtype),
                dim=len(w),
                inputs=[self.kin.u, self.kin.v, self._tets, elem, w, out_u, out_v],
                device=self.device,
            )
            out.append(
                MeshView(
                    name=f"{self.bodies[body_index].name}_render",
                    points=rest_points + out_u.numpy().astype(np.float64),
                    velocities=out_v.numpy().astype(np.float64),
                    topology_version=0,
                    faces=faces,
                )
            )
        return out

    def render_points(self, index: int = 0) -> np.ndarray:
        """Current world vertices of the ``index``-th render mesh [m], float64 [render_vertex_count, 3]."""
        name = f"{self.bodies[self.model.render[index].body].name}_render"
        return next(v.points for v in self.views() if v.name == name)

    # -- host-side views and diagnostics (vectorised numpy) -----------------------------------------------------
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

    def _host_displacements(self, positions, name: str):
        """World positions [m] [vertex_count, 3] -> displacements (float64 difference, then the solver's dtype)."""
        p = np.asarray(positions, dtype=np.float64)
        if p.shape != (self.point_count, 3):
            raise ParameterError(name, p.shape, f"shape ({self.point_count}, 3)")
        return p - self._rest_h

    def set_positions(self, positions):
        """Sets the displacements so that the vertices are at world ``positions`` [m] (shape [vertex_count, 3]);
        recomputes the accelerations (explicit)."""
        self.kin.set_displacements(self._host_displacements(positions, "positions"))
        if self.integrator == "explicit":
            self._update_accelerations()

    def set_displacements(self, displacements):
        """Overwrites the displacements [m] (shape [vertex_count, 3]); recomputes the accelerations (explicit)."""
        u = np.asarray(displacements, dtype=np.float64)
        if u.shape != (self.point_count, 3):
            raise ParameterError("displacements", u.shape, f"shape ({self.point_count}, 3)")
        self.kin.set_displacements(u)
        if self.integrator == "explicit":
            self._update_accelerations()

    def set_velocities(self, velocities):
        """Overwrites velocities [m/s], shape [vertex_count, 3]."""
        v = np.asarray(velocities, dtype=np.float64)
        if v.shape != (self.point_count, 3):
            raise ParameterError("velocities", v.shape, f"shape ({self.point_count}, 3)")
        self.kin.set_velocities(v)
        if self.integrator == "explicit":
            self._update_accelerations()

    def nodal_forces(self, positions=None) -> np.ndarray:
        """Internal elastic forces [N] at the current (or given world) positions, shape [vertex_count, 3] (no loads,
        no plastic update)."""
        import warp as wp

        from ..kernels.fem import solver as ks

        u = None
        if positions is not None:
            u = wp.array(
                self._host_displacements(positions, "positions").astype(self.np_dtype),
                dtype=self.vec3,
                device=self.device,
            )
        self._compute_element_forces(0.0, u)
        out = wp.zeros(self.point_count, dtype=self.vec3, device=self.device)
        wp.launch(
            ks.vertex_kernels(self.dtype)["gather_forces"],
            dim=self.point_count,
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

        m = self.model
        blocks = wp.zeros(16 * self.element_count, dtype=self.mat33, device=self.device)
        wp.launch(
            ke.element_stiffness_blocks_kernel(self.dtype, self._rotated),
            dim=self.element_count,
            inputs=[m.dm_inv, m.volume, m.lame, self._rotation, blocks],
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
        import warp as wp

        from ..kernels.fem import elements as ke

        m = self.model
        wp.launch(
            ke.element_energy_kernel(self.dtype, self._measure_id, self.plastic),
            dim=self.element_count,
            inputs=[
                self.kin.u,
                self._tets,
                m.dm_inv,
                m.volume,
                m.lame,
                self._plastic_strain,
                self._energy,
            ],
            device=self.device,
        )
        return float(self._energy.numpy().astype(np.float64).sum())

    def gravity_potential(self) -> float:
        """-sum m g . x [J] (world positions)."""
        return float(-np.dot(self._mass_h, self.positions() @ self.gravity_host))

    def piece_count(self) -> int:
        """Number of face-connected pieces of all bodies together."""
        from .fracture import element_pieces

        return int(element_pieces(self._tets_h)[0])


__all__ = ["CgReport", "SolverFem", "StaticSolveReport"]

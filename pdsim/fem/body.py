"""Tetrahedral FEM bodies: a linear-tetrahedron mesh of a solid, its material, strain measure, integrator,
plasticity and fracture settings, and its boundary conditions (the scene-facing part of the FEM method)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..geometry import SolidShape
from ..materials import Material
from ..regions import region_mask
from ..validate import check_range
from .mesh import DEFAULT_MIN_QUALITY, TetMesh, tetrahedralize

MEASURES = ("linear", "corotated", "green")
INTEGRATORS = ("explicit", "implicit")
PRECISIONS = ("float32", "float64")
STIFFNESS_MODES = ("matrix_free", "assembled")


@dataclass(frozen=True)
class FemPlasticity:
    """Plasticity parameters of the slides' update rule (kernels/fem/elements.py), on the Frobenius norm of the strain.

    Args:
        yield_strain: elastic strain norm above which the element flows [-], > 0.
        creep: rate at which the plastic strain absorbs the elastic strain [1/s], > 0 (the per-step fraction is
            min(creep dt, 1)).
        max_strain: largest plastic strain norm [-], > 0.
    """

    yield_strain: float
    creep: float
    max_strain: float

    def __post_init__(self):
        object.__setattr__(self, "yield_strain", check_range("yield_strain", self.yield_strain, 0.0, None))
        object.__setattr__(self, "creep", check_range("creep", self.creep, 0.0, None))
        object.__setattr__(self, "max_strain", check_range("max_strain", self.max_strain, 0.0, None))


class FemBody:
    """A solid meshed with linear tetrahedra, simulated with the finite element method.

    Args:
        shape: a closed surface (:class:`pdsim.SolidShape`, meshed with fTetWild at ``edge_length``) or a ready
            :class:`pdsim.fem.mesh.TetMesh` (``load_tet_mesh``, ``box_tet_mesh``, ``tet_mesh_from_arrays``).
        material: density and elastic constants (nu < 0.5 is enforced by Material).
        edge_length: target edge length of the mesher [m] (surfaces only); default 1/20 of the bounding-box diagonal.
        measure: strain measure "linear", "corotated" (default) or "green".
        integrator: "explicit" (default) or "implicit".
        plasticity: plastic flow parameters, or None for a purely elastic body (nothing is allocated or launched).
        tensile_strength: largest principal stress before an element cracks [Pa], > 0; None: no fracture.
        damping: mass-proportional damping c [1/s], >= 0 (a = f / m + g - c v).
        implicit_step_ratio: implicit integrator: the step the scene uses, as a multiple of the explicit limit, >= 1.
        render_mesh: a high-resolution surface embedded in the tetrahedra (barycentric) and written as its own
            UsdGeom.Mesh ("<name>_render") that follows them; True embeds ``shape`` itself (surfaces only). It is not
            cut by cracks: where the body fractures, its triangles stretch across the gap. Default None.
        name: label in the USD cache; defaults to the shape's name.
        min_quality: element quality check of the mesh (see pdsim.fem.mesh), in [0, 1).
        mesh_cache: folder where meshes made by fTetWild are kept and reused (its output varies from run to run;
            see pdsim.fem.mesh.tetrahedralize), or None.
    """

    def __init__(
        self,
        shape: SolidShape | TetMesh,
        material: Material,
        *,
        edge_length: float | None = None,
        measure: str = "corotated",
        integrator: str = "explicit",
        plasticity: FemPlasticity | None = None,
        tensile_strength: float | None = None,
        damping: float = 0.0,
        implicit_step_ratio: float = 10.0,
        render_mesh: SolidShape | bool | None = None,
        name: str | None = None,
        min_quality: float = DEFAULT_MIN_QUALITY,
        mesh_cache: str | None = None,
    ):
        if not isinstance(material, Material):
            raise ParameterError("material", material, "a pdsim.Material")
        if measure not in MEASURES:
            raise ParameterError("measure", measure, " or ".join(map(repr, MEASURES)))
        if integrator not in INTEGRATORS:
            raise ParameterError("integrator", integrator, " or ".join(map(repr, INTEGRATORS)))
        if integrator == "implicit" and measure == "green":
            raise ParameterError("measure", measure, "'linear' or 'corotated' with the implicit integrator")
        if plasticity is not None and not isinstance(plasticity, FemPlasticity):
            raise ParameterError("plasticity", plasticity, "a pdsim.fem.FemPlasticity or None")
        if isinstance(shape, TetMesh):
            if edge_length is not None:
                raise ParameterError("edge_length", edge_length, "None for a ready TetMesh (it is not remeshed)")
            self.mesh = shape
        elif isinstance(shape, SolidShape):
            self.mesh = tetrahedralize(shape, edge_length=edge_length, min_quality=min_quality, cache_dir=mesh_cache)
        else:
            raise ParameterError("shape", shape, "a pdsim SolidShape or a pdsim.fem.mesh.TetMesh")
        if render_mesh is True:
            if not isinstance(shape, SolidShape):
                raise ParameterError("render_mesh", True, "a SolidShape (True needs a surface shape to embed)")
            render_mesh = shape
        elif render_mesh is False:
            render_mesh = None
        if render_mesh is not None and not isinstance(render_mesh, SolidShape):
            raise ParameterError("render_mesh", render_mesh, "a pdsim SolidShape, True or None")
        self.render_mesh = render_mesh
        self.material = material
        self.measure = measure
        self.integrator = integrator
        self.plasticity = plasticity
        self.tensile_strength = (
            None if tensile_strength is None else check_range("tensile_strength", tensile_strength, 0.0, None)
        )
        self.damping = check_range("damping", damping, 0.0, None, lo_open=False)
        self.implicit_step_ratio = check_range("implicit_step_ratio", implicit_step_ratio, 1.0, None, lo_open=False)
        self.name = name or shape.name
        n = self.mesh.vertex_count
        self.kind = np.zeros(n, dtype=np.int32)
        self.prescribed_velocity = np.zeros((n, 3), dtype=np.float64)
        self.initial_velocity = np.zeros((n, 3), dtype=np.float64)
        self.release_time = np.full(n, np.inf)  # prescribed vertices become free at this time [s]

    @property
    def vertex_count(self) -> int:
        return self.mesh.vertex_count

    @property
    def element_count(self) -> int:
        return self.mesh.element_count

    @property
    def rest_positions(self) -> np.ndarray:
        """Rest positions of the mesh vertices [m], shape [vertex_count, 3]."""
        return self.mesh.vertices

    @property
    def fractures(self) -> bool:
        """True when the body can crack (a tensile strength is set)."""
        return self.tensile_strength is not None

    @classmethod
    def build_solver(cls, bodies, *, device, gravity, ground, contact=None, colliders=()):
        """The scene's solver for all its FEM bodies. ``colliders`` (static meshes, kinematic projectiles) act on the
        vertices; ``contact`` (particle contact between unbonded particles) has no FEM counterpart yet: FEM pieces and
        bodies pass through each other, and the setting is ignored."""
        from .solver import SolverFem

        return SolverFem(bodies, device=device, gravity=gravity, ground=ground, colliders=colliders)

    def _select(self, region) -> np.ndarray:
        mask = region_mask(region, self.mesh.vertices, field="region")
        if not mask.any():
            raise ParameterError("region", region, f"a region containing at least one vertex of '{self.name}'")
        return mask

    def fix(self, region) -> int:
        """Holds the vertices whose rest position lies in ``region`` at rest; returns how many."""
        mask = self._select(region)
        self.kind[mask] = 1
        self.prescribed_velocity[mask] = 0.0
        self.release_time[mask] = np.inf
        return int(mask.sum())

    def set_velocity(self, region, velocity, *, until: float | None = None) -> int:
        """Moves the vertices in ``region`` at the constant ``velocity`` [m/s] (a displacement-driven boundary); with
        ``until`` [s] (> 0) they are released (become free, keeping their velocity) at that time."""
        v = np.asarray(velocity, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ParameterError("velocity", velocity, "a sequence of 3 finite numbers [m/s]")
        release = np.inf if until is None else check_range("until", until, 0.0, None)
        mask = self._select(region)
        self.kind[mask] = 2
        self.prescribed_velocity[mask] = v
        self.release_time[mask] = release
        return int(mask.sum())

    def set_initial_velocity(self, velocity, region=None) -> int:
        """Initial velocity [m/s]: a vector for all vertices (or those in ``region``), or an array [vertex_count, 3]."""
        v = np.asarray(velocity, dtype=np.float64)
        n = self.vertex_count
        if v.shape == (n, 3) and region is None:
            mask, values = np.ones(n, dtype=bool), v
        elif v.shape == (3,):
            mask = np.ones(n, dtype=bool) if region is None else self._select(region)
            values = np.broadcast_to(v, (int(mask.sum()), 3))
        else:
            raise ParameterError("velocity", velocity, f"3 numbers or an array of shape ({n}, 3)")
        if not np.all(np.isfinite(values)):
            raise ParameterError("velocity", velocity, "finite values")
        self.initial_velocity[mask] = values
        return int(mask.sum())

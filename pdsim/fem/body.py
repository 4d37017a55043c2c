"""Tetrahedral FEM bodies: a linear-tetrahedron mesh of a solid, its material, strain measure, integrator,
plasticity and fracture settings (the scene-facing part of the FEM method). Boundary conditions, loads and initial
velocities are the shared point-body API (pdsim/bodies.py, pdsim/loads.py) acting on the mesh vertices."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bodies import PointBody
from ..checks import check_range
from ..errors import ParameterError
from ..geometry import SolidShape
from ..loads import surface_forces_from_triangles
from ..materials import Material
from ..regions import region_mask
from .fracture import closed_surface_defects
from .mesh import DEFAULT_MIN_QUALITY, TetMesh, signed_volumes, tetrahedralize

MEASURES = ("linear", "corotated", "green")
INTEGRATORS = ("explicit", "implicit")
PRECISIONS = ("float32", "float64")
STIFFNESS_MODES = ("matrix_free", "assembled")
CRACK_SURFACES = ("smooth", "elements")
MASS_SCALING = 0.2  # FemBody.mass_scaling's default: elements under 0.2 of the median height take added mass


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


class FemBody(PointBody):
    """A solid meshed with linear tetrahedra, simulated with the finite element method (``method = "fem"``).

    Its points are the mesh vertices: ``fix``, ``set_velocity``, ``set_initial_velocity`` and the loads
    (``add_traction``, ``add_pressure``, ``add_body_force``, ``add_force``, ``add_point_force``,
    ``add_velocity_kick``) select vertices by their rest position (pdsim/bodies.py); a surface load acts on the boundary
    faces of the mesh whose centroid lies in its region (:meth:`surface_point_forces`).

    Args:
        shape: a closed surface (:class:`pdsim.SolidShape`, meshed with fTetWild at ``edge_length``) or a ready
            :class:`pdsim.fem.mesh.TetMesh` (``load_tet_mesh``, ``box_tet_mesh``, ``tet_mesh_from_arrays``).
        material: density and elastic constants (nu < 0.5 is enforced by Material).
        edge_length: target edge length of the mesher [m] (surfaces only); default 1/20 of the bounding-box diagonal.
        measure: strain measure "linear", "corotated" (default) or "green".
        integrator: "explicit" (default) or "implicit".
        plasticity: plastic flow parameters, or None for a purely elastic body (nothing is allocated or launched).
        tensile_strength: largest principal stress before an element cracks [Pa], > 0; None: no fracture.
        fracture_energy: energy a crack consumes per unit area of new crack surface, G_c [J/m^2], >= 0 (default 0):
            a split happens only when the strain energy around it covers G_c times the crack area it opens, and that
            energy is then taken from the motion around the crack (pdsim/fem/fracture.py). Needs tensile_strength.
        damping: mass-proportional damping c [1/s], >= 0 (a = f / m + g - c v).
        implicit_step_ratio: implicit integrator: the step the scene uses, as a multiple of the explicit limit, >= 1.
        mass_scaling: elements whose height (3 V / largest face area) is below this fraction of the body's median
            element height take a density (fraction x median / height)^2 times the material's, so that their stable
            step is that of an element of that height (selective mass scaling, :func:`mass_scaling_factors`); in
            [0, 1), 0 for none. The default, MASS_SCALING = 0.2, leaves fTetWild's usual meshes untouched (their
            smallest element is 0.26 to 0.30 of the median) and lifts the step of a mesh holding a few elements far
            smaller than the rest about tenfold for about 1e-4 of the body's mass; the run's summary states what it
            added.
        render_mesh: a high-resolution surface embedded in the tetrahedra (barycentric) and output as its own mesh
            view ("<name>_render") that follows them; True embeds ``shape`` itself (surfaces only). It is not cut by
            cracks: where the body fractures, its triangles stretch across the gap. Default None.
        name: label of the body in outputs; defaults to the shape's name.
        min_quality: element quality check of the mesh (see pdsim.fem.mesh), in [0, 1).
        mesh_cache: folder where meshes made by fTetWild are kept and reused (its output varies from run to run;
            see pdsim.fem.mesh.tetrahedralize), or None.
        crack_surfaces: how the surface "<name>_surface" of a body that can fracture is drawn: "smooth" (default)
            draws each piece as its part of the input surface (the ``SolidShape`` it was meshed from, or the boundary
            of a ready TetMesh) closed by smooth crack surfaces fitted to the element faces the cracks opened
            (pdsim/fragment_surfaces.py over the mesh vertices; docs/fem_fracture.md); "elements" draws the
            boundary faces of each piece's tetrahedra (crack surfaces are staircases of element faces). Bodies
            without ``tensile_strength`` always draw their boundary faces.
    """

    method = "fem"

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
        fracture_energy: float = 0.0,
        damping: float = 0.0,
        implicit_step_ratio: float = 10.0,
        mass_scaling: float = MASS_SCALING,
        render_mesh: SolidShape | bool | None = None,
        name: str | None = None,
        min_quality: float = DEFAULT_MIN_QUALITY,
        mesh_cache: str | None = None,
        crack_surfaces: str = "smooth",
    ):
        if not isinstance(material, Material):
            raise ParameterError("material", material, "a pdsim.Material")
        if measure not in MEASURES:
            raise ParameterError("measure", measure, " or ".join(map(repr, MEASURES)))
        if integrator not in INTEGRATORS:
            raise ParameterError("integrator", integrator, " or ".join(map(repr, INTEGRATORS)))
        if integrator == "implicit" and measure == "green":
            raise ParameterError("measure", measure, "'linear' or 'corotated' with the implicit integrator")
        if not isinstance(crack_surfaces, str) or crack_surfaces not in CRACK_SURFACES:
            raise ParameterError("crack_surfaces", crack_surfaces, " or ".join(map(repr, CRACK_SURFACES)))
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
        self.fracture_energy = check_range("fracture_energy", fracture_energy, 0.0, None, lo_open=False)
        if self.fracture_energy > 0.0 and self.tensile_strength is None:
            raise ParameterError("fracture_energy", fracture_energy, "0 without a tensile_strength (no fracture)")
        self.damping = check_range("damping", damping, 0.0, None, lo_open=False)
        self.implicit_step_ratio = check_range("implicit_step_ratio", implicit_step_ratio, 1.0, None, lo_open=False)
        self.mass_scaling = check_range("mass_scaling", mass_scaling, 0.0, 1.0, lo_open=False)
        self.name = name or shape.name
        self.crack_surfaces = crack_surfaces
        # the closed input surface smooth crack surfaces are drawn from; None where element faces are drawn
        self.surface_shape = None
        if self.fractures and crack_surfaces == "smooth":
            self.surface_shape = shape if isinstance(shape, SolidShape) else mesh_surface(self.mesh, self.name)
        self._init_points()

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

    @property
    def point_count(self) -> int:
        """Vertex count (the body's points)."""
        return self.mesh.vertex_count

    @property
    def point_rest_positions(self) -> np.ndarray:
        """Rest positions of the vertices [m] (world), float64 [vertex_count, 3]."""
        return self.mesh.vertices

    def point_masses(self) -> np.ndarray:
        """Lumped vertex masses [kg]: a quarter of rho V of each incident element (rho with its mass scaling),
        float64 [vertex_count]."""
        factors = mass_scaling_factors(self.mesh.element_heights, self.mass_scaling)
        return lumped_masses(self.mesh.vertices, self.mesh.tets, self.material.density * factors)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World bounding box (lo, hi) [m] of the rest vertices, float64 [3] each."""
        return self.mesh.vertices.min(axis=0), self.mesh.vertices.max(axis=0)

    def _select(self, region) -> np.ndarray:
        mask = region_mask(region, self.mesh.vertices, field="region")
        if not mask.any():
            raise ParameterError("region", region, f"a region containing at least one vertex of '{self.name}'")
        return mask

    def surface_point_forces(self, region, traction, pressure: float):
        """Forces [N] of a traction [Pa] (3 numbers) and a pressure [Pa] on the boundary faces of the mesh whose
        centroid lies in ``region``, each face's force shared equally by its three vertices: (vertex indices int64
        [k], forces float64 [k, 3]). ParameterError when the region holds no boundary face."""
        return face_point_forces(self.mesh.vertices, self.mesh.boundary_faces(), region, traction, pressure)


def mesh_surface(mesh: TetMesh, name: str) -> SolidShape:
    """The boundary of a tet mesh as a closed surface (its boundary faces on the vertices they use), for drawing
    smooth crack surfaces. ParameterError (crack_surfaces) when it is not a closed 2-manifold: an edge of the boundary
    not shared by exactly two faces of opposite directions, as where two parts of the mesh touch along an edge."""
    faces = np.asarray(mesh.boundary_faces(), dtype=np.int64)
    if closed_surface_defects(faces):
        raise ParameterError(
            "crack_surfaces",
            "smooth",
            f"'elements' for '{name}': the boundary of its tet mesh is not a closed 2-manifold (some edge is not "
            "shared by exactly two boundary faces), so it bounds no solid to draw smooth crack surfaces from",
        )
    used, local = np.unique(faces, return_inverse=True)
    return SolidShape(vertices=mesh.vertices[used], faces=local.reshape(-1, 3).astype(np.int32), name=name)


def mass_scaled_heights(heights: np.ndarray, fraction: float) -> np.ndarray:
    """The heights [m] that set the elements' explicit steps under selective mass scaling, float64 [m]: each element's
    height, raised to fraction x median(heights) where it is below (unchanged with fraction 0)."""
    heights = np.asarray(heights, dtype=np.float64)
    if fraction <= 0.0 or len(heights) == 0:
        return heights
    return np.maximum(heights, fraction * float(np.median(heights)))


def mass_scaling_factors(heights: np.ndarray, fraction: float) -> np.ndarray:
    """Density factors of selective mass scaling, float64 [m]: (fraction x median(heights) / height)^2 for the
    elements whose height [m] is below that fraction of the median, 1 for the others (and for all with fraction 0).
    An element's explicit stable step, proportional to its height over its wave speed, grows as the square root of its
    density: the scaled elements take the step of an element of height fraction x median
    (:func:`mass_scaled_heights`), and the mass added is sum (factor - 1) rho V."""
    heights = np.asarray(heights, dtype=np.float64)
    return (mass_scaled_heights(heights, fraction) / heights) ** 2


def lumped_masses(vertices: np.ndarray, tets: np.ndarray, density) -> np.ndarray:
    """Lumped vertex masses [kg], float64 [vertex_count]: each element gives rho V / 4 to its four corners
    (``density`` [kg/m^3] a number or per element)."""
    share = np.broadcast_to(np.asarray(density, dtype=np.float64), (len(tets),)) * signed_volumes(vertices, tets) / 4.0
    return np.bincount(np.asarray(tets).ravel(), weights=np.repeat(share, 4), minlength=len(vertices))


def face_point_forces(vertices: np.ndarray, faces: np.ndarray, region, traction, pressure: float):
    """Surface-load forces on the vertices of outward ``faces`` [f, 3] (indices into ``vertices`` [m], float64
    [n, 3]) whose centroid lies in ``region``: (vertex indices int64 [k], forces [N] float64 [k, 3]); each face's
    force (pdsim.loads.surface_forces_from_triangles: traction times area minus pressure times area times the outward
    normal) is shared equally by its three vertices and summed per vertex."""
    idx, _, forces = surface_forces_from_triangles(
        vertices, np.asarray(faces), region, np.asarray(traction, dtype=np.float64), float(pressure)
    )
    corners = np.asarray(faces)[idx].ravel().astype(np.int64)
    share = np.repeat(forces / 3.0, 3, axis=0)
    pts, inverse = np.unique(corners, return_inverse=True)
    inverse = inverse.ravel()
    out = np.stack([np.bincount(inverse, weights=share[:, d], minlength=len(pts)) for d in range(3)], axis=1)
    return pts, out

"""What the tetrahedral FEM solver (:class:`pdsim.fem.solver.SolverFem`) draws and shows to contact: per body a
PointsView of its input vertices, a MeshView "<name>_surface" of its pieces (the boundary faces of its elements, or
:class:`SmoothSurface`'s input surface closed by smooth crack surfaces) and the embedded render meshes; the closed
surfaces of the pieces for contact between methods.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from ..errors import FeatureNotAvailableError
from ..fragment_labels import connected_components
from ..fragment_surfaces import FragmentSurfaces
from ..kernels.fem import elements as ke
from ..output.views import MeshView, PointsView
from .body import FemBody
from .fracture import element_pieces
from .mesh import boundary_faces


class SmoothSurface:
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


class FemViews:
    """The views of :class:`pdsim.fem.solver.SolverFem` (a mixin: they read the solver's topology, kinematics and
    model, and cache per topology the surfaces ``_surfaces``, the pieces ``_fragments``, the contact mesh
    ``_contact_mesh`` and per body its :class:`SmoothSurface` ``_smooth_surfaces``)."""

    def _new_smooth_surfaces(self) -> list:
        """Per body: its :class:`SmoothSurface` (a body that can fracture, with crack_surfaces="smooth"), else None;
        the spacing is the mesh's mean edge length."""
        return [
            None if b.surface_shape is None else SmoothSurface(b, 2.0 * self.model.widths[i], str(self.device))
            for i, b in enumerate(self.bodies)
        ]

    def _boundary_faces_h(self):
        """(boundary faces int32 [k, 3], face ids 4 e + k int64 [k]) of the current element corners
        (pdsim.fem.mesh.boundary_faces), computed once per topology: the corners array is replaced, never changed in
        place, when fracture splits vertices."""
        cached = getattr(self, "_boundary_cache", None)
        if cached is None or cached[0] is not self._tets_h:
            cached = (self._tets_h, *boundary_faces(self._tets_h, return_face_ids=True))
            self._boundary_cache = cached
        return cached[1], cached[2]

    def contact_mesh(self):
        """The closed surface of every piece of every body, for contact with particle methods
        (pdsim.contact.MethodContact): (vertex ids int32 [v], triangles int32 [3 f] indexing those ids, both Warp
        arrays; topology version, which changes when fracture changes the surface). float32 solvers only."""
        if self.precision != "float32":
            names = ", ".join(f"'{b.name}'" for b in self.bodies)
            raise FeatureNotAvailableError(
                f"fem bodies ({names}) with precision={self.precision!r} cannot take part in contact between methods "
                "(its kernels are float32 only); use precision='float32'"
            )
        if self._contact_mesh is None:
            faces, _ = self._boundary_faces_h()
            ids, local = np.unique(faces, return_inverse=True)
            self._contact_mesh = (
                wp.array(ids.astype(np.int32), dtype=wp.int32, device=self.device),
                wp.array(local.ravel().astype(np.int32), dtype=wp.int32, device=self.device),
            )
        return (*self._contact_mesh, self.topology_version)

    def contact_pieces(self):
        """Piece labels of the contact mesh for contact between FEM surfaces (pdsim.contact.MethodContact): (label of
        each contact-mesh vertex int32 [v], label of each triangle int32 [f]) Warp arrays, the labels 0 to
        contact_piece_count() - 1. A piece is a vertex-connected set of the current elements: separate bodies and the
        pieces a crack has cut free have different labels, the two sides of a crack that has not yet cut a piece free
        the same. Rebuilt when the topology version changes."""
        return self._pieces_of_contact_mesh()[1:3]

    def contact_piece_count(self) -> int:
        """The number of pieces (contact_pieces) on the contact mesh: with one, no surface vertex has a face of
        another piece to meet."""
        return self._pieces_of_contact_mesh()[3]

    def _pieces_of_contact_mesh(self):
        """(topology version, vertex labels, face labels, piece count) of the contact mesh, cached per version."""
        ids, faces, version = self.contact_mesh()
        if self._contact_pieces is None or self._contact_pieces[0] != version:
            tets = np.asarray(self._tets_h, dtype=np.int64)
            labels = connected_components(self.point_count, np.repeat(tets[:, :1], 3, axis=1), tets[:, 1:])
            pieces, vertex = np.unique(labels[ids.numpy()], return_inverse=True)  # labels 0..count-1
            vertex = vertex.astype(np.int32)
            face = vertex[faces.numpy().reshape(-1, 3)[:, 0]]
            self._contact_pieces = (
                version,
                wp.array(vertex, dtype=wp.int32, device=self.device),
                wp.array(face, dtype=wp.int32, device=self.device),
                len(pieces),
            )
        return self._contact_pieces

    def contact_steps(self):
        """Per point, the stable step [s] of its smallest incident element (SolverFem model ``element_dt_h``),
        float32 Warp array: contact between FEM surfaces sizes its stiffness on it (kernels/surface_contact.py), so
        a vertex's contact is as stiff as the elements around it bear, whatever step the run takes. Sized on the
        run's step alone, a mesh whose one small element forces a step 30 times smaller made every other vertex's
        contact 1000 times stiffer than its elements, and contact crushed them (inverted elements, or speeds past the
        watchdog's limit)."""
        if self._contact_steps is None:
            step = np.full(self.point_count, np.inf)
            tets = np.asarray(self._tets_h, dtype=np.int64)
            np.minimum.at(step, tets.ravel(), np.repeat(self.model.element_dt_h, 4))
            self._contact_steps = wp.array(step.astype(np.float32), dtype=float, device=self.device)
        return self._contact_steps

    def contact_skin(self) -> tuple[float, float]:
        """(skin, band) [m] of contact between FEM surfaces: a surface vertex is a point (skin 0: the faces a crack
        separates lie on each other when the piece comes free, and a skin would push them apart at once), found inside
        another piece down to ``band`` (one mean edge length of the smallest body) below its surface."""
        width = float(min(self.model.widths))  # half a mean edge length
        return 0.0, 2.0 * width

    def _element_fragments(self) -> np.ndarray:
        """Piece id of every element, int64 [element_count]: the body-local index of the smallest element of its
        face-connected piece (0 for an intact body; a piece keeps its id when another splits off it)."""
        if self._fragments is None:
            _, labels = element_pieces(self._tets_h)
            _, first = np.unique(labels, return_index=True)
            self._fragments = first[labels] - self.element_offsets[self.element_body]
        return self._fragments

    def _surface_data(self):
        """Per body: (vertex ids [k], triangles [f, 3] into those ids, fragment per face, crack flag per face),
        rebuilt when the topology changed."""
        if self._surfaces is None:
            faces, fid = self._boundary_faces_h()
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
        input surface with smooth crack surfaces (:class:`SmoothSurface`); a MeshView "<name>_render" per embedded
        render mesh."""
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
            # FemFractureEvents._apply_topology), so the points keep their count and identity over an animation
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
            ke.embed_points(
                displacements=self.kin.u,
                velocities=self.kin.v,
                tets=self._tets,
                element=elem,
                weights=w,
                out_displacement=out_u,
                out_velocity=out_v,
                dtype=self.dtype,
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

    def piece_count(self) -> int:
        """Number of face-connected pieces of all bodies together."""
        return int(element_pieces(self._tets_h)[0])


__all__ = ["FemViews", "SmoothSurface"]

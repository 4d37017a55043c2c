"""Fracture events of the tetrahedral FEM solver (:class:`pdsim.fem.solver.SolverFem`): after a step, the elements
over their strength split vertices along crack planes (pdsim/fem/fracture.py holds the host topology work: crack
planes, vertex splits, the Griffith test, the fracture energy); the solver's vertex data and kinematics are then
rebuilt on the new numbering, the boundary conditions, loads and kicks carried over by :class:`SplitBody`.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..errors import ParameterError
from ..loads import PointLoads
from ..regions import region_mask
from .body import FemBody, face_point_forces
from .fracture import (
    best_offsets,
    can_split,
    choose_splits,
    griffith_filter,
    make_manifold,
    opened_faces,
    pay_fracture_energy,
    separation_directions,
    split_vertices,
    triangle_areas,
    vertex_incidence,
)

GRIFFITH_ROUNDS = 4  # fracture: rounds of the Griffith test before a step's remaining splits are made untested


class SplitBody(PointLoads):
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


class FemFractureEvents:
    """The fracture events of :class:`pdsim.fem.solver.SolverFem` (a mixin: they read and replace the solver's
    topology arrays, ``_tets_h``, ``_rest_h``, ``_crack_vertex_h``, ``_crack_plane_h``, ``_debt_h`` and the
    strengths, and rebuild its vertex data with ``_build_vertex_data``)."""

    def apply_fracture(self) -> int:
        """Evaluates the stresses at the current displacements (no plastic update) and performs the crack splits of
        every element over its strength, as a step does; returns the number of vertex splits."""
        if not self.fracture:
            raise ParameterError("tensile_strength", None, "a value > 0 on some body to use fracture")
        before = self.split_count
        self.element_forces(0.0)
        self._fracture_event()
        return self.split_count - before

    def _fracture_event(self) -> bool:
        """Pays fracture energy still owed, then splits vertices where elements exceed their strength (only when the
        kernel counted one) and the Griffith test passes (pdsim/fem/fracture.py); True if the topology changed."""
        if self._debt_h.any():
            self._pay_fracture_energy()
        if int(self._over_count.numpy()[0]) == 0:
            return False
        principal = self._principal.numpy().astype(np.float64)
        nv = self.point_count
        over = np.flatnonzero(principal[:, 3] > self._strength_h)
        over = over[can_split(self._tets_h, over, nv)]  # the others would be refused by choose_splits
        if over.size == 0:
            return False
        rest, centroids = self._rest_local_h, self.model.centroids_h
        incidence = vertex_incidence(self._tets_h, nv)  # the corners of each vertex, shared by the passes below
        directions = separation_directions(
            self._tets_h, over, self._element_stresses, self.model.volume_h, principal[over, :3], incidence=incidence
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
            incidence=incidence,
        )
        if len(verts) == 0:
            return False
        origins, fits = best_offsets(
            self._tets_h, rest, centroids, verts, normals, anchors, new_crack, incidence=incidence
        )
        if not fits.all():
            verts, normals, sources, anchors, origins = (a[fits] for a in (verts, normals, sources, anchors, origins))
            if len(verts) == 0:
                return False
        gc = self.model.fracture_energy_h
        energy = None
        for round_ in range(GRIFFITH_ROUNDS + 1):
            tets1, parent1 = split_vertices(self._tets_h, rest, centroids, verts, normals, origins, incidence=incidence)
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
        free = self.kin.point_condition_host < 0
        v, self._debt_h, paid = pay_fracture_energy(
            self._tets_h, self.lumped_mass_host, self.kin.velocities(), self._debt_h, free
        )
        if paid > 0.0:
            self.kin.set_velocities(v)
            self.fracture_dissipated += paid

    def _apply_topology(self, tets: np.ndarray, parent: np.ndarray, crack: np.ndarray, crack_plane, debt):
        """Installs new element corners; vertex i of the new numbering copies the state of old vertex parent[i]
        (displacement, velocity, acceleration, boundary condition). Vertices are then renumbered body by body (stable:
        a single body keeps the numbering of the split), and the kinematics rebuilt from host arrays. The split keeps
        the old numbering as a prefix and appends the copies, so each body's first vertex_count vertices remain its
        input vertices (views() relies on it). ``renumbering`` keeps (version before, version after, new index of
        each old vertex) for what refers to the old numbering within the step (pdsim.contact.MethodContact.end_step)."""
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
        old_count = kin.u.shape[0]
        self._build_vertex_data(self._split_bodies(), state)
        # (version before, version after, new index of each old vertex): the split keeps old vertex j as its vertex j
        self.renumbering = (self.topology_version, self.topology_version + 1, inverse[:old_count])
        self.topology_version += 1
        if self.integrator == "explicit":
            self.update_accelerations()

    def points_in_current_numbering(self, version: int, points):
        """The point indices ``points`` (a Warp int32 array of the numbering of topology ``version``) in the current
        numbering: ``points`` itself when the topology is unchanged, mapped through ``renumbering`` when one split led
        from ``version`` to the current one (a split vertex's indices go to the copy that keeps its number), else
        None. The mapping runs on the host, on the steps of a split only (pdsim.contact.MethodContact.end_step)."""
        if version == self.topology_version:
            return points
        renumbering = getattr(self, "renumbering", None)
        if renumbering is None or (renumbering[0], renumbering[1]) != (version, self.topology_version):
            return None
        mapped = np.asarray(renumbering[2])[points.numpy()]
        return wp.array(mapped.astype(np.int32), dtype=wp.int32, device=points.device)

    def _split_bodies(self) -> list:
        """Per body: its :class:`SplitBody` on the current vertices and element corners (what the kinematics read
        from the bodies after fracture split their vertices)."""
        faces, fid = self._boundary_faces_h()
        original = np.isin(fid, self.model.surface_face_ids)
        face_body = self.element_body[fid // 4]
        proxies = []
        for i, b in enumerate(self.bodies):
            lo, hi = np.searchsorted(self._vertex_body_h, [i, i + 1])
            mine = original & (face_body == i)
            proxies.append(SplitBody(b, self._rest_h[lo:hi], faces[mine] - lo, self._point_condition_h[lo:hi].copy()))
        return proxies


__all__ = ["GRIFFITH_ROUNDS", "FemFractureEvents", "SplitBody"]

"""Contact between mesh surfaces (FEM-FEM: two bodies, or the pieces of a cracked body), the part of
:class:`pdsim.contact.MethodContact` that pairs the surface vertices of each mesh solver with the faces of the other
pieces (kernels/surface_contact.py): the pairs' forces within the step, and after it the hard floor on the pairs
found deeper than SURFACE_FLOOR.
"""

from __future__ import annotations

import warp as wp

from .kernels import surface_contact as ksf

SURFACE_FLOOR = 0.01
"""Depth of the hard floor of contact between FEM surfaces (kernels/surface_contact.py) as a fraction of the contact
band (one mean edge length): a surface vertex deeper than 1 % of an edge inside another piece loses, after the step's
kicks, the approach the next drift would carry (an inelastic impulse), so it sinks no deeper while the penalty of the
one law pushes it out; above that depth the penalty acts alone."""

PIECE_BOUNDS_MAX = 64
"""Contact between FEM surfaces skips the search of a surface vertex whose neighbourhood meets the bounds of no other
piece (kernels/surface_contact.py, near_foreign_piece) while the mesh has at most this many pieces. The test loops
over the pieces for every vertex: with the hundreds of pieces of a shattered body that loop would be the cost, so
above this count every vertex is searched (a bound chosen, not measured)."""

SURFACE_FLOOR_ITERATIONS = 4
"""Passes of the hard floor of contact between FEM surfaces per step (MethodContact.end_step): each pass divides a
pair's impulse by the largest share of floor pairs among its points (kernels/surface_contact.py
surface_floor_count), so pairs that share points (the two orders of a face-to-face contact) do not add up their
corrections; the passes converge on the correction of all pairs together (4 and 8 passes part the two FEM cubes of
tests/test_fem_contact.py's head-on collision at the same speed within 2e-4 of the approach speed)."""


class SurfacePairs:
    """The surface pairs of :class:`pdsim.contact.MethodContact` (a mixin: it reads the contact's settings
    ``damping_ratio``, ``friction``, ``step_safety`` and ``surfaces``, its caches ``_scratch`` and ``_meshes`` and
    its per-solver helpers ``_mesh``, ``_side``, ``_force_scale`` and ``_work_account``)."""

    def end_step(self, dt: float) -> None:
        """The hard floor of the surface contact (kernels/surface_contact.py, surface_floor_impulse) on the pairs the
        last :meth:`apply` found deeper than SURFACE_FLOOR, with the velocities and accelerations of the step's end
        (after every solver's ``end_step``; step length ``dt`` [s]). Where a solver's topology changed in its
        ``end_step`` (an FEM fracture split), the pairs' points are carried to its new numbering
        (``points_in_current_numbering`` of the mesh solvers). On the CPU, a pair of solvers with no pair deeper than
        the floor launches nothing (the passes would change nothing); on a GPU every pass runs, since telling would
        take a read from the device every step."""
        if not self.surfaces:
            return
        pairs = []
        for a in self.mesh_solvers:
            for b in self.mesh_solvers:
                entry = self._scratch.get(("pairs", id(a), id(b)))
                if entry is None or (a.kin.u.device.is_cpu and not (entry[1].numpy() >= 0).any()):
                    continue  # no pair deeper than the floor (read where it costs nothing: host memory)
                _, a_points, _, _, _ = self._meshes[id(a)]
                _, b_points, b_faces, _, _ = self._meshes[id(b)]
                a_points = a.points_in_current_numbering(entry[0][0], a_points)
                b_points = b.points_in_current_numbering(entry[0][1], b_points)
                if a_points is None or b_points is None:
                    continue
                common = {"pair_face": entry[1], "pair_weights": entry[2], "v_points": a_points, "m_points": b_points}
                pairs.append((a, b, dict(common, m_faces=b_faces, device=a.kin.u.device), entry[3]))
        for a, b, common, _ in pairs:
            ksf.floor_counts(v_count=self._floor(a)[1], m_count=self._floor(b)[1], **common)
        touched = []
        for a, b, _, _ in pairs:
            touched += [s for s in (a, b) if all(s is not t for t in touched)]
        for _ in range(SURFACE_FLOOR_ITERATIONS):
            for a, b, common, pair_normal in pairs:
                ksf.floor_impulses(
                    pair_normal=pair_normal,
                    v_v=a.kin.v,
                    v_a=a.kin.a,
                    v_mass=a.kin.mass,
                    v_kind=a.kin.point_kind,
                    m_v=b.kin.v,
                    m_a=b.kin.a,
                    m_mass=b.kin.mass,
                    m_kind=b.kin.point_kind,
                    dt=dt,
                    v_count=self._floor(a)[1],
                    m_count=self._floor(b)[1],
                    v_kick=self._floor(a)[0],
                    m_kick=self._floor(b)[0],
                    **common,
                )
            for ms in touched:
                ksf.apply_floor(kick=self._floor(ms)[0], velocities=ms.kin.v, device=ms.kin.u.device)
        for ms in touched:
            self._floor(ms)[1].zero_()

    def _pairs(self, a, b, count: int):
        """The floor's pairs of the vertices of mesh solver ``a`` against the faces of ``b`` (face, barycentric
        weights, normal per surface vertex of ``a``: kernels/surface_contact.py vertex_face_contact), tagged with
        both solvers' topology versions; reallocated when the vertex count changes."""
        key = ("pairs", id(a), id(b))
        entry = self._scratch.get(key)
        versions = (self._meshes[id(a)][0], self._meshes[id(b)][0])
        if entry is None or entry[1].shape[0] != count:
            d = a.kin.u.device
            entry = [
                versions,
                wp.full(count, -1, dtype=wp.int32, device=d),
                wp.zeros(count, dtype=wp.vec3, device=d),
                wp.zeros(count, dtype=wp.vec3, device=d),
            ]
            self._scratch[key] = entry
        entry[0] = versions
        return entry

    def _floor(self, solver):
        """The solver's accumulators of the surface contact's hard floor (kernels/surface_contact.py): the velocity
        change [m/s] and the share of floor pairs per point, zero between steps; reallocated when the point count
        changes (FEM fracture adds vertices)."""
        key = ("floor", id(solver))
        entry = self._scratch.get(key)
        n = solver.kin.u.shape[0]
        if entry is None or entry[0].shape[0] != n:
            d = solver.kin.u.device
            entry = (wp.zeros(n, dtype=wp.vec3, device=d), wp.zeros(n, dtype=float, device=d))
            self._scratch[key] = entry
        return entry

    def _surface_pair(self, a, b, rate: float, dt: float) -> None:
        """The surface vertices of mesh solver ``a`` against the faces of ``b`` (of other pieces when a is b; nothing
        to do, and no launch, while ``a`` is one piece)."""
        if a is b and a.contact_piece_count() < 2:
            self._scratch.pop(("pairs", id(a), id(a)), None)  # no floor pairs this step
            return
        _, a_points, _, _, _ = self._mesh(a)
        _, b_points, b_faces, b_x, b_mesh = self._mesh(b)
        a_label, _ = a.contact_pieces()
        b_vertex_label, b_label = b.contact_pieces()
        if a is not b:  # labels of different solvers never match
            a_label = self._foreign_label(a_label)
        skin_a, band_a = a.contact_skin()
        skin_b, band_b = b.contact_skin()
        v_damping, v_friction = self._side(a)
        m_damping, m_friction = self._side(b)
        _, pair_face, pair_weights, pair_normal = self._pairs(a, b, a_points.shape[0])
        piece_lo, piece_hi, piece_count = self._piece_bounds(b, b_x, b_vertex_label)
        ksf.vertex_face_forces(
            v_points=a_points,
            v_label=a_label,
            v_rest=a.kin.rest,
            v_u=a.kin.u,
            v_v=a.kin.v,
            v_mass=a.kin.mass,
            v_to_force=self._force_scale(a),
            mesh=b_mesh.id,
            m_x=b_x,
            m_points=b_points,
            m_faces=b_faces,
            m_label=b_label,
            m_v=b.kin.v,
            m_mass=b.kin.mass,
            m_to_force=self._force_scale(b),
            skin=min(skin_a, skin_b),
            band=min(band_a, band_b),
            stiffness_rate=rate,
            damping_ratio=self.damping_ratio,
            friction=self.friction,
            v_damping_ratio=v_damping,
            v_friction=v_friction,
            m_damping_ratio=m_damping,
            m_friction=m_friction,
            v_force=a.force,
            m_force=b.force,
            dt=dt,
            v_work=self._work_account(a),
            m_work=self._work_account(b),
            floor=SURFACE_FLOOR * min(band_a, band_b),
            pair_face=pair_face,
            pair_weights=pair_weights,
            pair_normal=pair_normal,
            v_step=a.contact_steps(),
            m_step=b.contact_steps(),
            step_safety=self.step_safety,
            piece_lo=piece_lo,
            piece_hi=piece_hi,
            piece_count=piece_count,
            device=a.kin.u.device,
        )

    def _piece_bounds(self, solver, positions, labels):
        """(lower, upper bounds of each piece of the solver's contact mesh at its vertices' ``positions`` with their
        piece ``labels``, the piece count) for the surface contact's skip of vertices near no other piece
        (kernels/surface_contact.py, piece_bounds); a count of 0 (no skip) above PIECE_BOUNDS_MAX pieces."""
        count = solver.contact_piece_count()
        key = ("bounds", id(solver))
        entry = self._scratch.get(key)
        if entry is None or entry[0].shape[0] != max(count, 1):
            d = positions.device
            entry = (wp.zeros(max(count, 1), dtype=wp.vec3, device=d), wp.zeros(max(count, 1), dtype=wp.vec3, device=d))
            self._scratch[key] = entry
        if count > PIECE_BOUNDS_MAX:
            return entry[0], entry[1], 0
        ksf.bounds_of_pieces(
            m_x=positions, m_label=labels, piece_lo=entry[0], piece_hi=entry[1], device=positions.device
        )
        return entry[0], entry[1], count

    def _foreign_label(self, labels):
        """Labels that match no face label (-1 everywhere), the size of ``labels``."""
        key = ("foreign", labels.shape[0])
        out = self._scratch.get(key)
        if out is None:
            out = wp.full(labels.shape[0], -1, dtype=wp.int32, device=labels.device)
            self._scratch[key] = out
        return out


__all__ = ["PIECE_BOUNDS_MAX", "SURFACE_FLOOR", "SURFACE_FLOOR_ITERATIONS", "SurfacePairs"]

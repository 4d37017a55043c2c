"""Checkpoint and restore of the tetrahedral FEM solver (:class:`pdsim.fem.solver.SolverFem`): the shared kinematics,
the element state and, after fracture, the topology, so that a restored run continues bit for bit.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..errors import ParameterError
from ..solver import array_state, assign_state


class FemCheckpoint:
    """:meth:`checkpoint` and :meth:`restore` of :class:`pdsim.fem.solver.SolverFem` (a mixin: they read and replace
    the solver's topology arrays, element state and kinematics; the split bodies come from
    :class:`pdsim.fem.fracture_events.FemFractureEvents`)."""

    def checkpoint(self) -> dict:
        """The state to continue this run exactly (pdsim.solver.Solver.checkpoint): the shared kinematics, the element
        state (rotations, plastic strains, principal stresses) and, after fracture, the topology (split vertices,
        element corners, retired strengths, versions)."""
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
            self._build_vertex_data(self._split_bodies())
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
        self._contact_pieces = None
        self._smooth_surfaces = self._new_smooth_surfaces()  # drawn again from the restored topology


__all__ = ["FemCheckpoint"]

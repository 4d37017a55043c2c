"""Method-neutral views of a solver's state, the only thing the output writer sees.

Every solver returns, once a frame, a list of views: :class:`PointsView` (points with named per-point attributes) and
:class:`MeshView` (a triangle surface with a topology version and per-face attributes). Attribute names mean the
same in every method (``ATTRIBUTES``); a solver writes the ones its live features define and no others. Colliders
(the ground plane, static meshes, projectiles) give a :class:`RigidView` each: a mesh in its body frame and a pose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np

ATTRIBUTES = {
    # name: (kind, meaning)
    "displacement": ("vector3f", "displacement from the rest position [m]"),
    "damage": ("float", "broken share of a point's bonds or elements [-], 0 intact, 1 detached"),
    "fragment": ("int", "fragment (connected piece) id, stable over the animation"),
    "plastic_strain": ("float", "equivalent plastic strain [-]"),
    "dilatation": ("float", "volumetric strain [-]"),
    "crack": ("int", "1 on faces created by fracture, 0 on the input surface"),
    "kind": ("int", "lattice point kind (follower, leader, frame, fictitious)"),
    "pe1": ("float", "lattice pseudo-energy PE1 [m^2]"),
    "pe2": ("float", "lattice pseudo-energy PE2 [m]"),
    "pe1_intact": ("float", "lattice PE1 over intact links [m^2]"),
    "broken_links": ("int", "lattice links lost by a point"),
}


def attribute_kind(name: str) -> str:
    """USD primvar kind ("float", "int", "vector3f") of a shared attribute name."""
    try:
        return ATTRIBUTES[name][0]
    except KeyError:
        raise KeyError(
            f"attribute {name!r} is not a shared output attribute ({', '.join(sorted(ATTRIBUTES))})"
        ) from None


@dataclass
class PointsView:
    """Points of one body at one frame.

    name: the body's name (the prim name). positions: world positions [m], float64 [n, 3]. velocities: [m/s],
    float64 [n, 3]. widths: point diameters [m], [n]. attributes: {shared name: values [n] or [n, 3]}.
    reactions: {boundary condition name: force [N] it exerts on the body, float64 [3]} (written as the custom
    attributes ``pdsim:reaction:<name>``)."""

    name: str
    positions: np.ndarray
    velocities: np.ndarray
    widths: np.ndarray
    attributes: dict = field(default_factory=dict)
    reactions: dict = field(default_factory=dict)


@dataclass
class MeshView:
    """A triangle surface of one body at one frame.

    name: prim name (``<body>_surface`` for a body's surface). points: world vertex positions [m], float64 [v, 3].
    velocities: vertex velocities [m/s], float64 [v, 3], or None. topology_version: an integer that changes exactly
    when ``faces`` or the vertex count changes. faces: triangles, int [f, 3], wound counter-clockwise seen from
    outside. face_attributes: {shared name: [f]} (``crack`` marks the faces made by fracture, ``fragment`` the piece
    of each face). vertex_attributes: {shared name: [v] or [v, 3]}, optional per-vertex values (e.g. the damage of the
    particle a vertex follows), written as vertex primvars."""

    name: str
    points: np.ndarray
    velocities: np.ndarray | None
    topology_version: int
    faces: np.ndarray
    face_attributes: dict = field(default_factory=dict)
    vertex_attributes: dict = field(default_factory=dict)


@dataclass
class EventsView:
    """The crack events of one body in one frame: one row per bond (or link) that broke during the frame.

    name: the body's name (the prim is ``/World/<name>_crack_events``). positions: world positions of the broken bonds'
    midpoints at the frame's end [m], float64 [m, 3]. normals: unit directions of the bonds when they broke (the normal
    of the crack face they open), float [m, 3]. energies: elastic energy each bond held when it broke, released by
    the break [J], float [m]. origin: a point near the body [m] (float64 [3]; the solver's frame origin), the prim's
    static translate the positions are stored relative to."""

    name: str
    positions: np.ndarray
    normals: np.ndarray
    energies: np.ndarray
    origin: np.ndarray


@dataclass
class RigidView:
    """A rigid body of the scene (ground plane, static mesh collider, projectile, dynamic rigid body, a rigid piece of
    a peridynamic body) at one frame.

    name: prim name. points: vertices in the body frame [m], float64 [v, 3]. faces: triangles, int [f, 3], wound
    counter-clockwise seen from outside. translation: world position of the body frame's origin [m], float64 [3].
    orientation: rotation of the body frame, unit quaternion (x, y, z, w), float64 [4]; a world point is
    ``translation + rotate(orientation, point)``. static: True when the pose never changes (written once).
    group: the prim under ``/World`` that holds the body (``"colliders"``; ``"<body>_pieces"`` for the rigid pieces
    of a body), or None for ``/World`` itself (the ground). The geometry (points, faces) must be the same on every
    frame; a body first seen after the cache's first frame is hidden before it. velocity [m/s] of the body frame's
    origin and angular_velocity [rad/s] (world axes), float64 [3] each: a dynamic rigid body's or a rigid piece's
    (written as ``pdsim:velocity`` and ``pdsim:angularVelocity``), None for the others. face_attributes: {shared
    name: [f]}, static (a rigid piece's ``crack`` and ``fragment``, written with the mesh as for a surface)."""

    name: str
    points: np.ndarray
    faces: np.ndarray
    translation: np.ndarray
    orientation: np.ndarray
    static: bool = False
    group: str | None = "colliders"
    velocity: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    face_attributes: dict = field(default_factory=dict)


@dataclass
class DeferredView:
    """A view whose values are computed later, possibly on another thread: ``build()`` returns it (a
    :class:`MeshView`), or a list of views (a body's surface and the rigid pieces cut from it). ``build`` holds
    copies of the state it needs, never the solver's live arrays, so the solver may advance before it runs. name: the
    prim name of the view it builds (the first one of a list)."""

    name: str
    build: Callable[[], MeshView]


def _copied(value):
    """``value`` with every numpy array in it (also inside a dict) copied."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, dict):
        return {k: _copied(v) for k, v in value.items()}
    return value


def copied_view(view):
    """``view`` (a PointsView, MeshView or RigidView) with copies of its arrays, so that it keeps the values of now
    while the solver advances (a solver's arrays may be views of its live state); a DeferredView as it is (it holds
    copies already)."""
    if isinstance(view, DeferredView):
        return view
    return replace(view, **{f.name: _copied(getattr(view, f.name)) for f in fields(view)})


def resolve_views(views) -> list:
    """``views`` with every :class:`DeferredView` replaced by the view (or, in order, the views) it builds, in the
    calling thread."""
    out = []
    for v in views:
        built = v.build() if isinstance(v, DeferredView) else v
        out.extend(built if isinstance(built, list) else [built])
    return out


__all__ = [
    "ATTRIBUTES",
    "DeferredView",
    "EventsView",
    "MeshView",
    "PointsView",
    "RigidView",
    "attribute_kind",
    "copied_view",
    "resolve_views",
]

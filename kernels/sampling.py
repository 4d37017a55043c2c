"""Kernels that sample solids: exact inside tests against a closed triangle mesh."""

import warp as wp

from .launch import launch


@wp.kernel
def mark_points_inside_mesh(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_dist: float,
    inside: wp.array(dtype=wp.int32),
):
    """inside[i] = 1 when points[i] lies strictly inside the closed mesh (generalised winding number > 0.5; the mesh
    must be built with support_winding_number=True)."""
    i = wp.tid()
    q = wp.mesh_query_point_sign_winding_number(mesh, points[i], max_dist, 2.0, 0.5)  # accuracy 2, threshold 0.5
    inside[i] = 0
    if q.result:
        if q.sign < 0.0:
            inside[i] = 1


def points_inside_mesh(mesh: wp.Mesh, points: wp.array, max_dist: float) -> wp.array:
    """Launches :func:`mark_points_inside_mesh` over ``points`` (on the mesh's device); returns the int32 mask."""
    inside = wp.zeros(points.shape[0], dtype=wp.int32, device=points.device)
    wp.launch(
        mark_points_inside_mesh, dim=points.shape[0], inputs=[mesh.id, points, max_dist, inside], device=points.device
    )
    return inside


@wp.kernel
def signed_distance_winding(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_dist: float,
    distance: wp.array(dtype=float),
):
    """distance[i] = distance [m] from points[i] to the nearest triangle, negative inside (generalised winding number
    > 0.5; the mesh must be built with support_winding_number=True; max_dist where no triangle is within max_dist)."""
    i = wp.tid()
    q = wp.mesh_query_point_sign_winding_number(mesh, points[i], max_dist, 2.0, 0.5)  # accuracy 2, threshold 0.5
    distance[i] = max_dist
    if q.result:
        closest = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        distance[i] = q.sign * wp.length(points[i] - closest)


def winding_signed_distance(mesh: wp.Mesh, points: wp.array, max_dist: float) -> wp.array:
    """Launches :func:`signed_distance_winding` over ``points`` (on the mesh's device); returns the float32 distances
    [m] (negative inside)."""
    distance = wp.zeros(points.shape[0], dtype=float, device=points.device)
    launch(
        signed_distance_winding, points.shape[0], device=points.device,
        mesh=mesh.id, points=points, max_dist=max_dist, distance=distance,
    )  # fmt: skip
    return distance

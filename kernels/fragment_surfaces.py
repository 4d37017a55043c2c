"""Kernels for fragment surfaces (pdsim/fragment_surfaces/regions.py): signed distances of points to a closed mesh,
and their nearest points on it."""

import warp as wp


@wp.kernel
def closest_point_on_solid(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_dist: float,
    distance: wp.array(dtype=float),
    closest: wp.array(dtype=wp.vec3),
):
    """distance[i] = distance [m] of points[i] [m] to the closed mesh's surface, negative inside (the side by
    ``wp.mesh_query_point``: the orientation of the nearest face hit by three axis-aligned rays, a majority vote, exact
    on a closed surface), and closest[i] = the point [m] of that surface nearest points[i] (points[i] itself where the
    query finds none). ``max_dist`` [m] must exceed every point's distance to the mesh."""
    i = wp.tid()
    p = points[i]
    q = wp.mesh_query_point(mesh, p, max_dist)
    distance[i] = max_dist
    closest[i] = p
    if q.result:
        c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        distance[i] = q.sign * wp.length(c - p)
        closest[i] = c


def closest_points(mesh_id, points, max_dist: float, distance, closest):
    """Launches :func:`closest_point_on_solid` over ``points`` (vec3 [n]) on the current device: signed distance [m]
    float [n] (negative inside) and the nearest surface point [m] vec3 [n] of each point to the closed mesh
    ``mesh_id`` (a wp.Mesh id)."""
    wp.launch(closest_point_on_solid, dim=len(points), inputs=[mesh_id, points, max_dist, distance, closest])

"""Kernels for fragment surfaces (pdsim/fragment_surfaces.py): which lattice points lie near a closed triangle mesh."""

import warp as wp


@wp.kernel
def mark_points_near_solid(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_dist: float,
    radius: float,
    near: wp.array(dtype=wp.int32),
):
    """near[i] = 1 when points[i] [m] lies inside the closed mesh (generalised winding number > 0.5) or within
    ``radius`` [m] of its surface; 0 otherwise. ``max_dist`` [m] must exceed every point's distance to the mesh."""
    i = wp.tid()
    p = points[i]
    q = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist, 0.5, 2.0)
    near[i] = 0
    if q.result:
        dist = wp.length(wp.mesh_eval_position(mesh, q.face, q.u, q.v) - p)
        if q.sign < 0.0 or dist <= radius:
            near[i] = 1

"""Preview renderer kernels (pdsim/preview/render.py): one primary ray per pixel against a triangle BVH, Lambert +
ambient shading from one key light, shadow rays, and an infinite ground plane that fades into the background.

Coordinates are the renderer's frame: world positions [m] minus a fixed origin near the scene (so float32 keeps
sub-millimetre precision far from the world origin). The BVH (a ``wp.Mesh``) holds the surface triangles first
(indices ``0 .. surface_tris - 1``) and then ``tris_per_sphere`` triangles per point sphere (instanced icospheres).
"""

import warp as wp


@wp.func
def shade(
    albedo: wp.vec3,
    n: wp.vec3,
    light: wp.vec3,
    fill: wp.vec3,
    world_up: wp.vec3,
    ambient: float,
    lit: float,
):
    """Lambert shading with a hemispherical ambient, a key light and an unshadowed fill light of a quarter of the key's
    strength: albedo * (ambient (0.65 + 0.35 n.up) + (1 - ambient) (max(n.L, 0) lit + 0.25 max(n.F, 0))).
    All vectors unit length; lit in [0, 1] (0 in the key light's shadow). (Mirrored by ``_ground_albedo`` in
    pdsim/preview/render.py.)"""
    sky = ambient * (0.65 + 0.35 * wp.dot(n, world_up))
    key = (1.0 - ambient) * (wp.max(wp.dot(n, light), 0.0) * lit + 0.25 * wp.max(wp.dot(n, fill), 0.0))
    return albedo * (sky + key)


@wp.kernel
def render_preview(
    mesh: wp.uint64,
    has_mesh: int,
    surface_tris: int,
    tris_per_sphere: int,
    corner_colors: wp.array(dtype=wp.vec3),
    corner_normals: wp.array(dtype=wp.vec3),
    sphere_centers: wp.array(dtype=wp.vec3),
    sphere_colors: wp.array(dtype=wp.vec3),
    eye: wp.vec3,
    forward: wp.vec3,
    right: wp.vec3,
    up: wp.vec3,
    tan_x: float,
    tan_y: float,
    light: wp.vec3,
    fill: wp.vec3,
    world_up: wp.vec3,
    ambient: float,
    shadows: int,
    ground: int,
    ground_offset: float,
    ground_center: wp.vec3,
    ground_fade: float,
    ground_color: wp.vec3,
    background: wp.vec3,
    eps: float,
    max_t: float,
    image: wp.array2d(dtype=wp.vec3),
    coverage: wp.array2d(dtype=wp.int32),
):
    """Renders one pixel (row i from the top, column j from the left) of a pinhole camera at ``eye`` looking along
    ``forward`` (unit), with image-plane axes ``right`` and ``up`` (unit) and half-extents ``tan_x``, ``tan_y`` at
    unit distance.

    ``light`` and ``fill`` are unit directions towards the key and fill lights (see ``shade``); ``ambient`` the
    ambient share. Surface triangle t has per-corner linear colours ``corner_colors[3t + k]`` and shading normals
    ``corner_normals[3t + k]`` (zero: the face normal; interpolated with the hit's barycentrics u, v:
    u p0 + v p1 + (1 - u - v) p2); sphere triangle t belongs to sphere s = (t - surface_tris) / tris_per_sphere,
    shaded with the exact sphere normal about ``sphere_centers[s]`` and the colour ``sphere_colors[s]``. Surfaces are
    two-sided. With ``shadows`` = 0 no shadow rays are cast; with ``ground`` = 0 there is no ground. The ground is the
    plane
    world_up . x = ground_offset, seen from above only; its colour fades into ``background`` as
    exp(-(d / ground_fade)^2) with the distance d from ``ground_center``. Shadow rays start ``eps`` [m] off the
    surface along the geometric normal and reach ``max_t`` [m].

    Writes the linear colour to ``image[i, j]`` and 1 to ``coverage[i, j]`` where a surface or sphere was hit
    (0 for ground and background).
    """
    i, j = wp.tid()
    height = image.shape[0]
    width = image.shape[1]
    x = (2.0 * (float(j) + 0.5) / float(width) - 1.0) * tan_x
    y = (1.0 - 2.0 * (float(i) + 0.5) / float(height)) * tan_y
    d = wp.normalize(forward + x * right + y * up)

    t_hit = max_t
    hit = bool(False)
    face = int(0)
    bu = float(0.0)
    bv = float(0.0)
    n_geo = wp.vec3(0.0, 0.0, 1.0)
    if has_mesh != 0:
        q = wp.mesh_query_ray(mesh, eye, d, max_t)
        if q.result:
            hit = True
            t_hit = q.t
            face = q.face
            bu = q.u
            bv = q.v
            n_geo = q.normal

    t_ground = max_t
    if ground != 0:
        dn = wp.dot(d, world_up)
        if dn < 0.0:
            t_ground = (ground_offset - wp.dot(eye, world_up)) / dn
            if t_ground < 0.0:
                t_ground = max_t

    color = background
    coverage[i, j] = 0
    if hit and t_hit <= t_ground:
        p = eye + t_hit * d
        if wp.dot(n_geo, d) > 0.0:
            n_geo = -n_geo
        albedo = wp.vec3(0.0)
        n = n_geo
        if face < surface_tris:
            bw = 1.0 - bu - bv
            albedo = bu * corner_colors[3 * face] + bv * corner_colors[3 * face + 1] + bw * corner_colors[3 * face + 2]
            ns = bu * corner_normals[3 * face] + bv * corner_normals[3 * face + 1] + bw * corner_normals[3 * face + 2]
            if wp.length(ns) > 1.0e-12:
                n = wp.normalize(ns)
                if wp.dot(n, d) > 0.0:
                    n = -n
        else:
            s = (face - surface_tris) / tris_per_sphere
            albedo = sphere_colors[s]
            n = wp.normalize(p - sphere_centers[s])
            if wp.dot(n, d) > 0.0:
                n = n_geo
        lit = float(1.0)
        if shadows != 0 and wp.dot(n_geo, light) > 0.0:
            sq = wp.mesh_query_ray(mesh, p + eps * n_geo, light, max_t)
            if sq.result:
                lit = 0.0
        color = shade(albedo, n, light, fill, world_up, ambient, lit)
        coverage[i, j] = 1
    elif t_ground < max_t:
        p = eye + t_ground * d
        lit = float(1.0)
        if shadows != 0 and has_mesh != 0:
            sq = wp.mesh_query_ray(mesh, p + eps * world_up, light, max_t)
            if sq.result:
                lit = 0.0
        g = shade(ground_color, world_up, light, fill, world_up, ambient, lit)
        r = wp.length(p - ground_center) / ground_fade
        f = wp.exp(-r * r)
        color = f * g + (1.0 - f) * background
    image[i, j] = color


def render_image(inputs: list, image, coverage, device) -> None:
    """Launch ``render_preview`` over every pixel of ``image`` (dim = image.shape = (height, width)) on ``device``.
    ``inputs``: the kernel's inputs in its order, ``mesh`` to ``max_t``; ``image`` and ``coverage`` its outputs."""
    wp.launch(render_preview, dim=image.shape, inputs=inputs, outputs=[image, coverage], device=device)

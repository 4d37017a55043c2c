"""Rendering a USD cache: the per-frame BVH of surfaces and instanced point spheres, the camera and lights, and the
images written as PNG, GIF or MP4 (:func:`render_cache`, :func:`write_preview`)."""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import imageio.v2 as iio2
import imageio.v3 as iio
import numpy as np
import warp as wp

from ..errors import ParameterError
from ..kernels.preview import render_image
from .camera import Camera, camera_from_spec, direction, horizontal_axes
from .colors import AMBIENT, BACKGROUND, Coloring, linear
from .options import FIT_MODES, FIT_REACH, SUFFIXES, parse_frames, parse_size
from .reader import FrameGeometry, StageReader

BVH_CONSTRUCTOR = "sah"  # Warp's BVH builder for the per-frame wp.Mesh (see docs/preview.md for the measurements)


def _icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices float64 [v, 3] on the unit sphere and outward triangles int32 [t, 3]
    (level 0: 12 vertices, 20 triangles; each level quadruples the triangles)."""
    g = (1.0 + math.sqrt(5.0)) / 2.0
    v = [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g]]
    v += [[0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6]]
    f += [[7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10]]
    f += [[8, 6, 7], [9, 8, 1]]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in v]
    faces = f
    for _ in range(level):
        mid = {}

        def midpoint(a, b, mid=mid):
            key = (min(a, b), max(a, b))
            if key not in mid:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                mid[key] = len(verts) - 1
            return mid[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = new
    return np.array(verts), np.array(faces, dtype=np.int32)


@dataclass
class PreviewResult:
    """What :func:`render_cache` rendered.

    Attributes:
        images: one uint8 [height, width, 3] sRGB image per frame.
        frames: the frame numbers (time codes) rendered.
        camera: the camera used.
        bounds: (lo, hi) [m], the box of the geometry the camera was fitted to (``fit``), float64 [3] each.
        coverage: one bool [height, width] mask per frame, True where a surface or point was hit.
        color_range: (lo, hi) of the ramp for a float ``color`` attribute, else None.
        seconds: wall time per frame [s] (reading, BVH build and rendering).
        fps: the stage's frames per second.
    """

    images: list
    frames: list
    camera: Camera
    bounds: tuple
    coverage: list
    color_range: tuple | None
    seconds: list
    fps: float


class _Renderer:
    """Builds the BVH of a frame and launches the ray-cast kernel (Warp, CPU or CUDA)."""

    def __init__(self, device: str):
        self.device = device
        self.bvh_constructor = BVH_CONSTRUCTOR
        self._ico = {level: _icosphere(level) for level in (0, 1)}

    def render(
        self, geo: FrameGeometry, camera: Camera, origin, *, ground, ground_center, fade, light, fill, shadows, ss, eps
    ):
        """Renders one frame: sRGB uint8 [H, W, 3] and the coverage mask bool [H, W]. ``origin`` [m] is subtracted
        from all positions before they go to float32; ``ground`` is the ground height [m] along the up axis (None: no
        ground); ``fade`` [m] the ground's fade distance; ``light`` and ``fill`` the unit directions towards the key
        and fill lights; ``shadows`` whether shadow rays are cast; ``ss`` the supersampling factor; ``eps`` [m] the
        shadow-ray offset."""
        surf_points = [p - origin for p in geo.surf_points]
        offsets = np.cumsum([0] + [len(p) for p in surf_points])
        tris = [t + o for t, o in zip(geo.surf_tris, offsets)]
        n_surf_tris = int(sum(len(t) for t in tris))
        centers = np.concatenate(geo.centers) - origin if geo.centers else np.zeros((0, 3))
        radii = np.concatenate(geo.radii) if geo.radii else np.zeros(0)
        colors = np.concatenate(geo.colors) if geo.colors else np.zeros((0, 3), np.float32)
        level = 1 if len(centers) <= 20000 else 0
        iv, it = self._ico[level]
        # instanced icospheres, circumscribing each sphere by the mean of inscribed and circumscribed radius
        inflate = 1.0 / (0.5 * (1.0 + _inradius(iv, it)))
        sphere_points = (centers[:, None, :] + (radii * inflate)[:, None, None] * iv[None]).reshape(-1, 3)
        sphere_tris = (it[None] + (offsets[-1] + len(iv) * np.arange(len(centers)))[:, None, None]).reshape(-1, 3)
        points = np.concatenate([*surf_points, sphere_points]).astype(np.float32)
        indices = np.concatenate([*tris, sphere_tris]).astype(np.int32).ravel() if len(points) else np.zeros(0, int)
        dev = self.device
        width, height = camera.width * ss, camera.height * ss
        has_mesh = int(len(indices) > 0)
        mesh = None
        if has_mesh:
            mesh = wp.Mesh(
                points=wp.array(points, dtype=wp.vec3, device=dev),
                indices=wp.array(indices, dtype=wp.int32, device=dev),
                bvh_constructor=self.bvh_constructor,
            )
        corner_colors = np.concatenate(geo.surf_colors).reshape(-1, 3) if geo.surf_colors else np.zeros((1, 3))
        corner_normals = np.concatenate(geo.surf_normals).reshape(-1, 3) if geo.surf_normals else np.zeros((1, 3))
        f, r, u = camera.basis()
        tx, ty = camera.tan_half
        image = wp.zeros((height, width), dtype=wp.vec3, device=dev)
        coverage = wp.zeros((height, width), dtype=wp.int32, device=dev)

        def arr(a):
            a = np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3)
            return wp.array(a if len(a) else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=dev)

        up = camera.up
        ground_on, ground_offset = (0, 0.0) if ground is None else (1, float(ground - origin @ up))
        eye = camera.eye - origin
        if ground_on and (eye @ up) < ground_offset:
            ground_on = 0  # looking from below the ground: leave it out
        far = float(1.0e3 * (fade + np.linalg.norm(eye)) + 1.0)
        # a shadow catcher: the lit ground shades to exactly the background colour, so only shadows show on it
        ground_albedo = linear(BACKGROUND) / _ground_albedo(light, fill, up)
        render_image(
            [
                mesh.id if mesh is not None else wp.uint64(0),
                has_mesh,
                n_surf_tris,
                len(it),
                arr(corner_colors),
                arr(corner_normals),
                arr(centers),
                arr(colors),
                wp.vec3(*eye),
                wp.vec3(*f),
                wp.vec3(*r),
                wp.vec3(*u),
                float(tx),
                float(ty),
                wp.vec3(*light),
                wp.vec3(*fill),
                wp.vec3(*up),
                AMBIENT,
                int(bool(shadows)),
                ground_on,
                ground_offset,
                wp.vec3(*(ground_center - origin)),
                float(fade),
                wp.vec3(*ground_albedo),
                wp.vec3(*linear(BACKGROUND)),
                float(eps),
                far,
            ],
            image,
            coverage,
            dev,
        )
        img = image.numpy()
        cov = coverage.numpy().astype(bool)
        if ss > 1:
            img = img.reshape(camera.height, ss, camera.width, ss, 3).mean(axis=(1, 3))
            cov = cov.reshape(camera.height, ss, camera.width, ss).any(axis=(1, 3))
        srgb = np.power(np.clip(img, 0.0, 1.0), 1.0 / 2.2)
        return (srgb * 255.0 + 0.5).astype(np.uint8), cov


def _ground_albedo(light: np.ndarray, fill: np.ndarray, up: np.ndarray) -> float:
    """The shading factor of a lit, upward-facing surface (kernels/preview.py ``shade`` with n = up, lit = 1). It
    repeats ``shade``'s arithmetic on the host, once per frame, since a ``wp.func`` cannot be called from Python."""
    return AMBIENT + (1.0 - AMBIENT) * (max(float(light @ up), 0.0) + 0.25 * max(float(fill @ up), 0.0))


def _inradius(verts: np.ndarray, tris: np.ndarray) -> float:
    """Smallest distance from the centre to a face plane of a unit icosphere (its inscribed radius)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    n = np.cross(b - a, c - a)
    return float(np.min(np.abs(np.einsum("ij,ij->i", n, a)) / np.linalg.norm(n, axis=1)))


def render_cache(
    cache: str | os.PathLike,
    frames: str | list[int] | None = None,
    *,
    color: str | None = None,
    camera: str | Camera | None = None,
    size: str | tuple[int, int] | None = (640, 480),
    ground: bool = True,
    shadows: bool = True,
    supersample: int = 1,
    categorical: bool | None = None,
    points: str = "auto",
    fit: str = "auto",
    default_frames: str = "all",
    device: str = "cpu",
) -> PreviewResult:
    """Renders frames of a USD cache to images.

    Args:
        cache: path of a USD file (.usd, .usda, .usdc), opened with ``Usd.Stage.Open``.
        frames: a ``--frames`` spec (see :func:`parse_frames`), a list of frame numbers, or None (``default_frames``:
            "all" or "last").
        color: primvar to colour by (see the module docstring); None: displayColor / neutral with crack faces.
        camera: a ``--camera`` spec (see :func:`camera_from_spec`) or a :class:`Camera` (its size wins over ``size``).
        size: image size (width, height) [pixels] or "WxH".
        ground: draw the ground plane (with shadows) at the lowest point of the geometry.
        shadows: cast shadow rays.
        supersample: rays per pixel along each axis (1..4; 2 gives 4 rays per pixel, box-filtered).
        categorical: colour ``color`` by a palette (True) or a ramp (False); None: palette for integer primvars.
        points: which ``UsdGeom.Points`` prims are drawn as spheres: "auto" (those without a surface mesh
            ``<name>_surface`` beside them: a lattice's points, not a peridynamic or FEM body's), "all" or "none".
        fit: what the automatic camera frames, of the bodies (not colliders or projectiles): "auto", the bodies
            over all frames as far as ``FIT_REACH`` (0.5) times the rest pose's largest extent past the rest pose
            on every side (the object and the action around it fill the picture; debris that flies farther leaves
            it); "all" frames of the cache whatever their extent; the "selected" frames; or the "first" frame (the
            rest pose). "auto", "all" and "first" give the same camera for every still and animation of a cache.
            The ground stays at the lowest point of all frames.
        device: Warp device ("cpu" or "cuda").

    Raises:
        ParameterError: for a missing or unreadable cache, frames out of range, an unknown attribute, a bad camera
            spec or size.
    """
    stage = StageReader(cache, points)
    width, height = (camera.width, camera.height) if isinstance(camera, Camera) else parse_size(size)
    if isinstance(frames, list | tuple):
        selected = [int(f) for f in frames]
        bad = [f for f in selected if f not in stage.frames]
        if bad or not selected:
            raise ParameterError(
                "frames", frames, f"frame numbers from {stage.frames[0]} to {stage.frames[-1]} (at least one)"
            )
    else:
        selected = parse_frames(frames, stage.frames, default=default_frames)
    if not (isinstance(supersample, int) and 1 <= supersample <= 4):
        raise ParameterError("supersample", supersample, "an integer from 1 to 4")
    coloring = Coloring()
    color_range = None
    if color is not None:
        name = color[len("primvars:") :] if color.startswith("primvars:") else color
        names = stage.primvar_names()
        if name not in names:
            listed = ", ".join(names) if names else "none: the cache has no primvars"
            raise ParameterError("color", color, f"a primvar of the cache ({listed})")
        values = stage.attribute_values(name, selected)
        flat = np.concatenate(values) if values else np.zeros(0)
        is_int = flat.dtype.kind in "iub"
        coloring = Coloring(name, is_int if categorical is None else bool(categorical))
        finite = flat[np.isfinite(flat)] if flat.size else flat
        if not coloring.categorical and finite.size:
            coloring.lo, coloring.hi = float(finite.min()), float(finite.max())
            color_range = (coloring.lo, coloring.hi)

    if fit not in FIT_MODES:
        raise ParameterError("fit", fit, "one of " + ", ".join(FIT_MODES))
    up = stage.up
    if not isinstance(camera, Camera):  # a bad spec fails before the pass over the frames
        camera_from_spec(camera, np.zeros(3), np.ones(3), up, (width, height))
    all_lo, all_hi, ground_height = stage.bounds(stage.frames)
    lo, hi = _fitted_box(stage, fit, selected, all_lo, all_hi)
    cam = camera if isinstance(camera, Camera) else camera_from_spec(camera, lo, hi, up, (width, height))
    centre = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    ground_offset = (float(all_lo @ up) if ground_height is None else ground_height) if ground else None
    ground_center = centre - ((centre @ up) - (all_lo @ up)) * up
    # key light 30 degrees to the left of the camera's azimuth, 50 degrees high; fill light 70 degrees to its right
    e1, e2 = horizontal_axes(up)
    view = cam.eye - cam.target
    az = math.degrees(math.atan2(view @ e2, view @ e1)) if np.linalg.norm(view - (view @ up) * up) > 1e-9 else 0.0
    light = direction(az - 30.0, 50.0, up)
    fill = direction(az + 70.0, 15.0, up)
    default_radius = 0.004 * diag
    eps = 1.0e-4 * diag

    renderer = _Renderer(device)
    images, coverage, seconds = [], [], []
    for f in selected:
        t0 = time.perf_counter()
        geo = stage.frame(f, coloring, default_radius)
        img, cov = renderer.render(
            geo,
            cam,
            centre,
            ground=ground_offset,
            ground_center=ground_center,
            fade=1.6 * diag,
            light=light,
            fill=fill,
            shadows=shadows,
            ss=supersample,
            eps=eps,
        )
        images.append(img)
        coverage.append(cov)
        seconds.append(time.perf_counter() - t0)
    return PreviewResult(images, selected, cam, (lo, hi), coverage, color_range, seconds, stage.fps)


def _fitted_box(stage: StageReader, fit: str, selected: list[int], all_lo, all_hi) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) [m] of the box the automatic camera frames for ``fit`` (see :func:`render_cache`)."""
    if fit == "all":
        return all_lo, all_hi
    if fit == "selected":
        return stage.bounds(selected, detect_ground=False)[:2]
    rest_lo, rest_hi = stage.bounds(stage.frames[:1], detect_ground=False)[:2]
    if fit == "first":
        return rest_lo, rest_hi
    reach = FIT_REACH * float(np.max(rest_hi - rest_lo))
    return np.maximum(all_lo, rest_lo - reach), np.minimum(all_hi, rest_hi + reach)


def write_preview(
    cache: str | os.PathLike,
    out: str | os.PathLike,
    frames: str | list[int] | None = None,
    *,
    fps: float | None = None,
    **options,
) -> PreviewResult:
    """Renders ``cache`` and writes ``out``: a PNG still (one frame; default the last) or a GIF / MP4 animation (one
    image per selected frame; default all frames).

    Args:
        cache, frames, options: as for :func:`render_cache`.
        out: path ending in .png, .gif or .mp4 (MP4: H.264 through imageio-ffmpeg; even width and height).
        fps: animation frame rate [1/s]; default the stage's frames per second divided by the frame step.

    The file is written under a temporary name next to ``out`` and renamed when complete, so a failed run leaves
    nothing behind. Raises ParameterError for bad inputs (before rendering).
    """
    out = os.fspath(out)
    suffix = os.path.splitext(out)[1].lower()
    if suffix not in SUFFIXES:
        raise ParameterError("out", out, "a path ending in .png (still), .gif or .mp4 (animation)")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise ParameterError("out", out, "a path in an existing folder")
    if fps is not None and not (isinstance(fps, int | float) and math.isfinite(fps) and 0.0 < fps <= 1000.0):
        raise ParameterError("fps", fps, "a number of frames per second in (0, 1000]")
    size = options.get("size", (640, 480))
    if suffix == ".mp4" and not isinstance(options.get("camera"), Camera):
        w, h = parse_size(size)
        if w % 2 or h % 2:
            raise ParameterError("size", size, "an even width and height for .mp4 (H.264), e.g. 640x480")
    if suffix == ".png":
        stage_frames = StageReader(cache).frames
        chosen = frames if isinstance(frames, list | tuple) else parse_frames(frames, stage_frames, default="last")
        if len(chosen) != 1:
            raise ParameterError(
                "frames", frames, "one frame for a .png still (e.g. --frames 7 or 7:8); use .gif or .mp4 for several"
            )
        frames = list(chosen)
    result = render_cache(cache, frames, default_frames="all", **options)
    step = result.frames[1] - result.frames[0] if len(result.frames) > 1 else 1
    rate = float(fps) if fps is not None else result.fps / max(step, 1)
    _write_images(out, suffix, result.images, rate)
    return result


def _write_images(out: str, suffix: str, images: list, fps: float) -> None:
    """Writes images (uint8 [H, W, 3]) to ``out`` through a temporary file renamed when complete."""
    folder, name = os.path.split(os.path.abspath(out))
    tmp = os.path.join(folder, f".{name}.{os.getpid()}.tmp{suffix}")
    try:
        if suffix == ".png":
            iio.imwrite(tmp, images[0], extension=".png")
        elif suffix == ".gif":
            # duration per frame [ms]; loop=0 repeats forever
            iio.imwrite(tmp, np.stack(images), extension=".gif", duration=1000.0 / fps, loop=0)
        else:
            writer = iio2.get_writer(
                tmp,
                format="FFMPEG",
                mode="I",
                fps=fps,
                codec="libx264",
                pixelformat="yuv420p",
                quality=8,
                macro_block_size=1,
                ffmpeg_log_level="error",
            )
            try:
                for img in images:
                    writer.append_data(img)
            finally:
                writer.close()
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)

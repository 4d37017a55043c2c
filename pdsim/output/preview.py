"""Preview renderer: stills (PNG) and animations (GIF, MP4) of any USD cache, ray cast on the CPU with Warp.

The cache is read like a renderer reads it, through ``pxr.Usd.Stage.Open`` (so sublayers, references and value clips
resolve as USD resolves them): every visible ``UsdGeom.Mesh`` (polygons fan-triangulated, each frame's points and
that frame's topology, world transforms applied, authored normals for shading) and ``UsdGeom.Points`` prims, drawn as
spheres of their widths (instanced icospheres with exact sphere normals). By default a body's points ``<b>`` are left
out when its surface ``<b>_surface`` or render mesh ``<b>_render`` (a Mesh or an Xform of fragment meshes) is beside
them, and a visible ``<b>_render`` stands for ``<b>_surface`` (the prim names of docs/cache_format.md; other stages
draw every prim). Guide and proxy prims are skipped; a flat ground quad is replaced by the preview's ground plane.

Shading: Lambert + hemispherical ambient from a key light above and to the left of the camera and a weak fill light,
shadow rays (self-shadowing and shadows on a ground plane at the lowest point of the geometry over all frames, which
shows only the shadows and fades into the background). Colours: ``displayColor`` (linear RGB) where authored, else a
neutral material with the faces whose ``crack`` primvar is 1 (or that lie in a ``crack`` GeomSubset) in a contrasting
interior colour. ``color=ATTR`` colours every prim that carries the primvar ATTR (constant, uniform, vertex, varying
or faceVarying; a vector by its length): floats through a colour ramp over the value range of the rendered frames,
integers (fragment ids, kinds) by a categorical palette. A body's surface, fragment or render mesh without ATTR takes
it from the body's Points prim (the value of the nearest point of each vertex), so ``color="damage"`` shows a
peridynamic body's damage on its surface.

The camera is a pinhole with a 35 degree vertical field of view. By default it looks at the centre of the bounding box
of all frames' geometry from a three-quarter view (azimuth -60 degrees about the stage's up axis, elevation 25
degrees), at the distance that fits that box into the image; see :func:`camera_from_spec` for the other choices.

Library use::

    from pdsim.output.preview import render_cache, write_preview

    result = render_cache("cache.usdc", frames=[3], size=(640, 480))   # images as uint8 [H, W, 3]
    write_preview("cache.usdc", "cache.gif")                          # every frame, animated

Errors in the inputs raise :class:`pdsim.ParameterError` naming the field and what is allowed; nothing is written
then (the output file is written to a temporary name and renamed when complete).
"""

from __future__ import annotations

import functools
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError

__all__ = [
    "SUFFIXES",
    "Camera",
    "PreviewResult",
    "camera_from_spec",
    "parse_frames",
    "parse_size",
    "render_cache",
    "write_preview",
]

SUFFIXES = (".png", ".gif", ".mp4")
FOV_Y_DEG = 35.0  # vertical field of view of the automatic camera [degrees]
DEFAULT_AZIMUTH = -60.0  # [degrees] about the up axis, from the first horizontal axis (x) towards the second
DEFAULT_ELEVATION = 25.0  # [degrees] above the horizontal plane
FIT_MARGIN = 0.88  # the fitted bounding box spans at most this fraction of the image's half-extents
MAX_SIZE = 8192  # largest image side [pixels]
BVH_CONSTRUCTOR = "sah"  # Warp's BVH builder for the per-frame wp.Mesh (see docs/preview.md for the measurements)
FIT_MODES = ("all", "selected", "first")  # which frames the automatic camera is fitted to (see render_cache)
POINTS_MODES = ("auto", "all", "none")  # which UsdGeom.Points prims are drawn (see render_cache)

# Colours in sRGB [0, 1]; converted to linear for shading (authored displayColor is linear RGB already).
NEUTRAL = (0.74, 0.72, 0.68)
CRACK = (0.86, 0.36, 0.16)
BACKGROUND = (0.95, 0.96, 0.97)
AMBIENT = 0.3  # share of the ambient (sky) term in the shading of a surface facing up
MISSING = (0.55, 0.55, 0.55)  # a value that is not finite under a ramp
# Viridis at 9 evenly spaced stops (sRGB).
_RAMP = np.array(
    [
        [0.267, 0.005, 0.329],
        [0.283, 0.141, 0.458],
        [0.254, 0.265, 0.530],
        [0.207, 0.372, 0.553],
        [0.164, 0.471, 0.558],
        [0.128, 0.567, 0.551],
        [0.135, 0.659, 0.518],
        [0.267, 0.749, 0.441],
        [0.478, 0.821, 0.318],
        [0.741, 0.873, 0.150],
        [0.993, 0.906, 0.144],
    ]
)
# A categorical palette of 20 colours (Tableau 20, sRGB) for integer primvars.
_PALETTE = (
    np.array(
        [
            [31, 119, 180],
            [255, 127, 14],
            [44, 160, 44],
            [214, 39, 40],
            [148, 103, 189],
            [140, 86, 75],
            [227, 119, 194],
            [127, 127, 127],
            [188, 189, 34],
            [23, 190, 207],
            [174, 199, 232],
            [255, 187, 120],
            [152, 223, 138],
            [255, 152, 150],
            [197, 176, 213],
            [196, 156, 148],
            [247, 182, 210],
            [199, 199, 199],
            [219, 219, 141],
            [158, 218, 229],
        ]
    )
    / 255.0
)


def _linear(srgb) -> np.ndarray:
    """sRGB [0, 1] -> linear (gamma 2.2), float32 of the same shape."""
    return np.power(np.clip(np.asarray(srgb, dtype=np.float32), 0.0, 1.0), 2.2).astype(np.float32)


def ramp_colors(t: np.ndarray) -> np.ndarray:
    """Viridis sRGB colours [..., 3] of values ``t`` in [0, 1] (clipped; NaN gives grey)."""
    t = np.asarray(t, dtype=np.float64)
    bad = ~np.isfinite(t)
    x = np.clip(np.where(bad, 0.0, t), 0.0, 1.0) * (len(_RAMP) - 1)
    k = np.minimum(x.astype(np.int64), len(_RAMP) - 2)
    f = (x - k)[..., None]
    out = (1.0 - f) * _RAMP[k] + f * _RAMP[k + 1]
    out[bad] = MISSING
    return out


def palette_colors(ids: np.ndarray) -> np.ndarray:
    """Categorical sRGB colours [..., 3] of integer ids (cycling through 20 colours)."""
    ids = np.asarray(ids)
    return _PALETTE[np.mod(np.rint(np.nan_to_num(ids)).astype(np.int64), len(_PALETTE))]


# --------------------------------------------------------------------------------------------------------------------
# Camera


@dataclass
class Camera:
    """A pinhole camera.

    Attributes:
        eye: camera position [m] (world), float64 [3].
        target: point looked at [m] (world), float64 [3].
        up: world up direction (the stage's up axis), unit float64 [3].
        fov_y: vertical field of view [degrees].
        width, height: image size [pixels].
    """

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_y: float
    width: int
    height: int

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(forward, right, up) of the image plane: unit float64 [3] each, right-handed (right x up = -forward)."""
        f = self.target - self.eye
        f = f / np.linalg.norm(f)
        up = self.up - (self.up @ f) * f  # the stage's up as seen in the image: continuous up to the pole
        if np.linalg.norm(up) < 1.0e-6:  # looking straight along the up axis: any horizontal direction is image up
            up = np.roll(self.up, 1)
            up = up - (up @ f) * f
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        return f, r, np.cross(r, f)

    @property
    def tan_half(self) -> tuple[float, float]:
        """(tan of half the horizontal, tan of half the vertical) field of view."""
        ty = math.tan(math.radians(0.5 * self.fov_y))
        return ty * self.width / self.height, ty

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates of world points [m], float [n, 3] -> (xy float64 [n, 2], depth [m] float64 [n]).

        x is the column and y the row from the top-left image corner, in pixels (pixel (i, j) covers
        [j, j + 1) x [i, i + 1), so its centre is (j + 0.5, i + 0.5)); depth is the distance along the view direction.
        """
        f, r, u = self.basis()
        tx, ty = self.tan_half
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.eye
        depth = p @ f
        x = (p @ r) / depth / tx
        y = (p @ u) / depth / ty
        return np.stack([(x + 1.0) * 0.5 * self.width, (1.0 - y) * 0.5 * self.height], axis=1), depth


def _horizontal_axes(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two horizontal unit axes (e1, e2) with e1 x e2 = up: (x, y) for a Z-up stage, (x, -z) for a Y-up stage."""
    e1 = np.array([1.0, 0.0, 0.0])
    return e1, np.cross(up, e1)


def _direction(azimuth: float, elevation: float, up: np.ndarray) -> np.ndarray:
    """Unit vector from the target towards the eye for an azimuth and elevation [degrees]."""
    e1, e2 = _horizontal_axes(up)
    a, e = math.radians(azimuth), math.radians(elevation)
    return math.cos(e) * (math.cos(a) * e1 + math.sin(a) * e2) + math.sin(e) * up


def _fit_distance(lo, hi, direction, up, fov_y, width, height) -> float:
    """Smallest eye distance [m] from the box centre along ``direction`` at which all 8 corners of the box [lo, hi]
    project inside FIT_MARGIN of the image."""
    centre = 0.5 * (lo + hi)
    cam = Camera(centre + direction, centre, up, fov_y, width, height)
    _, r, u = cam.basis()
    tx, ty = cam.tan_half
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
    along = corners @ direction  # towards the eye
    need = np.maximum(np.abs(corners @ r) / (FIT_MARGIN * tx), np.abs(corners @ u) / (FIT_MARGIN * ty)) + along
    size = float(np.linalg.norm(hi - lo))
    return max(float(need.max()), float(along.max()) + 0.05 * size, 1.0e-6)


def camera_from_spec(
    spec: str | None, lo: np.ndarray, hi: np.ndarray, up: np.ndarray, size: tuple[int, int], fov_y: float = FOV_Y_DEG
) -> Camera:
    """The camera of a ``--camera`` spec for geometry within the box [lo, hi] [m] (world, float [3] each).

    ``spec``:
        - None: automatic three-quarter view (azimuth -60, elevation 25 degrees), distance fitted to the box;
        - ``"AZIMUTH,ELEVATION"`` or ``"AZIMUTH,ELEVATION,DISTANCE"``: degrees, degrees, metres. The camera looks at the
          box centre; azimuth turns about the up axis from +x towards +y (Z-up) or -z (Y-up); elevation is in
          (-90, 90); without a distance it is fitted to the box;
        - ``"eye=X,Y,Z:target=X,Y,Z"`` [m] (world); ``target`` may be left out (then the box centre).

    Raises ParameterError("camera", ...) for anything else.
    """
    allowed = (
        "'AZIMUTH,ELEVATION[,DISTANCE]' (degrees, degrees with -90 < ELEVATION < 90, metres > 0) "
        "or 'eye=X,Y,Z:target=X,Y,Z' (metres, eye != target)"
    )
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo + hi)
    width, height = size
    if spec is None or not spec.strip():
        d = _direction(DEFAULT_AZIMUTH, DEFAULT_ELEVATION, up)
        return Camera(centre + d * _fit_distance(lo, hi, d, up, fov_y, width, height), centre, up, fov_y, width, height)

    def numbers(text: str, count: tuple[int, ...]) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise ParameterError("camera", spec, allowed) from None
        if len(values) not in count or not all(math.isfinite(v) for v in values):
            raise ParameterError("camera", spec, allowed)
        return values

    text = spec.strip()
    if "=" in text:
        parts = {}
        for part in text.split(":"):
            key, sep, value = part.partition("=")
            key = key.strip().lower()
            if not sep or key not in ("eye", "target") or key in parts:
                raise ParameterError("camera", spec, allowed)
            parts[key] = np.array(numbers(value, (3,)))
        if "eye" not in parts:
            raise ParameterError("camera", spec, allowed)
        target = parts.get("target", centre)
        if np.linalg.norm(parts["eye"] - target) < 1.0e-9:
            raise ParameterError("camera", spec, allowed)
        return Camera(parts["eye"], target, up, fov_y, width, height)
    values = numbers(text, (2, 3))
    azimuth, elevation = values[0], values[1]
    if not -90.0 < elevation < 90.0 or (len(values) == 3 and values[2] <= 0.0):
        raise ParameterError("camera", spec, allowed)
    d = _direction(azimuth, elevation, up)
    dist = values[2] if len(values) == 3 else _fit_distance(lo, hi, d, up, fov_y, width, height)
    return Camera(centre + d * dist, centre, up, fov_y, width, height)


# --------------------------------------------------------------------------------------------------------------------
# Option parsing


def parse_size(spec: str | tuple[int, int] | None) -> tuple[int, int]:
    """``"WxH"`` (pixels, 16..8192 each) -> (W, H); None gives (640, 480)."""
    if spec is None:
        return 640, 480
    allowed = f"'WIDTHxHEIGHT' in pixels, each an integer from 16 to {MAX_SIZE} (e.g. 640x480)"
    if isinstance(spec, str):
        parts = spec.lower().split("x")
        try:
            w, h = (int(p) for p in parts)
        except ValueError:
            raise ParameterError("size", spec, allowed) from None
    else:
        w, h = spec
    if not (16 <= w <= MAX_SIZE and 16 <= h <= MAX_SIZE):
        raise ParameterError("size", spec, allowed)
    return int(w), int(h)


def parse_frames(spec: str | int | None, available: list[int], *, default: str = "all") -> list[int]:
    """Frame numbers selected by ``spec`` among the cache's consecutive frame numbers ``available``.

    ``spec``: ``"N"`` one frame; ``"A:B"`` or ``"A:B:STEP"`` frames A, A + STEP, ... before B (A inclusive, B
    exclusive, like Python slices; A defaults to the first frame, B to one past the last). Negative values count
    from the end (-1 is the last frame). None selects ``default``: ``"all"`` frames or the ``"last"`` one. A frame
    outside the cache or an empty selection raises ParameterError("frames", ...).
    """
    first, last = available[0], available[-1]
    if spec is None:
        return list(available) if default == "all" else [last]
    allowed = (
        f"a frame N or a range A:B[:STEP] with {first} <= N <= {last} and {first} <= A < B <= {last + 1} "
        "(A inclusive, B exclusive, like Python slices; negative values count from the end)"
    )

    def value(text: str) -> int:
        v = int(text)
        return v + last + 1 if v < 0 else v

    try:
        parts = [str(int(spec))] if isinstance(spec, int | np.integer) else [p.strip() for p in str(spec).split(":")]
        if len(parts) == 1:
            n = value(parts[0])
            if not first <= n <= last:
                raise ParameterError("frames", spec, allowed)
            return [n]
        if len(parts) > 3:
            raise ParameterError("frames", spec, allowed)
        a = value(parts[0]) if parts[0] else first
        b = value(parts[1]) if parts[1] else last + 1
        step = int(parts[2]) if len(parts) == 3 and parts[2] else 1
    except ValueError:
        raise ParameterError("frames", spec, allowed) from None
    if step < 1 or not (first <= a < b <= last + 1):
        raise ParameterError("frames", spec, allowed)
    return list(range(a, b, step))


# --------------------------------------------------------------------------------------------------------------------
# Reading the stage


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


def _triangulate(counts: np.ndarray, indices: np.ndarray, holes: np.ndarray | None):
    """Fan triangulation of polygons: (triangles [t, 3] point indices, face of each triangle [t], face-vertex index
    of each corner [t, 3]). Faces with fewer than 3 vertices and hole faces give no triangles."""
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else np.zeros(0, np.int64)
    ntri = np.maximum(counts - 2, 0)
    if holes is not None and len(holes):
        h = np.asarray(holes, dtype=np.int64)
        ntri[h[(h >= 0) & (h < len(counts))]] = 0
    face = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # triangle number within its face
    s = starts[face]
    corner = np.stack([s, s + k + 1, s + k + 2], axis=1)
    return np.asarray(indices, dtype=np.int64)[corner], face, corner


def _expand(values, interpolation: str, n_faces: int, n_points: int, n_fv: int, tri, face, corner):
    """Per-corner values [t, 3, ...] of a mesh primvar, or None when its length does not fit its interpolation."""
    v = np.asarray(values)
    if v.ndim == 0 or len(v) == 0:
        return None
    if interpolation == "constant":
        return np.broadcast_to(v[0], (len(tri), 3, *v.shape[1:]))
    if interpolation == "uniform" and len(v) == n_faces:
        return np.repeat(v[face][:, None], 3, axis=1)
    if interpolation in ("vertex", "varying") and len(v) == n_points:
        return v[tri]
    if interpolation == "faceVarying" and len(v) == n_fv:
        return v[corner]
    return None


def _scalar(values: np.ndarray) -> np.ndarray:
    """Scalar per element: the values themselves, or the length of vector values [..., k]."""
    v = np.asarray(values)
    if v.dtype == bool:
        v = v.astype(np.int32)
    if v.ndim >= 2 and v.shape[-1] > 1:
        return np.linalg.norm(v.astype(np.float64), axis=-1)
    return v[..., 0] if v.ndim >= 2 else v


def _matrix(xf_cache, prim) -> np.ndarray:
    """Local-to-world matrix of a prim, float64 [4, 4], row-vector convention (p' = p M[:3, :3] + M[3, :3])."""
    return np.array(xf_cache.GetLocalToWorldTransform(prim), dtype=np.float64)


def _transform(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    if np.allclose(m, np.eye(4)):
        return points
    return points @ m[:3, :3] + m[3, :3]


def _primvar(prim, name: str, t):
    """(values, interpolation) of the primvar ``name`` at time code t (indexed primvars flattened), or None."""
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
    if not pv or not pv.HasValue():
        return None
    values = pv.ComputeFlattened(t)
    if values is None:
        return None
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError):
        return None
    if arr.dtype.kind not in "biuf":
        return None
    if arr.ndim == 0:
        arr = arr.reshape(1)
    return arr, str(pv.GetInterpolation())


@dataclass
class _FrameGeometry:
    """One frame's renderable geometry, world coordinates [m]."""

    surf_points: list = field(default_factory=list)  # float64 [v, 3] per mesh
    surf_tris: list = field(default_factory=list)  # int [t, 3] per mesh (local indices)
    surf_colors: list = field(default_factory=list)  # linear float32 [t, 3, 3] per mesh
    surf_normals: list = field(default_factory=list)  # float32 [t, 3, 3] per mesh (zeros: use the face normal)
    centers: list = field(default_factory=list)  # float64 [s, 3] per points prim
    radii: list = field(default_factory=list)  # float64 [s] per points prim
    colors: list = field(default_factory=list)  # linear float32 [s, 3] per points prim


class _Stage:
    """A USD stage opened for rendering: its renderable prims, up axis and frames."""

    def __init__(self, path: str, points: str = "auto"):
        from pxr import Sdf, Tf, Usd, UsdGeom

        if points not in POINTS_MODES:
            raise ParameterError("points", points, "one of " + ", ".join(POINTS_MODES))
        self.points_mode = points

        readable = "an existing, readable USD file (.usd, .usda, .usdc)"
        if not isinstance(path, str | os.PathLike) or not os.path.isfile(path):
            raise ParameterError("cache", os.fspath(path) if isinstance(path, os.PathLike) else path, readable)
        path = os.fspath(path)
        try:
            if not Sdf.FileFormat.FindByExtension(os.path.splitext(path)[1].lstrip(".").lower() or "x"):
                raise ParameterError("cache", path, readable)
            stage = Usd.Stage.Open(path)
        except Tf.ErrorException:
            stage = None
        if stage is None:
            raise ParameterError("cache", path, readable)
        self.path = path
        self.stage = stage
        self.ground_prims = set()
        self.up = np.array([0.0, 1.0, 0.0]) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else np.eye(3)[2]
        self.meshes, self.points = [], []
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Points):
                if UsdGeom.Imageable(prim).ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
                    continue
                (self.meshes if prim.IsA(UsdGeom.Mesh) else self.points).append(prim)
        # a body's Points prim <name> is covered by its surface mesh <name>_surface when there is one
        # a body's Points prim <b> is covered by its surface <b>_surface or render mesh <b>_render (a Mesh, or an
        # Xform of fragment meshes) beside it; a visible <b>_render stands for <b>_surface
        self._roots = {prim.GetPath(): self._surface_root(prim) for prim in self.meshes}
        self.surface_of = {}
        for root, body in self._roots.values():
            if body is not None:
                self.surface_of.setdefault(body.GetPath(), set()).add(root)
        if not self.meshes and not self.points:
            raise ParameterError("cache", path, "a USD stage with at least one UsdGeom.Mesh or UsdGeom.Points prim")
        if stage.HasAuthoredTimeCodeRange():
            start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
            self.frames = list(range(math.ceil(start), math.floor(end) + 1)) or [round(start)]
        else:
            samples = set()
            for prim in self.meshes + self.points:
                samples.update(UsdGeom.PointBased(prim).GetPointsAttr().GetTimeSamples())
            self.frames = sorted({round(s) for s in samples}) or [0]
            self.frames = list(range(self.frames[0], self.frames[-1] + 1))
        self.fps = float(stage.GetFramesPerSecond() or stage.GetTimeCodesPerSecond() or 24.0)

    # -- queries -----------------------------------------------------------------------------------------------------

    def visible(self, prim, t) -> bool:
        from pxr import UsdGeom

        return UsdGeom.Imageable(prim).ComputeVisibility(t) != UsdGeom.Tokens.invisible

    def drawn_points(self, t) -> list:
        """The Points prims drawn at time t: all visible ones (mode "all"), none (mode "none"), or (mode "auto") the
        visible ones that are not covered by a visible sibling surface mesh ``<name>_surface``."""
        if self.points_mode == "none":
            return []
        out = []
        for prim in self.points:
            if not self.visible(prim, t):
                continue
            covers = self.surface_of.get(prim.GetPath(), ())
            if self.points_mode == "auto" and any(self.visible(root, t) for root in covers):
                continue
            out.append(prim)
        return out

    def primvar_names(self) -> list[str]:
        """Names of the numeric primvars with a value on any renderable prim."""
        from pxr import UsdGeom

        names = set()
        for prim in self.meshes + self.points:
            for pv in UsdGeom.PrimvarsAPI(prim).GetPrimvarsWithValues():
                names.add(pv.GetPrimvarName())
        return sorted(names)

    @staticmethod
    def _surface_root(mesh_prim):
        """(R, B): the prim R named ``<b>_surface`` or ``<b>_render`` that the mesh is or lies under and the Points
        prim B named ``<b>`` beside R (a body's surface, render mesh or fragment prims and the body's points), or
        (None, None)."""
        from pxr import UsdGeom

        prim = mesh_prim
        while prim and not prim.IsPseudoRoot():
            name = prim.GetName()
            for suffix in ("_surface", "_render"):
                if name.endswith(suffix) and len(name) > len(suffix):
                    body = prim.GetParent().GetChild(name[: -len(suffix)])
                    if body and body.IsA(UsdGeom.Points):
                        return prim, body
            prim = prim.GetParent()
        return None, None

    def source_points(self, mesh_prim):
        """The body's Points prim ``<b>`` of a mesh that is or lies under ``<b>_surface`` / ``<b>_render``, or None."""
        return self._roots[mesh_prim.GetPath()][1]

    def drawn_meshes(self, t) -> list:
        """The meshes drawn at time t: the visible ones, less the ground-like ones and a body's ``<b>_surface`` when
        its ``<b>_render`` is visible."""
        out = []
        for prim in self.meshes:
            if prim.GetPath() in self.ground_prims or not self.visible(prim, t):
                continue
            root, body = self._roots[prim.GetPath()]
            if root is not None and root.GetName().endswith("_surface"):
                render = root.GetParent().GetChild(body.GetName() + "_render")
                if render and render.GetPath() != root.GetPath() and self.visible(render, t):
                    continue
            out.append(prim)
        return out

    def _mesh_topology(self, prim, t):
        """(world points float64 [v, 3], triangles [t, 3], face [t], corner [t, 3], face count, face-vertex count)
        of a mesh at time t, or None when it has no usable points or faces."""
        from pxr import UsdGeom

        mesh = UsdGeom.Mesh(prim)
        pts = mesh.GetPointsAttr().Get(t)
        counts = mesh.GetFaceVertexCountsAttr().Get(t)
        idx = mesh.GetFaceVertexIndicesAttr().Get(t)
        if pts is None or counts is None or idx is None or len(pts) == 0 or len(counts) == 0:
            return None
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        counts, idx = np.asarray(counts, dtype=np.int64), np.asarray(idx, dtype=np.int64)
        if counts.sum() != len(idx) or (len(idx) and (idx.min() < 0 or idx.max() >= len(pts))):
            return None  # inconsistent topology at this time: skip the prim rather than render garbage
        holes = mesh.GetHoleIndicesAttr().Get(t)
        tri, face, corner = _triangulate(counts, idx, None if holes is None else np.asarray(holes))
        if len(tri) == 0:
            return None
        return pts, tri, face, corner, len(counts), len(idx)

    def _points(self, prim, t):
        """(points float64 [n, 3] local, radii float64 [n]) of a Points prim at t, or None."""
        from pxr import UsdGeom

        geom = UsdGeom.Points(prim)
        pts = geom.GetPointsAttr().Get(t)
        if pts is None or len(pts) == 0:
            return None
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        widths = geom.GetWidthsAttr().Get(t)
        w = np.asarray(widths, dtype=np.float64) if widths is not None else np.zeros(0)
        if len(w) == len(pts):
            radii = 0.5 * w
        elif len(w) >= 1:
            radii = np.full(len(pts), 0.5 * w[0])
        else:
            radii = np.full(len(pts), np.nan)  # filled in by the caller from the scene size
        return pts, radii

    def bounds(self, frames, *, detect_ground: bool = True) -> tuple[np.ndarray, np.ndarray, float | None]:
        """(lo, hi) [m] of all geometry over ``frames`` (points grown by their radii) and the ground height [m]
        along the up axis of a ground-like mesh if there is one (else None): a mesh perpendicular to the up axis
        (thickness below 1e-6 of its width), at least as wide as all other geometry and below its middle
        (pdsim writes the scene's ground plane as such a quad, /World/ground). It is left out of the box and of the
        rendering; the preview's ground plane, at its height, stands for it. ``detect_ground=False`` keeps the
        ground-like prims found by an earlier call and returns None for the height."""
        from pxr import UsdGeom

        boxes = {}  # prim path -> (lo, hi)
        if detect_ground:
            self.ground_prims = set()
        for f in frames:
            xf = UsdGeom.XformCache(f)
            for prim in self.drawn_meshes(f) + self.drawn_points(f):
                if prim.IsA(UsdGeom.Mesh):
                    pts = UsdGeom.Mesh(prim).GetPointsAttr().Get(f)
                    if pts is None or len(pts) == 0:
                        continue
                    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
                    r = 0.0
                else:
                    got = self._points(prim, f)
                    if got is None:
                        continue
                    pts, radii = got
                    r = float(np.nanmax(radii)) if np.isfinite(radii).any() else 0.0
                p = _transform(pts, _matrix(xf, prim))
                lo, hi = p.min(axis=0) - r, p.max(axis=0) + r
                key = prim.GetPath()
                if key in boxes:
                    lo, hi = np.minimum(boxes[key][0], lo), np.maximum(boxes[key][1], hi)
                boxes[key] = (lo, hi)
        if not boxes:
            raise ParameterError("cache", self.path, "a cache whose prims have points in the selected frames")
        ground = None
        if detect_ground and len(boxes) > 1:
            e1, e2 = _horizontal_axes(self.up)
            for key, (lo, hi) in boxes.items():
                others = [b for k, b in boxes.items() if k != key]
                olo = np.min([b[0] for b in others], axis=0)
                ohi = np.max([b[1] for b in others], axis=0)
                span = hi - lo
                horizontal = max(abs(span @ e1), abs(span @ e2))
                oh = max(abs((ohi - olo) @ e1), abs((ohi - olo) @ e2))
                height, others_mid = float(lo @ self.up), float(0.5 * (olo + ohi) @ self.up)
                flat = abs(span @ self.up) <= 1.0e-6 * horizontal
                if flat and horizontal >= oh and height <= others_mid:
                    self.ground_prims.add(key)
                    ground = height
        kept = [b for k, b in boxes.items() if k not in self.ground_prims] or list(boxes.values())
        lo = np.min([b[0] for b in kept], axis=0)
        hi = np.max([b[1] for b in kept], axis=0)
        return lo, hi, ground

    # -- colours -----------------------------------------------------------------------------------------------------

    def attribute_values(self, name: str, frames) -> list[np.ndarray]:
        """The scalar values of primvar ``name`` on every renderable prim over ``frames`` (for its range)."""
        out = []
        for f in frames:
            for prim in self.meshes + self.points:
                got = _primvar(prim, name, f)
                if got is not None:
                    out.append(_scalar(got[0]).ravel())
        return out

    def frame(self, t, color: _Coloring, default_radius: float) -> _FrameGeometry:
        """The geometry and colours of all visible renderable prims at time code t."""
        from pxr import UsdGeom

        geo = _FrameGeometry()
        xf = UsdGeom.XformCache(t)
        for prim in self.drawn_meshes(t):
            topo = self._mesh_topology(prim, t)
            if topo is None:
                continue
            pts, tri, face, corner, n_faces, n_fv = topo
            m = _matrix(xf, prim)
            world = _transform(pts, m)
            expand = functools.partial(
                _expand, n_faces=n_faces, n_points=len(pts), n_fv=n_fv, tri=tri, face=face, corner=corner
            )
            colors = None
            if color.name is not None:
                got = _primvar(prim, color.name, t)
                per_corner = None if got is None else expand(_scalar(got[0]), got[1])
                if per_corner is None:
                    per_corner = self._transferred(prim, color.name, t, world, xf, expand)
                if per_corner is not None:
                    colors = _linear(color.map(per_corner))
            if colors is None:
                colors = self._base_colors(prim, t, expand, face, len(tri))
            normals = np.zeros((len(tri), 3, 3), np.float32)
            got = self._normals(prim, t)
            if got is not None:
                n = expand(*got)
                if n is not None and n.shape[-1:] == (3,):
                    a = m[:3, :3]
                    n = np.asarray(n, np.float64) @ np.linalg.inv(a).T
                    normals = (n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)).astype(np.float32)
            geo.surf_points.append(world)
            geo.surf_tris.append(tri)
            geo.surf_colors.append(np.asarray(colors, np.float32))
            geo.surf_normals.append(normals)
        for prim in self.drawn_points(t):
            got = self._points(prim, t)
            if got is None:
                continue
            pts, radii = got
            m = _matrix(xf, prim)
            world = _transform(pts, m)
            scale = float(np.cbrt(abs(np.linalg.det(m[:3, :3])))) if not np.allclose(m, np.eye(4)) else 1.0
            radii = np.where(np.isfinite(radii), radii * scale, default_radius)
            colors = None
            if color.name is not None:
                pv = _primvar(prim, color.name, t)
                if pv is not None:
                    v = _scalar(pv[0])
                    if len(v) == len(pts):
                        colors = _linear(color.map(v))
                    elif len(v) >= 1:
                        colors = _linear(color.map(np.broadcast_to(v[:1], (len(pts),))))
            if colors is None:  # displayColor (linear RGB) where authored, else neutral
                colors = np.broadcast_to(_linear(NEUTRAL), (len(pts), 3))
                dc = _primvar(prim, "displayColor", t)
                if dc is not None and dc[0].ndim == 2 and dc[0].shape[1] == 3:
                    if len(dc[0]) == len(pts):
                        colors = dc[0]
                    elif len(dc[0]) >= 1:
                        colors = np.broadcast_to(dc[0][0], (len(pts), 3))
            geo.centers.append(world)
            geo.radii.append(radii)
            geo.colors.append(np.asarray(colors, np.float32))
        return geo

    def _normals(self, prim, t):
        """(normals, interpolation) authored on a mesh (``primvars:normals`` before ``normals``), or None."""
        from pxr import UsdGeom

        got = _primvar(prim, "normals", t)
        if got is not None:
            return got
        mesh = UsdGeom.Mesh(prim)
        values = mesh.GetNormalsAttr().Get(t)
        if values is None or len(values) == 0:
            return None
        return np.asarray(values, dtype=np.float64).reshape(-1, 3), str(mesh.GetNormalsInterpolation())

    def _base_colors(self, prim, t, expand, face, n_tris) -> np.ndarray:
        """Linear per-corner colours [t, 3, 3] without an attribute: ``displayColor`` (linear RGB, as USD has it)
        where authored; else neutral with the crack faces (primvar ``crack`` == 1 or GeomSubset ``crack``) in the
        crack colour."""
        from pxr import UsdGeom

        dc = _primvar(prim, "displayColor", t)
        if dc is not None and dc[0].ndim == 2 and dc[0].shape[1] == 3:
            colors = expand(*dc)
            if colors is not None:
                return np.asarray(colors, np.float32)
        colors = np.array(np.broadcast_to(_linear(NEUTRAL), (n_tris, 3, 3)), dtype=np.float32)
        crack = np.zeros(n_tris, bool)
        got = _primvar(prim, "crack", t)
        if got is not None:
            c = expand(*got)
            if c is not None and c.ndim == 2:
                crack |= c[:, 0] == 1
        for subset in UsdGeom.Subset.GetGeomSubsets(UsdGeom.Imageable(prim), UsdGeom.Tokens.face):
            if subset.GetPrim().GetName() == "crack":
                idx = subset.GetIndicesAttr().Get(t)
                if idx is not None and len(idx):
                    in_subset = np.zeros(max(int(face.max(initial=0)), int(np.max(idx))) + 1, bool)
                    in_subset[np.asarray(idx, dtype=np.int64)] = True
                    crack |= in_subset[face]
        colors[crack] = _linear(CRACK)
        return colors

    def _transferred(self, prim, name, t, world, xf, expand):
        """Per-corner values of ``name`` for a body's surface, fragment or render mesh from the body's Points prim
        (the value of the nearest point of each vertex), or None."""
        source = self.source_points(prim)
        if source is None:
            return None
        got = _primvar(source, name, t)
        pts = self._points(source, t)
        if got is None or pts is None:
            return None
        values = _scalar(got[0])
        if len(values) != len(pts[0]):
            return None
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(_transform(pts[0], _matrix(xf, source))).query(world)
        return expand(values[nearest], "vertex")


@dataclass
class _Coloring:
    """How values become colours: a ramp over [lo, hi] for floats, a palette for integers."""

    name: str | None = None
    categorical: bool = False
    lo: float = 0.0
    hi: float = 1.0

    def map(self, values: np.ndarray) -> np.ndarray:
        """sRGB colours [..., 3] of scalar values [...]."""
        if self.categorical:
            return palette_colors(values)
        span = self.hi - self.lo
        t = (np.asarray(values, np.float64) - self.lo) / span if span > 0 else np.full(np.shape(values), 0.5)
        return ramp_colors(t)


# --------------------------------------------------------------------------------------------------------------------
# Rendering


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
        import warp as wp

        self.wp = wp
        self.device = device
        self.bvh_constructor = BVH_CONSTRUCTOR
        self._ico = {level: _icosphere(level) for level in (0, 1)}

    def render(
        self, geo: _FrameGeometry, camera: Camera, origin, *, ground, ground_center, fade, light, fill, shadows, ss, eps
    ):
        """Renders one frame: sRGB uint8 [H, W, 3] and the coverage mask bool [H, W]. ``origin`` [m] is subtracted
        from all positions before they go to float32; ``ground`` is the ground height [m] along the up axis (None: no
        ground); ``fade`` [m] the ground's fade distance; ``light`` and ``fill`` the unit directions towards the key
        and fill lights; ``shadows`` whether shadow rays are cast; ``ss`` the supersampling factor; ``eps`` [m] the
        shadow-ray offset."""
        wp = self.wp
        from pdsim.kernels.preview import render_preview

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
        ground_albedo = _linear(BACKGROUND) / _ground_albedo(light, fill, up)
        wp.launch(
            render_preview,
            dim=(height, width),
            inputs=[
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
                wp.vec3(*_linear(BACKGROUND)),
                float(eps),
                far,
            ],
            outputs=[image, coverage],
            device=dev,
        )
        img = image.numpy()
        cov = coverage.numpy().astype(bool)
        if ss > 1:
            img = img.reshape(camera.height, ss, camera.width, ss, 3).mean(axis=(1, 3))
            cov = cov.reshape(camera.height, ss, camera.width, ss).any(axis=(1, 3))
        srgb = np.power(np.clip(img, 0.0, 1.0), 1.0 / 2.2)
        return (srgb * 255.0 + 0.5).astype(np.uint8), cov


def _ground_albedo(light: np.ndarray, fill: np.ndarray, up: np.ndarray) -> float:
    """The shading factor of a lit, upward-facing surface (kernels/preview.py ``shade`` with n = up, lit = 1)."""
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
    fit: str = "all",
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
        fit: the geometry the automatic camera frames: "all" frames of the cache (the same camera for every still
            and animation of the cache), the "selected" frames, or the "first" frame (the rest pose: debris that
            flies far away leaves the picture instead of shrinking it). The ground stays at the lowest point of all
            frames.
        device: Warp device ("cpu" or "cuda").

    Raises:
        ParameterError: for a missing or unreadable cache, frames out of range, an unknown attribute, a bad camera
            spec or size.
    """
    stage = _Stage(cache, points)
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
    coloring = _Coloring()
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
        coloring = _Coloring(name, is_int if categorical is None else bool(categorical))
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
    fit_frames = {"all": None, "selected": selected, "first": stage.frames[:1]}[fit]
    lo, hi = (all_lo, all_hi) if fit_frames is None else stage.bounds(fit_frames, detect_ground=False)[:2]
    cam = camera if isinstance(camera, Camera) else camera_from_spec(camera, lo, hi, up, (width, height))
    centre = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    ground_offset = (float(all_lo @ up) if ground_height is None else ground_height) if ground else None
    ground_center = centre - ((centre @ up) - (all_lo @ up)) * up
    # key light 30 degrees to the left of the camera's azimuth, 50 degrees high; fill light 70 degrees to its right
    e1, e2 = _horizontal_axes(up)
    view = cam.eye - cam.target
    az = math.degrees(math.atan2(view @ e2, view @ e1)) if np.linalg.norm(view - (view @ up) * up) > 1e-9 else 0.0
    light = _direction(az - 30.0, 50.0, up)
    fill = _direction(az + 70.0, 15.0, up)
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
        stage_frames = _Stage(cache).frames
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
    import imageio.v3 as iio

    folder, name = os.path.split(os.path.abspath(out))
    tmp = os.path.join(folder, f".{name}.{os.getpid()}.tmp{suffix}")
    try:
        if suffix == ".png":
            iio.imwrite(tmp, images[0], extension=".png")
        elif suffix == ".gif":
            # duration per frame [ms]; loop=0 repeats forever
            iio.imwrite(tmp, np.stack(images), extension=".gif", duration=1000.0 / fps, loop=0)
        else:
            import imageio.v2 as iio2

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

"""The preview's pinhole camera and the ``--camera`` spec: an automatic three-quarter view fitted to a bounding box,
an azimuth and elevation (and distance), or an eye and target."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError

FOV_Y_DEG = 35.0  # vertical field of view of the automatic camera [degrees]
DEFAULT_AZIMUTH = -60.0  # [degrees] about the up axis, from the first horizontal axis (x) towards the second
DEFAULT_ELEVATION = 25.0  # [degrees] above the horizontal plane
FIT_MARGIN = 0.88  # the fitted bounding box spans at most this fraction of the image's half-extents


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


def horizontal_axes(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two horizontal unit axes (e1, e2) with e1 x e2 = up: (x, y) for a Z-up stage, (x, -z) for a Y-up stage."""
    e1 = np.array([1.0, 0.0, 0.0])
    return e1, np.cross(up, e1)


def direction(azimuth: float, elevation: float, up: np.ndarray) -> np.ndarray:
    """Unit vector from the target towards the eye for an azimuth and elevation [degrees]."""
    e1, e2 = horizontal_axes(up)
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
        d = direction(DEFAULT_AZIMUTH, DEFAULT_ELEVATION, up)
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
    d = direction(azimuth, elevation, up)
    dist = values[2] if len(values) == 3 else _fit_distance(lo, hi, d, up, fov_y, width, height)
    return Camera(centre + d * dist, centre, up, fov_y, width, height)

"""Checked numpy arrays to USD values for the cache writer: the Sdf type names and Vt arrays of the attribute kinds,
shape/dtype/finiteness checks, extents, prim identifiers, the per-frame samples of a Points or Mesh prim, and the
atomic export of a layer."""

from __future__ import annotations

import contextlib
import errno
import math
import os
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Vt

SUFFIXES = (".usdc", ".usda", ".usd")
PRIMVAR_KINDS = ("float", "int", "vector3f", "color3f")


def check_cache_settings(path, fps, start_frame, up_axis, meters_per_unit, save_interval_s) -> Path:
    """``path`` as a Path after checking the settings of a UsdCache (see there); ValueError naming the first bad
    one."""
    out = Path(path)
    if out.suffix.lower() not in SUFFIXES:
        raise ValueError(f"path {str(path)!r} must end in one of {', '.join(SUFFIXES)}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps={fps!r} must be a finite number > 0")
    if up_axis not in ("Y", "Z"):
        raise ValueError(f"up_axis={up_axis!r} must be 'Y' or 'Z'")
    if not (math.isfinite(meters_per_unit) and meters_per_unit > 0):
        raise ValueError(f"meters_per_unit={meters_per_unit!r} must be a finite number > 0")
    if not (math.isfinite(save_interval_s) and save_interval_s >= 0):
        raise ValueError(f"save_interval_s={save_interval_s!r} must be a finite number >= 0")
    if int(start_frame) != start_frame or start_frame < 0:
        raise ValueError(f"start_frame={start_frame!r} must be an integer >= 0")
    if not out.parent.is_dir():
        raise ValueError(f"folder {str(out.parent)!r} of the cache does not exist")
    if out.is_dir():
        raise ValueError(f"path {str(path)!r} is a folder")
    return out


def type_names() -> dict:
    """``{kind: Sdf.ValueTypeName}`` of the attribute kinds the cache writes."""
    t = Sdf.ValueTypeNames
    return {
        "float": t.FloatArray,
        "int": t.IntArray,
        "vector3f": t.Vector3fArray,
        "color3f": t.Color3fArray,
        "points": t.Point3fArray,
        "normals": t.Normal3fArray,
        "extent": t.Float3Array,
        "double3": t.Double3,
        "double": t.Double,
        "quatf": t.Quatf,
        "token": t.Token,
        "quath": t.QuathArray,
        "int64": t.Int64Array,
        "float3": t.Float3Array,
    }


def vt_array(kind: str, values: np.ndarray):
    """A Vt array of a primvar kind from a checked numpy array."""
    return {
        "float": Vt.FloatArray,
        "int": Vt.IntArray,
        "vector3f": Vt.Vec3fArray,
        "color3f": Vt.Vec3fArray,
        "points": Vt.Vec3fArray,
        "normals": Vt.Vec3fArray,
    }[kind].FromNumpy(values)


def check_array(name: str, array, *, shape: tuple[int, ...], shape_text: str, kind: str = "float") -> np.ndarray:
    """Return ``array`` as a C-contiguous numpy array after checking its shape, dtype kind and finiteness.

    Args:
        name: Name used in error messages.
        array: Array-like value.
        shape: Expected shape; ``-1`` matches any length on that axis.
        shape_text: Expected shape as shown to the user, e.g. ``"[point_count, 3] = [100, 3]"``.
        kind: ``"float"`` (converted to float32) or ``"int"`` (integer or bool, converted to int32).

    Raises:
        ValueError: Wrong shape, wrong dtype kind, or non-finite values.
    """
    a = np.asarray(array)
    if a.ndim != len(shape) or any(e != -1 and e != s for e, s in zip(shape, a.shape, strict=False)):
        raise ValueError(f"{name} has shape {list(a.shape)}; expected {shape_text}")
    if kind == "int":
        if not (np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_):
            raise ValueError(f"{name} must hold integers, got dtype {a.dtype}")
        if a.size and (a.min() < np.iinfo(np.int32).min or a.max() > np.iinfo(np.int32).max):
            raise ValueError(f"{name} has values outside the int32 range")
        return np.ascontiguousarray(a, dtype=np.int32)
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{name} must hold real numbers, got dtype {a.dtype}")
    a = np.ascontiguousarray(a, dtype=np.float32)
    if not np.isfinite(a).all():
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise ValueError(
            f"{name} (shape {shape_text}) has {bad} non-finite values (NaN or inf) after conversion to float32"
        )
    return a


def primvar_array(label: str, kind: str, values, n: int, count_name: str) -> np.ndarray:
    """A checked primvar array of ``n`` elements of ``kind``."""
    if kind in ("vector3f", "color3f"):
        return check_array(label, values, shape=(n, 3), shape_text=f"[{count_name}, 3] = [{n}, 3]")
    return check_array(label, values, shape=(n,), shape_text=f"[{count_name}] = [{n}]", kind=kind)


def extent(lo: np.ndarray, hi: np.ndarray):
    """Return a ``Vt.Vec3fArray`` extent ``[min, max]`` from two float arrays of shape [3]."""
    return Vt.Vec3fArray([Gf.Vec3f(*(float(v) for v in lo)), Gf.Vec3f(*(float(v) for v in hi))])


def export_layer(layer, target: Path) -> None:
    """Export ``layer`` to ``target`` atomically: a temporary file in the same folder with the same extension (so USD
    picks the same format), then ``os.replace``."""
    tmp = target.with_name(f".{target.name}.tmp{target.suffix}")
    try:
        try:
            exported = layer.Export(str(tmp))
        except Tf.ErrorException as exc:  # a failed write (disk full, read-only folder): an OSError naming the file
            raise _write_error(str(exc), target) from None
        if not exported:
            raise _write_error("", target)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise


def _write_error(text: str, target: Path) -> OSError:
    """The OSError of a layer export that failed with USD's error ``text``: its errno when the text names one (disk
    full, read-only file system, permission denied), else EIO."""
    for code in (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EDQUOT):
        if os.strerror(code) in text:
            return OSError(code, os.strerror(code), str(target))
    return OSError(errno.EIO, "USD could not export the layer", str(target))


def identifier(name: str) -> str:
    """A valid USD identifier made of ``name``."""
    return Tf.MakeValidIdentifier(name)


def check_primvar_kinds(kinds: dict, label: str) -> None:
    """ValueError unless every ``{name: kind}`` has a kind of PRIMVAR_KINDS and a valid USD name (``displayColor``:
    kind color3f)."""
    for pv_name, kind in kinds.items():
        if kind not in PRIMVAR_KINDS:
            raise ValueError(f"{label} {pv_name!r} has kind {kind!r}; allowed: {', '.join(PRIMVAR_KINDS)}")
        if not (isinstance(pv_name, str) and Sdf.Path.IsValidNamespacedIdentifier(pv_name)):
            raise ValueError(f"{label} name {pv_name!r} is not a valid USD identifier")
        if pv_name == "displayColor" and kind != "color3f":
            raise ValueError(f"{label} displayColor must have kind 'color3f', got {kind!r}")


def points_samples(handle, positions, velocities, primvars) -> list:
    """Checked per-frame samples ``[(attribute, kind, Vt value)]`` of a Points prim: positions, velocities, primvars
    and the extent of the spheres of the points' widths."""
    n = handle.point_count
    shape3 = f"[point_count, 3] = [{n}, 3]"
    x = check_array("positions", positions, shape=(n, 3), shape_text=shape3)
    samples = [("points", "points", Vt.Vec3fArray.FromNumpy(x))]
    if velocities is not None:
        v = check_array("velocities", velocities, shape=(n, 3), shape_text=shape3)
        samples.append(("velocities", "vector3f", Vt.Vec3fArray.FromNumpy(v)))
    for pv_name, values in (primvars or {}).items():
        kind = handle.primvar_kinds.get(pv_name)
        if kind is None:
            raise ValueError(
                f"primvar {pv_name!r} was not declared in add_points (declared: {sorted(handle.primvar_kinds)})"
            )
        a = primvar_array(f"primvar {pv_name!r}", kind, values, n, "point_count")
        samples.append((f"primvars:{pv_name}", kind, vt_array(kind, a)))
    if n:
        r = 0.5 * handle._widths[:, None]
        samples.append(("extent", "extent", extent((x - r).min(axis=0), (x + r).max(axis=0))))
    return samples


def mesh_samples(handle, points, faces, velocities, normals, face_primvars, vertex_primvars):
    """Checked per-frame samples ``[(attribute, kind, Vt value)]`` of a mesh, its topology samples
    ``[(prim path, attribute, kind, Vt value)]`` (None without faces), vertex and face counts."""
    x = check_array("points", points, shape=(-1, 3), shape_text="[vertex_count, 3]")
    nv = int(x.shape[0])
    samples = [("points", "points", Vt.Vec3fArray.FromNumpy(x))]
    topology = None
    if faces is None:
        if not handle._has_topology:
            raise ValueError(f"write_mesh({handle.path!r}): the first call must pass faces")
        if nv != handle.vertex_count:
            raise ValueError(
                f"points has shape [{nv}, 3] but the current topology has {handle.vertex_count} vertices; "
                "pass faces when the vertex count changes"
            )
        face_kinds = {k: v for k, v in (face_primvars or {}).items() if k != "displayColor"}
        if face_kinds:
            raise ValueError("face_primvars are written with the topology: pass faces too")
        nf = handle._face_count
    else:
        f = check_array("faces", faces, shape=(-1, 3), shape_text="[triangle_count, 3]", kind="int")
        if f.size and (f.min() < 0 or f.max() >= nv):
            raise ValueError(f"faces has vertex indices outside [0, {nv}) (vertex_count = {nv})")
        nf = int(f.shape[0])
        topology = [
            (handle.path, "faceVertexCounts", "int", Vt.IntArray.FromNumpy(np.full(nf, 3, np.int32))),
            (handle.path, "faceVertexIndices", "int", Vt.IntArray.FromNumpy(f.reshape(-1))),
        ]
    shape3 = f"[vertex_count, 3] = [{nv}, 3]"
    if velocities is not None:
        v = check_array("velocities", velocities, shape=(nv, 3), shape_text=shape3)
        samples.append(("velocities", "vector3f", Vt.Vec3fArray.FromNumpy(v)))
    if normals is not None:
        if handle.normals is None:
            raise ValueError(f"mesh {handle.path} was declared without normals")
        n_expected = 3 * nf if handle.normals == "faceVarying" else nv
        label = "[3 x triangle_count, 3]" if handle.normals == "faceVarying" else "[vertex_count, 3]"
        nrm = check_array("normals", normals, shape=(n_expected, 3), shape_text=f"{label} = [{n_expected}, 3]")
        samples.append(("normals", "normals", Vt.Vec3fArray.FromNumpy(nrm)))
    for pv, values in (face_primvars or {}).items():
        kind = handle.face_primvar_kinds.get(pv)
        if kind is None:
            raise ValueError(f"face primvar {pv!r} was not declared in add_mesh({handle.path!r})")
        a = primvar_array(f"face primvar {pv!r}", kind, values, nf, "triangle_count")
        if pv == "displayColor":  # may change every frame
            samples.append((f"primvars:{pv}", kind, vt_array(kind, a)))
        else:
            topology.append((handle.path, f"primvars:{pv}", kind, vt_array(kind, a)))
    for pv, values in (vertex_primvars or {}).items():
        kind = handle.vertex_primvar_kinds.get(pv)
        if kind is None:
            raise ValueError(f"vertex primvar {pv!r} was not declared in add_mesh({handle.path!r})")
        a = primvar_array(f"vertex primvar {pv!r}", kind, values, nv, "vertex_count")
        samples.append((f"primvars:{pv}", kind, vt_array(kind, a)))
    lo, hi = (x.min(axis=0), x.max(axis=0)) if nv else (np.zeros(3), np.zeros(3))
    samples.append(("extent", "extent", extent(lo, hi)))
    return samples, topology, nv, nf


def sparse_points_samples(handle, positions, widths, normals, primvars) -> list:
    """Checked samples ``[(attribute, kind, Vt value)]`` of a Points prim whose count changes per frame (a
    SparsePointsHandle's): points, widths, normals, every declared primvar and the extent of the points."""
    x = check_array("positions", positions, shape=(-1, 3), shape_text="[n, 3]")
    n = len(x)
    w = check_array("widths", widths, shape=(n,), shape_text=f"[n] = [{n}]")
    nrm = check_array("normals", normals, shape=(n, 3), shape_text=f"[n, 3] = [{n}, 3]")
    values = dict(primvars or {})
    if set(values) != set(handle.primvar_kinds):
        raise ValueError(f"primvars {sorted(values)} must be the declared ones {sorted(handle.primvar_kinds)}")
    samples = [("points", "points", vt_array("points", x)), ("widths", "float", vt_array("float", w))]
    samples.append(("normals", "normals", vt_array("normals", nrm)))
    for pv_name, kind in handle.primvar_kinds.items():
        a = primvar_array(f"primvar {pv_name!r}", kind, values[pv_name], n, "n")
        samples.append((f"primvars:{pv_name}", kind, vt_array(kind, a)))
    lo, hi = (x.min(axis=0), x.max(axis=0)) if n else (np.zeros(3), np.zeros(3))
    samples.append(("extent", "extent", extent(lo, hi)))
    return samples


def instancer_samples(positions, velocities, orientations, scales, ids) -> list:
    """Checked samples ``[(attribute, kind, Vt value)]`` of a PointInstancer with one prototype: positions,
    velocities, orientations (quaternions (x, y, z, w) [n, 4], as half-precision quath), uniform scales [n] (as
    float3), protoIndices (all 0), ids (int64) and the extent of the instances' spheres of diameter ``scales``."""
    x = check_array("positions", positions, shape=(-1, 3), shape_text="[n, 3]")
    n = len(x)
    v = check_array("velocities", velocities, shape=(n, 3), shape_text=f"[n, 3] = [{n}, 3]")
    q = check_array("orientations", orientations, shape=(n, 4), shape_text=f"[n, 4] = [{n}, 4]")
    sc = check_array("scales", scales, shape=(n,), shape_text=f"[n] = [{n}]")
    i = np.asarray(ids, dtype=np.int64).reshape(-1)
    if i.shape != (n,):
        raise ValueError(f"ids has shape {list(i.shape)}; expected [n] = [{n}]")
    r = 0.5 * sc[:, None]
    lo, hi = ((x - r).min(axis=0), (x + r).max(axis=0)) if n else (np.zeros(3), np.zeros(3))
    return [
        ("positions", "points", vt_array("points", x)),
        ("velocities", "vector3f", vt_array("vector3f", v)),
        ("orientations", "quath", Vt.QuathArray.FromNumpy(np.ascontiguousarray(q, dtype=np.float16))),  # x, y, z, w
        ("scales", "float3", Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(np.repeat(sc[:, None], 3, axis=1)))),
        ("protoIndices", "int", Vt.IntArray.FromNumpy(np.zeros(n, np.int32))),
        ("ids", "int64", Vt.Int64Array.FromNumpy(i)),
        ("extent", "extent", extent(lo, hi)),
    ]


def subset_samples(handle, subsets: dict | None, nf: int) -> list:
    """Topology samples ``[(prim path, "indices", "int", Vt value)]`` of the declared face subsets of a mesh of ``nf``
    faces from ``{subset name: face indices}``; a declared subset left out is empty."""
    out = []
    for name, idx in (subsets or {}).items():
        if name not in handle.subsets:
            raise ValueError(f"subset {name!r} was not declared in add_mesh({handle.path!r})")
        i = check_array(f"subset {name!r}", idx, shape=(-1,), shape_text="[k]", kind="int")
        if i.size and (i.min() < 0 or i.max() >= nf):
            raise ValueError(f"subset {name!r} has face indices outside [0, {nf})")
        out.append((f"{handle.path}/{name}", "indices", "int", Vt.IntArray.FromNumpy(i)))
    for name in sorted(set(handle.subsets) - set(subsets or {})):  # a subset left out is empty
        out.append((f"{handle.path}/{name}", "indices", "int", Vt.IntArray()))
    return out


def pose_values(translation, orientation):
    """(Gf.Vec3d translation, Gf.Quatf unit orientation) of a translation (3 numbers) and a quaternion (x, y, z, w)
    (normalised); ValueError when not finite or the quaternion is zero."""
    t = np.asarray(translation, dtype=np.float64)
    q = np.asarray(orientation, dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,) or not (np.isfinite(t).all() and np.isfinite(q).all()):
        raise ValueError(f"translation (3 numbers) and orientation (4 numbers) must be finite, got {t!r}, {q!r}")
    norm = float(np.linalg.norm(q))
    if norm == 0.0:
        raise ValueError("orientation must be a non-zero quaternion (x, y, z, w)")
    q = q / norm
    return Gf.Vec3d(*t.tolist()), Gf.Quatf(float(q[3]), Gf.Vec3f(float(q[0]), float(q[1]), float(q[2])))

"""Reading USD files: the pdsim metadata, run id and files of a cache, the check that a clip cache's run folder is
there (:func:`check_cache_files`, called by every pdsim reader), world-space points of a prim, flattening a cache into
one layer, the USD tet-mesh input reader, and the errors of every ``pxr.UsdValidation`` validator on a stage."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom

from ..errors import GeometryError, PdsimError

try:
    from pxr import UsdValidation
except ImportError as error:  # usd-core older than 24.11: usd_problems raises RuntimeError
    UsdValidation = None
    _USD_VALIDATION_MISSING = error
else:
    _USD_VALIDATION_MISSING = None

__all__ = [
    "CacheError",
    "cache_files",
    "cache_run",
    "check_cache_files",
    "flatten_cache",
    "pdsim_info",
    "read_tet_mesh",
    "usd_problems",
    "world_points",
]


class CacheError(PdsimError, OSError):
    """A cache that cannot be read or packed: its run folder is missing, or the disk has no room to pack it. The
    message is one line naming the files and what to do."""


def pdsim_info(path: Path) -> dict:
    """The ``customLayerData pdsim`` dictionary of the top-level layer at ``path`` (empty when there is none)."""
    layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
    if layer is None:
        raise ValueError(f"{str(path)!r} is not a USD layer")
    return dict(layer.customLayerData.get("pdsim", {}))


def cache_run(path: str | os.PathLike) -> str | None:
    """The run id (``customLayerData pdsim:run``) of the pdsim cache at ``path``; None when it names none."""
    run = pdsim_info(Path(path)).get("run")
    return None if run is None else str(run)


def cache_files(path: str | os.PathLike) -> list[Path]:
    """Every file of the cache at ``path``: the top-level layer and the files of the run folder it names (manifest and
    frame layers); what to copy or archive to move a cache (``flatten_cache`` makes a single file instead)."""
    path = Path(path)
    layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
    if layer is None:
        raise FileNotFoundError(f"no USD layer at {str(path)!r}")
    info = dict(layer.customLayerData.get("pdsim", {}))
    files = [path]
    if info.get("frames"):
        check_cache_files(path)
        run_dir = (path.parent / info["frames"]).resolve()
        files += sorted(p for p in run_dir.iterdir() if p.is_file() and not p.name.startswith("."))
    return files


def check_cache_files(path: str | os.PathLike) -> None:
    """CacheError unless every file the cache at ``path`` refers to is there: a clip-layout cache
    (``customLayerData pdsim:frames``) needs its run folder and manifest beside it; a packed cache (one file) and USD
    files that are not pdsim caches pass. Without this check a stage whose clips are missing opens with no points."""
    path = Path(path)
    try:
        info = pdsim_info(path)
    except (ValueError, Tf.ErrorException):
        return  # not a layer: the caller's own open reports it
    frames = info.get("frames")
    if not frames:
        return
    run_dir = (path.parent / str(frames)).resolve()
    if not any((run_dir / f"manifest{suffix}").is_file() for suffix in (".usdc", ".usda")):
        folder = Path(str(frames).removeprefix("./"))
        raise CacheError(
            f"{str(path)!r} is a clip-layout cache whose frames are in the folder {str(folder)!r} beside it, which is "
            f"missing: copy that folder next to {path.name} (or pack the cache into one file with "
            f"'pdsim pack {path.name}' where both are)"
        )


def world_points(prim, time) -> np.ndarray:
    """The ``points`` of a PointBased prim at ``time`` in world space [stage units], float64 [n, 3]: the stored
    float32 points through the prim's local-to-world transform in double precision (pdsim writes each body's points
    relative to a double ``xformOp:translate``)."""
    pts = np.asarray(UsdGeom.PointBased(prim).GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    xf = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time), dtype=np.float64)
    return pts @ xf[:3, :3] + xf[3, :3]  # USD matrices act on row vectors


def flatten_cache(path: str | os.PathLike, out: str | os.PathLike) -> None:
    """Write the cache at ``path`` as one self-contained layer at ``out`` (value clips baked into time samples). The
    whole animation is held in memory while flattening (pdsim.output.usd_pack.pack_cache packs a cache clip by clip
    instead)."""
    check_cache_files(path)
    stage = Usd.Stage.Open(os.fspath(path))
    layer = stage.Flatten()
    layer.customLayerData = {}
    if not layer.Export(os.fspath(out)):
        raise OSError(f"USD could not export the flattened cache to {os.fspath(out)!r}")


def read_tet_mesh(path: str, prim_path: str | None):
    """Vertices [m] (float64 [v, 3], world space) and tetrahedra (int64 [t, 4]) of a ``UsdGeom.TetMesh`` in the
    stage at ``path`` (the prim at ``prim_path``, or the first TetMesh); GeometryError when there is none. The USD
    input reader of pdsim.fem.load_tet_mesh."""
    try:
        stage = Usd.Stage.Open(path)
    except Exception as exc:  # noqa: BLE001 (pxr raises Tf errors)
        raise GeometryError(f"{path}: cannot open USD stage ({exc})") from None
    if prim_path is not None:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.TetMesh):
            raise GeometryError(f"{path}: no UsdGeom.TetMesh at {prim_path}")
    else:
        prim = next((p for p in stage.Traverse() if p.IsA(UsdGeom.TetMesh)), None)
        if prim is None:
            raise GeometryError(f"{path}: the stage holds no UsdGeom.TetMesh")
    tm = UsdGeom.TetMesh(prim)
    time = Usd.TimeCode.Default()
    pts = np.asarray(tm.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    idx = np.asarray(tm.GetTetVertexIndicesAttr().Get(time) or [], dtype=np.int64).reshape(-1, 4)
    xf = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time), dtype=np.float64)
    pts = pts @ xf[:3, :3] + xf[3, :3]  # USD matrices act on row vectors
    return pts, idx


def usd_problems(path: str | os.PathLike) -> list[str]:
    """Run every validator registered with ``pxr.UsdValidation`` on the stage at ``path``.

    Args:
        path: A USD file.

    Returns:
        One string per validation error of type Error (``"Error: (<validator>.<error>) <message>"``); warnings and
        infos are left out. Empty when the stage is valid.

    Raises:
        RuntimeError: ``pxr.UsdValidation`` is missing (usd-core older than 24.11) or has no validators registered.
        pxr.Tf.ErrorException: The file cannot be opened as a USD stage.
    """
    if UsdValidation is None:
        raise RuntimeError(
            "usd_problems needs pxr.UsdValidation (usd-core >= 24.11); the installed usd-core does not provide it"
        ) from _USD_VALIDATION_MISSING
    missing = [
        n for n in ("ValidationRegistry", "ValidationContext", "ValidationErrorType") if not hasattr(UsdValidation, n)
    ]
    if missing:
        raise RuntimeError(f"pxr.UsdValidation lacks {', '.join(missing)}; unsupported usd-core version")

    if not Path(path).is_file():
        raise FileNotFoundError(f"no USD file at {str(path)!r}")
    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    if not validators:
        raise RuntimeError("pxr.UsdValidation has no validators registered (plugins not found)")
    context = UsdValidation.ValidationContext(validators=validators)
    errors = context.Validate(stage)
    error_type = UsdValidation.ValidationErrorType.Error
    return [e.GetErrorAsString() for e in errors if e.GetType() == error_type]

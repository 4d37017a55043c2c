"""Packing a clip-layout cache (a top-level layer plus its run folder of frame layers) into one self-contained layer.

:func:`pack_cache` copies the top-level layer without its value-clip metadata, then the samples of every clip (each
frame layer, each topology layer) as time samples of the packed layer, clip by clip. What it holds in memory: the
declarations of the top-level layer, one clip layer at a time, and the samples added since the last save; the packed
layer is a crate file saved every ``chunk_bytes`` of clip files, and USD's crate format appends the new samples to the
file and keeps the saved ones on disk (read back lazily), so the peak memory does not grow with the frame count
(docs/cache_format.md has the figures). A ``.usda`` cache is packed as text, which USD writes whole at each save.

The packed layer plays as the clip cache does at every frame: an attribute a clip does not sample takes its
manifest's default at that clip's frame (an empty array, the empty extent), as USD resolves value clips. It is written
to a temporary name beside ``out`` and renamed over it only when complete; the free space is checked first, and any
failure removes the temporary file and leaves ``out`` and the clip cache as they were. The temporary file of a packing
that was killed is removed by the next packing to the same ``out``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

from pxr import Sdf, Tf

from .usd_files import CacheError, check_cache_files, pdsim_info

__all__ = ["pack_cache", "packed_size_estimate"]

CHUNK_BYTES = 64 * 1024 * 1024  # clip bytes copied between two saves of the packed layer
_SPARE_BYTES = 16 * 1024 * 1024  # free space kept beyond the estimate


def packed_size_estimate(path: str | os.PathLike) -> int:
    """Bytes the packed cache of the clip cache at ``path`` needs on disk: the top-level layer plus every file of its
    run folder (the packed layer holds the same samples; crate's deduplication can only make it smaller)."""
    path = Path(path)
    info = pdsim_info(path)
    total = path.stat().st_size
    run_dir = path.parent / str(info.get("frames", ""))
    if info.get("frames") and run_dir.is_dir():
        total += sum(p.stat().st_size for p in run_dir.iterdir() if p.is_file())
    return total


def _clips(top: Sdf.Layer, folder: Path) -> list[tuple[Path, float, Path | None]]:
    """(clip file, its frame, its manifest) of every clip of the top-level layer ``top`` in ``folder``, in order of
    the clip sets (topology sets first) and frames."""
    world = top.GetPrimAtPath("/World")
    clips = dict(world.GetInfo("clips") or {}) if world is not None else {}
    out = []
    for meta in clips.values():
        manifest = meta.get("manifestAssetPath")
        manifest = None if manifest is None else folder / manifest.path
        template = meta.get("templateAssetPath")
        if template:
            start, end = float(meta["templateStartTime"]), float(meta["templateEndTime"])
            stride = float(meta.get("templateStride", 1.0))
            digits = template.count("#")
            frame = start
            while frame <= end:
                name = template.replace("#" * digits, f"{round(frame):0{digits}d}")
                out.append((folder / name, frame, manifest))
                frame += stride
        else:
            assets = list(meta.get("assetPaths", []))
            for time, index in meta.get("active", []):
                out.append((folder / assets[int(index)].path, float(time), manifest))
    return out


def _manifest_defaults(manifest: Path | None, cache: dict) -> dict:
    """{attribute path: (type name, default value or None)} of the manifest layer at ``manifest`` (read once)."""
    if manifest is None:
        return {}
    if manifest not in cache:
        layer = Sdf.Layer.OpenAsAnonymous(str(manifest))
        if layer is None:
            raise CacheError(f"the manifest {str(manifest)!r} of the cache is missing or unreadable")
        entries = {}

        def collect(path):
            if path.IsPropertyPath():
                spec = layer.GetAttributeAtPath(path)
                if spec is not None:
                    entries[path] = (spec.typeName, spec.default if spec.HasDefaultValue() else None)

        layer.Traverse(Sdf.Path.absoluteRootPath, collect)
        cache[manifest] = entries
    return cache[manifest]


def _attribute(layer: Sdf.Layer, path: Sdf.Path, type_name):
    """The attribute spec at ``path`` of ``layer``, made (with an ``over`` for a missing prim) when absent."""
    spec = layer.GetAttributeAtPath(path)
    if spec is None:
        prim = layer.GetPrimAtPath(path.GetPrimPath()) or Sdf.CreatePrimInLayer(layer, path.GetPrimPath())
        spec = Sdf.AttributeSpec(prim, path.name, type_name)
    return spec


def _copy_clip(out: Sdf.Layer, clip: Path, frame: float, defaults: dict) -> None:
    """Copy the time samples of the clip layer ``clip`` (active at ``frame``) into ``out``; the manifest attributes it
    does not sample get their manifest default at ``frame``."""
    layer = Sdf.Layer.OpenAsAnonymous(str(clip))
    if layer is None:
        raise CacheError(f"the clip {str(clip)!r} of the cache is missing or unreadable")
    sampled = set()

    def copy(path):
        if not path.IsPropertyPath():
            return
        spec = layer.GetAttributeAtPath(path)
        times = layer.ListTimeSamplesForPath(path)
        if spec is None or not times:
            return
        _attribute(out, path, spec.typeName)
        for t in times:
            out.SetTimeSample(path, t, layer.QueryTimeSample(path, t))
        sampled.add(path)

    layer.Traverse(Sdf.Path.absoluteRootPath, copy)
    for path, (type_name, default) in defaults.items():
        if path not in sampled and default is not None:
            _attribute(out, path, type_name)
            out.SetTimeSample(path, frame, default)


def _command(source: Path, target: Path) -> str:
    """The ``pdsim pack`` command that packs ``source`` into ``target``."""
    return f"pdsim pack {source}" + ("" if target == source else f" {target}")


def _free_bytes(folder: Path) -> int:
    """Free bytes on the file system of ``folder``."""
    return shutil.disk_usage(folder).free


def _check_space(source: Path, target: Path) -> None:
    """CacheError when the folder of ``target`` has less free space than the packed cache of ``source`` needs."""
    need = packed_size_estimate(source) + _SPARE_BYTES
    free = _free_bytes(target.parent)
    if free < need:
        raise CacheError(
            f"cannot pack {str(source)!r} into one file: about {need / 1e6:.1f} MB needed, {free / 1e6:.1f} MB free "
            f"in {str(target.parent)!r}; the clip cache is kept and plays as it is (free space, then "
            f"'{_command(source, target)}')"
        )


def pack_cache(
    path: str | os.PathLike, out: str | os.PathLike | None = None, *, chunk_bytes: int = CHUNK_BYTES
) -> Path:
    """Pack the clip-layout cache at ``path`` into one self-contained layer at ``out``.

    Args:
        path: The top-level layer of a clip-layout cache (its run folder beside it).
        out: Where to write the packed cache; None or ``path`` itself: replace ``path`` and then remove its run
            folder (and the frames folder when it is empty). The format follows the extension of ``out``.
        chunk_bytes: Clip bytes copied between two saves of the packed layer (bounds the memory, see the module
            docstring).

    Returns:
        The path of the packed cache.

    Raises:
        CacheError: The run folder is missing, the disk has too little free space, or USD cannot write the file; the
            message is one line, and ``out`` (an earlier cache there too) and the clip cache are left as they were.
    """
    source = Path(path)
    target = source if out is None else Path(out)
    if not source.is_file():
        raise CacheError(f"no cache at {str(source)!r}")
    try:
        info = pdsim_info(source)
    except (ValueError, Tf.ErrorException):
        raise CacheError(f"{str(source)!r} is not a USD layer (a pdsim cache: .usdc, .usda or .usd)") from None
    if not info.get("frames"):
        raise CacheError(f"{str(source)!r} is already one self-contained file (no clip folder to pack)")
    check_cache_files(source)
    target.parent.mkdir(parents=True, exist_ok=True)
    _check_space(source, target)
    run_dir = (source.parent / str(info["frames"])).resolve()

    for stale in target.parent.glob(f".{target.name}.pack-*.tmp*"):  # left by a packing that was killed
        _remove(stale)
    tmp = target.with_name(f".{target.name}.pack-{os.getpid()}.tmp{target.suffix}")
    top = Sdf.Layer.OpenAsAnonymous(str(source))
    try:
        head = Sdf.Layer.CreateAnonymous(f"pdsim_packed{target.suffix.lower()}")
        head.TransferContent(top)
        world = head.GetPrimAtPath("/World")
        for key in ("clips", "clipSets"):
            if world is not None and world.HasInfo(key):
                world.ClearInfo(key)
        packed_info = {k: v for k, v in info.items() if k not in ("run", "frames", "definedAt")}
        packed_info["layout"] = "packed"
        head.customLayerData = {"pdsim": packed_info}
        if not head.Export(str(tmp)):
            raise CacheError(f"USD could not write {str(tmp)!r}")
        del head
        layer = Sdf.Layer.FindOrOpen(str(tmp))
        manifests: dict = {}
        pending = 0
        for clip, frame, manifest in _clips(top, source.parent):
            _copy_clip(layer, clip, frame, _manifest_defaults(manifest, manifests))
            pending += clip.stat().st_size
            if pending >= chunk_bytes:
                _save(layer, tmp)
                pending = 0
        _save(layer, tmp)
        del layer
        os.replace(tmp, target)
        opened = Sdf.Layer.Find(str(target))
        if opened is not None:  # this process has the old file open (a stage held elsewhere): show it the new one
            with contextlib.suppress(Exception):
                opened.Reload(force=True)
    except CacheError:
        _remove(tmp)
        raise
    except Exception as exc:  # noqa: BLE001 (pxr raises Tf errors; OSError for a full disk)
        _remove(tmp)
        free = _free_bytes(target.parent)
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise CacheError(
            f"cannot pack {str(source)!r} into {str(target)!r}: {reason} ({free / 1e6:.1f} MB free); the clip cache "
            f"is kept and plays as it is (then '{_command(source, target)}')"
        ) from None
    if target == source:
        shutil.rmtree(run_dir, ignore_errors=True)
        with contextlib.suppress(OSError):
            run_dir.parent.rmdir()  # the frames folder, when no other run is left in it
    return target


def _save(layer: Sdf.Layer, tmp: Path) -> None:
    if not layer.Save():
        raise CacheError(f"USD could not save {str(tmp)!r}")


def _remove(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        tmp.unlink()

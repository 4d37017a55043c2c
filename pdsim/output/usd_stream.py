"""The files of a streamed USD cache: one layer per finished frame, the topology clips, the manifests of the clip sets,
the top-level layer with the value-clip metadata, the run folders, and the reopening of a cache to continue it.

``FrameStream`` owns what is on disk; :class:`pdsim.output.usd.UsdCache` authors the samples of each frame into a
``PendingFrame`` and hands the finished ones to :meth:`FrameStream.finish`. The layout on disk, the crash safety and
the re-run rules are in the docstring of pdsim/output/usd.py and in docs/cache_format.md.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Vt

from .usd_files import cache_run, pdsim_info
from .usd_pack import pack_cache
from .usd_values import SUFFIXES, export_layer, extent

CACHE_FORMAT_VERSION = 2  # customLayerData pdsim:cacheFormat (1: the single-layer caches without value clips)
FRAME_DIGITS = 6


class FrameLayer:
    """The samples of one frame for one clip set: an anonymous layer of ``over`` prim specs with time samples at the
    frame."""

    def __init__(self, frame: int, suffix: str):
        self.frame = frame
        self.layer = Sdf.Layer.CreateAnonymous(f"pdsim_frame{suffix}")

    def sample(self, prim_path: str, name: str, type_name, value) -> str:
        """Author ``value`` at the frame on ``prim_path.name``; returns the attribute path."""
        prim = self.layer.GetPrimAtPath(prim_path) or Sdf.CreatePrimInLayer(self.layer, prim_path)
        spec = prim.attributes.get(name) if name in prim.attributes else None
        if spec is None:
            spec = Sdf.AttributeSpec(prim, name, type_name)
        self.layer.SetTimeSample(spec.path, float(self.frame), value)
        return str(spec.path)


class PendingFrame:
    """What one frame writes: the layer of the per-frame clip set, the layers of the topology clip sets that change at
    the frame, and samples of the top-level layer (visibility) applied when the frame finishes."""

    def __init__(self, frame: int, suffix: str):
        self.frame = frame
        self.suffix = suffix
        self.samples = FrameLayer(frame, suffix)
        self.topology: dict[str, FrameLayer] = {}
        self.top_samples: list = []  # (Usd attribute of the top-level layer, value)

    def topology_layer(self, clip_set: str) -> FrameLayer:
        layer = self.topology.get(clip_set)
        if layer is None:
            layer = self.topology[clip_set] = FrameLayer(self.frame, self.suffix)
        return layer


class FrameStream:
    """The run folder, frame layers, manifests and top-level layer of one cache at ``path``.

    Args:
        path: The cache's top-level layer; its extension picks the format (frame layers: ``.usda`` for a ``.usda``
            cache, else ``.usdc``).
        start_frame: First frame of the cache.
        save_interval_s: Minimum wall-clock time between rewrites of the top-level layer [s] (0: after every frame).
        metadata: Extra ``customLayerData`` under ``pdsim`` (the dictionary is read at every top-level write).

    :meth:`start` begins a new run, :meth:`reopen` takes over the run of an existing cache.
    """

    def __init__(self, path: Path, *, start_frame: int, save_interval_s: float, metadata: dict, pack: bool = False):
        self.path = path
        self.pack = pack  # on success, pack the run into one file at ``path`` and remove the run folder
        self.start_frame = start_frame
        self.save_interval_s = save_interval_s
        self.metadata = metadata
        self.suffix = ".usda" if path.suffix.lower() == ".usda" else ".usdc"  # frame layers: text for text caches
        self.frames_dir = path.with_name(f"{path.stem}.frames")
        self.partial_path = path.with_name(f"{path.stem}.partial{path.suffix}")
        # clip set -> {attribute path: Sdf type name} of every attribute its clips sample; "default" holds the
        # per-frame samples, "topology_<mesh>" the topology of a mesh (or of a surface's fragment prims)
        self.manifests: dict[str, dict[str, object]] = {"default": {}}
        self.manifests_written: dict[str, int] = {}  # clip set -> size of its manifest on disk
        self.topology_frames: dict[str, list[int]] = {}  # topology clip set -> frames of its clips
        self.defined_at: dict[str, int] = {}  # prim path -> the frame being written when it was defined (> start)
        self.last_finished: int | None = None
        self.frames_written = 0
        self.top_written = None  # last frame whose top-level layer is on disk
        self.last_save_end = time.monotonic()
        self.staged = False  # an earlier cache is at ``path``: replace it only on success
        self.top_path = path
        self.run_id = ""
        self.run_dir = self.frames_dir

    def start(self) -> None:
        """Begin a new run: a fresh run folder; the top-level layer goes to :attr:`partial_path` when ``path``
        exists."""
        self.staged = self.path.exists()
        self.top_path = self.partial_path if self.staged else self.path
        self.run_id = self._new_run_id()
        self.run_dir = self.frames_dir / self.run_id
        self.run_dir.mkdir(parents=True)

    def reopen(self, frame: int, run: str | None, fps: float, up_axis: str, meters_per_unit: float):
        """Take over the cache at ``path`` (or ``partial_path``) at its finished frame ``frame`` (``append_frame`` of
        UsdCache): its run folder, manifests and topology clips up to ``frame``. Returns its top-level layer as an
        anonymous layer without the clip metadata and without what the frames after ``frame`` added (samples, the
        prims defined while writing them)."""
        candidates = [p for p in (self.partial_path, self.path) if p.is_file()]
        if not candidates:
            raise FileNotFoundError(f"no cache at {str(self.path)!r} (nor {str(self.partial_path)!r}) to continue")
        infos = {p: pdsim_info(p) for p in candidates}
        if run is not None:
            matches = [p for p in candidates if infos[p].get("run") == run]
            if not matches:
                found = ", ".join(f"{p.name}: {infos[p].get('run')!r}" for p in candidates)
                raise ValueError(f"no cache beside {str(self.path)!r} holds the run {run!r} (found {found})")
            top = matches[0]
        else:
            top = candidates[0]
        info = infos[top]
        if info.get("cacheFormat") != CACHE_FORMAT_VERSION or not info.get("run") or not info.get("frames"):
            raise ValueError(f"{str(top)!r} is not a pdsim cache of format {CACHE_FORMAT_VERSION}")
        self.staged = top == self.partial_path
        self.top_path = top
        self.run_id = str(info["run"])
        self.run_dir = self.frames_dir / self.run_id
        if (self.path.parent / str(info["frames"])).resolve() != self.run_dir.resolve() or not self.run_dir.is_dir():
            raise ValueError(f"the run folder {str(self.run_dir)!r} of {str(top)!r} is missing")

        source = Sdf.Layer.OpenAsAnonymous(str(top))
        checks = {
            "fps": (source.timeCodesPerSecond, fps),
            "start_frame": (source.startTimeCode, float(self.start_frame)),
            "up_axis": (source.pseudoRoot.GetInfo("upAxis"), up_axis),
            "meters_per_unit": (source.pseudoRoot.GetInfo("metersPerUnit"), meters_per_unit),
        }
        for name, (theirs, mine) in checks.items():
            if theirs != mine:
                raise ValueError(f"{name}={mine!r} differs from the cache's {theirs!r} ({str(top)!r})")
        last = int(source.endTimeCode)
        if not self.start_frame <= frame <= last:
            raise ValueError(
                f"append_frame={frame} is not a finished frame of {str(top)!r} (frames {self.start_frame}..{last})"
            )
        old_clips = dict(source.GetPrimAtPath("/World").GetInfo("clips") or {})

        # the top-level layer without its clips and without what the frames after ``frame`` added
        layer = Sdf.Layer.CreateAnonymous(f"pdsim_cache{self.path.suffix.lower()}")
        layer.TransferContent(source)
        del source
        world = layer.GetPrimAtPath("/World")
        for key in ("clips", "clipSets"):
            if world.HasInfo(key):
                world.ClearInfo(key)
        layer.customLayerData = {}
        defined = {str(k): int(v) for k, v in dict(info.get("definedAt", {})).items()}
        removed = sorted((p for p, f in defined.items() if f > frame), key=lambda p: p.count("/"))
        for path in removed:
            spec = layer.GetPrimAtPath(path)
            if spec is not None:  # None: its parent went first
                del layer.GetPrimAtPath(Sdf.Path(path).GetParentPath()).nameChildren[spec.name]
        self.defined_at = {p: f for p, f in defined.items() if f <= frame}

        def drop_later(path):
            if path.IsPropertyPath():
                for t in layer.ListTimeSamplesForPath(path):
                    if t > frame:
                        layer.EraseTimeSample(path, t)

        layer.Traverse(Sdf.Path.absoluteRootPath, drop_later)

        def gone(attr_path: str) -> bool:
            return any(attr_path.startswith(p + "/") or attr_path.startswith(p + ".") for p in removed)

        # clip sets: the manifests on disk (they may name attributes first sampled after ``frame``: harmless) and the
        # topology clips up to ``frame``
        folder = top.parent
        for clip_set, meta in old_clips.items():
            manifest_path = meta.get("manifestAssetPath")
            entries: dict[str, object] = {}
            if manifest_path is not None:
                manifest = Sdf.Layer.OpenAsAnonymous(str(folder / manifest_path.path))
                if manifest is None:
                    raise ValueError(f"the manifest {manifest_path.path!r} of {str(top)!r} is missing")

                def collect(path, manifest=manifest, entries=entries):
                    if path.IsPropertyPath():
                        spec = manifest.GetAttributeAtPath(path)
                        if spec is not None:
                            entries[str(path)] = spec.typeName

                manifest.Traverse(Sdf.Path.absoluteRootPath, collect)
            kept = {p: t for p, t in entries.items() if not gone(p)}
            self.manifests[clip_set] = kept
            self.manifests_written[clip_set] = len(kept) if len(kept) == len(entries) else -1
            if clip_set != "default":
                frames = [round(float(t)) for t, _ in meta.get("active", [])]
                frames = [f for f in frames if f <= frame]
                if frames:
                    self.topology_frames[clip_set] = frames

        self.last_finished = frame
        return layer

    def remove_frames_after(self, frame: int) -> None:
        """Delete the frame and topology layers of the run folder after ``frame`` (the top-level layer no longer names
        them)."""
        for child in self.run_dir.iterdir():
            parts = child.name.split(".")
            if (
                len(parts) >= 3
                and child.is_file()
                and len(parts[-2]) == FRAME_DIGITS
                and parts[-2].isdigit()
                and int(parts[-2]) > frame
            ):
                child.unlink()

    def _new_run_id(self) -> str:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        base = f"run-{stamp}-{os.getpid()}"
        run, k = base, 1
        while (self.frames_dir / run).exists():
            run, k = f"{base}-{k}", k + 1
        return run

    def finish(self, frame: int, pending: dict, layer) -> None:
        """Write the frames after the last finished one up to ``frame``: their layers (taken out of ``pending``,
        frame -> PendingFrame; an empty one for a frame without samples), their top-level samples into ``layer``, the
        manifests that grew, then the top-level layer ``layer`` (unless ``save_interval_s`` holds it back)."""
        first = self.start_frame if self.last_finished is None else self.last_finished + 1
        for f in range(first, frame + 1):
            done = pending.pop(f, None) or PendingFrame(f, self.suffix)
            export_layer(done.samples.layer, self.frame_file(f))
            for clip_set, topology in done.topology.items():
                export_layer(topology.layer, self.topology_file(clip_set, f))
                self.topology_frames.setdefault(clip_set, []).append(f)
            for attr, value in done.top_samples:
                attr.Set(value, float(f))
        self.last_finished = frame
        self.frames_written += frame + 1 - first
        for clip_set, manifest in self.manifests.items():
            if manifest and len(manifest) != self.manifests_written.get(clip_set):
                self._write_manifest(clip_set)
        if self.save_interval_s == 0 or time.monotonic() - self.last_save_end >= self.save_interval_s:
            self.write_top(layer)

    def frame_file(self, frame: int) -> Path:
        return self.run_dir / f"frame.{frame:0{FRAME_DIGITS}d}{self.suffix}"

    def topology_file(self, clip_set: str, frame: int) -> Path:
        return self.run_dir / f"{clip_set}.{frame:0{FRAME_DIGITS}d}{self.suffix}"

    def _manifest_file(self, clip_set: str) -> Path:
        name = "manifest" if clip_set == "default" else f"{clip_set}.manifest"
        return self.run_dir / f"{name}{self.suffix}"

    def _write_manifest(self, clip_set: str) -> None:
        manifest = Sdf.Layer.CreateAnonymous(f"pdsim_manifest{self.suffix}")
        for path, type_name in self.manifests[clip_set].items():
            p = Sdf.Path(path)
            prim = manifest.GetPrimAtPath(p.GetPrimPath()) or Sdf.CreatePrimInLayer(manifest, p.GetPrimPath())
            spec = Sdf.AttributeSpec(prim, p.name, type_name)
            # the value of a frame whose clip has no sample (a fragment prim before it appears): no geometry
            if p.name == "extent":  # the empty box, as UsdGeom computes it for no points
                big = float(np.finfo(np.float32).max)
                spec.default = extent(np.full(3, big), np.full(3, -big))
            elif type_name.isArray:
                spec.default = type_name.defaultValue
        export_layer(manifest, self._manifest_file(clip_set))
        self.manifests_written[clip_set] = len(self.manifests[clip_set])

    def _relative(self, target: Path) -> str:
        return "./" + target.relative_to(self.path.parent).as_posix()

    def write_top(self, layer) -> None:
        """Export the top-level layer ``layer`` with the clip metadata of the finished frames (atomic replace)."""
        if self.last_finished is None:
            return
        out = Sdf.Layer.CreateAnonymous(f"pdsim_top{self.path.suffix.lower()}")
        out.TransferContent(layer)
        template = self._relative(self.run_dir / f"frame.{'#' * FRAME_DIGITS}{self.suffix}")
        clips = {
            "default": {
                "primPath": "/World",
                "manifestAssetPath": Sdf.AssetPath(self._relative(self._manifest_file("default"))),
                "templateAssetPath": template,
                "templateStartTime": float(self.start_frame),
                "templateEndTime": float(self.last_finished),
                "templateStride": 1.0,
            }
        }
        for clip_set, frames in self.topology_frames.items():
            clips[clip_set] = {
                "primPath": "/World",
                "manifestAssetPath": Sdf.AssetPath(self._relative(self._manifest_file(clip_set))),
                "assetPaths": Sdf.AssetPathArray([self._relative(self.topology_file(clip_set, f)) for f in frames]),
                "active": Vt.Vec2dArray([Gf.Vec2d(f, i) for i, f in enumerate(frames)]),
            }
        world = out.GetPrimAtPath("/World")
        world.SetInfo("clips", clips)
        # topology sets first: each attribute takes its values from the first clip set whose manifest names it
        world.SetInfo("clipSets", Sdf.StringListOp.CreateExplicit([*self.topology_frames, "default"]))
        out.endTimeCode = float(self.last_finished)
        info = {
            "cacheFormat": CACHE_FORMAT_VERSION,
            "run": self.run_id,
            "frames": self._relative(self.run_dir),
            "framesWritten": self.last_finished - self.start_frame + 1,
        }
        if self.defined_at:
            info["definedAt"] = dict(self.defined_at)
        info.update(self.metadata)
        out.customLayerData = {"pdsim": info}
        export_layer(out, self.top_path)
        self.top_written = self.last_finished
        self.last_save_end = time.monotonic()

    def close(self, layer, success: bool) -> None:
        """End the run: without a finished frame remove the run folder (and the frames folder when empty); else write
        the top-level layer ``layer`` when it is behind and, on ``success``, move it to ``path`` and remove the
        leftovers of earlier runs (see UsdCache.close)."""
        if self.last_finished is None:
            shutil.rmtree(self.run_dir, ignore_errors=True)
            with contextlib.suppress(OSError):
                self.frames_dir.rmdir()  # only when empty
            return
        if self.top_written != self.last_finished:
            self.write_top(layer)
        if success:
            if self.pack:
                self._pack()
                return
            if self.staged:
                os.replace(self.partial_path, self.path)
                self.top_path = self.path
            elif self.partial_path.is_file():  # a failed run's leftover, superseded by this one
                self.partial_path.unlink()
            self._remove_unreferenced_runs()

    def _pack(self) -> None:
        """Pack the finished run into one file at ``path`` (pdsim.output.usd_pack: a temporary file renamed over
        ``path``), then remove the partial top-level layer, the run folder and the runs no layer refers to. A failed
        pack (CacheError) leaves ``path`` and this run's clip cache as they were."""
        pack_cache(self.top_path, self.path)
        if self.partial_path.is_file():  # this run's staged layer, or a failed run's leftover superseded by it
            self.partial_path.unlink()
        self.top_path = self.path
        shutil.rmtree(self.run_dir, ignore_errors=True)
        if self.frames_dir.is_dir():
            self._remove_unreferenced_runs()
            with contextlib.suppress(OSError):
                self.frames_dir.rmdir()  # only when empty

    def _remove_unreferenced_runs(self) -> None:
        """Remove the run folders under the frames folder that no top-level layer beside ``path`` names."""
        keep = {self.run_id}
        for suffix in SUFFIXES:
            for candidate in (
                self.path.with_suffix(suffix),
                self.path.with_name(f"{self.path.stem}.partial{suffix}"),
            ):
                if not candidate.is_file() or candidate == self.path:
                    continue
                with contextlib.suppress(Exception):
                    run = cache_run(candidate)
                    if run:
                        keep.add(run)
        for child in self.frames_dir.iterdir():
            if child.is_dir() and child.name.startswith("run-") and child.name not in keep:
                shutil.rmtree(child, ignore_errors=True)

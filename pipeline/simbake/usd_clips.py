"""Long shots as value clips (``--clips N``): frames go into clip layers of N frames each.

Beside the output ``CACHE.usdc`` the bake writes ``CACHE.clips/``::

    clip.0001.usdc ...      a complete cache (usd_writer.CacheWriter) of frames
                            [start + k N, start + (k + 1) N], one frame shared with the next
                            clip so that times between two clips interpolate as in one file
    topology.usdc           everything but the time samples (UsdUtils.StitchClipsTopology)
    manifest.usda           which attributes the clips sample (UsdUtils.StitchClipsManifest)

and the output itself is a small layer: the stage metadata, provenance and QA summary, the
topology as a sublayer, and ``clips`` metadata on ``/World`` (``assetPaths``, ``active``,
``times``: the identity, ``manifestAssetPath``, ``primPath``) that stitch the clips together. Opening it
reads back the same values at every frame as a single-file cache. Each clip is written and
closed before the next begins, so memory does not grow with the length of the shot. The
clip folder is written beside under a temporary name and renamed into place with the output
(and a bake's other outputs: simbake.outputs).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

from pxr import Sdf, UsdUtils, Vt

from .outputs import Outputs, check_outputs
from .usd_values import merge_into, to_usd
from .usd_writer import CacheWriter, StreamingWriter, one_thread

__all__ = ["ClipsWriter"]


class ClipsWriter(StreamingWriter):
    """The interface of :class:`CacheWriter`, writing clip layers of ``clip_frames`` frames."""

    def __init__(self, path: str | Path, *, clip_frames: int, fps: float, start_frame: int,
                 end_frame: int, bodies: Sequence, cloths: Sequence = (),
                 provenance: Mapping[str, Any] = {}, instancers: Sequence = (), outputs=None):
        if int(clip_frames) < 1:
            raise ValueError(f"clip_frames must be >= 1, got {clip_frames}")
        self.path = Path(path)
        self.clip_frames = int(clip_frames)
        self.start_frame, self.end_frame = int(start_frame), int(end_frame)
        self.instancer_groups = tuple(instancers)
        self._args = dict(fps=fps, bodies=bodies, cloths=cloths, provenance=provenance, instancers=instancers)
        self._fps = float(fps)
        self._provenance = dict(provenance)
        self._layer_data: dict = {}
        self.folder = self.path.with_name(f"{self.path.stem}.clips")
        self._own_outputs = outputs is None  # alone (not one of a bake's outputs): commits itself
        if self._own_outputs:
            check_outputs([self.path], [self.folder], ())
        self.outputs = Outputs() if outputs is None else outputs
        self._tmp = self.outputs.temp_dir(self.folder)
        self._clips: list[tuple[str, int, int]] = []  # file name, first frame, last frame
        self._writer: CacheWriter | None = None
        self._done = False

    # -- frames -------------------------------------------------------------------------------

    def _open(self, first: int) -> None:
        last = min(first + self.clip_frames, self.end_frame)  # shares `last` with the next clip
        name = f"clip.{len(self._clips) + 1:04d}.usdc"
        self._writer = self._clip_writer(self._tmp / name, first, last)
        self._clips.append((name, first, last))

    def _clip_writer(self, path: Path, first: int, last: int) -> StreamingWriter:
        return CacheWriter(path, start_frame=first, end_frame=last, **self._args)

    def write_frame(self, frame: int, *args, **kwargs) -> None:
        if self._writer is None:
            self._open(frame)
        self._writer.write_frame(frame, *args, **kwargs)
        if frame == self._clips[-1][2]:  # the clip is complete
            self._writer.close()
            self._writer = None
            if frame < self.end_frame:  # the shared frame opens the next clip
                self._open(frame)
                self._writer.write_frame(frame, *args, **kwargs)

    def add_layer_data(self, data: Mapping[str, Any]) -> None:
        merge_into(self._layer_data, dict(data))

    # -- finishing ----------------------------------------------------------------------------

    def close(self) -> Path:
        if self._done:
            return self.path
        try:
            if self._writer is not None or not self._clips or self._clips[-1][2] != self.end_frame:
                raise RuntimeError(f"{self.path}: frames missing; nothing saved")
            files = [str(self._tmp / name) for name, _, _ in self._clips]
            # stitching is a parallel reduction whose order sets the layer's internal order, and
            # with it the .usdc bytes (the same content): stitched on one thread into a scratch
            # layer, then parsed from its text (one fixed order) and exported as the topology
            scratch = self._tmp / ".stitched.usdc"
            with one_thread():
                stitched = Sdf.Layer.CreateNew(str(scratch))
                UsdUtils.StitchClipsTopology(stitched, files)
                parsed = Sdf.Layer.CreateAnonymous(".usda")
                parsed.ImportFromString(stitched.ExportToString())
                del stitched
                scratch.unlink()
                parsed.Export(str(self._tmp / "topology.usdc"))
                topology = Sdf.Layer.FindOrOpen(str(self._tmp / "topology.usdc"))
                for root, name in self._clip_roots():
                    manifest = Sdf.Layer.CreateNew(str(self._tmp / name))
                    UsdUtils.StitchClipsManifest(manifest, topology, files, Sdf.Path(root))
                    manifest.Save()
            result = self._result_layer()
            # the folder and the output, into place together (with a bake's other outputs)
            self.outputs.stage(self._tmp, self.folder)
            self.outputs.write(self.path, lambda tmp: _export(result, tmp))
            if self._own_outputs:
                self.outputs.commit()
        except BaseException:
            self.abort()
            raise
        self._done = True
        return self.path

    def _clip_roots(self) -> list[tuple[str, str]]:
        """(prim path that carries the clips metadata, its manifest's file name)."""
        return [("/World", "manifest.usda")]

    def _set_clips(self, layer: Sdf.Layer, root: str, manifest: str) -> None:
        """``clips`` metadata on ``root`` (an over): every clip, stage time = clip time."""
        folder = f"./{self.folder.name}"
        # stage time is clip time everywhere: one identity mapping, no jumps (a jump would add
        # a sample just before each clip's start)
        times = [(float(self.start_frame), float(self.start_frame)), (float(self.end_frame), float(self.end_frame))]
        prim = Sdf.CreatePrimInLayer(layer, root)  # an over; authored without a stage,
        prim.SetInfo("clips", {"default": {  # so nothing resolves before the files exist
            "assetPaths": Sdf.AssetPathArray([f"{folder}/{name}" for name, _, _ in self._clips]),
            "primPath": root,
            "active": Vt.Vec2dArray([(float(a), float(k)) for k, (_, a, _) in enumerate(self._clips)]),
            "times": Vt.Vec2dArray(times),
            "manifestAssetPath": Sdf.AssetPath(f"{folder}/{manifest}"),
        }})

    def _result_layer(self) -> Sdf.Layer:
        """The output: metadata, the topology sublayered, clips metadata on /World."""
        folder = f"./{self.folder.name}"
        first = Sdf.Layer.FindOrOpen(str(self._tmp / self._clips[0][0]))
        layer = Sdf.Layer.CreateAnonymous(".usda")
        root = layer.pseudoRoot
        for key in ("upAxis", "metersPerUnit", "kilogramsPerUnit"):
            root.SetInfo(key, first.pseudoRoot.GetInfo(key))
        layer.timeCodesPerSecond = layer.framesPerSecond = self._fps
        layer.startTimeCode, layer.endTimeCode = float(self.start_frame), float(self.end_frame)
        layer.defaultPrim = "World"
        data = to_usd(self._provenance, "customLayerData")
        merge_into(data, to_usd(self._layer_data, "customLayerData"))
        layer.customLayerData = data
        layer.subLayerPaths.append(f"{folder}/topology.usdc")
        self._set_clips(layer, "/World", "manifest.usda")
        return layer

    def abort(self) -> None:
        if self._done:
            return
        if self._writer is not None:
            self._writer.abort()
            self._writer = None
        shutil.rmtree(self._tmp, ignore_errors=True)
        if self._own_outputs:
            self.outputs.abort()


def _export(layer: Sdf.Layer, path: str) -> None:
    fmt = "usda" if path.endswith(".usda") else "usdc"
    if not layer.Export(path, args={"format": fmt}):
        raise OSError(f"{path}: writing the clips layer failed")


class ShotClipsWriter(ClipsWriter):
    """``--clips N`` for a USD shot: each clip is a shot cache layer of ``over``s
    (usd_layer.ShotLayerWriter) holding N + 1 frames' time samples at the input's own prim
    paths; the topology (the overs, xformOpOrder, scale, the level-set Volumes: everything
    but the samples) is sublayered by the output, which carries the input's stage metadata
    and ``clips`` metadata on each root prim the cache writes under (one manifest each).
    Composed over the input it reads back the same values at every frame as the single-file
    shot cache."""

    def __init__(self, path: str | Path, scene, *, clip_frames: int, provenance: Mapping[str, Any] = {},
                 level_sets: Mapping | None = None, outputs=None):
        shot = scene.shot
        super().__init__(path, clip_frames=clip_frames, fps=shot.time_codes_per_second,
                         start_frame=scene.start_frame, end_frame=scene.end_frame, bodies=(),
                         provenance=provenance, outputs=outputs)
        self._scene = scene
        self._level_sets = dict(level_sets or {})
        self._roots: list[tuple[str, str]] = []
        self._breaks: dict[str, int] = {}

    def write_joint_breaks(self, breaks: Mapping[str, int]) -> None:
        """Broken joints go into the output layer itself (the clips carry no joint prims): its
        time samples are stronger than the clips', and read as in a single-file shot cache."""
        self._breaks.update(breaks)

    def _clip_writer(self, path: Path, first: int, last: int) -> StreamingWriter:
        from .usd_layer import ShotLayerWriter

        writer = ShotLayerWriter(path, self._scene, provenance=self._provenance, start_frame=first,
                                 end_frame=last, level_sets=self._level_sets)
        if not self._roots:  # the root prims of everything sampled: one clip set each
            roots = sorted({str(Sdf.Path(p).GetPrefixes()[0]) for p in writer.sampled_prims}) or ["/World"]
            self._roots = [(root, "manifest.usda" if len(roots) == 1 else f"manifest.{root[1:]}.usda")
                           for root in roots]
        return writer

    def _clip_roots(self) -> list[tuple[str, str]]:
        return self._roots

    def _result_layer(self) -> Sdf.Layer:
        from .usd_layer import author_joint_breaks, copy_stage_metadata

        layer = Sdf.Layer.CreateAnonymous(".usda")
        copy_stage_metadata(layer, self._scene.shot)
        data = to_usd(self._provenance, "customLayerData")
        merge_into(data, to_usd(self._layer_data, "customLayerData"))
        layer.customLayerData = data
        layer.subLayerPaths.append(f"./{self.folder.name}/topology.usdc")
        for root, manifest in self._roots:
            self._set_clips(layer, root, manifest)
        author_joint_breaks(layer, self._breaks, self.start_frame, self.end_frame)
        return layer

"""The driver: scene and assets in, a core World stepped frame by frame, frames out to USD.

No physics here: the world is built from the validated scene, stepped in C++ (with the GIL
released) one frame at a time, and each frame's poses are handed to the USD writer, which
streams them to disk. A non-finite state stops the bake with SimulationError and no file.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import _core, __version__
from .assets import BodyAsset, ClothAsset, load_assets, load_cloth
from .errors import OutputError, SceneError, SimulationError
from .files import check_output_path, describe
from .limits import check_budget, check_scene
from .qa import QualityRecorder, qa_path
from .scene import Scene
from .usd_writer import BodyPrim, CacheWriter, ClothPrim

USD_SUFFIXES = (".usdc", ".usda", ".usd")


@dataclass
class BakeStats:
    output: Path
    frames: int                    # frames written, the initial state included
    substeps: int                  # solver steps taken in all
    wall_seconds: float
    max_penetration: float         # deepest penetration seen at any written frame (m): bodies
                                   # into bodies or the ground, cloth past a surface
    profile: dict = field(default_factory=dict)  # wall seconds per stage of the step
    qa: Path | None = None         # the QA sidecar (CACHE.qa.json), None when qa=False
    warnings: list = field(default_factory=list)  # QA figures over their thresholds, one line each

    def summary(self) -> str:
        return (f"{self.frames} frames, {self.substeps} substeps, {self.wall_seconds:.2f} s wall, "
                f"max penetration {self.max_penetration * 1000:.3f} mm -> {self.output}")


def build_world(scene: Scene, assets: list[BodyAsset], cloths: list[ClothAsset] = (),
                **settings) -> "_core.World":
    """The core World for the scene; `settings` go to _core.World (max_substep, threads, ...)."""
    world = _core.World(gravity=np.array(scene.gravity), **settings)
    if scene.ground is not None:
        world.set_ground(scene.ground.height, scene.ground.friction, scene.ground.restitution)
    for index, (body, asset) in enumerate(zip(scene.bodies, assets)):
        volume = asset.mass_properties["volume"]
        mass = body.mass if body.mass is not None else body.density * volume
        try:
            world.add_body(asset.level_set, asset.samples, asset.mass_properties, mass,
                           np.array(body.position), np.array(body.orientation),
                           np.array(body.linear_velocity), np.array(body.angular_velocity),
                           body.friction, body.restitution, body.kinematic)
        except ValueError as error:
            raise SceneError(scene.source, f"bodies[{index}]", str(error)) from None
        if body.keys:
            world.set_kinematic_track(index, [k.time for k in body.keys],
                                      np.array([k.position for k in body.keys]),
                                      np.array([k.orientation for k in body.keys]))
    for index, (cloth, asset) in enumerate(zip(scene.cloths, cloths)):
        try:
            world.add_cloth(asset.vertices, asset.triangles, cloth.area_density, cloth.model,
                            cloth.stretch_stiffness, cloth.poisson_ratio, cloth.bend_stiffness,
                            cloth.damping, cloth.strain_limit, cloth.compression, list(cloth.pinned),
                            cloth.integrator, cloth.friction, cloth.thickness,
                            self_collision=cloth.self_collision)
        except ValueError as error:
            raise SceneError(scene.source, f"cloths[{index}]", str(error)) from None
    return world


def _provenance(scene: Scene) -> dict:
    return {
        "simbake": {
            "version": __version__,
            "scene": scene.path.name,
            "scene_sha256": scene.hash(),
            "solver": {"substeps": scene.substeps, "fps": scene.fps},
            # for viewers that draw it (simbake preview): the plane y = height
            "ground": {"height": scene.ground.height} if scene.ground is not None else None,
        }
    }


def bake(scene: Scene, output: str | Path, *,
         on_frame: Callable[[int, int], None] | None = None, qa: bool = True) -> BakeStats:
    """Simulate the scene and stream its USD cache to `output` (appears only when complete).

    on_frame(done, total) is called after each written frame (for progress bars). With `qa`
    (the default) every written frame's quality figures are measured (simbake.qa) and written
    beside the cache as CACHE.qa.json, summarized in its customLayerData.
    """
    output = Path(output)
    check_scene(scene)  # a Scene made in Python (or from USD) meets the same range as a file's
    check_output_path(output, USD_SUFFIXES, inputs=scene.input_files())
    if qa:
        check_output_path(qa_path(output), (".json",), inputs=scene.input_files())
    start = time.perf_counter()
    assets = load_assets(scene)
    cloths = [load_cloth(scene, i) for i in range(len(scene.cloths))]
    world = build_world(scene, assets, cloths)
    prims = [
        BodyPrim(name=body.name, points=asset.vertices,
                 face_vertex_counts=np.full(len(asset.triangles), 3, dtype=np.int32),
                 face_vertex_indices=asset.triangles.reshape(-1), normals=asset.normals,
                 dynamic=(not body.kinematic or bool(body.keys) or any(body.linear_velocity)
                          or any(body.angular_velocity)))
        for body, asset in zip(scene.bodies, assets)
    ]
    cloth_prims = [ClothPrim(name=cloth.name, face_vertex_counts=np.full(len(asset.triangles), 3, dtype=np.int32),
                             face_vertex_indices=asset.triangles.reshape(-1))
                   for cloth, asset in zip(scene.cloths, cloths)]
    check_budget(scene, output, scene.substeps or world.automatic_substeps(1.0 / scene.fps),
                 sum(p.dynamic for p in prims), [len(c.vertices) for c in cloths])
    try:
        return _bake(scene, output, world, assets, cloths, prims, cloth_prims, on_frame, qa, start)
    except Exception as error:
        if isinstance(error, (SceneError, SimulationError, OutputError)) or not _write_failure(error):
            raise
        raise OutputError(f"{output}: cannot write: {describe(error)}; nothing was replaced") from None


def _write_failure(error: Exception) -> bool:
    """An OSError, or USD's own report of a failed save (Tf.ErrorException)."""
    return isinstance(error, OSError) or type(error).__name__ == "ErrorException"


def _bake(scene, output, world, assets, cloths, prims, cloth_prims, on_frame, qa, start) -> BakeStats:
    frame_dt = 1.0 / scene.fps
    total = scene.frame_count
    recorder = QualityRecorder(scene) if qa else None
    pipeline_profile = {"quality": 0.0, "usd_writer": 0.0}
    max_penetration = 0.0
    with CacheWriter(output, fps=scene.fps, start_frame=scene.start_frame, end_frame=scene.end_frame,
                     bodies=prims, cloths=cloth_prims, provenance=_provenance(scene)) as writer:
        for frame in range(scene.start_frame, scene.end_frame + 1):
            frame_start = time.perf_counter()
            substeps = 0
            if frame > scene.start_frame:
                substeps = world.step_frame(frame_dt, scene.substeps)
                stats = world.statistics()
                if not stats["finite"]:
                    raise SimulationError(f"{scene.source}: the state became non-finite at frame {frame}; "
                                          "nothing was written (try more [solver] substeps)")
                max_penetration = max(max_penetration, stats["max_penetration"], stats["cloth_penetration"])
            if recorder is not None:
                measured = time.perf_counter()
                recorder.record(frame, world, substeps, measured - frame_start)
                pipeline_profile["quality"] += time.perf_counter() - measured
            written = time.perf_counter()
            translations, orientations = world.mesh_poses()
            states = [world.cloth_state(i) for i in range(len(cloths))]
            writer.write_frame(frame, translations, orientations, cloth_points=[s[0] for s in states],
                               cloth_velocities=[s[1] for s in states], cloth_normals=[s[2] for s in states])
            pipeline_profile["usd_writer"] += time.perf_counter() - written
            if on_frame:
                on_frame(frame - scene.start_frame + 1, total)
        if recorder is not None:
            writer.add_layer_data({"simbake": {"qa": recorder.layer_summary()}})
    profile = {**world.profile(), **pipeline_profile}
    sidecar, warnings = None, []
    if recorder is not None:
        summary = recorder.summary()
        max_penetration = max(summary[k]["worst"] for k in ("body_penetration", "cloth_penetration")
                              if k in summary)
        sidecar = recorder.write(output, profile)
        warnings = recorder.warnings(sidecar.name)
    return BakeStats(output=output, frames=total, substeps=int(world.statistics()["substeps"]),
                     wall_seconds=time.perf_counter() - start, max_penetration=max_penetration,
                     profile=profile, qa=sidecar, warnings=warnings)

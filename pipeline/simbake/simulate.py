"""The driver: scene and assets in, a core World stepped frame by frame, frames out to USD.

No physics here: the world is built from the validated scene, stepped in C++ (with the GIL
released) one frame at a time, and each frame's poses are handed to the USD writer, which
streams them to disk. A non-finite state stops the bake with SimulationError and no file.
"""

from __future__ import annotations

import contextlib
import gc
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import _core
from .assets import BodyAsset, ClothAsset, bake_level_set, load_assets, load_cloth
from .errors import OutputError, SceneError, SimulationError
from .files import check_output_path, describe
from .outputs import Outputs, check_outputs
from .loading import with_frames
from .limits import check_budget, check_memory_in_flight, check_scene, crowding
from .normals import corner_normals
from .qa import QualityRecorder, qa_path
from .qa_motion import MotionFigures, bounding_radius, lumped_masses, mean_edge
from .scene import JOINT_DOFS, Scene
from .usd_instancer import quaternion_rate
from .usd_writer import BodyPrim, CacheWriter, ClothPrim, InstancerGroup
from .version import __version__

USD_SUFFIXES = (".usdc", ".usda", ".usd")
INSTANCING_MODES = ("auto", "always", "never")
INSTANCING_AUTO = 100  # bodies sharing one shape from which "auto" writes a PointInstancer
MAX_THREADS = 1024     # --threads: more than any machine this runs on


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


def body_mass(body, asset: BodyAsset) -> float:
    """A body's mass (kg): given, or its density times its shape's volume."""
    return body.mass if body.mass is not None else body.density * asset.mass_properties["volume"]


def build_world(scene: Scene, assets: list[BodyAsset], cloths: list[ClothAsset] = (),
                **settings) -> "_core.World":
    """The core World for the scene; `settings` go to _core.World (max_substep, threads, ...)."""
    world = _core.World(gravity=np.array(scene.gravity), **settings)
    if scene.ground is not None:
        world.set_ground(height=scene.ground.height, friction=scene.ground.friction,
                         restitution=scene.ground.restitution)
    for index, (body, asset) in enumerate(zip(scene.bodies, assets)):
        mass = body_mass(body, asset)
        # a mesh body's level set comes with its mesh: its sharp edges are held out of cloth
        mesh = ({"mesh_vertices": asset.vertices, "mesh_triangles": asset.triangles}
                if body.shape.kind == "mesh" and asset.level_set is not None else {})
        # (a deforming body's mesh is in world coordinates: its pose is the identity)
        origin, orientation = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)) if body.deformation is not None \
            else (body.position, body.orientation)
        try:
            world.add_body(shape=asset.level_set, samples=asset.samples,
                           mass_properties=_mass_properties(body, asset, mass), mass=mass,
                           origin=np.array(origin), orientation=np.array(orientation),
                           linear_velocity=np.array(body.linear_velocity),
                           angular_velocity=np.array(body.angular_velocity), friction=body.friction,
                           restitution=body.restitution, kinematic=body.kinematic, **mesh)
        except ValueError as error:
            raise SceneError(scene.source, scene.source_key(f"bodies[{index}]"), str(error)) from None
        if body.keys:
            world.set_kinematic_track(index, [k.time for k in body.keys],
                                      np.array([k.position for k in body.keys]),
                                      np.array([k.orientation for k in body.keys]))
    for index, (cloth, asset) in enumerate(zip(scene.cloths, cloths)):
        try:
            world.add_cloth(rest=asset.vertices, triangles=asset.triangles, area_density=cloth.area_density,
                            model=cloth.model, stretch_stiffness=cloth.stretch_stiffness,
                            poisson_ratio=cloth.poisson_ratio, bend_stiffness=cloth.bend_stiffness,
                            damping=cloth.damping, strain_limit=cloth.strain_limit,
                            compression=cloth.compression, pinned=list(cloth.pinned), attached=list(cloth.attached),
                            integrator=cloth.integrator, friction=cloth.friction, thickness=cloth.thickness,
                            self_collision=cloth.self_collision)
        except ValueError as error:
            raise SceneError(scene.source, scene.source_key(f"cloths[{index}]"), str(error)) from None
    _add_joints(world, scene)
    set_deforming_frames(scene, world, assets, scene.start_frame)
    _attach_cloths(world, scene)
    return world


def _attach_cloths(world, scene: Scene) -> None:
    """Each cloth's attached points bound to their body where they are at the start frame
    (a deforming body's surface already set there)."""
    index = {b.name: i for i, b in enumerate(scene.bodies)}
    for k, cloth in enumerate(scene.cloths):
        if cloth.attached:
            try:
                world.attach_cloth(k, index[cloth.attach_to])
            except ValueError as error:
                raise SceneError(scene.source, scene.source_key(f"cloths[{k}].attach.to"), str(error)) from None


def set_deforming_frames(scene: Scene, world, assets: list[BodyAsset], frame: int) -> None:
    """Each deforming collider's surface at `frame` (Body.deformation): its vertices and their
    level set (baked at the body's voxel size, or read from the level-set cache), where the
    world's next frame ends it; at the start frame, where it starts, still."""
    for index, body in enumerate(scene.bodies):
        if body.deformation is None:
            continue
        vertices = np.ascontiguousarray(body.deformation.vertices[frame - scene.start_frame])
        level_set = bake_level_set(vertices, body.deformation.triangles, assets[index].voxel_size)
        world.set_deforming_frame(index, vertices, level_set, 1.0 / scene.fps)


def _add_joints(world, scene: Scene) -> None:
    """The scene's joints, filtered pairs and collision groups into the world."""
    index = {b.name: i for i, b in enumerate(scene.bodies)}
    for k, joint in enumerate(scene.joints):
        lower, upper = [-np.inf] * 6, [np.inf] * 6
        for dof, lo, hi in joint.limits:
            lower[JOINT_DOFS.index(dof)], upper[JOINT_DOFS.index(dof)] = lo, hi
        drives = {}
        for name, d in joint.drives:
            dof = {"linear": f"trans_{joint.axis}", "angular": f"rot_{joint.axis}"}.get(name, name)
            drives[dof] = _core.JointDrive(stiffness=d.stiffness, damping=d.damping,
                                           target_position=d.target_position, target_velocity=d.target_velocity,
                                           max_force=d.max_force, acceleration=d.type == "acceleration")
        try:
            world.add_joint(type=joint.type, body0=index.get(joint.body0, -1), body1=index.get(joint.body1, -1),
                            local_position0=np.array(joint.local_position0),
                            local_rotation0=np.array(joint.local_rotation0),
                            local_position1=np.array(joint.local_position1),
                            local_rotation1=np.array(joint.local_rotation1), axis=joint.axis,
                            lower_limit=joint.lower_limit, upper_limit=joint.upper_limit,
                            cone_angle0=joint.cone_angle0, cone_angle1=joint.cone_angle1,
                            min_distance=joint.min_distance, max_distance=joint.max_distance,
                            dof_lower=lower, dof_upper=upper, drives=drives, break_force=joint.break_force,
                            break_torque=joint.break_torque, enabled=joint.enabled,
                            collision_enabled=joint.collision_enabled)
        except ValueError as error:
            raise SceneError(scene.source, scene.source_key(f"joints[{k}]"), str(error)) from None
    for a, b in scene.filtered_pairs:
        world.filter_pair(index[a], index[b])
    if scene.collision_groups:
        world.set_collision_groups([[index[name] for name, groups in scene.collision_groups if g in groups]
                                    for g in range(len(scene.group_filters))],
                                   [list(f) for f in scene.group_filters])


def _joint_breaks(scene: Scene, world, frame: int, broken: dict) -> None:
    """Joints that broke during the frame just stepped, by name, with the frame."""
    if not scene.joints:
        return
    for j, enabled in enumerate(world.joint_states()["enabled"]):
        if not enabled and scene.joints[j].enabled and scene.joints[j].name not in broken:
            broken[scene.joints[j].name] = frame


def _write_joint_breaks(scene: Scene, writer, broken: dict) -> None:
    """A TOML cache records breaks in customLayerData["simbake"]["joints_broken"] (name: frame);
    a shot's layer writes physics:jointEnabled false over the joint's prim from that frame."""
    if not broken:
        return
    if scene.shot is None:
        writer.add_layer_data({"simbake": {"joints_broken": dict(sorted(broken.items()))}})
        return
    paths = {j.name: j.prim_path for j in scene.joints}
    writer.write_joint_breaks({paths[name]: frame for name, frame in broken.items()})


@dataclass
class _FrameState:
    frame: int
    translations: np.ndarray            # (bodies, 3) mesh origins (m)
    orientations: np.ndarray            # (bodies, 4) (w, x, y, z)
    cloth_points: list                  # per cloth (n, 3) (m)
    cloth_velocities: list              # per cloth (n, 3) (m/s), the solver's
    cloth_normals: list                 # per cloth (n, 3)


def _frame_state(frame: int, world, cloth_count: int) -> _FrameState:
    translations, orientations = world.mesh_poses()
    states = [world.cloth_state(i) for i in range(cloth_count)]
    return _FrameState(frame, np.array(translations), np.array(orientations),
                       [np.array(s[0]) for s in states], [np.array(s[1]) for s in states],
                       [np.array(s[2]) for s in states])


def _write_frame(writer, state: _FrameState, following: _FrameState | None, fps: float,
                 previous_rates: list) -> None:
    """One frame to the cache. Cloth velocities are the motion over the frame, (x[f+1] - x[f])
    x fps, so that a renderer's motion blur (points + velocity x time) lands on the next
    frame's points; the last frame keeps the solver's own velocities. Bodies' velocities and
    angular velocities (for PointInstancers) are their poses' motion over the frame too; the
    last frame repeats the one before (`previous_rates` carries it)."""
    velocities = state.cloth_velocities
    if following is not None:
        velocities = [(b - a) * fps for a, b in zip(state.cloth_points, following.cloth_points)]
    extra = {}
    if getattr(writer, "instancer_groups", ()):
        if following is not None:
            previous_rates[:] = [(following.translations - state.translations) * fps,
                                 quaternion_rate(state.orientations, following.orientations, 1.0 / fps)]
        elif not previous_rates:
            previous_rates[:] = [np.zeros_like(state.translations), np.zeros_like(state.translations)]
        extra = {"body_velocities": previous_rates[0], "body_angular_velocities": previous_rates[1]}
    writer.write_frame(state.frame, state.translations, state.orientations, cloth_points=state.cloth_points,
                       cloth_velocities=velocities, cloth_normals=state.cloth_normals, **extra)


def _mass_properties(body, asset: BodyAsset, mass: float) -> dict:
    """The shape's mass properties (at unit density), with an authored centre of mass and
    inertia (a USD shot's PhysicsMassAPI) in their place; the core scales inertia by
    mass / volume, so an authored inertia I goes in as I * volume / mass."""
    if body.center_of_mass is None and body.inertia is None:
        return asset.mass_properties
    props = dict(asset.mass_properties)
    if body.center_of_mass is not None:
        props["center"] = np.array(body.center_of_mass, dtype=np.float64)
    if body.inertia is not None:
        props["inertia"] = np.array(body.inertia, dtype=np.float64) * props["volume"] / mass
    return props


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


def _moves(body) -> bool:
    """A body whose pose changes over the bake (dynamic, keyed or kinematic with a velocity)."""
    return not body.kinematic or bool(body.keys) or any(body.linear_velocity) or any(body.angular_velocity)


def instancer_groups(scene: Scene, instancing: str = "auto") -> list[InstancerGroup]:
    """Bodies that share one shape (the same primitive and size, or the same mesh file), as
    PointInstancers: with "always" every shape two or more bodies share, with "auto" those
    shared by at least INSTANCING_AUTO bodies, with "never" none."""
    if instancing not in INSTANCING_MODES:
        raise SceneError(scene.source, "--instancing", f"must be one of {', '.join(INSTANCING_MODES)}, got {instancing!r}")
    least = {"always": 2, "auto": INSTANCING_AUTO, "never": None}[instancing]
    if least is None:
        return []
    shared: dict = {}
    for index, body in enumerate(scene.bodies):
        shape = body.shape
        if shape.kind == "mesh" and shape.mesh_path is None:
            continue  # an inline mesh (a USD shot's collider)
        shared.setdefault((shape.kind, shape.radius, shape.size, shape.mesh_path), []).append(index)
    names = {b.name for b in scene.bodies} | {c.name for c in scene.cloths}
    groups = []
    for (kind, _, _, mesh), members in shared.items():
        if len(members) < least:
            continue
        base = f"{(mesh.stem if mesh is not None else kind)}_instances"
        base = base if base[:1].isalpha() else f"_{base}"
        base = "".join(c if c.isalnum() or c == "_" else "_" for c in base)
        name = base
        while name in names:
            name += "_"
        names.add(name)
        groups.append(InstancerGroup(name, tuple(members)))
    return groups


def _level_set_bodies(scene: Scene, groups) -> list[int]:
    """Bodies whose baked .vdb a bake copies beside the cache: the mesh bodies, not drawn by a
    PointInstancer, that something can touch (simbake.assets.needs_level_set)."""
    from .assets import needs_level_set

    instanced = {i for g in groups for i in g.bodies}
    return [i for i, b in enumerate(scene.bodies)
            if i not in instanced and b.shape.kind == "mesh" and needs_level_set(scene, i)]


def level_set_folder(output: Path) -> Path:
    return output.with_name(f"{output.stem}.vdb")


def _level_set_files(scene: Scene, assets, output: Path, groups, outputs: Outputs) -> dict:
    """The baked .vdb of each (non-instanced) mesh body, copied into a temp folder beside the
    output (staged in `outputs` as OUTPUT_STEM.vdb/): body index -> its final path."""
    import shutil

    from .assets import level_set_cache_path

    wanted = [(i, scene.bodies[i], assets[i]) for i in _level_set_bodies(scene, groups)
              if assets[i].level_set is not None and assets[i].voxel_size > 0]
    if not wanted:
        return {}
    final = level_set_folder(output)
    tmp = outputs.temp_dir(final)
    files: dict[int, Path] = {}
    written: dict[int, str] = {}  # id(level set) -> file name: copies of one mesh share a file
    for index, body, asset in wanted:
        if body.deformation is not None:  # one grid a frame
            files[index] = deforming_level_set_files(scene, body, asset, tmp, final)
            continue
        name = written.get(id(asset.level_set))
        if name is None:
            shell = max(body.shape.thickness, asset.voxel_size) if body.shape.thickness > 0 else 0.0
            cached = level_set_cache_path(asset.vertices, asset.triangles, asset.voxel_size, thickness=shell)
            stem = body.shape.mesh_path.stem if body.shape.mesh_path is not None else body.name
            name = f"{stem}.{cached.stem[:12]}.vdb"
            if cached.is_file():
                shutil.copyfile(cached, tmp / name)  # the very file the solver read or baked
            else:
                asset.level_set.write(str(tmp / name))
            written[id(asset.level_set)] = name
        files[index] = final / name
    outputs.stage(tmp, final)  # renamed into place with the cache
    return files


class _SharedNormals:
    """corner_normals, computed once per distinct mesh (a pile of boxes has one)."""

    def __init__(self):
        self._known: dict[bytes, np.ndarray] = {}

    def __call__(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        v, t = np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(triangles, dtype=np.int64)
        key = b"%d:" % len(v) + v.tobytes() + t.tobytes()
        if key not in self._known:
            self._known[key] = corner_normals(v, t)
        return self._known[key]


def deforming_level_set_files(scene: Scene, body, asset: BodyAsset, tmp: Path, final: Path) -> tuple[Path, ...]:
    """A deforming collider's level set at every frame (baked, or read from the level-set
    cache: the very grids the solver reads), copied into `tmp` as NAME.FRAME.HASH.vdb: their
    final paths in `final`, in frame order from the start frame."""
    import shutil

    from .assets import level_set_cache_path

    paths = []
    d = body.deformation
    for k, vertices in enumerate(d.vertices):
        vertices = np.ascontiguousarray(vertices)
        level_set = bake_level_set(vertices, d.triangles, asset.voxel_size)
        cached = level_set_cache_path(vertices, d.triangles, asset.voxel_size)
        name = f"{body.name}.{scene.start_frame + k:04d}.{cached.stem[:12]}.vdb"
        if cached.is_file():
            shutil.copyfile(cached, tmp / name)
        else:
            level_set.write(str(tmp / name))
        paths.append(final / name)
    return tuple(paths)


def _body_prim_files(scene: Scene, body, level_set) -> dict:
    """A body prim's level set (a file, or a deforming body's file a frame) and a deforming
    body's points at every frame (usd_writer.BodyPrim)."""
    if body.deformation is None:
        return {"level_set": str(level_set or "")}
    return {"frames": body.deformation.vertices, "first_frame": scene.start_frame,
            "level_sets": tuple(str(p) for p in level_set or ())}


def _cache_writer(scene: Scene, output: Path, assets, cloths, instancing: str = "auto",
                  clips: int | None = None, level_sets: dict | None = None, outputs: Outputs | None = None):
    """The writer of the scene's cache: a standalone stage (version 1) for a TOML scene, a
    layer of overs for a USD shot (simbake.usd_layer)."""
    level_sets = level_sets or {}
    if scene.shot is not None:
        if clips is not None:
            from .usd_clips import ShotClipsWriter

            return ShotClipsWriter(output, scene, clip_frames=clips, provenance=_provenance(scene),
                                   level_sets=level_sets, outputs=outputs)
        from .usd_layer import ShotLayerWriter

        return ShotLayerWriter(output, scene, provenance=_provenance(scene), level_sets=level_sets,
                               outputs=outputs)
    normals = _SharedNormals()
    prims = [
        BodyPrim(name=body.name, points=asset.vertices,
                 face_vertex_counts=np.full(len(asset.triangles), 3, dtype=np.int32),
                 face_vertex_indices=asset.triangles.reshape(-1),
                 normals=normals(asset.vertices, asset.triangles),  # hard edges hard
                 interpolation="faceVarying",
                 dynamic=_moves(body), **_body_prim_files(scene, body, level_sets.get(index)))
        for index, (body, asset) in enumerate(zip(scene.bodies, assets))
    ]
    cloth_prims = [ClothPrim(name=cloth.name, face_vertex_counts=np.full(len(asset.triangles), 3, dtype=np.int32),
                             face_vertex_indices=asset.triangles.reshape(-1))
                   for cloth, asset in zip(scene.cloths, cloths)]
    settings = dict(fps=scene.fps, start_frame=scene.start_frame, end_frame=scene.end_frame,
                    bodies=prims, cloths=cloth_prims, provenance=_provenance(scene),
                    instancers=instancer_groups(scene, instancing), outputs=outputs)
    if clips is not None:
        from .usd_clips import ClipsWriter

        return ClipsWriter(output, clip_frames=clips, **settings)
    return CacheWriter(output, **settings)


def _check_outputs(scene: Scene, output: Path, qa: bool, shot: Path | None, instancing: str,
                   clips: int | None) -> None:
    """Every output, and every folder the bake replaces, against every input and each other,
    before any work (simbake.outputs)."""
    if shot is not None and scene.shot is None:
        raise SceneError(shot, "", "--shot needs a USD shot as input (.usd, .usda, .usdc)")
    inputs = scene.input_files() + (scene.shot.dependencies if scene.shot is not None else ())
    files = [(output, USD_SUFFIXES)] + ([(qa_path(output), (".json",))] if qa else []) \
        + ([(shot, USD_SUFFIXES)] if shot is not None else [])
    for path, suffixes in files:
        check_output_path(path, suffixes, inputs=inputs)
    groups = [] if scene.shot is not None else instancer_groups(scene, instancing)
    folders = ([output.with_name(f"{output.stem}.clips")] if clips is not None else []) \
        + ([level_set_folder(output)] if _level_set_bodies(scene, groups) else [])
    check_outputs([path for path, _ in files], folders, inputs)


def _bake_frames(scene: Scene, world, writer, recorder, on_frame, pipeline_profile: dict, assets=()) -> float:
    """Step the world frame by frame into `writer`; returns the deepest penetration seen (m).
    Each frame is written once the next is stepped (its velocities are the motion over it)."""
    frame_dt = 1.0 / scene.fps
    total = scene.frame_count
    max_penetration = 0.0
    pending = None  # the last frame stepped, written once the next one is known
    rates: list = []  # bodies' velocities over the frame written last
    cloth_count = len(scene.cloths)
    broken: dict = {}  # joint name: the first frame it is broken at
    deforming = any(b.deformation is not None for b in scene.bodies)
    if deforming:
        pipeline_profile["deforming_level_sets"] = 0.0
    for frame in range(scene.start_frame, scene.end_frame + 1):
        frame_start = time.perf_counter()
        substeps = 0
        if frame > scene.start_frame:
            if deforming:
                baked = time.perf_counter()
                set_deforming_frames(scene, world, assets, frame)
                pipeline_profile["deforming_level_sets"] += time.perf_counter() - baked
            substeps = world.step_frame(frame_dt, scene.substeps)
            # (with QA the penetration is its independent measure: the solver's is not asked for)
            stats = world.statistics(penetrations=recorder is None)
            if not stats["finite"]:
                raise SimulationError(f"{scene.source}: the state became non-finite at frame {frame}; "
                                      "nothing was written (try more [solver] substeps)")
            if recorder is None:
                max_penetration = max(max_penetration, stats["max_penetration"], stats["cloth_penetration"])
            check_memory_in_flight(scene, frame)
            _joint_breaks(scene, world, frame, broken)
        written = time.perf_counter()
        stepping = written - frame_start
        current = _frame_state(frame, world, cloth_count)
        pipeline_profile["usd_writer"] += time.perf_counter() - written
        if recorder is not None:
            measured = time.perf_counter()
            recorder.record(frame, world, substeps, stepping, current.translations)
            pipeline_profile["quality"] += time.perf_counter() - measured
        written = time.perf_counter()
        if pending is not None:  # the previous frame, its cloth velocities now known
            _write_frame(writer, pending, current, scene.fps, rates)
            if on_frame:
                on_frame(pending.frame - scene.start_frame + 1, total)
        pending = current
        pipeline_profile["usd_writer"] += time.perf_counter() - written
    written = time.perf_counter()
    _write_frame(writer, pending, None, scene.fps, rates)  # the last frame: its own velocities
    pipeline_profile["usd_writer"] += time.perf_counter() - written
    if on_frame:
        on_frame(total, total)
    _write_joint_breaks(scene, writer, broken)
    if recorder is not None:
        writer.add_layer_data({"simbake": {"qa": recorder.layer_summary()}})
    return max_penetration


def bake(scene: Scene, output: str | Path, *,
         on_frame: Callable[[int, int], None] | None = None, qa: bool = True,
         shot: str | Path | None = None, instancing: str = "auto", clips: int | None = None,
         threads: int = 0, start_frame: int | None = None, end_frame: int | None = None) -> BakeStats:
    """Simulate the scene and stream its USD cache to `output` (appears only when complete).

    `start_frame`/`end_frame` (``--frames``) bake another range than the scene's own: the
    initial state is written at the new start (a USD shot is read again at that range, see
    simbake.loading.with_frames).

    on_frame(done, total) is called after each written frame (for progress bars). With `qa`
    (the default) every written frame's quality figures are measured (simbake.qa) and written
    beside the cache as CACHE.qa.json, summarized in its customLayerData. For a USD shot the
    cache is a layer of overs; `shot` also writes a stage that sublayers it over the input.
    `instancing` ("auto", "always", "never"): bodies sharing a shape as PointInstancers
    (TOML scenes only: a shot's cache overrides the input's own prims; see instancer_groups).
    `clips` N: value-clip layers of N frames each in OUTPUT_STEM.clips/, stitched by the
    output (simbake.usd_clips). Every .vdb the bake used is copied into OUTPUT_STEM.vdb/ and
    shown as a guide Volume under its body. `threads`: the core's worker threads (0: every
    CPU); the cache is the same bits at any count.
    """
    output = Path(output)
    scene = with_frames(scene, start_frame, end_frame)
    check_scene(scene)  # a Scene made in Python (or from USD) meets the same range as a file's
    instancer_groups(scene, instancing)  # a bad mode is an error before any work
    if clips is not None:
        if isinstance(clips, bool) or not isinstance(clips, int) or clips < 1:
            raise SceneError(scene.source, "--clips", f"must be a whole number of frames >= 1, got {clips!r}")
    if isinstance(threads, bool) or not isinstance(threads, int) or not 0 <= threads <= MAX_THREADS:
        raise SceneError(scene.source, "--threads", f"must be a whole number in [0, {MAX_THREADS}], got {threads!r}")
    shot = Path(shot) if shot is not None else None
    _check_outputs(scene, output, qa, shot, instancing, clips)
    start = time.perf_counter()
    assets = load_assets(scene)
    cloths = [load_cloth(scene, i) for i in range(len(scene.cloths))]
    world = build_world(scene, assets, cloths, threads=threads)
    check_budget(scene, output, scene.substeps or world.automatic_substeps(1.0 / scene.fps),
                 sum(_moves(body) for body in scene.bodies),
                 [(len(a.vertices), crowding(c.thickness, mean_edge(a.vertices, a.triangles)))
                  for c, a in zip(scene.cloths, cloths)])
    try:
        return _bake(scene, output, world, assets, cloths, start, on_frame, qa, shot, instancing, clips)
    except Exception as error:
        if isinstance(error, (SceneError, SimulationError, OutputError)) or not _write_failure(error):
            raise
        raise OutputError(f"{output}: cannot write: {describe(error)}; nothing was replaced") from None


def _write_failure(error: Exception) -> bool:
    """An OSError, or USD's own report of a failed save (Tf.ErrorException)."""
    return isinstance(error, OSError) or type(error).__name__ == "ErrorException"


def _motion_figures(scene: Scene, assets, cloths) -> MotionFigures:
    """The QA's motion figures (simbake.qa_motion) for these bodies and cloths."""
    masses = [body_mass(b, a) for b, a in zip(scene.bodies, assets)]
    return MotionFigures(scene, np.array(masses, dtype=np.float64).reshape(-1),
                         np.array([bounding_radius(a.vertices) for a in assets]).reshape(-1),
                         [lumped_masses(a.vertices, a.triangles, c.area_density) for c, a in zip(scene.cloths, cloths)])


@contextlib.contextmanager
def _no_full_collections():
    """Everything alive before the frames (modules, the scene, the world) set aside from the
    garbage collector's passes: the frames make short-lived objects by the thousand (a
    sample's Gf values), and each pass would otherwise walk every object of pxr and NumPy too.
    What the frames make is still collected."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _bake(scene, output, world, assets, cloths, start, on_frame, qa, shot, instancing, clips) -> BakeStats:
    total = scene.frame_count
    recorder = QualityRecorder(scene, _motion_figures(scene, assets, cloths)) if qa else None
    pipeline_profile = {"quality": 0.0, "usd_writer": 0.0}
    groups = [] if scene.shot is not None else instancer_groups(scene, instancing)  # TOML only
    with Outputs() as outputs:  # everything staged, then swapped in together (or nothing)
        level_sets = _level_set_files(scene, assets, output, groups, outputs)
        with _cache_writer(scene, output, assets, cloths, instancing, clips, level_sets, outputs) as writer:
            with _no_full_collections():
                max_penetration = _bake_frames(scene, world, writer, recorder, on_frame, pipeline_profile, assets)
        if shot is not None:
            from .usd_layer import write_shot_stage

            write_shot_stage(shot, output, scene.shot, outputs=outputs)
        profile = {**world.profile(), **pipeline_profile}
        sidecar, warnings = None, []
        if recorder is not None:
            summary = recorder.summary()
            max_penetration = max(summary[k]["worst"] for k in ("body_penetration", "cloth_penetration")
                                  if k in summary)
            sidecar = recorder.write(output, profile, outputs=outputs)
            warnings = recorder.warnings(sidecar.name)
        outputs.commit()
    return BakeStats(output=output, frames=total, substeps=int(world.statistics(penetrations=False)["substeps"]),
                     wall_seconds=time.perf_counter() - start, max_penetration=max_penetration,
                     profile=profile, qa=sidecar, warnings=warnings)

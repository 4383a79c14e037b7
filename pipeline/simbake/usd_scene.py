"""USD shots as scenes: read a stage's UsdPhysics description into the validated Scene.

A USD stage is a scene, as a TOML file is (DESIGN.md, "USD shots in, cache layers out").
OpenUSD's own parser, ``UsdPhysics.UsdPhysicsLoadStageFromPrimRange``, finds the physics
scene, the rigid bodies, their colliders and materials; simbake's own applied schema
``SimbakeClothAPI`` (``schemas/``, registered by :mod:`simbake.usd_schema`) marks cloth
meshes. Everything is converted here to the TOML path's units and axes (SI, Y up), so that
nothing after loading knows where a scene came from; what the cache layer needs to go back
(prim paths, parents' transforms, units) travels beside it as :class:`ShotInfo`.

Frames. A body's frame is its prim's world transform at the start time code without its
scale (its rotation and translation); its collider geometry (primitive or mesh, scale
included) is expressed in that frame. Stage coordinates ``x_s`` become simbake's
``x = metersPerUnit * C x_s``, where ``C`` is the identity for a Y-up stage and the rotation
of -90 degrees about X for a Z-up one (stage +Z becomes +Y, stage +Y becomes -Z). A body
frame's rotation ``R_s`` becomes ``C R_s C^T`` and body-frame coordinates ``b`` become
``metersPerUnit * C b``, so the same shot authored Z up gives the very same bodies (and the
same samples, in the same order) as authored Y up.

Matrices here are numpy and act on column vectors (USD's ``Gf.Matrix4d`` acts on rows:
``np.array(m).T`` converts).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import SceneError
from .scene import (Body, Cloth, Ground, Key, Scene, Shape, DEFAULT_DENSITY, CLOTH_MODELS,
                    COMPRESSION_MODES, CLOTH_INTEGRATORS, RESERVED_NAMES)
from . import usd_schema
from .usd_deforming import deformation_source, read_deformation
from .usd_joints import joint_kinds, read_filtering, read_joints
from .limits import INERTIA_TOLERANCE, MAX_FRAMES, check_scene
from .rotations import quat_from_matrix, quat_matrix
from .usd_writer import one_thread
from .usd_diagnostics import clean, error_texts, location, shown_path, syntax_message, trapped

__all__ = ["ShotInfo", "ShotBody", "ShotCloth", "load_shot"]

CLOTH_API = "SimbakeClothAPI"
_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # stage Z-up -> Y-up
_SQRT_HALF = math.sqrt(0.5)
_TOL = 1e-6  # relative tolerance on orthogonality and uniform scale of transforms
DEFORMING_REACH = 2  # voxels a deforming collider's vertex may move in a frame: the grids'
                     # exterior band (3 voxels) less one, where phi is still a distance


# --------------------------------------------------------------------------------------------
# What the cache layer needs to write back into the shot
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ShotBody:
    """A dynamic body of the shot: where its simulated pose goes back."""

    index: int                 # into Scene.bodies
    prim_path: str
    parent_rotation: tuple     # quaternion (w, x, y, z) of the parent's world rotation (stage axes)
    parent_translation: tuple  # parent's world translation (stage units)
    parent_scale: float        # the parent's uniform world scale
    scale: tuple | None        # the prim's own local scale, None when (1, 1, 1)
    op_types: dict = field(default_factory=dict)  # xformOp name -> the input's value type name
    # under another dynamic body (whose pose the cache changes): world-space ops after
    # !resetXformStack! (the parent_* fields are then the identity)
    reset_xform_stack: bool = False
    # an animated parent: its (rotation (w, x, y, z), translation, uniform scale) at every
    # time code from the start, in place of the parent_* fields
    parent_track: tuple = ()
    # under a parent with non-uniform scale or shear (or a sheared or mirrored body): the
    # body's world transform is written whole, a time-sampled xformOp:transform after
    # !resetXformStack!, as [R(t) A, t(t)] with A (3x3, stage units, rows) the start's world
    # transform in the body frame (the scale, shear and mirror the collision shape holds)
    shape_matrix: tuple | None = None


@dataclass(frozen=True)
class ShotCloth:
    """A cloth mesh of the shot: world (stage) to the prim's local space."""

    index: int                    # into Scene.cloths
    prim_path: str
    world_to_local: tuple         # 4x4 (column vectors), stage units
    normals_interpolation: bool = True  # author the 'normals' interpolation as "vertex"


@dataclass(frozen=True)
class ShotInfo:
    """The input shot, for writing a cache layer that composes over it."""

    path: Path                    # the root layer (absolute)
    layers: tuple[str, ...]       # real paths of every layer the stage used (never overwritten)
    up_axis: str                  # "Y" | "Z"
    meters_per_unit: float
    kilograms_per_unit: float
    time_codes_per_second: float
    frames_per_second: float | None
    start_time_code: float
    end_time_code: float
    default_prim: str
    bodies: tuple[ShotBody, ...]
    cloths: tuple[ShotCloth, ...]
    # every file the stage names (layers, clips, assets such as .vdb files), resolved: never
    # an output, never inside a folder an output replaces
    dependencies: tuple[Path, ...] = ()
    # instanceable prims above a simulated prim: made ordinary (instanceable = false) in the
    # cache layer, where composition would ignore overs on their instance proxies
    instances: tuple[str, ...] = ()
    # (a scene key, the prim and attribute it was read from), for messages about the range
    keys: tuple[tuple[str, str], ...] = ()

    def usd_key(self, key: str) -> str:
        """The prim and attribute that a scene key (``bodies[0].shape.size[1]``) was read from."""
        found = [(k, where) for k, where in self.keys if key == k or key.startswith((k + ".", k + "["))]
        return max(found, key=lambda e: len(e[0]))[1] if found else key

    @property
    def axes(self) -> np.ndarray:
        """C: stage axes -> simbake's (Y up)."""
        return _Z_UP if self.up_axis == "Z" else np.eye(3)

    @property
    def axes_quaternion(self) -> tuple[float, float, float, float]:
        return (_SQRT_HALF, -_SQRT_HALF, 0.0, 0.0) if self.up_axis == "Z" else (1.0, 0.0, 0.0, 0.0)


# --------------------------------------------------------------------------------------------
# Small math (column vectors; quaternions (w, x, y, z))
# --------------------------------------------------------------------------------------------

def _matrix(gf_matrix) -> np.ndarray:
    return np.array(gf_matrix, dtype=np.float64).T


def _polar(m3: np.ndarray):
    """m3 = R A with R the proper rotation nearest to m3 (SVD polar decomposition; a mirror
    is left in A) and A = R^T m3 (scale, shear, mirror), or None for a singular m3."""
    u, s, vt = np.linalg.svd(m3)
    if not s.min() > _TOL * s.max():
        return None
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    return r, r.T @ m3


def _rotation_and_scale(m3: np.ndarray):
    """m3 = R diag(k) with R a proper rotation, or None (shear, a mirror, a zero scale)."""
    k = np.linalg.norm(m3, axis=0)
    if not np.all(k > 0):
        return None
    r = m3 / k
    if np.abs(r.T @ r - np.eye(3)).max() > _TOL or np.linalg.det(r) <= 0:
        return None
    return r, k


def _vec(value) -> tuple[float, float, float]:
    return tuple(float(c) for c in value)  # type: ignore[return-value]


def _decimal(value) -> float:
    """A float32 attribute's value as the decimal its author wrote (0.6f -> 0.6, not
    0.6000000238): the shortest decimal that rounds to the same float32. Doubles pass."""
    value = float(value)
    single = np.float32(value)
    return float(str(single)) if float(single) == value and math.isfinite(value) else value


def _decimals(values) -> tuple[float, ...]:
    return tuple(_decimal(v) for v in values)


def _show(values) -> str:
    """Numbers as a user wrote them: (100, 0.001, 0.001), not (np.float64(100.0), ...)."""
    return "(" + ", ".join(f"{float(v):g}" for v in np.asarray(values, dtype=np.float64).reshape(-1)) + ")"


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------

def load_shot(path: str | os.PathLike[str], frames: tuple[int, int] | None = None) -> Scene:
    """Read a USD stage as a Scene; `frames` (START, END), when given, is the range to bake
    in place of the stage's own startTimeCode/endTimeCode (``--frames``; a stage with no range
    needs it). Raise :class:`SceneError` (one line) on any problem:
    a syntax error (at its line and column, in whichever layer), a composition error (a
    missing or cyclic sublayer, a reference or payload that does not resolve), bad values.
    OpenUSD's own warnings become the scene's warnings; nothing of OpenUSD's reaches stderr."""
    usd_schema.register()  # before the first stage, so SimbakeClothAPI is a known schema
    from pxr import Tf, Usd

    file = os.fspath(path)
    given = Path(file).absolute()
    stage_path = given.parent.resolve() / given.name
    if not stage_path.is_file():
        raise SceneError(file, "", "file not found" if not stage_path.exists() else "not a file")
    stage, raised = None, []
    with trapped() as opened:
        try:
            stage = Usd.Stage.Open(str(stage_path), Usd.Stage.LoadAll)
        except Tf.ErrorException as error:
            raised = error_texts(error)
    if stage is None:
        raise _usd_error(file, stage_path, raised + opened.errors + opened.warnings, "cannot open USD stage")
    composition = [str(e) for e in stage.GetCompositionErrors()]
    if composition or opened.errors:
        raise _usd_error(file, stage_path, opened.errors + composition, "composition error")
    with trapped() as parsing:
        reader = _Reader(file, stage_path, stage, frames)
        scene = reader.scene()
    if parsing.errors:
        raise _usd_error(file, stage_path, parsing.errors, "OpenUSD reported an error")
    lines = [f"{file}: OpenUSD: {clean(text)}" for text in opened.warnings + parsing.warnings]
    scene = replace(scene, warnings=scene.warnings + tuple(dict.fromkeys(lines)))
    check_scene(scene)  # the physical range, named by prim and attribute
    return scene


def _usd_error(file: str, stage_path: Path, texts: list[str], what: str) -> SceneError:
    """One line for what OpenUSD reported: a syntax error at its location, else the first."""
    where = location(texts)
    if where is not None:
        return SceneError(shown_path(where[0], file, stage_path), where[1], syntax_message(texts))
    first = clean(texts[0]) if texts else "unreadable"
    more = f" (and {len(texts) - 1} more)" if len(texts) > 1 else ""
    return SceneError(file, "", f"{what}: {first}{more}")


class _Reader:
    """One stage read into a Scene; errors name the file, the prim path and the attribute."""

    def __init__(self, file: str, path: Path, stage, frames: tuple[int, int] | None = None):
        from pxr import UsdGeom, UsdPhysics

        self.file, self.path, self.stage = file, path, stage
        self.warnings: list[str] = []
        self.keys: list[tuple[str, str]] = []    # scene key -> "PRIM.attribute" (ShotInfo.keys)
        self.instances: set[str] = set()          # instanceable prims above simulated ones
        self._warned: set[str] = set()
        self._named: dict[str, list] = {}        # warn_once: name -> [first prim, problem, prims]
        axis = UsdGeom.GetStageUpAxis(stage)
        if axis not in ("Y", "Z"):
            raise self.error("", "upAxis", f"must be Y or Z, got {axis!r}")
        self.up_axis = axis
        self.mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
        self.kpu = float(UsdPhysics.GetStageKilogramsPerUnit(stage))
        for name, value in (("metersPerUnit", self.mpu), ("kilogramsPerUnit", self.kpu)):
            if not (math.isfinite(value) and value > 0):
                raise self.error("", name, f"must be a finite number > 0, got {value}")
        self.C = _Z_UP if axis == "Z" else np.eye(3)
        self.qC = (_SQRT_HALF, -_SQRT_HALF, 0.0, 0.0) if axis == "Z" else (1.0, 0.0, 0.0, 0.0)
        self.frames_given = frames is not None
        if frames is not None:  # --frames START:END overrides the stage's own range
            self.start, self.end = float(frames[0]), float(frames[1])
            start_name = end_name = "--frames"
        elif not stage.HasAuthoredTimeCodeRange():
            raise self.error("", "startTimeCode", "the stage has no startTimeCode and endTimeCode; give the "
                                                  "frames to bake with --frames START:END")
        else:
            self.start, self.end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
            start_name, end_name = "startTimeCode", "endTimeCode"
        for name, value in ((start_name, self.start), (end_name, self.end)):
            if not (math.isfinite(value) and value == int(value)):
                raise self.error("", name, f"must be an integer time code, got {value}")
        if self.end < self.start:
            raise self.error("", end_name, f"the end must be >= the start ({self.start:g}), got {self.end:g}")
        if self.end - self.start + 1 > MAX_FRAMES:  # before any animation is sampled
            raise self.error("", end_name, f"{self.end - self.start + 1:.0f} frames is more than the budget of "
                                           f"{MAX_FRAMES:,} frames in one bake; bake a part with --frames START:END")
        self.tcps = float(stage.GetTimeCodesPerSecond())
        if not (math.isfinite(self.tcps) and self.tcps > 0):
            raise self.error("", "timeCodesPerSecond", f"must be > 0, got {self.tcps}")
        self.xforms = UsdGeom.XformCache(Usd_time(self.start))

    # -- messages ---------------------------------------------------------------------------

    def error(self, prim_path, attribute: str, problem: str) -> SceneError:
        where = f"{prim_path}.{attribute}" if prim_path and attribute else str(prim_path or attribute)
        return SceneError(self.file, where, problem)

    def warn(self, prim_path, problem: str) -> None:
        """Once per prim path and kind of problem."""
        key = f"{prim_path}: {problem}"
        if key not in self._warned:
            self._warned.add(key)
            self.warnings.append(f"{self.file}: {prim_path}: {problem}")

    def warn_once(self, name: str, prim_path, problem: str) -> None:
        """Once per attribute or schema `name` however many prims author it: the first prim is
        named and the others counted (an opinion on 500 props is one line, not 500)."""
        entry = self._named.get(name)
        if entry is None:
            self._named[name] = [str(prim_path), problem, {str(prim_path)}]
            self.warnings.append(name)  # a placeholder, written out by _named_warnings
        else:
            entry[2].add(str(prim_path))

    def _named_warnings(self) -> None:
        for i, line in enumerate(self.warnings):
            if line in self._named:
                first, problem, prims = self._named[line]
                more = f" (and {len(prims) - 1} more prim{'s' if len(prims) > 2 else ''})" if len(prims) > 1 else ""
                self.warnings[i] = f"{self.file}: {first}: {problem}{more}"

    # -- conversions --------------------------------------------------------------------------

    def point(self, p) -> tuple[float, float, float]:
        return _vec(self.mpu * (self.C @ np.asarray(p, dtype=np.float64)))

    def direction(self, v, scale: float) -> tuple[float, float, float]:
        return _vec(scale * (self.C @ np.asarray(v, dtype=np.float64)))

    def world(self, prim, time=None) -> np.ndarray:
        from pxr import UsdGeom

        if time is None:
            return _matrix(self.xforms.GetLocalToWorldTransform(prim))
        return _matrix(UsdGeom.XformCache(time).GetLocalToWorldTransform(prim))

    def frame(self, prim, what: str, time=None, general: bool = False):
        """(R, t, k): the prim's world rotation, translation and scale along its own axes.
        `general`: a shear or a mirror is accepted (static colliders, dynamic bodies under a
        non-uniform parent): R is then the nearest rotation, the rest goes into the shape."""
        m = self.world(prim, time)
        parts = _rotation_and_scale(m[:3, :3])
        if parts is None and general and _polar(m[:3, :3]) is not None:
            r, a = _polar(m[:3, :3])
            return r, m[:3, 3], np.linalg.norm(a, axis=0)
        if parts is None:
            raise self.error(prim.GetPath(), "xformOpOrder",
                             f"the {what}'s world transform has a shear, a mirror or a zero scale; "
                             "simbake needs a rotation and a scale along the prim's own axes")
        return parts[0], m[:3, 3], parts[1]

    def pose(self, r: np.ndarray, t: np.ndarray):
        """A stage rigid frame -> simbake's (position (m), orientation (w, x, y, z)): the
        rotation C R C^T, so that body-frame coordinates turn with the axes too (b -> C b) and
        the same shot authored Y up or Z up gives the very same bodies."""
        return self.point(t), quat_from_matrix(self.C @ r @ self.C.T)

    def body_points(self, v: np.ndarray) -> np.ndarray:
        """Body-frame points of the stage (rows, stage units) -> simbake's (m): mpu C b."""
        return (np.asarray(v, dtype=np.float64) @ self.C.T) * self.mpu

    # -- the scene ----------------------------------------------------------------------------

    def scene(self) -> Scene:
        from pxr import Sdf, UsdPhysics

        # The parser runs on one thread: deterministic order of reports, and it is known
        # to race with many mesh colliders under one body on several threads.
        with one_thread():
            parsed = UsdPhysics.UsdPhysicsLoadStageFromPrimRange(self.stage, [Sdf.Path.absoluteRootPath])
        descs = {kind: list(zip(*value)) for kind, value in parsed.items()}
        T = UsdPhysics.ObjectType

        self.materials = {str(p): d for p, d in descs.get(T.RigidBodyMaterial, [])}
        shapes = {}
        for kind in (T.CubeShape, T.SphereShape, T.CapsuleShape, T.CylinderShape, T.MeshShape,
                     T.PlaneShape, T.Capsule1Shape, T.Cylinder1Shape):
            for p, d in descs.get(kind, []):
                shapes[str(p)] = d
        for kind, entries in descs.items():
            if kind not in _SUPPORTED:
                for p, _ in sorted(entries, key=lambda e: str(e[0])):
                    self.warn_once(str(kind), p, f"{_describe_kind(kind)} is not simulated by simbake; left out")
        self.substeps = self._physx()

        gravity = self._gravity(descs.get(T.Scene, []))
        self.dynamic_paths = {str(p) for p, d in descs.get(T.RigidBody, [])
                              if d.rigidBodyEnabled and not d.kinematicBody}
        used_names: set[str] = set()
        bodies: list[Body] = []
        shot_bodies: list[ShotBody] = []
        for p, d in sorted(descs.get(T.RigidBody, []), key=lambda e: str(e[0])):
            if not d.rigidBodyEnabled:
                self.warn(p, "physics:rigidBodyEnabled is false; left out")
                continue
            body, target = self._rigid_body(str(p), d, shapes, used_names, len(bodies))
            bodies.append(body)
            if target is not None:
                shot_bodies.append(target)

        ground = None
        for p, d in sorted(shapes.items()):
            if str(d.rigidBody):
                continue
            if not d.collisionEnabled:
                self.warn(p, "physics:collisionEnabled is false; left out")
                continue
            if d.type == T.PlaneShape:
                if ground is not None:
                    raise self.error(p, "", "a second static Plane: simbake has one ground plane")
                ground = self._ground(p, d)
            else:
                bodies.append(self._static_body(p, d, used_names, len(bodies)))

        cloths, shot_cloths = self._cloths(used_names, bodies)
        joints = read_joints(self, descs, bodies)
        filtered_pairs, collision_groups, group_filters = read_filtering(descs, bodies, self.stage)
        self._named_warnings()
        ranged = ("--frames", "--frames") if self.frames_given else ("startTimeCode", "endTimeCode")
        self.keys += [("scene.fps", "timeCodesPerSecond"), ("scene.start_frame", ranged[0]),
                      ("scene.end_frame", ranged[1]), ("solver.substeps", ranged[1])]
        fps_meta = self.stage.GetFramesPerSecond() if self.stage.GetRootLayer().HasFramesPerSecond() else None
        info = ShotInfo(
            path=self.path,
            layers=tuple(sorted({os.path.realpath(l.realPath) for l in self.stage.GetUsedLayers()
                                 if l.realPath})),
            up_axis=self.up_axis, meters_per_unit=self.mpu, kilograms_per_unit=self.kpu,
            time_codes_per_second=self.tcps, frames_per_second=fps_meta,
            start_time_code=self.start, end_time_code=self.end,
            default_prim=self.stage.GetRootLayer().defaultPrim,
            bodies=tuple(shot_bodies), cloths=tuple(shot_cloths), dependencies=self._dependencies(),
            instances=tuple(sorted(self.instances)), keys=tuple(self.keys))
        return Scene(path=self.path, source=self.file, fps=self.tcps, substeps=self.substeps,
                     start_frame=int(self.start),
                     end_frame=int(self.end), gravity=gravity, ground=ground, bodies=tuple(bodies),
                     cloths=tuple(cloths), joints=joints, filtered_pairs=filtered_pairs,
                     collision_groups=collision_groups, group_filters=group_filters,
                     warnings=tuple(self.warnings), shot=info)

    def _dependencies(self) -> tuple[Path, ...]:
        """Every layer and asset the stage names (sublayers, references, payloads, value clips,
        asset-valued attributes), resolved."""
        from pxr import Sdf, UsdUtils

        layers, assets, _ = UsdUtils.ComputeAllDependencies(Sdf.AssetPath(str(self.path)))
        paths = [layer.realPath for layer in layers if layer.realPath] + [a for a in assets if a]
        return tuple(dict.fromkeys(Path(os.path.realpath(p)) for p in paths))

    def _instance_roots(self, prim) -> None:
        """Remember every instance at or above `prim` (an instance proxy): the cache layer makes
        them ordinary prims so that composition reads its overs."""
        p = prim
        while p and not p.IsPseudoRoot():
            if p.IsInstance():
                self.instances.add(str(p.GetPath()))
            p = p.GetParent()

    def _gravity(self, scenes) -> tuple[float, float, float]:
        if not scenes:
            return (0.0, -9.81, 0.0)  # UsdPhysics: 9.81 m/s^2 down the up axis
        if len(scenes) > 1:
            self.warn(scenes[1][0], "a second PhysicsScene; simbake uses the first one's gravity")
        path, d = scenes[0]
        from pxr import UsdPhysics

        api = UsdPhysics.Scene(self.stage.GetPrimAtPath(path))
        self.keys.append(("scene.gravity", f"{path}.physics:gravityMagnitude"))
        # unauthored: 9.81 m/s^2 down the up axis, exactly (the parser's is a float32)
        direction = np.asarray(_decimals(d.gravityDirection), dtype=np.float64)
        if not api.GetGravityDirectionAttr().HasAuthoredValue():
            direction = self.C.T @ np.array([0.0, -1.0, 0.0])
        magnitude = _decimal(d.gravityMagnitude)
        if not api.GetGravityMagnitudeAttr().HasAuthoredValue() or magnitude == -math.inf:
            magnitude = 9.81 / self.mpu
        if not np.isfinite(direction).all():
            raise self.error(path, "physics:gravityDirection", f"must be finite, got {_show(direction)}")
        if not math.isfinite(magnitude):
            raise self.error(path, "physics:gravityMagnitude", f"must be finite, got {magnitude}")
        norm = np.linalg.norm(direction)
        if norm == 0:
            return (0.0, 0.0, 0.0) if magnitude == 0 else (0.0, -abs(magnitude) * self.mpu, 0.0)
        return self.direction(direction / norm, magnitude * self.mpu)

    # -- materials ----------------------------------------------------------------------------

    def _material(self, shape_path, shape) -> tuple[float, float, float | None]:
        """(friction, restitution, density in kg/m^3 or None) of a collider's physics material;
        its prim is left in `material_path` (the collider's when it has none)."""
        self.material_path = str(shape_path)
        for m in list(shape.materials) or self._binding_without_api(shape_path):
            d = self.materials.get(str(m))
            if d is None:
                continue
            friction, restitution = _decimal(d.dynamicFriction), _decimal(d.restitution)
            if not (math.isfinite(friction) and friction >= 0):
                raise self.error(m, "physics:dynamicFriction", f"must be a finite number >= 0, got {friction}")
            if not (math.isfinite(restitution) and 0 <= restitution <= 1):
                raise self.error(m, "physics:restitution", f"must be in [0, 1], got {restitution}")
            if _decimal(d.staticFriction) != friction:
                self.warn_once("physics:staticFriction", m,
                               f"physics:staticFriction ({float(d.staticFriction):g}) differs from "
                               f"physics:dynamicFriction ({friction:g}); simbake uses one Coulomb "
                               "coefficient, the dynamic one")
            density = _decimal(d.density)
            if not (math.isfinite(density) and density >= 0):
                raise self.error(m, "physics:density", f"must be a finite number >= 0 (0: unset), got {density}")
            self.material_path = str(m)
            return friction, restitution, density * self.kpu / self.mpu ** 3 if density > 0 else None
        return Body.friction, Body.restitution, None

    def _binding_without_api(self, shape_path) -> list[str]:
        """A `material:binding:physics` (else `material:binding`) relationship on the collider
        or an ancestor that has no MaterialBindingAPI applied: OpenUSD's parser ignores it, but
        it is the binding the author meant (OpenUSD's own usdPhysicsSpheresWithMaterial.usda is
        written so). Read, with one warning naming the missing API. The nearest prim wins, its
        physics-purpose binding before its all-purpose one, as UsdShade resolves them; a target
        without PhysicsMaterialAPI (a render material) is no physics material."""
        from pxr import UsdShade, UsdPhysics

        prim = self.stage.GetPrimAtPath(shape_path)
        while prim and not prim.IsPseudoRoot():
            if not prim.HasAPI(UsdShade.MaterialBindingAPI):
                for name in ("material:binding:physics", "material:binding"):
                    rel = prim.GetRelationship(name)
                    targets = [str(t) for t in rel.GetTargets()] if rel else []
                    target = self.stage.GetPrimAtPath(targets[0]) if targets else None
                    if target and target.HasAPI(UsdPhysics.MaterialAPI):
                        self.warn_once("MaterialBindingAPI", prim.GetPath(),
                                       f"{name} without MaterialBindingAPI applied (OpenUSD's parser ignores it); "
                                       "read as the author meant: apply MaterialBindingAPI for other tools")
                        if targets[0] not in self.materials:
                            self.materials[targets[0]] = _MaterialDesc(UsdPhysics.MaterialAPI(target))
                        return [targets[0]]
            prim = prim.GetParent()
        return []

    def _physx(self) -> int:
        """PhysX's own attributes (Omniverse Kit writes them: PhysxSchema is not in usd-core):
        those that map onto simbake settings are read, those whose value is what simbake does
        anyway pass, the rest are warned about once per attribute name (see _PHYSX_MAPPED and
        _PHYSX_NEUTRAL). Returns the solver's substeps per frame (0: automatic)."""
        substeps = 0
        for prim in self.stage.Traverse():
            listop = prim.GetMetadata("apiSchemas")  # unregistered schemas too (PhysxSchema)
            for schema in (listop.ApplyOperations([]) if listop else []):
                if schema.startswith("Physx") and schema.split(":")[0] in _PHYSX_BEHAVIOUR:
                    self.warn_once(schema, prim.GetPath(), f"{schema} {_PHYSX_BEHAVIOUR[schema.split(':')[0]]}")
            for attr in prim.GetAuthoredAttributes():
                name = attr.GetName()
                if not name.startswith("physx") or not attr.HasAuthoredValue():
                    continue
                value = attr.Get(self.start)
                if name in _PHYSX_MAPPED:
                    if name == "physxScene:timeStepsPerSecond":
                        substeps = self._physx_steps(prim, value)
                    continue  # read where the shape or body is read
                if name in _PHYSX_NEUTRAL and _same(value, _PHYSX_NEUTRAL[name]):
                    continue
                self.warn_once(name, prim.GetPath(), f"{name} = {_short(_value_text(value), 40)} is a PhysX "
                                                     "setting simbake does not read; ignored")
        return substeps

    def _physx_steps(self, prim, value) -> int:
        """physxScene:timeStepsPerSecond -> substeps per frame (the nearest whole number)."""
        try:
            steps_per_second = float(value)
        except (TypeError, ValueError):
            raise self.error(prim.GetPath(), "physxScene:timeStepsPerSecond", f"must be a number, got {value!r}") from None
        if not (math.isfinite(steps_per_second) and steps_per_second > 0):
            raise self.error(prim.GetPath(), "physxScene:timeStepsPerSecond", f"must be > 0, got {value}")
        substeps = max(1, round(steps_per_second / self.tcps))
        if abs(substeps * self.tcps - steps_per_second) > 1e-9 * steps_per_second:
            self.warn_once("physxScene:timeStepsPerSecond", prim.GetPath(),
                           f"physxScene:timeStepsPerSecond = {steps_per_second:g} is not a whole number of steps "
                           f"per frame at {self.tcps:g} fps; simbake takes {substeps} per frame")
        return substeps

    # -- shapes -------------------------------------------------------------------------------

    def _collider_geometry(self, prim, to_body: np.ndarray):
        """A collider's surface in a body frame (stage units): ('box', size) | ('sphere', r)
        when that is exact, else ('mesh', vertices, triangles). `to_body` maps the collider's
        local space into the body frame (4x4)."""
        from pxr import UsdGeom

        path = prim.GetPath()
        a, t = to_body[:3, :3], to_body[:3, 3]
        parts = _rotation_and_scale(a @ np.diag(np.sign(np.diag(a)) + (np.diag(a) == 0)))  # mirrors of a
        centred = np.abs(t).max() <= _TOL * max(1.0, np.abs(a).max())
        if prim.IsA(UsdGeom.Cube):
            size = self._positive(prim, "size", UsdGeom.Cube(prim).GetSizeAttr().Get())
            if centred and parts is not None and np.abs(parts[0] - np.eye(3)).max() <= _TOL:
                return ("box", size * parts[1])
            from . import _core

            v, f = _core.box_mesh(np.full(3, size), 1)
            return ("mesh", v @ a.T + t, _wound(np.asarray(f, dtype=np.int32), a))
        if prim.IsA(UsdGeom.Sphere):
            radius = self._positive(prim, "radius", UsdGeom.Sphere(prim).GetRadiusAttr().Get())
            if centred and parts is not None and np.ptp(parts[1]) <= _TOL * parts[1].max():
                return ("sphere", radius * float(parts[1].mean()))
            from . import _core
            from .assets import SPHERE_SUBDIVISIONS

            v, f = _core.sphere_mesh(radius, SPHERE_SUBDIVISIONS)
            return ("mesh", v @ a.T + t, _wound(np.asarray(f, dtype=np.int32), a))
        if prim.IsA(UsdGeom.Capsule) or prim.IsA(UsdGeom.Cylinder):
            import trimesh

            schema = UsdGeom.Capsule(prim) if prim.IsA(UsdGeom.Capsule) else UsdGeom.Cylinder(prim)
            radius = self._positive(prim, "radius", schema.GetRadiusAttr().Get())
            height = self._positive(prim, "height", schema.GetHeightAttr().Get(), allow_zero=True)
            axis = self._axis(prim, schema)
            if prim.IsA(UsdGeom.Capsule):
                mesh = trimesh.creation.capsule(height=height, radius=radius, count=[24, 24])
            else:
                mesh = trimesh.creation.cylinder(radius=radius, height=height, sections=32)
            v = np.asarray(mesh.vertices, dtype=np.float64)  # along z, centred
            v = {"X": v[:, [2, 0, 1]], "Y": v[:, [1, 2, 0]], "Z": v}[axis]
            return ("mesh", v @ a.T + t, _wound(np.asarray(mesh.faces, dtype=np.int32), a))
        if prim.IsA(UsdGeom.Mesh):
            v, f = self._approximated(prim, *self._mesh_triangles(prim))
            return ("mesh", v @ a.T + t, _wound(f, a))
        raise self.error(path, "", f"a collider of type {prim.GetTypeName() or 'none'} is not supported "
                                   "(Cube, Sphere, Capsule, Cylinder, Mesh, or a static Plane)")

    def _approximated(self, prim, v: np.ndarray, f: np.ndarray):
        """A mesh collider's physics:approximation (PhysicsMeshCollisionAPI), in its local
        space, as PhysX reads it (APPROXIMATIONS says what each becomes)."""
        from pxr import UsdPhysics

        attr = UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr()
        token = str(attr.Get()) if attr and attr.HasAuthoredValue() else "none"
        if token not in APPROXIMATIONS:
            self.warn_once(f"physics:approximation={token}", prim.GetPath(),
                           f"physics:approximation {token!r} is not one simbake knows "
                           f"({', '.join(APPROXIMATIONS)}); the mesh is used as it is")
            return v, f
        import trimesh

        if token == "convexHull":
            try:
                hull = trimesh.Trimesh(v, f, process=False).convex_hull
            except Exception:  # flat: no volume to hull (qhull refuses); the surface is its own hull
                return v, f
            return np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int32)
        if token == "boundingCube":
            from . import _core

            lo, hi = v.min(axis=0), v.max(axis=0)
            box, faces = _core.box_mesh(np.maximum(hi - lo, 1e-12), 1)
            return box + 0.5 * (lo + hi), np.asarray(faces, dtype=np.int32)
        if token == "boundingSphere":
            from . import _core
            from .assets import SPHERE_SUBDIVISIONS

            centre, radius = trimesh.nsphere.minimum_nsphere(v)
            ball, faces = _core.sphere_mesh(float(radius), SPHERE_SUBDIVISIONS)
            return ball + centre, np.asarray(faces, dtype=np.int32)
        return v, f  # none, meshSimplification, convexDecomposition, sdf: the mesh itself

    def _voxel_size(self, colliders, shape) -> float:
        """PhysX's physxSDFMeshCollision:sdfResolution (voxels along the longest extent) as
        the level set's voxel size (m); 0: automatic."""
        for prim in colliders:
            attr = prim.GetAttribute("physxSDFMeshCollision:sdfResolution")
            if not (attr and attr.HasAuthoredValue()) or shape.mesh_vertices is None:
                continue
            value = attr.Get()
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise self.error(prim.GetPath(), "physxSDFMeshCollision:sdfResolution", f"must be a number > 0, got {value!r}")
            v = np.asarray(shape.mesh_vertices)
            return float((v.max(axis=0) - v.min(axis=0)).max()) / float(value)
        return 0.0

    def _axis(self, prim, schema) -> str:
        """A Capsule's, Cylinder's or Plane's axis token: X, Y or Z."""
        axis = schema.GetAxisAttr().Get()
        if axis not in ("X", "Y", "Z"):
            raise self.error(prim.GetPath(), "axis", f"must be X, Y or Z, got {str(axis)!r}")
        return axis

    def _positive(self, prim, attribute: str, value, allow_zero: bool = False) -> float:
        value = float(value)
        ok = math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
        if not ok:
            bound = ">= 0" if allow_zero else "> 0"
            raise self.error(prim.GetPath(), attribute, f"must be a finite number {bound}, got {value}")
        return value

    def _mesh_triangles(self, prim) -> tuple[np.ndarray, np.ndarray]:
        """A Mesh's points (local, at the start) and its faces fanned into triangles."""
        from pxr import UsdGeom

        mesh = UsdGeom.Mesh(prim)
        path = prim.GetPath()
        points = mesh.GetPointsAttr().Get(self.start)
        counts = mesh.GetFaceVertexCountsAttr().Get(self.start)
        indices = mesh.GetFaceVertexIndicesAttr().Get(self.start)
        if points is None or len(points) == 0:
            raise self.error(path, "points", "the mesh has no points")
        if counts is None or indices is None or len(counts) == 0:
            raise self.error(path, "faceVertexCounts", "the mesh has no faces")
        v = np.asarray(points, dtype=np.float64)
        counts = np.asarray(counts, dtype=np.int64)
        indices = np.asarray(indices, dtype=np.int64)
        if not np.isfinite(v).all():
            raise self.error(path, "points", "contains NaN or infinity")
        if counts.min() < 3:
            raise self.error(path, "faceVertexCounts", f"every face needs at least 3 vertices, got {int(counts.min())}")
        if counts.sum() != len(indices):
            raise self.error(path, "faceVertexIndices", f"has {len(indices)} entries but faceVertexCounts "
                                                        f"sum to {int(counts.sum())}")
        if indices.min() < 0 or indices.max() >= len(v):
            raise self.error(path, "faceVertexIndices", f"an index is outside the {len(v)} points")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        tris = []
        for c in np.unique(counts):  # fan each face: (0, k, k + 1)
            s = starts[counts == c]
            for k in range(1, c - 1):
                tris.append(np.stack([indices[s], indices[s + k], indices[s + k + 1]], axis=-1))
        faces = np.concatenate(tris) if len(tris) == 1 else _face_order(tris, counts)
        if UsdGeom.Mesh(prim).GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            faces = faces[:, ::-1]
        return v, np.ascontiguousarray(faces, dtype=np.int32)

    # -- bodies -------------------------------------------------------------------------------

    def _name(self, prim_path: str, used: set[str]) -> str:
        from pxr import Sdf

        path = Sdf.Path(prim_path)
        name = path.name
        if name in used or name in RESERVED_NAMES:
            name = "_".join(str(path).strip("/").split("/"))
        while name in used or name in RESERVED_NAMES:
            name += "_"
        used.add(name)
        return name

    def _shape(self, owner_path, colliders: list, body_r, body_t, what: str, two_sided: bool = False):
        """The Shape (SI, body frame) of one or more collider prims of a body. `two_sided`
        (static and kinematic colliders): an open or non-manifold mesh is a two-sided surface
        with the collision thickness (physxCollision:restOffset, else SHELL_THICKNESS)."""
        pieces = []
        for prim in colliders:
            to_body = np.eye(4)
            world = self.world(prim)
            to_body[:3, :3] = body_r.T @ world[:3, :3]
            to_body[:3, 3] = body_r.T @ (world[:3, 3] - body_t)
            pieces.append((prim, self._collider_geometry(prim, to_body)))
        if len(pieces) == 1 and pieces[0][1][0] == "box":
            return Shape(kind="box", size=_vec(np.abs(self.C @ pieces[0][1][1]) * self.mpu))
        if len(pieces) == 1 and pieces[0][1][0] == "sphere":
            return Shape(kind="sphere", radius=float(pieces[0][1][1] * self.mpu))
        from . import _core

        vertices, triangles, offset = [], [], 0
        for prim, geometry in pieces:
            if geometry[0] == "box":
                v, f = _core.box_mesh(np.asarray(geometry[1], dtype=np.float64), 1)
            elif geometry[0] == "sphere":
                v, f = _core.sphere_mesh(float(geometry[1]), 8)
            else:
                v, f = geometry[1], geometry[2]
            vertices.append(self.body_points(v))
            triangles.append(np.asarray(f, dtype=np.int32) + offset)
            offset += len(v)
        v, f = np.concatenate(vertices), np.concatenate(triangles)
        thickness = 0.0
        if not two_sided:
            self._check_closed(pieces, v, f)
        elif not self._closed(v, f):
            thickness = self._thickness(pieces)
        return Shape(kind="mesh", mesh_vertices=_frozen(v), mesh_triangles=_frozen(f),
                     mesh_source=str(owner_path), thickness=thickness)

    @staticmethod
    def _closed(v, f) -> bool:
        import trimesh

        mesh = trimesh.Trimesh(v, f, process=True)
        return bool(mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0)

    def _thickness(self, pieces) -> float:
        """An open collider's half-thickness (m): PhysX's physxCollision:restOffset (the
        distance bodies come to rest at) when authored > 0, else SHELL_THICKNESS."""
        from .assets import SHELL_THICKNESS

        for prim, _ in pieces:
            attr = prim.GetAttribute("physxCollision:restOffset")
            if attr and attr.HasAuthoredValue():
                value = attr.Get()
                if not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise self.error(prim.GetPath(), "physxCollision:restOffset", f"must be a finite number, got {value!r}")
                if value > 0:
                    return float(value) * self.mpu
        return SHELL_THICKNESS

    def _check_closed(self, pieces, v, f) -> None:
        import trimesh

        mesh = trimesh.Trimesh(v, f, process=True)
        if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
            culprit = next((p for p, g in pieces if g[0] == "mesh"), pieces[0][0])
            raise self.error(culprit.GetPath(), "faceVertexIndices",
                             "a collider mesh must be closed and wound outwards (it has holes, open "
                             "edges or inconsistent winding); its mass and level set need an inside")

    def _cloth_keys(self, index: int, path) -> None:
        """Where each of cloth `index`'s scene keys was read from (for range messages)."""
        key = f"cloths[{index}]"
        self.keys += [(key, str(path)), (f"{key}.position", f"{path}.points")]
        self.keys += [(f"{key}.{name}", f"{path}.simbake:cloth:{_camel(name)}") for name in _CLOTH_KEYS]
        self.keys += [(f"{key}.attach.to", f"{path}.simbake:cloth:attachTo"),
                      (f"{key}.attach.points", f"{path}.simbake:cloth:attached")]

    def _rigid_body(self, path: str, d, shapes, used: set[str], index: int):
        from pxr import Usd, UsdGeom, UsdPhysics

        prim = self.stage.GetPrimAtPath(path)
        r, t, k = self.frame(prim, "rigid body", general=True)
        colliders = []
        for c in d.collisions:
            shape = shapes.get(str(c))
            if shape is None:
                self.warn(c, "a collider simbake cannot read (cone, points or custom shape); left out")
                continue
            if not shape.collisionEnabled:
                self.warn(c, "physics:collisionEnabled is false; left out")
                continue
            if shape.type == UsdPhysics.ObjectType.PlaneShape:
                raise self.error(c, "", "a Plane collider under a rigid body is not supported (planes are static ground)")
            colliders.append((self.stage.GetPrimAtPath(c), shape))
        if not colliders:
            raise self.error(path, "", "a rigid body needs a collider (PhysicsCollisionAPI on a Cube, "
                                       "Sphere, Capsule, Cylinder or Mesh at or under it)")
        shape = self._shape(path, [c for c, _ in colliders], r, t, "rigid body", two_sided=bool(d.kinematicBody))
        friction, restitution, material_density = self._material(colliders[0][0].GetPath(), colliders[0][1])
        self._body_keys(index, path, colliders[0][0].GetPath(), self.material_path)
        for c, s in colliders[1:]:
            if self._material(c.GetPath(), s)[:2] != (friction, restitution):
                self.warn(path, "colliders with different physics materials; simbake uses the first one's")

        mass, density, com, inertia = self._mass(prim, [c for c, _ in colliders], r, k, material_density)
        position, orientation = self.pose(r, t)
        kinematic = bool(d.kinematicBody)
        for name, value in (("physics:velocity", d.linearVelocity), ("physics:angularVelocity", d.angularVelocity)):
            if not np.isfinite(np.asarray(value, dtype=np.float64)).all():
                raise self.error(path, name, "must be finite")
        if d.startsAsleep:
            self.warn_once("physics:startsAsleep", path, "physics:startsAsleep is not supported; the body "
                                                         "starts awake (and sleeps after 0.5 s at rest)")
        keys = self._keys(prim) if kinematic else ()
        body = Body(
            name=self._name(path, used), shape=shape, density=density, mass=mass,
            voxel_size=self._voxel_size([c for c, _ in colliders], shape),
            position=position, orientation=orientation,
            linear_velocity=self.direction(_decimals(d.linearVelocity), self.mpu),
            angular_velocity=self.direction(_decimals(d.angularVelocity), math.pi / 180.0),
            friction=friction, restitution=restitution, kinematic=kinematic,
            keys=keys, center_of_mass=com, inertia=inertia, prim_path=path)
        if kinematic:
            return body, None  # the input's own animation already says where it is
        self._instance_roots(prim)  # the cache writes its pose: composition must read it
        return body, self._shot_body(prim, index, k)

    def _body_keys(self, index: int, path, collider, material) -> None:
        """Where each of body `index`'s scene keys was read from (for range messages)."""
        key = f"bodies[{index}]"
        self.keys += [(key, str(path)), (f"{key}.shape.radius", f"{collider}.radius"),
                      (f"{key}.shape.size", f"{collider}.size"), (f"{key}.density", f"{path}.physics:density"),
                      (f"{key}.mass", f"{path}.physics:mass"), (f"{key}.position", f"{path}.xformOp:translate"),
                      (f"{key}.keys", f"{path}.xformOp:translate"),
                      (f"{key}.linear_velocity", f"{path}.physics:velocity"),
                      (f"{key}.angular_velocity", f"{path}.physics:angularVelocity"),
                      (f"{key}.inertia", f"{path}.physics:diagonalInertia"),
                      (f"{key}.friction", f"{material}.physics:dynamicFriction"),
                      (f"{key}.restitution", f"{material}.physics:restitution")]

    def _shot_body(self, prim, index: int, world_scale: np.ndarray) -> ShotBody:
        from pxr import UsdGeom

        parent = prim.GetParent()
        ancestors = []
        p = parent
        while p and not p.IsPseudoRoot():
            ancestors.append(p)
            p = p.GetParent()
        reset = any(str(a.GetPath()) in self.dynamic_paths for a in ancestors)
        animated = not reset and any(UsdGeom.Xformable(a) and UsdGeom.Xformable(a).TransformMightBeTimeVarying()
                                     for a in ancestors)
        m = self.world(parent) if ancestors and not reset else np.eye(4)
        whole = self.world(prim)
        if self._needs_matrix(m, whole):  # the body moves rigidly; its shape holds the rest
            r, a = _polar(whole[:3, :3])
            return ShotBody(index=index, prim_path=str(prim.GetPath()), parent_rotation=(1.0, 0.0, 0.0, 0.0),
                            parent_translation=(0.0, 0.0, 0.0), parent_scale=1.0, scale=None,
                            reset_xform_stack=True, shape_matrix=tuple(_vec(row) for row in a))
        q, t, sigma = self._similarity(parent, m)
        track = ()
        if animated:
            from pxr import Usd

            track = tuple(self._similarity(parent, self.world(parent, Usd.TimeCode(code)))
                          for code in range(int(self.start), int(self.end) + 1))
        scale = world_scale / sigma
        ops = {}
        for op in UsdGeom.Xformable(prim).GetOrderedXformOps():
            ops[op.GetOpName()] = str(op.GetAttr().GetTypeName())
        for name in ("xformOp:translate", "xformOp:orient", "xformOp:scale"):
            attr = prim.GetAttribute(name)
            if attr and attr.GetTypeName():
                ops[name] = str(attr.GetTypeName())
        return ShotBody(index=index, prim_path=str(prim.GetPath()),
                        parent_rotation=q, parent_translation=t, parent_scale=sigma,
                        reset_xform_stack=reset, parent_track=track,
                        scale=None if np.abs(scale - 1).max() <= _TOL else _vec(scale),
                        op_types={n: ops[n] for n in ("xformOp:translate", "xformOp:orient", "xformOp:scale")
                                  if n in ops})

    @staticmethod
    def _needs_matrix(parent: np.ndarray, whole: np.ndarray) -> bool:
        """A parent that is not a similarity, or a body whose world transform is not a rotation
        times a scale along its own axes: translate/orient/scale cannot say where it goes."""
        parts = _rotation_and_scale(parent[:3, :3])
        return parts is None or np.ptp(parts[1]) > _TOL * parts[1].max() or _rotation_and_scale(whole[:3, :3]) is None

    def _similarity(self, parent, m: np.ndarray):
        """(rotation quaternion, translation, uniform scale) of a parent's world transform."""
        parts = _rotation_and_scale(m[:3, :3])
        if parts is None or np.ptp(parts[1]) > _TOL * parts[1].max():
            raise self.error(parent.GetPath(), "xformOpOrder",
                             "the parent of a dynamic rigid body must have a rotation and a uniform "
                             "scale (the cache overrides the body's own transform under it)")
        return quat_from_matrix(parts[0]), _vec(m[:3, 3]), float(parts[1].mean())

    def _mass(self, prim, colliders, r, k, material_density):
        """(mass kg | None, density kg/m^3 | None, centre of mass, inertia) from PhysicsMassAPI:
        the body's mass, else its density, else a collider's density, else the material's,
        else simbake's default density."""
        from pxr import UsdPhysics

        path = prim.GetPath()
        com = inertia = None
        mass = density = None
        if prim.HasAPI(UsdPhysics.MassAPI):
            api = UsdPhysics.MassAPI(prim)
            m = _decimal(api.GetMassAttr().Get() or 0.0)
            rho = _decimal(api.GetDensityAttr().Get() or 0.0)
            if not math.isfinite(m) or m < 0:
                raise self.error(path, "physics:mass", f"must be a finite number >= 0 (0: from density), got {m}")
            if not math.isfinite(rho) or rho < 0:
                raise self.error(path, "physics:density", f"must be a finite number >= 0 (0: default), got {rho}")
            if m > 0:
                mass = m * self.kpu
            elif rho > 0:
                density = rho * self.kpu / self.mpu ** 3
            com = self._center_of_mass(api, path, k)
            inertia = self._inertia(api, path)
            if inertia is not None and mass is None:
                raise self.error(path, "physics:mass", "an authored diagonalInertia needs an authored mass")
        if mass is None and density is None:
            for c in colliders:
                if c.HasAPI(UsdPhysics.MassAPI):
                    rho = _decimal(UsdPhysics.MassAPI(c).GetDensityAttr().Get() or 0.0)
                    if not math.isfinite(rho) or rho < 0:
                        raise self.error(c.GetPath(), "physics:density", f"must be a finite number >= 0 (0: unset), got {rho}")
                    if rho > 0:
                        density = rho * self.kpu / self.mpu ** 3
                        break
        if mass is None and density is None:
            density = material_density if material_density else DEFAULT_DENSITY
        return mass, density, com, inertia

    def _center_of_mass(self, api, path, k: np.ndarray):
        """An authored centre of mass in the body frame (m), or None (USD's unauthored value is
        -inf on every axis); NaN or a partly infinite point is an error."""
        c = api.GetCenterOfMassAttr().Get()
        if c is None:
            return None
        c = np.asarray(c, dtype=np.float64)
        if np.all(c == -np.inf):
            return None
        if not np.isfinite(c).all():
            raise self.error(path, "physics:centerOfMass", f"must be three finite numbers, got {_show(c)}")
        # authored in the prim's local space (its scale included) -> body frame (m)
        return _vec(self.body_points(c * k))

    def _inertia(self, api, path):
        """An authored inertia tensor (kg m^2, body frame) from diagonalInertia and
        principalAxes, or None when unauthored (zero). Refused unless physically possible:
        positive moments that satisfy the triangle inequality (no moment larger than the other
        two together, as for every real mass distribution), unit principal axes."""
        diag = api.GetDiagonalInertiaAttr().Get()
        if diag is None or not np.any(np.asarray(diag, dtype=np.float64) != 0):
            return None
        diag = np.asarray(diag, dtype=np.float64)
        if not (np.isfinite(diag).all() and (diag > 0).all()):
            raise self.error(path, "physics:diagonalInertia", f"must be three finite numbers > 0, got {_show(diag)}")
        largest = int(np.argmax(diag))
        if diag[largest] > (diag.sum() - diag[largest]) * (1 + INERTIA_TOLERANCE):
            raise self.error(path, "physics:diagonalInertia",
                             f"{_show(diag)} is not the inertia of any body: the largest moment must not exceed "
                             "the sum of the other two (triangle inequality)")
        axes = api.GetPrincipalAxesAttr().Get()
        q = (1.0, 0.0, 0.0, 0.0)
        if axes is not None:
            q = np.array([axes.GetReal(), *axes.GetImaginary()], dtype=np.float64)
            norm = float(np.linalg.norm(q)) if np.isfinite(q).all() else math.nan
            if not (math.isfinite(norm) and norm > 0) and np.any(q != 0):
                raise self.error(path, "physics:principalAxes", f"must be a finite, non-zero quaternion, got {_show(q)}")
            q = tuple(q / norm) if norm > 0 else (1.0, 0.0, 0.0, 0.0)
        rot = quat_matrix(q)
        tensor = self.C @ rot @ np.diag(diag * self.kpu * self.mpu ** 2) @ rot.T @ self.C.T
        return tuple(_vec(row) for row in tensor)

    def _keys(self, prim) -> tuple[Key, ...]:
        """A kinematic body's world pose at every time code when its transform is animated."""
        from pxr import Usd, UsdGeom

        animated = False
        p = prim
        while p and not p.IsPseudoRoot():
            if UsdGeom.Xformable(p) and UsdGeom.Xformable(p).TransformMightBeTimeVarying():
                animated = True
                break
            p = p.GetParent()
        if not animated:
            return ()
        keys = []
        for code in range(int(self.start), int(self.end) + 1):
            r, t, _ = self.frame(prim, "kinematic body", Usd.TimeCode(code))
            position, orientation = self.pose(r, t)
            keys.append(Key(time=(code - self.start) / self.tcps, position=position, orientation=orientation))
        return tuple(keys)

    def _static_body(self, path, d, used: set[str], index: int) -> Body:
        from pxr import UsdGeom

        prim = self.stage.GetPrimAtPath(path)
        source = deformation_source(prim) if prim.IsA(UsdGeom.Mesh) else None
        deforming = self._deforming_body(prim, d, used, index, source) if source is not None else None
        if deforming is not None:
            return deforming
        r, t, _ = self.frame(prim, "static collider", general=True)
        shape = self._shape(path, [prim], r, t, "static collider", two_sided=True)
        friction, restitution, _ = self._material(path, d)
        self._body_keys(index, path, path, self.material_path)
        position, orientation = self.pose(r, t)
        return Body(name=self._name(str(path), used), shape=shape, density=DEFAULT_DENSITY, mass=None,
                    voxel_size=self._voxel_size([prim], shape),
                    position=position, orientation=orientation, linear_velocity=(0.0, 0.0, 0.0),
                    angular_velocity=(0.0, 0.0, 0.0), friction=friction, restitution=restitution,
                    kinematic=True, prim_path=str(path))

    def _deforming_body(self, prim, d, used: set[str], index: int, source: str) -> Body | None:
        """A collider Mesh that deforms (simbake.usd_deforming): kinematic, at the origin, its
        shape the first frame's world surface and its surface at every frame in `deformation`.
        None for an open mesh: kept as before, a still two-sided surface (warned)."""
        from pxr import UsdPhysics

        path = prim.GetPath()
        v, f = self._mesh_triangles(prim)
        deformation = read_deformation(self, prim, f, len(v), source)
        first = deformation.vertices[0]
        what = "skinned by UsdSkel" if source == "skel" else "time-sampled points"
        if not self._closed(first, f):
            self.warn(path, f"a deforming collider ({what}) must be a closed mesh wound outwards; this one is "
                            "open, so it is kept still at its pose at the start time code")
            return None
        token = UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr().Get()
        if token not in (None, "none"):
            self.warn(path, f"physics:approximation {str(token)!r} is not applied to a deforming collider; "
                            "its own mesh is used at every frame")
        friction, restitution, _ = self._material(path, d)
        self._body_keys(index, path, path, self.material_path)
        shape = Shape(kind="mesh", mesh_vertices=first, mesh_triangles=deformation.triangles,
                      mesh_source=str(path))
        self._fast_deformation(path, deformation, self._voxel_size([prim], shape))
        return Body(name=self._name(str(path), used), shape=shape, density=DEFAULT_DENSITY, mass=None,
                    voxel_size=self._voxel_size([prim], shape), position=(0.0, 0.0, 0.0),
                    orientation=(1.0, 0.0, 0.0, 0.0), linear_velocity=(0.0, 0.0, 0.0),
                    angular_velocity=(0.0, 0.0, 0.0), friction=friction, restitution=restitution,
                    kinematic=True, prim_path=str(path), deformation=deformation)

    def _fast_deformation(self, path, deformation, voxel_size: float) -> None:
        """Warns when the surface moves further in a frame than its level sets' exterior band
        reaches (DEFORMING_REACH voxels): inside the frame the contacts blend the frame's two
        level sets, which are then no longer distances there."""
        from .assets import automatic_voxel_size

        voxel = voxel_size or automatic_voxel_size(deformation.vertices[0])
        moves = np.linalg.norm(np.diff(deformation.vertices, axis=0), axis=2)
        if len(moves) and moves.max() > DEFORMING_REACH * voxel:
            frame = int(self.start) + 1 + int(np.argmax(moves.max(axis=1)))
            self.warn(path, f"a vertex moves {moves.max() * 1e3:.3g} mm in the frame to time code {frame}, more "
                            f"than {DEFORMING_REACH} voxels of its level set ({voxel * 1e3:.3g} mm): contacts inside "
                            "such frames are approximate (more frames per second, or coarser voxels, keep them exact)")

    def _ground(self, path, d) -> Ground:
        prim = self.stage.GetPrimAtPath(path)
        from pxr import UsdGeom

        r, t, _ = self.frame(prim, "ground plane")
        axis = "XYZ".index(self._axis(prim, UsdGeom.Plane(prim)))
        normal = self.C @ r[:, axis]
        if abs(abs(normal[1]) - 1.0) > 1e-6:
            raise self.error(path, "axis", f"a static Plane is the ground and must face the stage's up "
                                           f"axis ({self.up_axis}); this one faces {_show(np.round(r[:, axis], 6))}")
        friction, restitution, _ = self._material(path, d)
        self.keys += [("ground.height", f"{path}.xformOp:translate"),
                      ("ground.friction", f"{self.material_path}.physics:dynamicFriction"),
                      ("ground.restitution", f"{self.material_path}.physics:restitution")]
        return Ground(height=self.point(t)[1], friction=friction, restitution=restitution)

    # -- cloth --------------------------------------------------------------------------------

    def _cloths(self, used: set[str], bodies: list[Body]):
        from pxr import Usd, UsdGeom, UsdPhysics

        cloths, targets = [], []
        for prim in self.stage.Traverse():
            if not _has_cloth_api(prim):
                continue
            path = prim.GetPath()
            if not prim.IsA(UsdGeom.Mesh):
                raise self.error(path, "", f"{CLOTH_API} applies to a Mesh, not a {prim.GetTypeName() or 'typeless prim'}")
            if prim.HasAPI(UsdPhysics.RigidBodyAPI) or prim.HasAPI(UsdPhysics.CollisionAPI):
                raise self.error(path, "", f"a {CLOTH_API} mesh cannot also be a rigid body or collider")
            local, faces = self._mesh_triangles(prim)
            world = self.world(prim)
            vertices = (local @ world[:3, :3].T + world[:3, 3]) @ self.C.T * self.mpu
            a = _ClothAttributes(self, prim)
            self._cloth_keys(len(cloths), path)
            self._instance_roots(prim)
            pinned = a.ints("pinned")
            bad = [i for i in pinned if not 0 <= i < len(vertices)]
            if bad:
                raise self.error(path, "simbake:cloth:pinned", f"point {bad[0]} does not exist (the mesh has {len(vertices)})")
            attach_to, attached = self._attachment(prim, a, bodies, pinned, len(vertices))
            cloth = Cloth(
                name=self._name(str(path), used), grid_size=None, grid_resolution=None, mesh_path=None,
                position=(0.0, 0.0, 0.0), orientation=(1.0, 0.0, 0.0, 0.0),
                area_density=a.number("areaDensity", Cloth.area_density, self.kpu / self.mpu ** 2, positive=True),
                stretch_stiffness=a.number("stretchStiffness", Cloth.stretch_stiffness, self.kpu),
                bend_stiffness=a.number("bendStiffness", Cloth.bend_stiffness, self.kpu * self.mpu ** 2),
                damping=a.number("damping", Cloth.damping, 1.0),
                strain_limit=a.number("strainLimit", Cloth.strain_limit, 1.0),
                compression=a.token("compression", Cloth.compression, COMPRESSION_MODES),
                friction=a.number("friction", Cloth.friction, 1.0),
                thickness=a.number("thickness", Cloth.thickness, self.mpu),
                pinned=tuple(pinned),
                model=a.token("model", Cloth.model, CLOTH_MODELS),
                poisson_ratio=a.number("poissonRatio", Cloth.poisson_ratio, 1.0, below=0.5),
                integrator=a.token("integrator", Cloth.integrator, CLOTH_INTEGRATORS),
                self_collision=a.boolean("selfCollision", Cloth.self_collision),
                attach_to=attach_to, attached=tuple(attached),
                mesh_vertices=_frozen(vertices), mesh_triangles=_frozen(faces), prim_path=str(path))
            if UsdGeom.Xformable(prim).TransformMightBeTimeVarying():
                self.warn(path, "the cloth's transform is animated; its rest shape and cache use the start time code's")
            targets.append(ShotCloth(index=len(cloths), prim_path=str(path),
                                     world_to_local=tuple(_vec(row) for row in np.linalg.inv(world))))
            cloths.append(cloth)
        return cloths, targets

    def _attachment(self, prim, a: _ClothAttributes, bodies: list[Body], pinned: list[int],
                    count: int) -> tuple[str, list[int]]:
        """simbake:cloth:attachTo (one target: a body's prim, a collider inside a rigid body, or a
        prim holding one body, such as a SkelRoot over its skinned collider) and
        simbake:cloth:attached (point indices, each once, none pinned): the body's name and the points."""
        path = prim.GetPath()
        rel = prim.GetRelationship("simbake:cloth:attachTo")
        targets = [str(t) for t in rel.GetTargets()] if rel else []
        attached = a.ints("attached")
        if not targets and not attached:
            return "", []
        if len(targets) != 1:
            raise self.error(path, "simbake:cloth:attachTo", f"must target one prim, the body the attached points "
                                                            f"ride; it targets {len(targets)}")
        if not attached:
            raise self.error(path, "simbake:cloth:attached", "lists no point: give the indices of the points "
                                                            "attachTo carries")
        first: dict[int, int] = {}
        for k, i in enumerate(attached):
            if not 0 <= i < count:
                raise self.error(path, "simbake:cloth:attached", f"point {i} does not exist (the mesh has {count})")
            if i in first:
                raise self.error(path, "simbake:cloth:attached", f"point {i} is listed twice (at {first[i]} and {k})")
            if i in pinned:
                raise self.error(path, "simbake:cloth:attached", f"point {i} is also in simbake:cloth:pinned; a point "
                                                                "is either pinned or attached")
            first[i] = k
        return self._attach_target(path, targets[0], bodies), attached

    def _attach_target(self, path, target: str, bodies: list[Body]) -> str:
        """The body an attachTo target names: its own prim, the nearest body above it (a collider of
        a rigid body), or the one body below it."""
        bodies = [b for b in bodies if b.prim_path]
        owners = [b for b in bodies if b.prim_path == target or target.startswith(b.prim_path + "/")]
        if owners:
            return max(owners, key=lambda b: len(b.prim_path)).name
        below = [b for b in bodies if b.prim_path.startswith(target.rstrip("/") + "/")]
        if len(below) == 1:
            return below[0].name
        if below:
            listed = ", ".join(sorted(b.prim_path for b in below)[:4])
            raise self.error(path, "simbake:cloth:attachTo", f"<{target}> holds {len(below)} bodies ({listed}"
                                                            f"{', ...' if len(below) > 4 else ''}); target one of them")
        raise self.error(path, "simbake:cloth:attachTo", f"<{target}> is not a simulated body: target a rigid body, "
                                                        "or a collider (static, time-sampled or skinned by UsdSkel)")


# physics:approximation of a mesh collider (UsdPhysics.MeshCollisionAPI), as simbake reads it:
APPROXIMATIONS = {
    "none": "the mesh itself (a closed mesh is a solid; an open static one a two-sided surface)",
    "meshSimplification": "the mesh itself: simbake does not simplify (its level set is already "
                          "a resolution-bound approximation)",
    "convexHull": "the convex hull of the mesh's points (trimesh)",
    "convexDecomposition": "the mesh itself: simbake's level sets take concave shapes whole, which "
                           "is what an exact decomposition would give",
    "boundingSphere": "the smallest sphere around the mesh's points (trimesh's minimum_nsphere)",
    "boundingCube": "the box around the mesh's points along the mesh's own axes",
    "sdf": "the mesh's signed distance field, simbake's own representation; "
           "physxSDFMeshCollision:sdfResolution sets its voxels across the longest extent",
}

_CLOTH_KEYS = ("area_density", "stretch_stiffness", "bend_stiffness", "damping", "strain_limit",
               "friction", "thickness", "poisson_ratio")


def _camel(key: str) -> str:
    first, *rest = key.split("_")
    return first + "".join(word.title() for word in rest)


class _ClothAttributes:
    """Typed reads of simbake:cloth:* on one prim; unauthored attributes give the SI default."""

    def __init__(self, reader: _Reader, prim):
        self.reader, self.prim = reader, prim

    def _get(self, name: str):
        attr = self.prim.GetAttribute(f"simbake:cloth:{name}")
        if not attr or not attr.HasAuthoredValue():
            return None
        return attr.Get(self.reader.start)

    @staticmethod
    def _type(value) -> str:
        """The type a value was authored with (the schema's own type may differ)."""
        from pxr import Sdf

        return str(Sdf.GetValueTypeNameForValue(value)) or type(value).__name__

    def _error(self, name: str, problem: str) -> SceneError:
        return self.reader.error(self.prim.GetPath(), f"simbake:cloth:{name}", problem)

    def number(self, name: str, default: float, unit: float, positive: bool = False,
               below: float | None = None) -> float:
        value = self._get(name)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self._error(name, f"must be a number, got {value!r}")
        value = _decimal(value)
        ok = math.isfinite(value) and (value > 0 if positive else value >= 0)
        if below is not None:
            ok = ok and value < below
        if not ok:
            bound = f"in [0, {below})" if below is not None else ("> 0" if positive else ">= 0")
            raise self._error(name, f"must be a finite number {bound}, got {value}")
        return value * unit

    def token(self, name: str, default: str, choices: tuple[str, ...]) -> str:
        value = self._get(name)
        if value is None:
            return default
        if str(value) not in choices:
            raise self._error(name, f"unknown value {str(value)!r} (expected one of: {', '.join(choices)})")
        return str(value)

    def boolean(self, name: str, default: bool) -> bool:
        value = self._get(name)
        if value is not None and not isinstance(value, bool):
            raise self._error(name, f"must be a bool (1 or 0), got {self._type(value)} {_short(repr(value))}")
        return default if value is None else value

    def ints(self, name: str) -> list[int]:
        """Point indices: an int[] (a float or string array would be guessed at, so it is refused)."""
        value = self._get(name)
        if value is None:
            return []
        if self._type(value) not in ("int[]", "int64[]", "uint[]", "uint64[]"):
            raise self._error(name, f"must be an int[] of point indices, got {self._type(value)} {_short(repr(value) if isinstance(value, str) else str(value))}")
        return [int(i) for i in value]


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------

class _MaterialDesc:
    """A physics material read from its prim (the parser's RigidBodyMaterialDesc fields),
    for a material bound without MaterialBindingAPI (the parser skips those)."""

    def __init__(self, api):
        self.dynamicFriction = api.GetDynamicFrictionAttr().Get() or 0.0
        self.staticFriction = api.GetStaticFrictionAttr().Get() or 0.0
        self.restitution = api.GetRestitutionAttr().Get() or 0.0
        self.density = api.GetDensityAttr().Get() or 0.0


# PhysX attributes simbake reads: the solver's steps per second (substeps per frame), and the
# collision thickness and SDF resolution of mesh colliders (see _Reader._collider_geometry)
_PHYSX_MAPPED = ("physxScene:timeStepsPerSecond", "physxCollision:restOffset",
                 "physxSDFMeshCollision:sdfResolution")
# PhysX attributes whose value, when it is this, is what simbake does anyway: no warning
_PHYSX_NEUTRAL = {
    "physxRigidBody:linearDamping": 0.0, "physxRigidBody:angularDamping": 0.0,
    "physxRigidBody:disableGravity": False, "physxRigidBody:enableCCD": True,
    "physxRigidBody:enableSpeculativeCCD": True, "physxRigidBody:retainAccelerations": False,
    "physxScene:enableCCD": True, "physxScene:enableGPUDynamics": False,
    "physxCollision:contactOffset": None,  # a detection margin: simbake's contacts are speculative
    "physxMaterial:frictionCombineMode": "average", "physxMaterial:restitutionCombineMode": "average",
}
# PhysX schemas that change what happens by being applied
_PHYSX_BEHAVIOUR = {
    "PhysxTriggerAPI": "(a trigger volume) is not simulated by simbake: the collider collides",
    "PhysxCharacterControllerAPI": "is not simulated by simbake; the prim is a plain collider",
    "PhysxDeformableBodyAPI": "is not simulated by simbake; left out",
    "PhysxDeformableSurfaceAPI": "is not simulated by simbake (use SimbakeClothAPI); left out",
    "PhysxParticleSystem": "is not simulated by simbake; left out",
    "PhysxVehicleAPI": "is not simulated by simbake; the prim is a plain rigid body",
}


def _same(value, neutral) -> bool:
    if neutral is None:
        return True
    if isinstance(neutral, str):
        return str(value) == neutral
    try:
        return bool(value == neutral) if isinstance(neutral, bool) else float(value) == float(neutral)
    except (TypeError, ValueError):
        return False


def _value_text(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


_SUPPORTED_NAMES = ("Scene", "RigidBody", "RigidBodyMaterial", "CubeShape", "SphereShape",
                    "CapsuleShape", "CylinderShape", "MeshShape", "PlaneShape", "Capsule1Shape",
                    "Cylinder1Shape", *joint_kinds())


class _SupportedKinds:
    def __contains__(self, kind) -> bool:
        return str(kind).rsplit(".", 1)[-1] in _SUPPORTED_NAMES


_SUPPORTED = _SupportedKinds()


def _describe_kind(kind) -> str:
    name = str(kind).rsplit(".", 1)[-1]
    if name.endswith("Joint"):
        return f"a joint ({name})"
    return {"Articulation": "an articulation", "CollisionGroup": "a collision group",
            "ConeShape": "a cone collider", "CustomShape": "a custom collider",
            "SpherePointsShape": "a sphere-points collider"}.get(name, name)


def _wound(faces: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Triangles wound outwards after the linear map `a` (a mirror turns them inside out)."""
    return faces[:, ::-1].copy() if np.linalg.det(a) < 0 else faces


def _has_cloth_api(prim) -> bool:
    """SimbakeClothAPI applied (also read when the schema was registered too late to be known)."""
    if CLOTH_API in prim.GetAppliedSchemas():
        return True
    listop = prim.GetMetadata("apiSchemas")
    return bool(listop) and CLOTH_API in listop.ApplyOperations([])


def _face_order(tris: list[np.ndarray], counts: np.ndarray) -> np.ndarray:
    """Fanned triangles in face order (so triangle order follows the mesh's faces)."""
    order = []
    starts = {}
    for c in np.unique(counts):
        starts[c] = np.flatnonzero(counts == c)
    keys = []
    for c in np.unique(counts):
        for k in range(1, c - 1):
            keys.append(starts[c] * 64 + k)
    keys = np.concatenate(keys)
    order = np.argsort(keys, kind="stable")
    return np.concatenate(tris)[order]


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def Usd_time(code: float):
    from pxr import Usd

    return Usd.TimeCode(code)

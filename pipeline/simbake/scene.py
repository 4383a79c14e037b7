"""Scene files: load and validate a simbake scene description (TOML, version 1).

A scene file describes one bake. Units are SI (metres, kilograms, seconds, radians),
Y is up, quaternions are ``[w, x, y, z]`` and paths are relative to the scene file::

    [scene]     fps = 24, start_frame = 1, end_frame = 120 (required), gravity = [0, -9.81, 0]
    [solver]    substeps = 0                      (0: automatic)
    [ground]    height, friction, restitution     (an infinite plane y = height; absent: none)
    [[bodies]]  name (required), mesh = "file.obj"  or  shape = { type = "sphere", radius = r }
                | { type = "box", size = [x, y, z] }, density or mass, position, orientation,
                linear_velocity, angular_velocity, friction, restitution, kinematic, voxel_size,
                keys = [{ time, position, orientation }, ...] (kinematic bodies only),
                mesh_sequence = "frames/body.%04d.obj" (kinematic: a deforming body, a file a frame)
    [[cloths]]  name (required), grid = { size = [w, d], resolution = [nx, nz] } or mesh = "...",
                position, orientation, area_density, stretch_stiffness, bend_stiffness,
                damping, strain_limit, compression, friction, thickness, pinned,
                model (springs | membrane), poisson_ratio, integrator (implicit | explicit),
                self_collision (true | false), attach = { to = "BODY", points = [...] }
    [[joints]]  name (required), type (fixed | revolute | prismatic | spherical | distance | d6),
                body0, body1 (body names; absent: the world), local_position0/1,
                local_rotation0/1, axis (x | y | z), lower_limit, upper_limit, cone_angle0/1,
                min_distance, max_distance, limits = { rot_x = [lo, hi] | "locked", ... } (d6),
                drives = { angular = { stiffness, damping, target_position, target_velocity,
                max_force, type = "force" | "acceleration" }, ... }, break_force, break_torque,
                enabled, collision_enabled
    filtered_pairs = [["a", "b"], ...]            (pairs of bodies that never collide)

The full reference, with defaults, is the section "Scene file (TOML), version 1" of
DESIGN.md; the defaults here are the dataclass defaults below.

:func:`load_toml_scene` checks everything that can be checked without reading a mesh: unknown
keys at every level, types, ranges, NaN and infinity, vector lengths, names (valid USD
prim names, unique across bodies and cloths, never ``World``), references (mesh files
must exist and be files). Loading the meshes themselves is ``assets.py``'s job. Type
rules: a boolean is not a number; an integer is accepted where a float is expected, a
float is never accepted where an integer is required.

Every problem raises :class:`~simbake.errors.SceneError` whose one-line message names the
file (as the user gave it), the key path and the problem, e.g.
``demo.toml: bodies[2].shape.radius: must be > 0, got -1.0``.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Optional

from .errors import SceneError
from .limits import check_scene

__all__ = ["Shape", "Ground", "Key", "Deformation", "Body", "Cloth", "Drive", "Joint", "Scene", "load_toml_scene",
           "read_scene_data", "scene_from_data"]

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

ZERO3: Vec3 = (0.0, 0.0, 0.0)
IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)
DEFAULT_DENSITY = 1000.0  # kg/m^3, used when a body gives neither density nor mass
SHAPE_TYPES = ("sphere", "box")
COMPRESSION_MODES = ("subgrid", "enforce", "none")
CLOTH_MODELS = ("springs", "membrane")
CLOTH_INTEGRATORS = ("implicit", "explicit")
RESERVED_NAMES = ("World",)  # the root prim of every cache
JOINT_TYPES = ("fixed", "revolute", "prismatic", "spherical", "distance", "d6")
JOINT_AXES = ("x", "y", "z")
JOINT_DOFS = ("trans_x", "trans_y", "trans_z", "rot_x", "rot_y", "rot_z")  # UsdPhysics' transX .. rotZ
DRIVE_TYPES = ("force", "acceleration")
INF = math.inf
_PRIM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


# --------------------------------------------------------------------------------------
# The validated scene
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Shape:
    """What a body is made of: an analytic primitive or a mesh file."""

    kind: str  # "sphere" | "box" | "mesh"
    radius: float = 0.0  # sphere
    size: Vec3 = ZERO3  # box: full edge lengths
    mesh_path: Path | None = None  # mesh: absolute path
    # mesh given inline (a USD shot's collider): (n, 3) float64 (m), (m, 3) int32, read-only,
    # closed; mesh_source names it (a prim path) for messages and level-set sharing
    mesh_vertices: Any = field(default=None, compare=False, repr=False)
    mesh_triangles: Any = field(default=None, compare=False, repr=False)
    mesh_source: str = ""
    # an open or non-manifold mesh of a kinematic or static collider: a two-sided surface of
    # this half-thickness (m), phi = |d| - thickness; 0 for a closed mesh (a solid)
    thickness: float = 0.0


@dataclass(frozen=True)
class Ground:
    """The infinite plane y = height."""

    height: float = 0.0
    friction: float = 0.5
    restitution: float = 0.0


@dataclass(frozen=True)
class Key:
    """A pose of a keyed kinematic body's mesh origin at a time (s after start_frame)."""

    time: float
    position: Vec3
    orientation: Quat  # (w, x, y, z), unit length


@dataclass(frozen=True)
class Deformation:
    """A deforming collider's surface at every frame of the bake (a USD shot's collider Mesh
    with time-sampled points, or one skinned by UsdSkel): world vertices, one topology."""

    vertices: Any = field(compare=False, repr=False)   # (frames, n, 3) float64 (m, Y up), read-only;
                                                       # row k is frame start_frame + k
    triangles: Any = field(compare=False, repr=False)  # (m, 3) int32, closed, wound outwards
    source: str = "points"                             # "points" (time-sampled) | "skel" (UsdSkel)
                                                       # | "sequence" (a TOML body's mesh_sequence)


@dataclass(frozen=True)
class Body:
    """A rigid body. Exactly one of ``density`` / ``mass`` is set."""

    name: str
    shape: Shape
    density: float | None
    mass: float | None
    position: Vec3
    orientation: Quat  # (w, x, y, z), unit length
    linear_velocity: Vec3
    angular_velocity: Vec3  # world frame, rad/s
    friction: float = 0.5
    restitution: float = 0.0
    kinematic: bool = False
    voxel_size: float = 0.0  # 0: automatic
    keys: tuple[Key, ...] = ()  # kinematic only: the path it follows, times increasing
    center_of_mass: Vec3 | None = None  # in the mesh's frame (m); None: the shape's centroid
    inertia: tuple[Vec3, Vec3, Vec3] | None = None  # about the centre of mass, mesh frame (kg m^2)
    prim_path: str = ""  # a USD shot's body: its prim, for messages
    # a deforming collider (kinematic, its shape the first frame's surface, its mesh in world
    # coordinates): the surface at every frame; None for a rigid body
    deformation: Deformation | None = field(default=None, compare=False, repr=False)
    # a TOML deforming body: its files' pattern (absolute, one %d field for the frame number),
    # each frame's mesh placed by position and orientation (read_sequences)
    mesh_sequence: Path | None = None


@dataclass(frozen=True)
class Cloth:
    """A cloth sheet: a regular grid in the XZ plane or a mesh file."""

    name: str
    grid_size: Vec2 | None
    grid_resolution: tuple[int, int] | None  # vertices along x and z
    mesh_path: Path | None
    position: Vec3
    orientation: Quat
    area_density: float = 0.1
    stretch_stiffness: float = 1000.0
    bend_stiffness: float = 1e-4
    damping: float = 0.01
    strain_limit: float = 0.1
    compression: str = "subgrid"
    friction: float = 0.3
    thickness: float = 0.005
    pinned: tuple[int, ...] = ()
    model: str = "springs"          # springs | membrane (StVK)
    poisson_ratio: float = 0.3      # membrane only
    integrator: str = "implicit"    # implicit (backward Euler) | explicit
    self_collision: bool = True     # kept from passing through itself (at `thickness`)
    # points bound at the first frame to the nearest point of a body's surface and carried with
    # it (core: contact/cloth_attachment.h): the body's name, and the vertex indices
    attach_to: str = ""
    attached: tuple[int, ...] = ()
    # a USD shot's cloth mesh, inline: (n, 3) float64 world rest positions (m), (m, 3) int32
    mesh_vertices: Any = field(default=None, compare=False, repr=False)
    mesh_triangles: Any = field(default=None, compare=False, repr=False)
    prim_path: str = ""


@dataclass(frozen=True)
class Drive:
    """A joint drive (UsdPhysics' PhysicsDriveAPI) on one degree of freedom, SI units: force =
    stiffness (target_position - position) + damping (target_velocity - velocity), at most
    max_force; an acceleration drive's gains are per unit of effective mass."""

    stiffness: float = 0.0        # N/m or N m/rad (acceleration: 1/s^2)
    damping: float = 0.0          # N s/m or N m s/rad (acceleration: 1/s)
    target_position: float = 0.0  # m or rad
    target_velocity: float = 0.0  # m/s or rad/s
    max_force: float = INF        # N or N m
    type: str = "force"           # force | acceleration


@dataclass(frozen=True)
class Joint:
    """A joint between two bodies (or a body and the world), UsdPhysics' joints in SI units.
    Frames are in each body's frame (its mesh origin and orientation); the world's frame for
    an absent body."""

    name: str
    type: str                     # fixed | revolute | prismatic | spherical | distance | d6
    body0: str = ""               # a body's name; "": the world
    body1: str = ""
    local_position0: Vec3 = ZERO3
    local_rotation0: Quat = IDENTITY
    local_position1: Vec3 = ZERO3
    local_rotation1: Quat = IDENTITY
    axis: str = "x"               # revolute, prismatic, spherical
    lower_limit: float = -INF     # revolute (rad), prismatic (m)
    upper_limit: float = INF
    cone_angle0: float = INF      # spherical (rad)
    cone_angle1: float = INF
    min_distance: float = 0.0     # distance (m)
    max_distance: float = INF
    limits: tuple[tuple[str, float, float], ...] = ()  # d6: (dof, lower, upper); lower > upper: locked
    drives: tuple[tuple[str, Drive], ...] = ()         # (linear | angular | trans_x .. rot_z, drive)
    break_force: float = INF      # N
    break_torque: float = INF     # N m
    enabled: bool = True
    collision_enabled: bool = False
    prim_path: str = ""           # a USD shot's joint: its prim


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A validated scene. Keyword-only because ``end_frame`` is required but follows defaults."""

    path: Path  # the scene file: absolute, its directory resolved
    source: str = ""  # the scene file as the user named it, for messages
    fps: float = 24.0
    start_frame: int = 1
    end_frame: int
    gravity: Vec3 = (0.0, -9.81, 0.0)
    substeps: int = 0  # per frame; 0: automatic
    ground: Ground | None = None
    bodies: tuple[Body, ...] = ()
    cloths: tuple[Cloth, ...] = ()
    joints: tuple[Joint, ...] = ()
    filtered_pairs: tuple[tuple[str, str], ...] = ()  # bodies (by name) that never collide
    # (a USD shot's collision groups, PhysicsCollisionGroup: each body's groups and each
    # group's filtered groups, by index)
    collision_groups: tuple[tuple[str, tuple[int, ...]], ...] = ()
    group_filters: tuple[tuple[int, ...], ...] = ()
    warnings: tuple[str, ...] = ()  # what loading left out or changed, one line each
    shot: Any = None  # a USD shot's simbake.usd_scene.ShotInfo (for its cache layer); else None

    @property
    def frame_count(self) -> int:
        """Number of written frames, start and end inclusive."""
        return self.end_frame - self.start_frame + 1

    def hash(self) -> str:
        """SHA-256 (hex) over the scene file and every mesh file it references (a USD shot:
        every layer its stage used, in sorted order).

        Files are read now, in a fixed order: the scene file, then the meshes in order of
        first reference (bodies, then cloths), each once. Each file contributes its own
        SHA-256 digest, so file boundaries cannot be confused.
        """
        digest = hashlib.sha256()
        for path in self.input_files():
            digest.update(_file_digest(path))
        return digest.hexdigest()

    def source_key(self, key: str) -> str:
        """Where a scene key was read from, for messages: the key itself for a TOML scene, the
        prim and attribute for a USD shot (``/World/Box.size`` for ``bodies[0].shape.size[1]``)."""
        return self.shot.usd_key(key) if self.shot is not None else key

    def input_files(self) -> tuple[Path, ...]:
        """Every file a bake of this scene reads: the scene file (a USD shot: every layer its
        stage used, in sorted order), then its meshes."""
        layers = tuple(Path(p) for p in self.shot.layers) if self.shot is not None else (self.path,)
        return (*layers, *self._mesh_paths())

    def _mesh_paths(self) -> tuple[Path, ...]:
        from .mesh_files import sequence_frame_path

        paths = [b.shape.mesh_path for b in self.bodies]
        for b in self.bodies:
            if b.mesh_sequence is not None:
                paths += [sequence_frame_path(b.mesh_sequence, f) for f in range(self.start_frame, self.end_frame + 1)]
        paths += [c.mesh_path for c in self.cloths]
        return tuple(dict.fromkeys(p for p in paths if p is not None))


def _file_digest(path: Path) -> bytes:
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                digest.update(chunk)
    except OSError as exc:
        raise _error(path, "", f"cannot read for hashing: {exc.strerror or exc}") from None
    return digest.digest()


# --------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------

_TOP_KEYS = ("scene", "solver", "ground", "bodies", "cloths", "joints", "filtered_pairs")
_SCENE_KEYS = ("fps", "start_frame", "end_frame", "gravity")
_SOLVER_KEYS = ("substeps",)
_GROUND_KEYS = ("height", "friction", "restitution")
_BODY_KEYS = (
    "name", "mesh", "shape", "density", "mass", "position", "orientation",
    "linear_velocity", "angular_velocity", "friction", "restitution", "kinematic",
    "voxel_size", "keys", "mesh_sequence",
)  # fmt: skip
_KEY_KEYS = ("time", "position", "orientation")
_SHAPE_KEYS = {"sphere": ("type", "radius"), "box": ("type", "size")}
_ANY_SHAPE_KEYS = ("type", "radius", "size")
_CLOTH_KEYS = (
    "name", "grid", "mesh", "position", "orientation", "area_density",
    "stretch_stiffness", "bend_stiffness", "damping", "strain_limit", "compression",
    "friction", "thickness", "pinned", "model", "poisson_ratio", "integrator", "self_collision", "attach",
)  # fmt: skip
_GRID_KEYS = ("size", "resolution")
_ATTACH_KEYS = ("to", "points")
_JOINT_KEYS = ("name", "type", "body0", "body1", "local_position0", "local_rotation0", "local_position1",
               "local_rotation1", "axis", "lower_limit", "upper_limit", "cone_angle0", "cone_angle1",
               "min_distance", "max_distance", "limits", "drives", "break_force", "break_torque", "enabled",
               "collision_enabled")
_DRIVE_KEYS = ("stiffness", "damping", "target_position", "target_velocity", "max_force", "type")
_TYPE_KEYS = {"revolute": ("axis", "lower_limit", "upper_limit"), "prismatic": ("axis", "lower_limit", "upper_limit"),
              "spherical": ("axis", "cone_angle0", "cone_angle1"), "distance": ("min_distance", "max_distance"),
              "d6": ("limits",)}
# the keys each table allows (simbake.wedge_takes checks --set key paths against it)
TABLE_KEYS = {"scene": _SCENE_KEYS, "solver": _SOLVER_KEYS, "ground": _GROUND_KEYS, "bodies": _BODY_KEYS,
              "cloths": _CLOTH_KEYS, "bodies.shape": _ANY_SHAPE_KEYS, "cloths.grid": _GRID_KEYS,
              "joints": _JOINT_KEYS}


def load_toml_scene(path: str | os.PathLike[str], frames: tuple | None = None) -> Scene:
    """Read and validate a TOML scene file; raise :class:`SceneError` on any problem.
    `frames` (start, end; either may be None): another range than the file's (``--frames``).
    (simbake.load_scene takes a USD shot too: simbake.loading.)"""
    file = os.fspath(path)  # named in messages exactly as the user gave it
    return scene_from_data(read_scene_data(file), file, frames)


def frame_range(file: str, start_frame, end_frame) -> tuple | None:
    """(start, end) as given (either may be None), checked as whole numbers; None when neither."""
    if start_frame is None and end_frame is None:
        return None
    for value in (start_frame, end_frame):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise _error(file, "--frames", f"frames must be whole numbers, got {value!r}")
    if start_frame is not None and end_frame is not None and end_frame < start_frame:
        raise _error(file, "--frames", f"END must be >= START, got {start_frame}:{end_frame}")
    return (start_frame, end_frame)


def stage_range(scene: Scene, frames: tuple) -> tuple[int, int]:
    """`frames` (start, end; either may be None: the scene's own) as a whole range, checked."""
    start = scene.start_frame if frames[0] is None else frames[0]
    end = scene.end_frame if frames[1] is None else frames[1]
    if end < start:
        raise _error(scene.source, "--frames", f"END must be >= START, got {start}:{end}")
    return (start, end)


def _scene_path(file: str) -> Path:
    """Canonical directory (no "..", as the OS would walk it), but the file's own name is
    kept, so a symlinked scene file finds meshes beside the link, as USD layers do."""
    given = Path(file).absolute()
    return given.parent.resolve() / given.name


def read_scene_data(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A TOML scene file's parsed tables, not yet validated (see :func:`scene_from_data`)."""
    file = os.fspath(path)
    return _read_toml(file, _scene_path(file))


def scene_from_data(data: dict[str, Any], path: str | os.PathLike[str], frames: tuple | None = None) -> Scene:
    """Validate parsed TOML tables as the scene file at `path` would be (paths relative to it,
    messages naming it): what load_toml_scene does after reading, over the range `frames` when
    given (a deforming body's files are those of the range). A wedge edits the tables of a
    scene file and validates each take's through here (simbake.wedge_takes)."""
    file = os.fspath(path)
    scene_path = _scene_path(file)
    base_dir = scene_path.parent
    root = _Table(file, "", data, _TOP_KEYS)

    settings = root.subtable("scene", _SCENE_KEYS, required=True)
    start_frame = settings.integer("start_frame", Scene.start_frame)
    end_frame = settings.integer("end_frame", check=_at_least(start_frame, "start_frame"))
    solver = root.subtable("solver", _SOLVER_KEYS)

    bodies = tuple(_body(t, base_dir) for t in root.tables("bodies", _BODY_KEYS))
    cloth_tables = root.tables("cloths", _CLOTH_KEYS)
    cloths = tuple(_cloth(t, base_dir) for t in cloth_tables)
    _check_unique_names(file, bodies, cloths)
    names = [b.name for b in bodies]
    for t, cloth in zip(cloth_tables, cloths):
        _check_attach_target(t, cloth, names)
    joints = tuple(_joint(t, names) for t in root.tables("joints", _JOINT_KEYS))
    _check_unique_joints(file, joints)

    scene = Scene(
        path=scene_path,
        source=file,
        fps=settings.number("fps", Scene.fps, _greater(0)),
        start_frame=start_frame,
        end_frame=end_frame,
        gravity=settings.vector("gravity", 3, Scene.gravity),
        substeps=solver.integer("substeps", Scene.substeps, _at_least(0)),
        ground=_ground(root.subtable("ground", _GROUND_KEYS)) if root.has("ground") else None,
        bodies=bodies,
        cloths=cloths,
        joints=joints,
        filtered_pairs=_filtered_pairs(root, names),
    )
    check_scene(scene)  # the physical range and the budget of what the scene alone decides
    if frames is not None and (frames[0], frames[1]) != (None, None):
        start, end = stage_range(scene, frames)
        scene = replace(scene, start_frame=start, end_frame=end)
        check_scene(scene)
    return read_sequences(scene)


def read_sequences(scene: Scene) -> Scene:
    """The scene with each ``mesh_sequence`` body's surface read at every frame of its range
    (Body.deformation: the files' meshes placed by the body's position and orientation, one
    topology) and its shape the first frame's, as a USD shot's deforming collider is read."""
    if all(b.mesh_sequence is None for b in scene.bodies):
        return scene
    from .mesh_files import read_mesh_sequence

    bodies = []
    for i, b in enumerate(scene.bodies):
        if b.mesh_sequence is not None:
            vertices, triangles = read_mesh_sequence(b.mesh_sequence, range(scene.start_frame, scene.end_frame + 1),
                                                     scene.source, f"bodies[{i}].mesh_sequence", b.position,
                                                     b.orientation)
            b = replace(b, shape=replace(b.shape, mesh_vertices=vertices[0], mesh_triangles=triangles),
                        deformation=Deformation(vertices=vertices, triangles=triangles, source="sequence"))
        bodies.append(b)
    return replace(scene, bodies=tuple(bodies))


def _parse_toml(text: str) -> dict[str, Any]:
    """The TOML document: parsed by rtoml (Rust; a 1000-body pile in a seventh of tomllib's
    time), and where rtoml refuses it, by tomllib, whose result or error is the one given (its
    messages name line and column; it reads a few documents rtoml refuses, 1e400 as inf)."""
    import rtoml

    try:
        return rtoml.loads(text)
    except Exception:  # noqa: BLE001 (rtoml's errors say less than tomllib's: ask it)
        return tomllib.loads(text)


def _read_toml(file: str, path: Path) -> dict[str, Any]:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise _error(file, "", "file not found") from None
    except IsADirectoryError:
        raise _error(file, "", "is a directory, not a scene file") from None
    except PermissionError:
        raise _error(file, "", "cannot read: permission denied") from None
    except (OSError, ValueError) as exc:
        raise _error(file, "", f"cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _error(file, "", f"invalid TOML: not UTF-8 text (byte offset {exc.start})") from None
    try:
        return _parse_toml(text)
    except tomllib.TOMLDecodeError as exc:
        raise _error(file, "", f"invalid TOML: {exc}") from None


def _ground(t: _Table) -> Ground:
    return Ground(
        height=t.number("height", Ground.height),
        friction=t.number("friction", Ground.friction, _at_least(0)),
        restitution=t.number("restitution", Ground.restitution, _within(0, 1)),
    )


def _body(t: _Table, base_dir: Path) -> Body:
    name = t.string("name", check=_prim_name)
    shape = _body_shape(t, base_dir)
    density = t.number("density", None, _greater(0))
    mass = t.number("mass", None, _greater(0))
    if density is not None and mass is not None:
        raise t.error("mass", "cannot be given together with density; give one of them")
    if density is None and mass is None:
        density = DEFAULT_DENSITY
    position = t.vector("position", 3, ZERO3)
    orientation = _orientation(t)
    kinematic = t.boolean("kinematic", Body.kinematic)
    sequence = _mesh_sequence(t, base_dir, kinematic)
    return Body(
        name=name,
        shape=shape,
        density=density,
        mass=mass,
        position=position,
        orientation=orientation,
        linear_velocity=t.vector("linear_velocity", 3, ZERO3),
        angular_velocity=t.vector("angular_velocity", 3, ZERO3),
        friction=t.number("friction", Body.friction, _at_least(0)),
        restitution=t.number("restitution", Body.restitution, _within(0, 1)),
        kinematic=kinematic,
        voxel_size=t.number("voxel_size", Body.voxel_size, _at_least(0)),
        keys=_keys(t, kinematic, position, orientation),
        mesh_sequence=sequence,
    )


def _mesh_sequence(t: _Table, base_dir: Path, kinematic: bool) -> Path | None:
    """``mesh_sequence = "frames/body.%04d.obj"``: a deforming body's files, one a frame (the
    frame number in the printf field), relative to the scene file; kinematic, moved by its
    frames alone (read_sequences reads them)."""
    if not t.has("mesh_sequence"):
        return None
    from .mesh_files import sequence_pattern_problem

    text = t.string("mesh_sequence", check=_non_empty)
    problem = sequence_pattern_problem(text)
    if problem:
        raise t.error("mesh_sequence", problem)
    if not kinematic:
        raise t.error("mesh_sequence", "a deforming body is kinematic: add kinematic = true (its frames move it)")
    for other in ("keys", "linear_velocity", "angular_velocity"):
        if t.has(other):
            raise t.error(other, "does not apply to a deforming body (mesh_sequence): its frames move it")
    return Path(os.path.abspath(base_dir / text))


def _keys(t: _Table, kinematic: bool, position: Vec3, orientation: Quat) -> tuple[Key, ...]:
    """``keys = [{ time, position, orientation }, ...]``: a kinematic body's path. A key's
    position and orientation default to the body's; times are seconds after start_frame."""
    if not t.has("keys"):
        return ()
    if not kinematic:
        raise t.error("keys", "only a kinematic body (kinematic = true) follows keys")
    keys = []
    for k in t.tables("keys", _KEY_KEYS):
        time = k.number("time")
        if keys and not time > keys[-1].time:
            raise k.error("time", f"must be later than the previous key's {keys[-1].time}, got {time}")
        keys.append(Key(time=time, position=k.vector("position", 3, position),
                        orientation=_orientation(k, orientation)))
    if not keys:
        raise t.error("keys", "must hold at least one key { time = ..., position = [...] }")
    return tuple(keys)


def _body_shape(t: _Table, base_dir: Path) -> Shape:
    if t.has("mesh") and t.has("shape"):
        raise t.error("shape", "cannot be given together with mesh; give one of them")
    if t.has("mesh_sequence"):
        for other in ("mesh", "shape"):
            if t.has(other):
                raise t.error(other, "cannot be given together with mesh_sequence; give one of them")
        return Shape(kind="mesh", mesh_source=t.string("mesh_sequence"))
    if t.has("mesh"):
        return Shape(kind="mesh", mesh_path=_mesh_file(t, "mesh", base_dir))
    if not t.has("shape"):
        raise t.error(None, 'needs either mesh = "FILE", shape = { type = ... } or mesh_sequence = "FILES.%04d.obj"')
    shape = t.subtable("shape", _ANY_SHAPE_KEYS)
    kind = shape.string("type", check=_one_of(SHAPE_TYPES))
    shape.only(_SHAPE_KEYS[kind], f"a {kind} shape")
    if kind == "sphere":
        return Shape(kind=kind, radius=shape.number("radius", check=_greater(0)))
    return Shape(kind=kind, size=shape.vector("size", 3, check=_greater(0)))


def _cloth(t: _Table, base_dir: Path) -> Cloth:
    name = t.string("name", check=_prim_name)
    if t.has("grid") and t.has("mesh"):
        raise t.error("mesh", "cannot be given together with grid; give one of them")
    if not (t.has("grid") or t.has("mesh")):
        raise t.error(None, 'needs either grid = { size, resolution } or mesh = "FILE"')
    grid_size = grid_resolution = mesh_path = None
    if t.has("grid"):
        grid = t.subtable("grid", _GRID_KEYS)
        grid_size = grid.vector("size", 2, check=_greater(0))
        grid_resolution = grid.integers("resolution", 2, check=_at_least(2))
    else:
        mesh_path = _mesh_file(t, "mesh", base_dir)
    pinned = t.integers("pinned", None, Cloth.pinned, _vertex_index(grid_resolution))
    attach_to, attached = _attach(t, grid_resolution, pinned)
    return Cloth(
        name=name,
        grid_size=grid_size,
        grid_resolution=grid_resolution,
        mesh_path=mesh_path,
        position=t.vector("position", 3, ZERO3),
        orientation=_orientation(t),
        area_density=t.number("area_density", Cloth.area_density, _greater(0)),
        stretch_stiffness=t.number("stretch_stiffness", Cloth.stretch_stiffness, _at_least(0)),
        bend_stiffness=t.number("bend_stiffness", Cloth.bend_stiffness, _at_least(0)),
        damping=t.number("damping", Cloth.damping, _at_least(0)),
        strain_limit=t.number("strain_limit", Cloth.strain_limit, _at_least(0)),
        compression=t.string("compression", Cloth.compression, _one_of(COMPRESSION_MODES)),
        friction=t.number("friction", Cloth.friction, _at_least(0)),
        thickness=t.number("thickness", Cloth.thickness, _at_least(0)),
        pinned=pinned,
        model=t.string("model", Cloth.model, _one_of(CLOTH_MODELS)),
        poisson_ratio=t.number("poisson_ratio", Cloth.poisson_ratio, _poisson),
        integrator=t.string("integrator", Cloth.integrator, _one_of(CLOTH_INTEGRATORS)),
        self_collision=t.boolean("self_collision", Cloth.self_collision),
        attach_to=attach_to,
        attached=attached,
    )


def _attach(t: _Table, resolution: tuple[int, int] | None, pinned: tuple[int, ...]) -> tuple[str, tuple[int, ...]]:
    """``attach = { to = "BODY", points = [...] }``: the body (checked once the bodies are
    known: _check_attach_target) and the vertices, each once, none of them pinned."""
    if not t.has("attach"):
        return "", ()
    a = t.subtable("attach", _ATTACH_KEYS)
    to = a.string("to", check=_non_empty)
    points = a.integers("points", None, check=_vertex_index(resolution))
    if not points:
        raise a.error("points", "must list at least one vertex index")
    first: dict[int, int] = {}
    for k, p in enumerate(points):
        if p in first:
            raise a.error(f"points[{k}]", f"vertex {p} is listed twice (also points[{first[p]}])")
        first[p] = k
        if p in pinned:
            raise a.error(f"points[{k}]", f"vertex {p} is also pinned (pinned[{pinned.index(p)}]); "
                                          "a point is either pinned or attached")
    return to, points


def _check_attach_target(t: _Table, cloth: Cloth, bodies: list[str]) -> None:
    if cloth.attach_to and cloth.attach_to not in bodies:
        listed = ", ".join(_short(b) for b in bodies[:8]) + (", ..." if len(bodies) > 8 else "")
        raise t.error("attach.to", f"no body named {_short(cloth.attach_to)!r}"
                                   + (f" (bodies: {listed})" if bodies else " (the scene has no bodies)"))


def _poisson(value: float) -> str | None:
    return None if 0.0 <= value < 0.5 else f"must be in [0, 0.5), got {value}"



def _joint(t: _Table, bodies: list[str]) -> Joint:
    """A ``[[joints]]`` table: keys of other types than its own are errors, bodies must exist."""
    kind = t.string("type", check=_one_of(JOINT_TYPES))
    own = _TYPE_KEYS.get(kind, ())
    for key in t.data:
        if any(key in keys for keys in _TYPE_KEYS.values()) and key not in own:
            raise t.error(key, f"does not apply to a {kind} joint")
    ends = [t.string(f"body{k}", "") for k in (0, 1)]
    for k, name in enumerate(ends):
        if name and name not in bodies:
            raise t.error(f"body{k}", f"no body named {_short(name)!r}")
    if ends[0] == ends[1]:
        raise t.error("body1", "must differ from body0 (absent: the world)")
    lower, upper = t.number("lower_limit", -INF), t.number("upper_limit", INF)
    if lower > upper:
        raise t.error("upper_limit", f"must be >= lower_limit ({lower}), got {upper}")
    # (a limit left out is infinite: that side is free)
    if kind == "revolute" and not ((lower == -INF or -math.pi <= lower) and (upper == INF or upper <= math.pi)):
        raise t.error("lower_limit" if -INF < lower < -math.pi else "upper_limit", "must be within [-pi, pi] rad")
    low_d, high_d = t.number("min_distance", 0.0, _at_least(0)), t.number("max_distance", INF, _at_least(0))
    if low_d > high_d:
        raise t.error("max_distance", f"must be >= min_distance ({low_d}), got {high_d}")
    return Joint(
        name=t.string("name", check=_prim_name), type=kind, body0=ends[0], body1=ends[1],
        local_position0=t.vector("local_position0", 3, ZERO3), local_rotation0=_orientation(t, key="local_rotation0"),
        local_position1=t.vector("local_position1", 3, ZERO3), local_rotation1=_orientation(t, key="local_rotation1"),
        axis=t.string("axis", "x", _one_of(JOINT_AXES)), lower_limit=lower, upper_limit=upper,
        cone_angle0=t.number("cone_angle0", INF, _at_least(0)), cone_angle1=t.number("cone_angle1", INF, _at_least(0)),
        min_distance=low_d, max_distance=high_d, limits=_joint_limits(t), drives=_joint_drives(t, kind),
        break_force=t.number("break_force", INF, _greater(0)), break_torque=t.number("break_torque", INF, _greater(0)),
        enabled=t.boolean("enabled", True), collision_enabled=t.boolean("collision_enabled", False))


def _joint_limits(t: _Table) -> tuple[tuple[str, float, float], ...]:
    """``limits = { rot_x = [lower, upper] | "locked", ... }``: a d6 joint's degrees of freedom
    (unlisted: free)."""
    table = t.subtable("limits", JOINT_DOFS)
    limits = []
    for dof in JOINT_DOFS:
        if not table.has(dof):
            continue
        if table.data[dof] == "locked":
            limits.append((dof, 1.0, -1.0))
            continue
        if isinstance(table.data[dof], str):
            raise table.error(dof, f'must be [lower, upper] or "locked", got {_describe(table.data[dof])}')
        lower, upper = table.vector(dof, 2)
        if lower > upper:
            raise table.error(dof, f'lower must be <= upper (write "locked" to lock it), got [{lower}, {upper}]')
        limits.append((dof, lower, upper))
    return tuple(limits)


def _joint_drives(t: _Table, kind: str) -> tuple[tuple[str, Drive], ...]:
    """``drives = { angular = {...}, ... }``: linear (prismatic), angular (revolute) or a d6 joint's
    degrees of freedom."""
    allowed = {"revolute": ("angular",), "prismatic": ("linear",), "d6": JOINT_DOFS}.get(kind, ())
    table = t.subtable("drives", allowed)
    drives = []
    for name in allowed:
        if not table.has(name):
            continue
        d = table.subtable(name, _DRIVE_KEYS)
        drives.append((name, Drive(
            stiffness=d.number("stiffness", 0.0, _at_least(0)), damping=d.number("damping", 0.0, _at_least(0)),
            target_position=d.number("target_position", 0.0), target_velocity=d.number("target_velocity", 0.0),
            max_force=d.number("max_force", INF, _at_least(0)), type=d.string("type", "force", _one_of(DRIVE_TYPES)))))
    return tuple(drives)


def _check_unique_joints(file: str, joints: Iterable[Joint]) -> None:
    seen: dict[str, int] = {}
    for i, j in enumerate(joints):
        if j.name in seen:
            raise _error(file, f"joints[{i}].name", f"duplicate joint name {j.name!r} (also joints[{seen[j.name]}])")
        seen[j.name] = i


def _filtered_pairs(root: _Table, bodies: list[str]) -> tuple[tuple[str, str], ...]:
    """``filtered_pairs = [["a", "b"], ...]``: pairs of bodies that never collide."""
    value = root.data.get("filtered_pairs", [])
    if not isinstance(value, list):
        raise root.error("filtered_pairs", f"must be an array of [name, name] pairs, got {_describe(value)}")
    pairs = []
    for i, pair in enumerate(value):
        key = f"filtered_pairs[{i}]"
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(n, str) for n in pair)):
            raise root.error(key, "must be a pair of body names [\"a\", \"b\"]")
        for name in pair:
            if name not in bodies:
                raise root.error(key, f"no body named {_short(name)!r}")
        if pair[0] == pair[1]:
            raise root.error(key, "names the same body twice")
        pairs.append((pair[0], pair[1]))
    return tuple(pairs)


def _orientation(t: _Table, default: Quat = IDENTITY, key: str = "orientation") -> Quat:
    """The ``orientation`` quaternion, normalized; a zero quaternion is an error."""
    q = t.vector(key, 4, default)
    scale = max(abs(c) for c in q)  # scale first so huge or tiny values cannot overflow
    if scale == 0.0:
        raise t.error(key, "must be a non-zero quaternion [w, x, y, z], got all zeros")
    q = tuple(c / scale for c in q)
    norm = math.hypot(*q)
    return tuple(c / norm for c in q)  # type: ignore[return-value]


def _mesh_file(t: _Table, name: str, base_dir: Path) -> Path:
    """The mesh file at key ``name``, resolved against the scene's directory; must exist."""
    text = t.string(name, check=_non_empty)
    try:
        path = (base_dir / text).resolve()
        exists, is_file = path.exists(), path.is_file()
    except (OSError, ValueError, RuntimeError) as exc:  # RuntimeError: a symlink loop
        raise t.error(name, f"cannot access mesh file {text!r}: {exc}") from None
    if not exists:
        raise t.error(name, f"mesh file not found: {path}")
    if not is_file:
        raise t.error(name, f"mesh path is not a file: {path}")
    if not os.access(path, os.R_OK):
        raise t.error(name, f"mesh file is not readable: {path}")
    return path


def _check_unique_names(file: str, bodies: Iterable[Body], cloths: Iterable[Cloth]) -> None:
    """Names become prim paths ``/World/<name>``, so they share one namespace."""
    seen: dict[str, str] = {}
    owners = [(f"bodies[{i}]", b.name) for i, b in enumerate(bodies)]
    owners += [(f"cloths[{i}]", c.name) for i, c in enumerate(cloths)]
    for owner, name in owners:
        if name in seen:
            raise _error(file, f"{owner}.name", f"duplicate name {name!r} (also {seen[name]})")
        seen[name] = owner


# --------------------------------------------------------------------------------------
# Reading typed values at key paths
# --------------------------------------------------------------------------------------

_REQUIRED: Any = object()  # default meaning "the key must be present"

Check = Callable[[Any], Optional[str]]  # a value -> a problem, or None when fine


class _Table:
    """A TOML table at a key path (``bodies[2].shape``) that allows only some keys.

    The typed readers (``number``, ``integer``, ``vector``, ...) return the value at a key
    converted and checked, or ``default`` when the key is absent; without a default the
    key is required.
    """

    def __init__(self, file: str, key: str, data: Any, allowed: Iterable[str]):
        self.file, self.key = file, key
        if not isinstance(data, dict):
            raise _error(file, key, f"must be a table, got {_describe(data)}")
        self.data: dict[str, Any] = data
        self.only(allowed)

    def only(self, allowed: Iterable[str], what: str = "") -> None:
        """Reject any key not in ``allowed``; ``what`` qualifies the message."""
        allowed = tuple(allowed)
        for name in self.data:
            if name not in allowed:
                where = f" for {what}" if what else ""
                listed = ", ".join(allowed)
                raise self.error(name, f"unknown key{where} (allowed: {listed})")

    def path(self, name: str | None) -> str:
        if name is None:
            return self.key
        return f"{self.key}.{name}" if self.key else name

    def error(self, name: str | None, problem: str) -> SceneError:
        return _error(self.file, self.path(name), problem)

    def has(self, name: str) -> bool:
        return name in self.data

    def _get(self, name: str, default: Any, convert: Callable[..., Any], *args: Any) -> Any:
        if name not in self.data:
            if default is _REQUIRED:
                raise self.error(name, "missing required key")
            return default
        return convert(self.file, self.path(name), self.data[name], *args)

    def number(self, name: str, default: Any = _REQUIRED, check: Check | None = None) -> Any:
        return self._get(name, default, _as_float, check)

    def integer(self, name: str, default: Any = _REQUIRED, check: Check | None = None) -> Any:
        return self._get(name, default, _as_int, check)

    def boolean(self, name: str, default: Any = _REQUIRED) -> Any:
        return self._get(name, default, _as_bool, None)

    def string(self, name: str, default: Any = _REQUIRED, check: Check | None = None) -> Any:
        return self._get(name, default, _as_str, check)

    def vector(
        self, name: str, n: int, default: Any = _REQUIRED, check: Check | None = None
    ) -> Any:
        """A tuple of exactly ``n`` finite floats."""
        return self._get(name, default, _as_array, n, "numbers", _as_float, check)

    def integers(
        self, name: str, n: int | None, default: Any = _REQUIRED, check: Check | None = None
    ) -> Any:
        """A tuple of integers, exactly ``n`` of them unless ``n`` is None."""
        return self._get(name, default, _as_array, n, "integers", _as_int, check)

    def subtable(self, name: str, allowed: Iterable[str], required: bool = False) -> _Table:
        """The table at ``name``; an empty one when it is absent and not required."""
        if name not in self.data and required:
            raise self.error(name, f"missing required table [{self.path(name)}]")
        return _Table(self.file, self.path(name), self.data.get(name, {}), allowed)

    def tables(self, name: str, allowed: Iterable[str]) -> list[_Table]:
        """The array of tables ``[[name]]``; empty when absent."""
        value = self.data.get(name, [])
        if not isinstance(value, list):
            problem = f"must be an array of tables ([[{name}]]), got {_describe(value)}"
            raise self.error(name, problem)
        key = self.path(name)
        return [_Table(self.file, f"{key}[{i}]", item, allowed) for i, item in enumerate(value)]


def _checked(file: str, key: str, value: Any, check: Check | None) -> Any:
    problem = check(value) if check else None
    if problem:
        raise _error(file, key, problem)
    return value


def _as_float(file: str, key: str, value: Any, check: Check | None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _error(file, key, f"must be a number, got {_describe(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise _error(file, key, f"must be a finite number, got {value!r}")
    return _checked(file, key, value, check)


def _as_int(file: str, key: str, value: Any, check: Check | None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _error(file, key, f"must be an integer, got {_describe(value)}")
    return _checked(file, key, value, check)


def _as_bool(file: str, key: str, value: Any, check: Check | None) -> bool:
    if not isinstance(value, bool):
        raise _error(file, key, f"must be true or false, got {_describe(value)}")
    return _checked(file, key, value, check)


def _as_str(file: str, key: str, value: Any, check: Check | None) -> str:
    if not isinstance(value, str):
        raise _error(file, key, f"must be a string, got {_describe(value)}")
    return _checked(file, key, value, check)


def _as_array(
    file: str,
    key: str,
    value: Any,
    length: int | None,
    noun: str,
    item: Callable[[str, str, Any, Check | None], Any],
    check: Check | None,
) -> tuple[Any, ...]:
    """An array (of exactly ``length`` elements if given), each converted by ``item``."""
    if not isinstance(value, list) or (length is not None and len(value) != length):
        expected = f"an array of {length} {noun}" if length is not None else f"an array of {noun}"
        if isinstance(value, list):
            got = f"{len(value)} element" + ("" if len(value) == 1 else "s")
        else:
            got = _describe(value)
        raise _error(file, key, f"must be {expected}, got {got}")
    return tuple(item(file, f"{key}[{i}]", v, check) for i, v in enumerate(value))


# Checks: each returns a problem or None.


def _greater(bound: float) -> Check:
    return lambda v: None if v > bound else f"must be > {bound}, got {v!r}"


def _at_least(bound: float, name: str = "") -> Check:
    shown = f"{name} ({bound})" if name else f"{bound}"
    return lambda v: None if v >= bound else f"must be >= {shown}, got {v!r}"


def _within(lo: float, hi: float) -> Check:
    return lambda v: None if lo <= v <= hi else f"must be in [{lo}, {hi}], got {v!r}"


def _one_of(choices: tuple[str, ...]) -> Check:
    listed = ", ".join(choices)
    return lambda v: None if v in choices else f"unknown value {v!r} (expected one of: {listed})"


def _non_empty(v: str) -> str | None:
    return None if v else "must not be empty"


def _prim_name(v: str) -> str | None:
    if not _PRIM_NAME.fullmatch(v):
        return (
            f"not a valid USD prim name: {_short(v)!r} (use letters, digits and _, "
            "not starting with a digit)"
        )
    if v in RESERVED_NAMES:
        return f"the name {v!r} is reserved for the root prim"
    return None


def _vertex_index(resolution: tuple[int, int] | None) -> Check:
    """Pinned vertex indices: >= 0, and < nx * nz for a grid (a mesh's count is unknown here)."""

    def check(v: int) -> str | None:
        if v < 0:
            return f"vertex index must be >= 0, got {v}"
        if resolution is not None and v >= resolution[0] * resolution[1]:
            nx, nz = resolution
            return f"vertex index out of range: the {nx}x{nz} grid has {nx * nz} vertices, got {v}"
        return None

    return check


# Messages.


def _error(file: str | Path, key: str, problem: str) -> SceneError:
    """A SceneError whose message is guaranteed to be one line."""
    return SceneError(_one_line(str(file)), _one_line(key), _one_line(problem))


def _one_line(text: str) -> str:
    """Escape newlines and other unprintable characters (they can come from user keys)."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


def _short(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _describe(value: Any) -> str:
    """A value as a TOML user would name it: ``integer 3``, ``string 'abc'``, ``table``."""
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, int):
        return f"integer {value}"
    if isinstance(value, float):
        return f"float {value!r}"
    if isinstance(value, str):
        return f"string {_short(value)!r}"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "table"
    return "date/time"  # tomllib's only other value types

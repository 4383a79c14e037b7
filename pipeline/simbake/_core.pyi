"""Type stub of simbake._core, the C++ core's bindings (bindings/module.cpp).

Arrays are numpy float64 unless noted; (n, 3) means n rows of x, y, z. Quaternions are
[w, x, y, z]. Units are SI. The settings and descriptions are the core's own structs,
constructed by keyword: a field left out keeps its C++ default (core/world/world_settings.h,
core/rigid/rigid_model.h, core/cloth/cloth_model.h), which is why no default is written here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
IndexArray = npt.NDArray[np.int32]

__version__: str
MAX_THREADS: int  # the most worker threads a World takes (WorldSettings.threads)

# ---- geometry

def sphere_mesh(radius: float, subdivisions: int) -> tuple[Array, IndexArray]: ...
def box_mesh(size: Array, subdivisions: int) -> tuple[Array, IndexArray]: ...
def vertex_normals(vertices: Array, triangles: IndexArray) -> Array: ...
def surface_samples(vertices: Array, triangles: IndexArray, max_spacing: float) -> Array: ...
def closed_mesh_depth(vertices: Array, triangles: IndexArray, points: Array, edges: IndexArray, threads: int = 0) -> tuple[float, float]: ...
def intersecting_triangle_pairs(vertices: Array, triangles: IndexArray) -> IndexArray: ...
def is_closed(vertices: Array, triangles: IndexArray) -> bool: ...
def mass_properties(vertices: Array, triangles: IndexArray) -> dict[str, Any]: ...
def sphere_mass_properties(radius: float) -> dict[str, Any]: ...
def box_mass_properties(size: Array) -> dict[str, Any]: ...

# ---- level sets

class LevelSet:
    """A signed distance function, negative inside: analytic (sphere, box) or a baked OpenVDB grid."""

    @staticmethod
    def sphere(radius: float) -> LevelSet: ...
    @staticmethod
    def box(size: Array) -> LevelSet: ...
    @staticmethod
    def bake(vertices: Array, triangles: IndexArray, voxel_size: float) -> LevelSet: ...
    @staticmethod
    def bake_shell(vertices: Array, triangles: IndexArray, voxel_size: float, thickness: float) -> LevelSet:
        """Any triangle soup (open, non-manifold) as a two-sided shell: phi = |d| - thickness (m)."""
    @staticmethod
    def read(path: str) -> LevelSet: ...
    def write(self, path: str, metadata: dict[str, str] = ...) -> None: ...
    @property
    def metadata(self) -> dict[str, str]: ...
    def phi(self, points: Array) -> Array: ...
    def normals(self, points: Array) -> Array: ...
    @property
    def bounds(self) -> tuple[Array, Array]: ...
    @property
    def voxel_size(self) -> float: ...
    @property
    def active_voxel_count(self) -> int: ...
    @property
    def memory_bytes(self) -> int: ...

# ---- settings and descriptions (keyword-constructed; unknown names are TypeError)

class WorldSettings:
    gravity: Array                   # (3,) m/s^2
    collision_sweeps: int
    contact_sweeps: int
    shock_sweeps: int
    sleep_speed: float               # m/s
    sleep_time: float                # s; 0 disables sleeping
    penetration_slop: float          # m
    penetration_recovery: float
    max_recovery_speed: float        # m/s
    contact_tolerance: float         # m/s
    speculative_contacts: bool
    box_contacts: bool
    max_substep: float               # s
    cloth_contact_substep: float     # s
    bounce_substep: float            # s
    cloth_contacts_in_solve: bool
    cloth_max_substep: float         # s
    travel_fraction: float
    joint_turn: float                # rad
    max_substeps: int
    threads: int                     # 0 (every CPU) to MAX_THREADS
    def __init__(self, **fields: Any) -> None: ...

class GroundDef:
    height: float                    # m
    friction: float
    restitution: float
    def __init__(self, **fields: Any) -> None: ...

class BodyDesc:
    shape: LevelSet | None           # None: nothing can touch the body
    samples: Array                   # (s, 3) surface samples, mesh coordinates (m)
    mesh_vertices: Array             # (n, 3) the closed mesh a baked shape was made from (or empty)
    mesh_triangles: IndexArray       # (m, 3) its triangles
    mass_properties: dict[str, Any]  # of the shape at density 1: volume, center, inertia
    mass: float                      # kg; ignored for kinematic bodies
    origin: Array                    # (3,) world position of the mesh origin (m)
    orientation: Array               # (4,) [w, x, y, z]
    linear_velocity: Array           # (3,) m/s
    angular_velocity: Array          # (3,) rad/s, world
    friction: float
    restitution: float
    kinematic: bool
    def __init__(self, **fields: Any) -> None: ...

class ClothDesc:
    rest: Array                      # (n, 3) rest = initial positions (m)
    triangles: IndexArray            # (m, 3)
    area_density: float              # kg/m^2
    model: str                       # springs | membrane
    stretch_stiffness: float         # N/m
    poisson_ratio: float
    bend_stiffness: float            # N m
    damping: float                   # s
    strain_limit: float              # 0 disables
    subgrid_scale: float
    compression: str                 # subgrid | enforce | none
    pinned: list[int]
    attached: list[int]
    integrator: str                  # implicit | explicit
    tolerance: float
    preconditioner: str              # automatic | block_jacobi | multigrid
    friction: float
    thickness: float                 # m
    self_collision: bool
    def __init__(self, **fields: Any) -> None: ...

class JointDrive:
    stiffness: float                 # N/m or N m/rad (acceleration drives: 1/s^2)
    damping: float                   # N s/m or N m s/rad (acceleration drives: 1/s)
    target_position: float           # m or rad
    target_velocity: float           # m/s or rad/s
    max_force: float                 # N or N m; inf: unbounded
    acceleration: bool               # False: a force drive
    def __init__(self, **fields: Any) -> None: ...

class JointDesc:
    type: str                        # fixed | revolute | prismatic | spherical | distance | d6
    body0: int                       # body index, or -1: the world
    body1: int
    local_position0: Array           # (3,) joint frame in body 0's mesh frame (m)
    local_rotation0: Array           # (4,) [w, x, y, z]
    local_position1: Array           # (3,) and in body 1's
    local_rotation1: Array
    axis: str                        # x | y | z (revolute, prismatic, spherical)
    lower_limit: float               # revolute (rad), prismatic (m); -inf: none
    upper_limit: float
    cone_angle0: float               # spherical (rad); inf: free
    cone_angle1: float
    min_distance: float              # distance (m)
    max_distance: float
    dof_lower: list[float]           # d6, trans_x .. rot_z (m, rad); lower > upper locks
    dof_upper: list[float]
    drives: dict[str, JointDrive]    # by degree of freedom: trans_x .. rot_z
    break_force: float               # N; inf: unbreakable
    break_torque: float              # N m
    enabled: bool
    collision_enabled: bool          # False: the two bodies never collide
    def __init__(self, **fields: Any) -> None: ...

# ---- the world

class World:
    def __init__(self, settings: WorldSettings | None = None, **fields: Any) -> None:
        """World(settings) or World(**WorldSettings fields); ValueError for a setting out of range."""
    @property
    def settings(self) -> WorldSettings: ...
    def set_ground(self, ground: GroundDef | None = None, **fields: Any) -> None: ...
    def add_body(self, desc: BodyDesc | None = None, **fields: Any) -> int: ...
    def add_cloth(self, desc: ClothDesc | None = None, **fields: Any) -> int: ...
    def add_joint(self, desc: JointDesc | None = None, **fields: Any) -> int: ...
    def filter_pair(self, a: int, b: int) -> None: ...
    def set_collision_groups(self, members: list[list[int]], filters: list[list[int]]) -> None: ...
    def attach_cloth(self, cloth: int, body: int) -> None: ...
    def set_deforming_frame(self, index: int, vertices: Array, level_set: LevelSet, frame_dt: float) -> None: ...
    def set_kinematic_track(self, index: int, times: list[float], positions: Array, orientations: Array) -> None: ...

    def step_frame(self, frame_dt: float, substeps: int = 0) -> int: ...
    def step(self, dt: float) -> None: ...
    def automatic_substeps(self, frame_dt: float) -> int: ...
    def automatic_cloth_steps(self, frame_dt: float) -> int: ...

    @property
    def body_count(self) -> int: ...
    @property
    def cloth_count(self) -> int: ...
    @property
    def sleeping_count(self) -> int: ...
    @property
    def joint_count(self) -> int: ...
    def joint_states(self) -> dict[str, npt.NDArray[Any]]:
        """enabled (n,) bool, broke_at (n,) s (NaN while whole), gap (n,) m and angle (n,) rad
        between each joint's frames, force (n, 3) N and torque (n, 3) N m on body 1 last step."""
    @property
    def time(self) -> float: ...
    def body_states(self) -> dict[str, npt.NDArray[Any]]:
        """center_of_mass (n, 3), orientation (n, 4), linear_velocity (n, 3),
        angular_momentum (n, 3), angular_velocity (n, 3), asleep (n,) bool."""
    def mesh_poses(self) -> tuple[Array, Array]: ...
    def asleep(self, index: int) -> bool: ...
    def cloth_state(self, index: int) -> tuple[Array, Array, Array]: ...
    def cloth_max_strain(self, index: int) -> float: ...
    def statistics(self, penetrations: bool = True) -> dict[str, Any]: ...
    def quality(self) -> dict[str, Any]: ...
    def profile(self) -> dict[str, float]:
        """Wall seconds per stage (core/world/stages.h names them)."""


class QualityMeter:
    """World.quality() frame after frame, measuring only what can have changed: the same figures."""
    def __init__(self) -> None: ...
    def measure(self, world: World) -> dict[str, Any]: ...

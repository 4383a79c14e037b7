"""The joint scenes of the peer benchmark and their measurements (shared by every engine).

Two scenes (SI units, Y up, g = 9.81; engines on Z up convert with scenes.vec_to_zup):
- chain50: the 50-link chain of tests/cpp/rigid/test_joints.cpp (FiftyLinkChainStaysClosed):
  links 0.1 x 0.02 x 0.02 m boxes of 0.1 kg laid along +x from the world origin, ball joints
  end to end, the first end held at the origin; no collisions, no ground; released level,
  10 s. An undriven, undamped mechanism: its energy is constant.
- ragdoll: assets/scenes/ragdoll.toml itself (read with tomllib): 15 bodies, 14 joints (D6
  joints with twist limits and round swing cones, limited hinges), kinematic stairs, the
  ground, friction 0.6 for every pair, 5 s.

Each engine records, at every 1/24 s frame boundary, every body's centre (Y up), orientation
[w, x, y, z] (Y up), linear and angular velocity (world), and hands them to `analyze`:
- joint gap: the largest distance between a joint's two frame origins, over joints and frames;
- limit error: the largest angle past a joint's limits (twist, swing cone, hinge range, and
  the off-axis angle of a hinge), over joints and frames;
- energy: kinetic (translational and rotational) plus potential m g y of the moving bodies;
  drift = the largest rise above the start (J) and the change start to end. The chain should
  keep it (its scale: m_total g L/2 = 5 kg x 9.81 x 2.5 m = 122.6 J released hanging straight); the ragdoll
  loses energy in inelastic contacts and must never gain any.
"""

from __future__ import annotations

import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

if __package__:
    from .scenes import quaternion_matrices as matrices
else:   # (an engine script's: benchmarks/peers on the path)
    from scenes import quaternion_matrices as matrices

G = 9.81
FPS = 24
ROOT = Path(__file__).resolve().parents[2]
RAGDOLL = ROOT / "assets" / "scenes" / "ragdoll.toml"


@dataclass
class Body:
    name: str
    shape: str                   # "box" | "sphere"
    size: tuple                  # box: edge lengths (m); sphere: (r, r, r)
    mass: float                  # (kg); kinematic: 0
    position: tuple              # centre (m), Y up
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)
    linear_velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)
    kinematic: bool = False
    collides: bool = True

    @property
    def inertia(self) -> np.ndarray:
        """Principal moments (kg m^2) about the body's own axes."""
        if self.shape == "sphere":
            return np.full(3, 0.4 * self.mass * self.size[0] ** 2)
        a, b, c = self.size
        return self.mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])


@dataclass
class Joint:
    name: str
    type: str                    # "spherical" | "revolute" | "d6"
    body0: int                   # index, -1: the world
    body1: int
    local_position0: tuple
    local_position1: tuple
    local_rotation0: tuple = (1.0, 0.0, 0.0, 0.0)
    local_rotation1: tuple = (1.0, 0.0, 0.0, 0.0)
    axis: str = "x"              # revolute: its axis in the joint frames
    lower: float = -math.inf     # revolute (rad)
    upper: float = math.inf
    twist: float = math.inf      # d6: twist half-range about frame X, swing cone half-angle (rad)
    cone: float = math.inf


@dataclass
class Scene:
    name: str
    title: str
    bodies: list
    joints: list
    seconds: float
    mu: float = 0.0
    ground: bool = False
    notes: list = field(default_factory=list)

    @property
    def frames(self) -> int:
        return int(round(self.seconds * FPS))

    def moving(self) -> list:
        return [i for i, b in enumerate(self.bodies) if not b.kinematic]


def chain50(seconds: float = 10.0) -> Scene:
    n, length, mass = 50, 0.1, 0.1
    bodies = [Body(f"link{i:02d}", "box", (length, 0.02, 0.02), mass, ((i + 0.5) * length, 0.0, 0.0),
                   collides=False) for i in range(n)]
    joints = [Joint(f"link{i:02d}_joint", "spherical", i - 1, i,
                    (0.0, 0.0, 0.0) if i == 0 else (0.5 * length, 0.0, 0.0), (-0.5 * length, 0.0, 0.0))
              for i in range(n)]
    return Scene("chain50", "50-link chain released level (ball joints, no collisions), 10 s", bodies, joints,
                 seconds)


def ragdoll(seconds: float | None = None) -> Scene:
    """The ragdoll scene file; `seconds` overrides its frame range."""
    data = tomllib.loads(RAGDOLL.read_text())
    bodies, index = [], {}
    for b in data["bodies"]:
        shape = b["shape"]
        size = tuple(shape["size"]) if shape["type"] == "box" else (shape["radius"],) * 3
        index[b["name"]] = len(bodies)
        q = np.array(b.get("orientation", (1.0, 0.0, 0.0, 0.0)), dtype=float)
        bodies.append(Body(b["name"], shape["type"], size, 0.0 if b.get("kinematic") else b["mass"],
                           tuple(b["position"]), tuple(q / np.linalg.norm(q)),
                           tuple(b.get("linear_velocity", (0.0, 0.0, 0.0))),
                           tuple(b.get("angular_velocity", (0.0, 0.0, 0.0))), bool(b.get("kinematic", False))))
    joints = []
    for j in data["joints"]:
        kw = dict(name=j["name"], type=j["type"], body0=index.get(j.get("body0", ""), -1), body1=index[j["body1"]],
                  local_position0=tuple(j.get("local_position0", (0.0, 0.0, 0.0))),
                  local_position1=tuple(j.get("local_position1", (0.0, 0.0, 0.0))),
                  local_rotation0=tuple(j.get("local_rotation0", (1.0, 0.0, 0.0, 0.0))),
                  local_rotation1=tuple(j.get("local_rotation1", (1.0, 0.0, 0.0, 0.0))))
        if j["type"] == "revolute":
            kw.update(axis=j.get("axis", "x"), lower=j.get("lower_limit", -math.inf),
                      upper=j.get("upper_limit", math.inf))
        elif j["type"] == "d6":
            limits = j["limits"]
            assert all(limits[t] == "locked" for t in ("trans_x", "trans_y", "trans_z")), j["name"]
            assert limits["rot_y"] == limits["rot_z"] and limits["rot_x"][0] == -limits["rot_x"][1], j["name"]
            kw.update(twist=limits["rot_x"][1], cone=limits["rot_y"][1])
        else:
            raise ValueError(f"{j['name']}: {j['type']} joints are not in the benchmark")
        joints.append(Joint(**kw))
    mu = data["ground"]["friction"]
    assert all(b.get("friction", 0.5) == mu for b in data["bodies"]), "every pair gets the ground's friction"
    return Scene("ragdoll", "assets/scenes/ragdoll.toml: 15-body ragdoll down five stairs, 5 s", bodies, joints,
                 seconds or (data["scene"]["end_frame"] - data["scene"]["start_frame"]) / data["scene"]["fps"],
                 mu=mu, ground=True)


SCENES = {"chain50": chain50, "ragdoll": ragdoll}


def build(name: str, seconds: float | None = None) -> Scene:
    return SCENES[name]() if seconds is None else SCENES[name](seconds)


# ---------------------------------------------------------------------------------------
# measurements


_AXIS = {"x": 0, "y": 1, "z": 2}


def joint_measures(scene: Scene, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame and joint: the gap between the frames' origins (m) and the angle past the
    limits (rad). x (f, n, 3), q (f, n, 4)."""
    R = matrices(q)
    f = x.shape[0]
    gaps = np.zeros((f, len(scene.joints)))
    past = np.zeros((f, len(scene.joints)))
    ident = np.broadcast_to(np.eye(3), (f, 3, 3))
    for k, j in enumerate(scene.joints):
        def frame(body, p, r):
            if body < 0:
                return np.broadcast_to(np.asarray(p, float), (f, 3)), ident @ matrices(np.asarray(r))
            return x[:, body] + R[:, body] @ np.asarray(p, float), R[:, body] @ matrices(np.asarray(r))
        a0, f0 = frame(j.body0, j.local_position0, j.local_rotation0)
        a1, f1 = frame(j.body1, j.local_position1, j.local_rotation1)
        gaps[:, k] = np.linalg.norm(a1 - a0, axis=-1)
        rel = np.swapaxes(f0, -1, -2) @ f1          # frame 1 in frame 0
        if j.type == "revolute":
            a = _AXIS[j.axis]
            b, c = (a + 1) % 3, (a + 2) % 3
            angle = np.arctan2(rel[:, c, b] - rel[:, b, c], rel[:, b, b] + rel[:, c, c])
            off = np.arccos(np.clip(rel[:, a, a], -1.0, 1.0))
            past[:, k] = np.maximum(np.maximum(angle - j.upper, j.lower - angle).clip(0.0), off)
        elif j.type == "d6":
            swing = np.arccos(np.clip(rel[:, 0, 0], -1.0, 1.0))     # between the X axes
            # twist about X: the quaternion of rel, 2 atan2(q_x, q_w) (any swing-twist order)
            qw = 0.5 * np.sqrt(np.clip(1.0 + rel[:, 0, 0] + rel[:, 1, 1] + rel[:, 2, 2], 0.0, None))
            qx4 = rel[:, 2, 1] - rel[:, 1, 2]                        # 4 q_w q_x
            twist = 2.0 * np.arctan2(qx4, 4.0 * qw * qw)
            past[:, k] = np.maximum((swing - j.cone).clip(0.0), (np.abs(twist) - j.twist).clip(0.0))
    return gaps, past


def energy(scene: Scene, x: np.ndarray, q: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(f,) kinetic plus potential energy (J) of the moving bodies."""
    ids = scene.moving()
    m = np.array([scene.bodies[i].mass for i in ids])
    inertia = np.array([scene.bodies[i].inertia for i in ids])          # (n, 3)
    R = matrices(q[:, ids])
    w_body = np.einsum("fnji,fnj->fni", R, w[:, ids])                    # R^T w
    kinetic = 0.5 * (m * (v[:, ids] ** 2).sum(-1)).sum(-1) + 0.5 * (inertia * w_body ** 2).sum(-1).sum(-1)
    return kinetic + G * (m * x[:, ids, 1]).sum(-1)


def analyze(scene: Scene, x, q, v, w) -> dict:
    x, q, v, w = (np.asarray(a, dtype=float) for a in (x, q, v, w))
    gaps, past = joint_measures(scene, x, q)
    e = energy(scene, x, q, v, w)
    ids = scene.moving()
    out = {
        "joint_gap_max_m": float(gaps.max()),
        "joint_gap_final_m": float(gaps[-1].max()),
        "limit_error_max_deg": float(np.degrees(past.max())),
        "limit_error_by_joint_deg": {j.name: round(float(np.degrees(past[:, k].max())), 4)
                                     for k, j in enumerate(scene.joints) if past[:, k].max() > 0.0},
        "energy_start_J": float(e[0]), "energy_end_J": float(e[-1]),
        "energy_rise_max_J": float((e - e[0]).max()),
        "energy_change_J": float(e[-1] - e[0]),
        "finite": bool(np.isfinite(x).all() and np.isfinite(v).all()),
        "speed_max": float(np.linalg.norm(v[:, ids], axis=-1).max()),
    }
    if scene.name == "chain50":
        out["lowest_tip_y_m"] = float(x[:, -1, 1].min())
        out["energy_scale_J"] = sum(b.mass for b in scene.bodies) * G * 2.5   # released hanging straight
    else:
        out["final_speed_max"] = float(np.linalg.norm(v[-1, ids], axis=-1).max())
        out["final_lowest_y_m"] = float(x[-1, ids, 1].min())
        out["final_x_range_m"] = [float(x[-1, ids, 0].min()), float(x[-1, ids, 0].max())]
    return out


class Recorder:
    """Every frame's state (frame 0 the start), Y up."""

    def __init__(self, scene: Scene):
        f, n = scene.frames + 1, len(scene.bodies)
        self.x, self.q = np.zeros((f, n, 3)), np.zeros((f, n, 4))
        self.v, self.w = np.zeros((f, n, 3)), np.zeros((f, n, 3))

    def record(self, frame: int, x, q, v, w) -> None:
        self.x[frame], self.q[frame], self.v[frame], self.w[frame] = x, q, v, w

    def analyze(self, scene: Scene) -> dict:
        return analyze(scene, self.x, self.q, self.v, self.w)


class Clock:
    """Wall and process CPU time of the stepping alone (`with clock:` around each step)."""

    def __init__(self):
        self.wall = self.cpu = 0.0

    def __enter__(self):
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall += time.perf_counter() - self._wall
        self.cpu += time.process_time() - self._cpu
        return False


def result(engine: str, version: str, scene: Scene, clock: Clock, recorder: Recorder, settings: dict) -> dict:
    """The JSON line an engine script prints. CPU time is the figure to compare on a shared
    machine (one thread each: wall = CPU when the engine has a core to itself)."""
    return {"engine": engine, "version": version, "scene": scene.name, "simulated_seconds": scene.seconds,
            "step_wall_seconds": clock.wall, "step_cpu_seconds": clock.cpu,
            "wall_per_simulated_second": clock.wall / scene.seconds,
            "cpu_per_simulated_second": clock.cpu / scene.seconds,
            "accuracy": recorder.analyze(scene), "settings": settings}


def common_args(argv=None):
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", choices=list(SCENES))
    ap.add_argument("--seconds", type=float, default=None)
    return ap.parse_args(argv)

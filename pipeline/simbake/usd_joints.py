"""Joints and collision filtering of a USD shot, from the descriptors OpenUSD's parser
(``UsdPhysics.UsdPhysicsLoadStageFromPrimRange``) returns, into the scene's ``Joint``s.

Frames: the parser gives ``localPose0/1`` in each body's unscaled frame (``localPos`` times
the body's scale), in stage units and axes; simbake's body frame is the prim's, turned by the
stage's axes (usd_scene.pose), so a body-frame position p becomes mpu C p and a rotation R
becomes C R C^T. A joint to a prim that is no body (or to nothing) is a joint to the world, its
frame composed with that prim's world transform. Angles are degrees in USD, radians here;
drives' gains, targets and force limits are converted from stage units (metersPerUnit,
kilogramsPerUnit, degrees) to SI.
"""

from __future__ import annotations

import math

import numpy as np

from .rotations import quat_from_matrix, quat_matrix
from .scene import Drive, Joint

_TYPES = {"FixedJoint": "fixed", "RevoluteJoint": "revolute", "PrismaticJoint": "prismatic",
          "SphericalJoint": "spherical", "DistanceJoint": "distance", "D6Joint": "d6"}
_DOFS = {"TransX": "trans_x", "TransY": "trans_y", "TransZ": "trans_z", "RotX": "rot_x", "RotY": "rot_y",
         "RotZ": "rot_z"}
DEG = math.pi / 180.0


def joint_kinds() -> tuple[str, ...]:
    """The parser's object types read here (usd_scene leaves them out of its 'left out' warning)."""
    return (*_TYPES, "Articulation", "CollisionGroup")


def read_joints(reader, descs: dict, bodies) -> tuple[Joint, ...]:
    """Every joint the parser found, sorted by prim path; `bodies` the scene's bodies so far."""
    by_path = {b.prim_path: b.name for b in bodies if b.prim_path}
    joints = []
    used: set[str] = set()
    entries = []
    for kind, pairs in descs.items():
        name = str(kind).rsplit(".", 1)[-1]
        if name in _TYPES:
            entries += [(str(p), name, d) for p, d in pairs]
    for path, kind, d in sorted(entries, key=lambda e: e[0]):
        reader.keys.append((f"joints[{len(joints)}]", path))
        joints.append(_joint(reader, path, _TYPES[kind], d, by_path, used, len(joints)))
    return tuple(joints)


def _body_of(path: str, by_path: dict) -> str:
    """The body a prim path is (or is under); "" when none."""
    p = path
    while p and p != "/":
        if p in by_path:
            return by_path[p]
        p = p.rsplit("/", 1)[0] or "/"
    return ""


def _end(reader, d, k: int, by_path: dict):
    """Body k's name and the joint frame in it (simbake units and axes)."""
    rel = str(getattr(d, f"rel{k}"))
    body = str(getattr(d, f"body{k}"))
    name = _body_of(body, by_path) if body else ""
    p = np.array(getattr(d, f"localPose{k}Position"), dtype=np.float64)
    q = getattr(d, f"localPose{k}Orientation")
    r = _rotation(q)
    if not name and rel:  # a prim that is no body: the frame in its world transform
        prim = reader.stage.GetPrimAtPath(rel)
        if prim:
            rw, tw, kw = reader.frame(prim, "joint body", general=True)
            p, r = rw @ (kw * p) + tw, rw @ r
    C = reader.C
    return name, tuple(float(c) for c in reader.mpu * (C @ p)), quat_from_matrix(C @ r @ C.T)


def _rotation(q) -> np.ndarray:
    w, v = float(q.GetReal()), q.GetImaginary()
    n = math.sqrt(w * w + sum(float(c) ** 2 for c in v)) or 1.0
    return quat_matrix((w / n, float(v[0]) / n, float(v[1]) / n, float(v[2]) / n))


def _joint(reader, path: str, kind: str, d, by_path: dict, used: set[str], index: int) -> Joint:
    body0, p0, q0 = _end(reader, d, 0, by_path)
    body1, p1, q1 = _end(reader, d, 1, by_path)
    if body0 == body1:
        raise reader.error(path, "physics:body1", "a joint needs two different bodies (or one and the world)"
                           if body0 else "a joint needs at least one rigid body (physics:body0 or physics:body1)")
    mpu, kpu = reader.mpu, reader.kpu
    fields = dict(name=_unique(path, used), type=kind, body0=body0, body1=body1, local_position0=p0,
                  local_rotation0=q0, local_position1=p1, local_rotation1=q1, prim_path=path,
                  enabled=bool(d.jointEnabled), collision_enabled=bool(d.collisionEnabled),
                  break_force=_positive(reader, path, "physics:breakForce", d.breakForce, kpu * mpu),
                  break_torque=_positive(reader, path, "physics:breakTorque", d.breakTorque, kpu * mpu * mpu))
    if kind in ("revolute", "prismatic", "spherical"):
        fields["axis"] = str(d.axis).rsplit(".", 1)[-1].lower()
    if kind in ("revolute", "prismatic") and d.limit.enabled:
        unit = DEG if kind == "revolute" else mpu
        lo, hi = d.limit.lower * unit, d.limit.upper * unit
        if kind == "revolute":  # (UsdPhysics writes +-inf, or a huge sentinel, for no limit)
            lo, hi = max(lo, -math.pi) if lo > -1e30 else -math.inf, min(hi, math.pi) if hi < 1e30 else math.inf
        fields.update(lower_limit=lo, upper_limit=hi)
    if kind == "spherical" and d.limit.enabled:
        fields.update(cone_angle0=_cone(d.limit.lower), cone_angle1=_cone(d.limit.upper))
    if kind == "distance":
        if d.minEnabled:
            fields["min_distance"] = max(0.0, d.limit.lower * mpu)
        if d.maxEnabled:
            fields["max_distance"] = max(fields.get("min_distance", 0.0), d.limit.upper * mpu)
    if kind in ("revolute", "prismatic") and d.drive.enabled:
        fields["drives"] = (("angular" if kind == "revolute" else "linear", _drive(reader, d.drive, kind == "revolute")),)
    if kind == "d6":
        fields["limits"] = tuple(_d6_limits(reader, path, d))
        fields["drives"] = tuple((_DOFS[_dof(p.first)], _drive(reader, p.second, _dof(p.first).startswith("Rot")))
                                 for p in d.jointDrives if _dof(p.first) in _DOFS and p.second.enabled)
    return Joint(**fields)


def _dof(dof) -> str:
    return str(dof).rsplit(".", 1)[-1]


def _d6_limits(reader, path: str, d):
    for pair in d.jointLimits:
        dof = _dof(pair.first)
        if dof not in _DOFS:
            reader.warn(path, f"a D6 limit on {dof} is not simulated by simbake; left out")
            continue
        limit = pair.second
        if not limit.enabled:
            continue
        unit = DEG if dof.startswith("Rot") else reader.mpu
        if limit.lower > limit.upper:
            yield (_DOFS[dof], 1.0, -1.0)  # locked
        else:
            yield (_DOFS[dof], max(limit.lower * unit, -1e30), min(limit.upper * unit, 1e30))


def _cone(degrees: float) -> float:
    return math.inf if not math.isfinite(degrees) or degrees < 0 or degrees >= 1e30 else degrees * DEG


def _drive(reader, drive, angular: bool) -> Drive:
    mpu, kpu = reader.mpu, reader.kpu
    position = DEG if angular else mpu                      # a target position's unit in SI
    force = kpu * mpu * mpu if angular else kpu * mpu       # a force's (torque's) unit in SI
    gain = 1.0 if drive.acceleration else force / position  # acceleration drives: per unit mass
    limit = drive.forceLimit
    return Drive(stiffness=float(drive.stiffness) * gain, damping=float(drive.damping) * gain,
                 target_position=float(drive.targetPosition) * position,
                 target_velocity=float(drive.targetVelocity) * position,
                 max_force=float(limit) * force if math.isfinite(limit) and 0 <= limit < 1e30 else math.inf,
                 type="acceleration" if drive.acceleration else "force")


def _positive(reader, path: str, name: str, value: float, unit: float) -> float:
    if math.isnan(value) or value <= 0:
        raise reader.error(path, name, f"must be > 0 (unauthored: unbreakable), got {value}")
    return value * unit if math.isfinite(value) and value < 1e30 else math.inf


def _unique(path: str, used: set[str]) -> str:
    """The joint's name: its prim's, made unique with its parents' (as bodies' names)."""
    parts = [p for p in path.split("/") if p]
    for k in range(1, len(parts) + 1):
        name = "_".join(parts[-k:])
        if name not in used:
            used.add(name)
            return name
    name, n = "_".join(parts), 1
    while f"{name}_{n}" in used:
        n += 1
    used.add(f"{name}_{n}")
    return f"{name}_{n}"


def read_filtering(descs: dict, bodies, stage) -> tuple[tuple, tuple, tuple]:
    """Filtered pairs (PhysicsFilteredPairsAPI on bodies or colliders) and collision groups
    (PhysicsCollisionGroup: filteredGroups, invertFilteredGroups, mergeGroup) as the scene's
    filtered_pairs, collision_groups and group_filters."""
    by_path = {b.prim_path: b.name for b in bodies if b.prim_path}
    pairs: set[tuple[str, str]] = set()
    shapes = []
    for kind, entries in descs.items():
        name = str(kind).rsplit(".", 1)[-1]
        for p, d in entries:
            if hasattr(d, "filteredCollisions") and name != "Articulation":
                a = _body_of(str(p), by_path)
                for other in d.filteredCollisions:
                    b = _body_of(str(other), by_path)
                    if a and b and a != b:
                        pairs.add(tuple(sorted((a, b))))
            if hasattr(d, "collisionGroups"):
                shapes.append((str(p), d))
    groups = {}
    for kind, entries in descs.items():
        if str(kind).rsplit(".", 1)[-1] == "CollisionGroup":
            for p, d in sorted(entries, key=lambda e: str(e[0])):
                groups[str(p)] = d
    if not groups:
        return tuple(sorted(pairs)), (), ()
    # (invertFilteredGroups and mergeGroup read from the prims: the parser's descriptor can
    # leave an unauthored invertFilteredGroups uninitialized)
    from pxr import UsdPhysics

    invert, merge = {}, {}
    for p in groups:
        group = UsdPhysics.CollisionGroup(stage.GetPrimAtPath(p))
        invert[p] = bool(group.GetInvertFilteredGroupsAttr().Get())
        merge[p] = group.GetMergeGroupNameAttr().Get() or ""
    # merged groups (the same mergeGroup name) are one group
    root = {}
    for p in groups:
        root[p] = next((q for q in groups if merge[p] and merge[q] == merge[p]), p)
    index = {r: k for k, r in enumerate(dict.fromkeys(root[p] for p in groups))}
    filters = [set() for _ in index]
    for p, d in groups.items():
        listed = {index[root[str(q)]] for q in d.filteredGroups if str(q) in root}
        filters[index[root[p]]] |= (set(index.values()) - listed) if invert[p] else listed
    members: dict[str, set[int]] = {}
    for p, d in shapes:
        body = _body_of(p, by_path)
        for g in d.collisionGroups:
            if body and str(g) in root:
                members.setdefault(body, set()).add(index[root[str(g)]])
    return (tuple(sorted(pairs)), tuple(sorted((b, tuple(sorted(g))) for b, g in members.items())),
            tuple(tuple(sorted(f)) for f in filters))

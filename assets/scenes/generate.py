"""Writes the shipped example scenes (all but demo.toml, which is written by hand).

Run `python assets/scenes/generate.py`; the outputs are checked in. Random placements use a
fixed seed, so running it again gives the same files.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

HERE = Path(__file__).resolve().parent


def vec(v, digits: int = 6) -> str:
    return "[" + ", ".join(f"{x:.{digits}g}" for x in v) + "]"


def random_orientation(rng: random.Random, max_angle: float) -> tuple[float, float, float, float]:
    """A rotation about a random axis by up to max_angle (rad), as [w, x, y, z]."""
    while True:
        axis = [rng.uniform(-1, 1) for _ in range(3)]
        n = math.sqrt(sum(a * a for a in axis))
        if 0.1 < n <= 1.0:
            break
    angle = rng.uniform(-max_angle, max_angle)
    s = math.sin(angle / 2) / n
    return (math.cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s)


def header(title: str, end_frame: int, friction: float = 0.5) -> str:
    return (f"# {title}\n# Written by generate.py; edit that and run it again.\n\n"
            f"[scene]\nfps = 24\nstart_frame = 1\nend_frame = {end_frame}\n\n"
            f"[ground]\nheight = 0.0\nfriction = {friction}\n")


def body(name: str, shape: str, position, digits: int = 6, **extra) -> str:
    """A [[bodies]] table; vectors to `digits` significant digits."""
    lines = [f'\n[[bodies]]\nname = "{name}"', shape, f"position = {vec(position, digits)}"]
    for key, value in extra.items():
        if isinstance(value, bool):
            lines.append(f"{key} = {'true' if value else 'false'}")
        elif isinstance(value, (tuple, list)):
            lines.append(f"{key} = {vec(value, digits)}")
        else:
            lines.append(f"{key} = {value}")
    return "\n".join(lines) + "\n"


def box(size) -> str:
    return f'shape = {{ type = "box", size = {vec(size)} }}'


def tower() -> str:
    text = header("A tower of ten 1 m boxes, stacked exactly; it must stand.", 241)
    for i in range(10):
        text += body(f"box{i:02d}", box((1, 1, 1)), (0, 0.5 + i, 0), density=500.0)
    return text


def pyramid(rows: int = 15) -> str:
    text = header(f"A 2D pyramid of {rows} rows of 1 m boxes ({rows * (rows + 1) // 2} boxes); it must stand.", 241)
    for r in range(rows):
        for k in range(rows - r):
            text += body(f"r{r:02d}_{k:02d}", box((1, 1, 1)), (k - 0.5 * (rows - r - 1), 0.5 + r, 0), density=500.0)
    return text


def dominoes(count: int = 50) -> str:
    text = header(f"A line of {count} dominoes; the first is tipped and they fall in turn.", 169, friction=0.6)
    size = (0.04, 0.4, 0.2)  # thickness, height, width (m)
    spacing = 0.25
    for i in range(count):
        extra = {"density": 650.0, "friction": 0.4}
        position = (i * spacing, 0.2, 0)
        if i == 0:  # leaning 10 degrees towards the next one, past its tipping angle (5.7)
            lean = math.radians(10.0)
            extra["orientation"] = (math.cos(lean / 2), 0, 0, -math.sin(lean / 2))
            # resting on its leading bottom edge: centre above that edge's ground point
            position = (0.5 * size[0] * math.cos(lean) + 0.5 * size[1] * math.sin(lean) - 0.5 * size[0],
                        0.5 * size[1] * math.cos(lean) + 0.5 * size[0] * math.sin(lean) + 1e-4, 0)
        text += body(f"domino{i:02d}", box(size), position, **extra)
    return text


def pile(count: int = 200) -> str:
    rng = random.Random(2026)
    text = header(f"{count} mixed nonconvex meshes (tori, L-shapes, spheres) poured onto the ground.", 145)
    meshes = ["../meshes/torus.obj", "../meshes/lshape.obj", "../meshes/sphere.obj"]
    side = 5
    for i in range(count):
        layer, cell = divmod(i, side * side)
        x, z = divmod(cell, side)
        position = (0.85 * (x - 2) + rng.uniform(-0.1, 0.1), 0.6 + 0.75 * layer, 0.85 * (z - 2) + rng.uniform(-0.1, 0.1))
        text += body(f"piece{i:03d}", f'mesh = "{meshes[i % 3]}"', position,
                     orientation=random_orientation(rng, math.pi), density=700.0,
                     angular_velocity=tuple(rng.uniform(-2, 2) for _ in range(3)))
    return text


def ring_toss() -> str:
    rng = random.Random(7)
    text = header("Tori dropped over thin posts: each ring must end around its post.", 97)
    posts = [(-1.0, 0.0), (0.0, 0.0), (1.0, 0.0)]
    for p, (x, z) in enumerate(posts):
        text += body(f"post{p}", box((0.06, 1.0, 0.06)), (x, 0.5, z), kinematic=True)
        for r in range(2):
            tilt = random_orientation(rng, 0.25)
            text += body(f"ring{p}_{r}", 'mesh = "../meshes/torus.obj"',
                         (x + rng.uniform(-0.05, 0.05), 1.4 + 0.5 * r, z + rng.uniform(-0.05, 0.05)),
                         orientation=tilt, density=600.0, friction=0.4)
    return text


def cloth(name: str, size, resolution, position, **extra) -> str:
    lines = [f'\n[[cloths]]\nname = "{name}"',
             f"grid = {{ size = {vec(size)}, resolution = [{resolution[0]}, {resolution[1]}] }}",
             f"position = {vec(position)}"]
    for key, value in extra.items():
        if isinstance(value, str):
            lines.append(f'{key} = "{value}"')
        elif isinstance(value, (tuple, list)):
            lines.append(f"{key} = [" + ", ".join(str(v) for v in value) + "]")
        else:
            lines.append(f"{key} = {value}")
    return "\n".join(lines) + "\n"


def drape() -> str:
    text = header("A 2 m square cloth (64 x 64) draped over a sphere and onto the ground.", 73)
    text += body("ball", 'shape = { type = "sphere", radius = 0.5 }', (0, 0.5, 0), kinematic=True, friction=0.5)
    text += cloth("sheet", (2.0, 2.0), (64, 64), (0, 1.2, 0), stretch_stiffness=2000.0, friction=0.4)
    return text


def flag() -> str:
    nx, nz = 48, 32
    text = header("A flag pinned along its pole edge, falling and swinging under gravity.", 97)
    text += body("pole", box((0.04, 3.0, 0.04)), (-0.77, 1.5, 0), kinematic=True)
    # the grid stands in the XY plane: turned 90 degrees about x, so grid z becomes -y
    pinned = [j * nx for j in range(nz)]
    text += cloth("flag", (1.5, 1.0), (nx, nz), (0, 2.4, 0), orientation=(0.7071068, 0.7071068, 0, 0),
                  pinned=pinned, area_density=0.15, stretch_stiffness=1500.0)
    return text


def tablecloth() -> str:
    text = header("A tablecloth dropped off-centre on a table; the overhanging side drags it off.", 97)
    text += body("table", box((1.2, 0.75, 0.8)), (0, 0.375, 0), kinematic=True, friction=0.2)
    text += cloth("tablecloth", (1.6, 1.2), (64, 48), (0.75, 0.8, 0), friction=0.2, area_density=0.2)
    return text


def cape_on_mover() -> str:
    text = header("A cape (pinned to nothing) draped on a keyed body that moves and turns.", 121)
    keys = ("[{ time = 0.0 }, { time = 1.0 }, { time = 2.5, position = [1.5, 1.2, 0.0], "
            "orientation = [0.7071068, 0.0, 0.7071068, 0.0] }, { time = 4.0, position = [3.0, 1.2, 1.0], "
            "orientation = [0.0, 0.0, 1.0, 0.0] }]")
    text += (body("mover", box((0.5, 0.8, 0.3)), (0, 1.2, 0), kinematic=True, friction=0.8)
             .rstrip("\n") + f"\nkeys = {keys}\n")
    text += cloth("cape", (1.0, 1.0), (40, 40), (0, 1.75, 0), friction=0.8, area_density=0.2)
    return text


def cloth_demo() -> str:
    rng = random.Random(11)
    text = header("Cloth and rigid bodies together: a sheet falls on tumbling shapes.", 97)
    for i in range(5):
        shape = box((0.4, 0.4, 0.4)) if i % 2 else 'shape = { type = "sphere", radius = 0.25 }'
        text += body(f"body{i}", shape, (rng.uniform(-0.6, 0.6), 0.4 + 0.5 * i, rng.uniform(-0.6, 0.6)),
                     angular_velocity=tuple(rng.uniform(-3, 3) for _ in range(3)), density=300.0)
    text += body("ring", 'mesh = "../meshes/torus.obj"', (0.0, 3.2, 0.0), density=400.0)
    text += cloth("sheet", (2.4, 2.4), (48, 48), (0, 3.6, 0), friction=0.4)
    return text


def heap() -> str:
    text = header("A long cloth, twisted one and a half turns, dropped on end: it piles on the ground "
                  "in many layers.", 121)
    text += ('\n[[cloths]]\nname = "heap"\nmesh = "../meshes/twisted_sheet.obj"\n'
             "position = [0, 1.75, 0]\nstretch_stiffness = 1000.0\nfriction = 0.4\n")
    return text


def towel_on_rod() -> str:
    text = header("A towel dropped over a thin rod: it folds over it and its halves hang against each other.",
                  97, friction=0.5)
    text += body("rod", box((0.03, 0.03, 1.2)), (0, 1.2, 0), kinematic=True, friction=0.8)
    text += cloth("towel", (1.2, 0.6), (48, 24), (0.04, 1.3, 0), friction=0.6, area_density=0.3,
                  stretch_stiffness=1500.0)
    return text


def box_plow() -> str:
    text = header("A box pushed along the ground into a sheet lying on it, a vertical edge first: the sheet "
                  "rucks up and folds against it.", 73)
    turn = (math.cos(math.pi / 8), 0.0, math.sin(math.pi / 8), 0.0)  # 45 degrees about y
    keys = (f"[{{ time = 0.0 }}, {{ time = 0.5 }}, {{ time = 2.5, position = [0.3, 0.2, 0.0], "
            f"orientation = {vec(turn)} }}]")
    text += (body("plow", box((0.4, 0.4, 0.4)), (-0.9, 0.2, 0), orientation=turn, kinematic=True, friction=0.5)
             .rstrip("\n") + f"\nkeys = {keys}\n")
    text += cloth("sheet", (1, 1), (20, 20), (0, 0.02, 0), friction=0.5)
    return text


def joint(name: str, kind: str, body0: str, body1: str, **extra) -> str:
    lines = [f'\n[[joints]]\nname = "{name}"\ntype = "{kind}"']
    if body0:
        lines.append(f'body0 = "{body0}"')
    lines.append(f'body1 = "{body1}"')
    for key, value in extra.items():
        if isinstance(value, str):
            lines.append(f'{key} = "{value}"')
        elif isinstance(value, (tuple, list)):
            lines.append(f"{key} = {vec(value)}")
        else:
            lines.append(f"{key} = {value:.6g}")
    return "\n".join(lines) + "\n"


def link_chain(prefix: str, anchor: str, start, count: int, length: float, mass: float, anchor_at) -> str:
    """`count` box links along +x from `start`, ball joints end to end, the first to `anchor`
    (its frame point `anchor_at`)."""
    text = ""
    for i in range(count):
        name = f"{prefix}{i:02d}"
        text += body(name, box((length, 0.05, 0.05)), (start[0] + (i + 0.5) * length, start[1], start[2]), mass=mass)
        text += joint(f"{name}_joint", "spherical", anchor if i == 0 else f"{prefix}{i - 1:02d}", name,
                      local_position0=anchor_at if i == 0 else (0.5 * length, 0, 0),
                      local_position1=(-0.5 * length, 0, 0))
    return text


def chain() -> str:
    text = header("A chain of 20 links hanging from a beam by one end, released level: it swings down "
                  "and whips about under the beam (ball joints; links collide with all but their "
                  "neighbours).", 241)
    text += body("beam", box((3.0, 0.2, 0.2)), (0, 3.2, 0), kinematic=True)
    text += link_chain("link", "beam", (-1.0, 3.0, 0), 20, 0.12, 0.3, (-1.0, -0.2, 0))
    return text


def door() -> str:
    text = header("A door (1 x 2 m, 20 kg) on two hinges to a post, pushed open: it swings to its "
                  "stop at 100 degrees and rests there.", 121)
    text += body("post", box((0.1, 2.2, 0.1)), (0, 1.1, 0), kinematic=True)
    text += body("door", box((1.0, 2.0, 0.04)), (0.55, 1.05, 0), mass=20.0, angular_velocity=(0, 2.5, 0))
    for name, y in (("hinge_top", 0.8), ("hinge_bottom", -0.8)):
        text += joint(name, "revolute", "post", "door", axis="y", local_position0=(0.05, y - 0.05, 0),
                      local_position1=(-0.5, y, 0), lower_limit=0.0, upper_limit=math.radians(100))
    return text


def wrecking_ball() -> str:
    text = header("A wrecking ball (400 kg) on a chain of six links swings into a wall of 100 bricks, "
                  "each row glued brick to brick by breakable fixed joints, rows resting on each other "
                  "in running bond: the glue holds while the wall stands and breaks where the ball hits.", 121)
    size = (0.4, 0.2, 0.25)
    for row in range(10):
        for col in range(10):
            x = -1.8 + col * size[0] + (0.5 * size[0] if row % 2 else 0.0) - (0.1 if row % 2 else 0.0)
            text += body(f"brick_{row}_{col}", box(size), (x, 0.1 + row * size[1], 0), density=1800.0)
    for row in range(10):
        for col in range(10):
            name = f"brick_{row}_{col}"
            glue = dict(break_force=2000.0, break_torque=600.0)
            if col + 1 < 10:
                text += joint(f"glue_{row}_{col}_r", "fixed", name, f"brick_{row}_{col + 1}",
                              local_position0=(0.5 * size[0], 0, 0), local_position1=(-0.5 * size[0], 0, 0), **glue)
    crane = (0.0, 5.4, -0.55)
    text += body("crane", box((0.4, 0.4, 0.4)), crane, kinematic=True)
    length, angle = 0.6, math.radians(60)  # the chain's angle from hanging straight down, away from the wall
    d = (0.0, -math.cos(angle), -math.sin(angle))
    top = (crane[0], crane[1] - 0.2, crane[2])
    turn = (math.cos(0.5 * angle), math.sin(0.5 * angle), 0.0, 0.0)  # the links' -y along d
    for i in range(6):
        c = tuple(top[k] + (i + 0.5) * length * d[k] for k in range(3))
        text += body(f"chain{i}", box((0.08, length, 0.08)), c, mass=10.0, orientation=turn)
        text += joint(f"chain{i}_joint", "spherical", "crane" if i == 0 else f"chain{i - 1}", f"chain{i}",
                      local_position0=(0, -0.2, 0) if i == 0 else (0, -0.5 * length, 0),
                      local_position1=(0, 0.5 * length, 0))
    ball = tuple(top[k] + (6 * length + 0.4) * d[k] for k in range(3))
    text += body("ball", 'shape = { type = "sphere", radius = 0.4 }', ball, mass=400.0)
    text += joint("ball_joint", "spherical", "chain5", "ball", local_position0=(0, -0.5 * length, 0),
                  local_position1=tuple(-0.4 * v for v in d))
    return text


# A ragdoll of 15 boxes and a sphere (the head), standing facing +x, lateral z, soles at y = 0:
# name, size (m), centre, mass (kg)
RAGDOLL_PARTS = [
    ("pelvis", (0.20, 0.16, 0.34), (0.0, 1.01, 0.0), 10.0),
    ("abdomen", (0.18, 0.16, 0.30), (0.0, 1.17, 0.0), 6.0),
    ("belly", (0.19, 0.16, 0.32), (0.0, 1.33, 0.0), 7.0),
    ("chest", (0.20, 0.20, 0.38), (0.0, 1.51, 0.0), 9.0),
    ("head", 0.11, (0.0, 1.78, 0.0), 5.0),
] + [part for side, z in (("l", 0.1), ("r", -0.1)) for part in [
    (f"thigh_{side}", (0.13, 0.44, 0.13), (0.0, 0.71, z), 7.0),
    (f"shin_{side}", (0.10, 0.42, 0.10), (0.0, 0.28, z), 3.5),
    (f"foot_{side}", (0.24, 0.07, 0.10), (0.05, 0.035, z), 1.0),
]] + [part for side, z in (("l", 0.25), ("r", -0.25)) for part in [
    (f"upper_arm_{side}", (0.09, 0.30, 0.09), (0.0, 1.42, z), 2.0),
    (f"forearm_{side}", (0.08, 0.28, 0.08), (0.0, 1.13, z), 1.5),
]]

# Its joints, at figure points: (name, type, parent, child, point, limits). d6: twist about the
# limb (frame X turned to the body's y), a round swing cone; revolute: about z (flexion)
RAGDOLL_JOINTS = [
    ("waist", "d6", "pelvis", "abdomen", (0.0, 1.09, 0.0), (0.25, 0.35)),
    ("spine", "d6", "abdomen", "belly", (0.0, 1.25, 0.0), (0.25, 0.35)),
    ("ribs", "d6", "belly", "chest", (0.0, 1.41, 0.0), (0.25, 0.35)),
    ("neck", "d6", "chest", "head", (0.0, 1.64, 0.0), (0.5, 0.6)),
] + [j for side, z in (("l", 0.1), ("r", -0.1)) for j in [
    (f"hip_{side}", "d6", "pelvis", f"thigh_{side}", (0.0, 0.93, z), (0.4, 1.0)),
    (f"knee_{side}", "revolute", f"thigh_{side}", f"shin_{side}", (0.0, 0.49, z), (-2.4, 0.0)),
    (f"ankle_{side}", "d6", f"shin_{side}", f"foot_{side}", (0.0, 0.07, z), (0.15, 0.45)),
]] + [j for side, z in (("l", 0.25), ("r", -0.25)) for j in [
    (f"shoulder_{side}", "d6", "chest", f"upper_arm_{side}", (0.0, 1.57, z), (0.8, 1.4)),
    (f"elbow_{side}", "revolute", f"upper_arm_{side}", f"forearm_{side}", (0.0, 1.27, z), (0.0, 2.5)),
]]

# Stairs down along +x: a landing 1.2 m up ending at x = 0, then five 0.2 m steps 0.35 m deep
STAIR_RISE, STAIR_RUN, STAIR_STEPS, STAIR_WIDTH = 0.2, 0.35, 5, 1.6


def stairs() -> str:
    top = (STAIR_STEPS + 1) * STAIR_RISE
    text = body("landing", box((1.2, top, STAIR_WIDTH)), (-0.6, 0.5 * top, 0), kinematic=True, friction=0.8)
    for k in range(1, STAIR_STEPS + 1):
        h = top - k * STAIR_RISE
        text += body(f"step{k}", box((STAIR_RUN, h, STAIR_WIDTH)), ((k - 0.5) * STAIR_RUN, 0.5 * h, 0),
                     kinematic=True, friction=0.8)
    return text


def ragdoll_inertia_about(name: str, point) -> float:
    """The largest moment of inertia (kg m^2) of a ragdoll part about an axis through `point`."""
    _, size, centre, mass = next(p for p in RAGDOLL_PARTS if p[0] == name)
    if isinstance(size, float):
        own = 0.4 * mass * size * size
    else:
        own = mass / 12.0 * max(size[i] ** 2 + size[j] ** 2 for i, j in ((0, 1), (1, 2), (0, 2)))
    return own + mass * math.dist(point, centre) ** 2


def ragdoll(tilt_deg: float = 60.0, back: float = -0.1, lift: float = 0.3, push: float = 1.2,
            spin: float = 2.0) -> str:
    text = header("A ragdoll of 15 bodies (pelvis, three torso pieces, head, arms, legs, feet; 67 kg) "
                  "pitching off a landing and tumbling down five stairs: D6 joints with twist limits and "
                  "round swing cones at the waist, spine, neck, shoulders, hips and ankles, limited "
                  "hinges at the elbows and knees.", 121, friction=0.8)
    text += stairs()
    # the figure pitches off the landing: its toes 0.1 m past the edge (`back`), 0.3 m up
    # (`lift`), leaning 60 degrees forward and turning on. (Standing on the landing and tipped
    # over, its feet sank 11-13 cm into it while its ankles were at their limits: the joints
    # are solved after the contacts, README Limitations; 2 cm at 40 substeps a frame)
    tilt = math.radians(tilt_deg)
    turn = (math.cos(-0.5 * tilt), 0.0, 0.0, math.sin(-0.5 * tilt))
    c, s = math.cos(tilt), math.sin(tilt)

    def turned(p):
        return (c * p[0] + s * p[1], -s * p[0] + c * p[1], p[2])

    # lifted so that its lowest point (a toe) is 5 mm above the landing
    lowest = min(turned((centre[0] + sx * 0.5 * size[0], centre[1] + sy * 0.5 * size[1], 0.0))[1]
                 for _, size, centre, _ in RAGDOLL_PARTS if not isinstance(size, float)
                 for sx in (-1, 1) for sy in (-1, 1))
    base = (-back, (STAIR_STEPS + 1) * STAIR_RISE + lift - lowest, 0.0)

    def place(p):
        q = turned(p)
        return (base[0] + q[0], base[1] + q[1], base[2] + q[2])

    centres, masses = {}, {}
    for name, size, centre, mass in RAGDOLL_PARTS:
        masses[name] = mass
        shape = (f'shape = {{ type = "sphere", radius = {size} }}' if isinstance(size, float) else box(size))
        centres[name] = centre
        # (to 12 digits: the joints' frames meet to 1e-12 m at the start, not 1e-6)
        text += body(name, shape, place(centre), digits=12, mass=mass, orientation=turn, friction=0.8,
                     linear_velocity=(push, 0.0, 0.0), angular_velocity=(0.0, 0.0, -spin))
    along_y = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # turns the joint's X to the body's y
    for name, kind, parent, child, point, limits in RAGDOLL_JOINTS:
        ends = {f"local_position{k}": tuple(point[i] - centres[b][i] for i in range(3))
                for k, b in enumerate((parent, child))}
        # joint damping (a drive to zero relative speed, no spring), 20% of the critical damping
        # of the child swinging from the joint alone: 2 (0.2) I w0 = 0.4 sqrt(I m g d), I about
        # the joint, d from the joint to the child's centre; the figure comes to rest
        damping = 0.4 * math.sqrt(ragdoll_inertia_about(child, point) * masses[child] * 9.81 *
                                  math.dist(point, centres[child]))
        drive = f"{{ damping = {damping:.4g} }}"
        if kind == "d6":
            twist, cone = limits
            text += joint(name, "d6", parent, child, **ends, local_rotation0=along_y, local_rotation1=along_y)
            text += (f'limits = {{ trans_x = "locked", trans_y = "locked", trans_z = "locked", '
                     f"rot_x = {vec((-twist, twist))}, rot_y = {vec((-cone, cone))}, rot_z = {vec((-cone, cone))} }}\n"
                     f"drives = {{ rot_x = {drive}, rot_y = {drive}, rot_z = {drive} }}\n")
        else:
            text += joint(name, "revolute", parent, child, **ends, axis="z", lower_limit=limits[0],
                          upper_limit=limits[1])
            text += f"drives = {{ angular = {drive} }}\n"
    return text


# The flywheel: a 24-sided wheel (assets/meshes/wheel.obj, circumradius 0.4 m, 0.1 m thick)
# with a bar glued across it, on a hinge to a stand, spun up by a velocity drive at its torque
# limit: name, (kg), (N m), (rad/s)
WHEEL_MASS, BAR_MASS, WHEEL_TORQUE, WHEEL_TARGET = 20.0, 2.0, 4.0, 0.8 * math.pi


def wheel() -> str:
    text = header("A flywheel (20 kg, a bar glued across it) on a hinge to a stand, spun up from rest by "
                  "a velocity drive (target 0.4 turn a second, at most 4 N m): it speeds up at the "
                  "torque limit for about a second, then turns at the target.", 73)
    text += body("stand", box((0.1, 1.1, 0.1)), (0, 0.55, -0.15), kinematic=True)
    text += body("wheel", 'mesh = "../meshes/wheel.obj"', (0, 0.6, 0), mass=WHEEL_MASS)
    text += body("bar", box((0.76, 0.06, 0.12)), (0, 0.6, 0), mass=BAR_MASS)
    text += joint("bar_glue", "fixed", "wheel", "bar")
    text += joint("axle", "revolute", "stand", "wheel", axis="z", local_position0=(0, 0.05, 0.15))
    text += (f"drives = {{ angular = {{ damping = 10000.0, target_velocity = {WHEEL_TARGET:.9g}, "
             f"max_force = {WHEEL_TORQUE} }} }}\n")
    return text

def main() -> None:
    for name, make in [("heap", heap), ("towel_on_rod", towel_on_rod), ("tower", tower), ("pyramid", pyramid), ("dominoes", dominoes), ("pile", pile),
                       ("ring_toss", ring_toss), ("drape", drape), ("flag", flag), ("tablecloth", tablecloth),
                       ("cape_on_mover", cape_on_mover), ("cloth_demo", cloth_demo), ("box_plow", box_plow),
                       ("chain", chain), ("door", door), ("wrecking_ball", wrecking_ball),
                       ("ragdoll", ragdoll), ("wheel", wheel)]:
        (HERE / f"{name}.toml").write_text(make())


if __name__ == "__main__":
    main()

"""Writes the shipped example scenes (all but demo.toml, which is written by hand).

Run `python assets/scenes/generate.py`; the outputs are checked in. Random placements use a
fixed seed, so running it again gives the same files.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

HERE = Path(__file__).resolve().parent


def vec(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"


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


def body(name: str, shape: str, position, **extra) -> str:
    lines = [f'\n[[bodies]]\nname = "{name}"', shape, f"position = {vec(position)}"]
    for key, value in extra.items():
        if isinstance(value, bool):
            lines.append(f"{key} = {'true' if value else 'false'}")
        elif isinstance(value, (tuple, list)):
            lines.append(f"{key} = {vec(value)}")
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


def main() -> None:
    for name, make in [("tower", tower), ("pyramid", pyramid), ("dominoes", dominoes), ("pile", pile),
                       ("ring_toss", ring_toss)]:
        (HERE / f"{name}.toml").write_text(make())


if __name__ == "__main__":
    main()

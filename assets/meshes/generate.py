"""Writes the shipped meshes (bodies: closed, consistently wound, origin at the centre; cloths:
open sheets): run it from anywhere with `python assets/meshes/generate.py`; the files are
checked in."""

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    lines = [f"# {path.name}, made by generate.py"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def torus(major: float, minor: float, n_major: int, n_minor: int):
    """Ring around the y axis: u goes round the ring, v round the tube."""
    u = np.arange(n_major) * 2 * np.pi / n_major
    v = np.arange(n_minor) * 2 * np.pi / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    radius = major + minor * np.cos(vv)
    vertices = np.stack([radius * np.cos(uu), minor * np.sin(vv), radius * np.sin(uu)], -1).reshape(-1, 3)
    faces = []
    for i in range(n_major):
        for j in range(n_minor):
            a, b = i * n_minor + j, ((i + 1) % n_major) * n_minor + j
            c, d = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor, i * n_minor + (j + 1) % n_minor
            faces += [(a, d, c), (a, c, b)]
    return vertices, np.array(faces)


def l_prism(outline, depth: float):
    """A polygon in the xy plane (counter-clockwise) extruded along z, centred on z = 0.
    The caps are a fan from vertex 0, which must see every other vertex."""
    outline = np.asarray(outline, dtype=float)
    n = len(outline)
    front = np.column_stack([outline, np.full(n, depth / 2)])
    back = np.column_stack([outline, np.full(n, -depth / 2)])
    vertices = np.vstack([front, back])
    faces = [(0, k, k + 1) for k in range(1, n - 1)]               # front, facing +z
    faces += [(n, n + k + 1, n + k) for k in range(1, n - 1)]       # back, facing -z
    for k in range(n):
        a, b = k, (k + 1) % n
        faces += [(a, n + a, n + b), (a, n + b, b)]                 # sides, facing out
    return vertices, np.array(faces)


def cube_sphere(radius: float, subdivisions: int):
    """A cube whose faces are split into s x s quads, projected onto the sphere."""
    s = subdivisions
    index: dict[tuple[int, int, int], int] = {}
    vertices: list[np.ndarray] = []
    faces = []

    def vertex(key):
        if key not in index:
            index[key] = len(vertices)
            cube = np.array(key, dtype=float) * (2.0 / s) - 1.0
            vertices.append(radius * cube / np.linalg.norm(cube))
        return index[key]

    for a in range(3):
        for side in (0, 1):
            u, v = (a + 1) % 3, (a + 2) % 3
            if side == 0:
                u, v = v, u
            for i in range(s):
                for j in range(s):
                    def corner(di, dj):
                        key = [0, 0, 0]
                        key[a], key[u], key[v] = side * s, i + di, j + dj
                        return vertex(tuple(key))
                    p00, p10, p11, p01 = corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)
                    faces += [(p00, p10, p11), (p00, p11, p01)]
    return np.array(vertices), np.array(faces)


def twisted_sheet(width: float, length: float, nw: int, nl: int, turns: float):
    """An open sheet twisted about its long (y) axis: a helicoid strip, `turns` whole turns
    from bottom to top, centred on the origin; vertex (i across, j along) at j * nw + i."""
    s = np.linspace(-width / 2, width / 2, nw)
    t = np.linspace(-length / 2, length / 2, nl)
    vertices = []
    for y in t:
        angle = 2 * np.pi * turns * (y + length / 2) / length
        for x in s:
            vertices.append((x * np.cos(angle), y, x * np.sin(angle)))
    faces = []
    for j in range(nl - 1):
        for i in range(nw - 1):
            a, b = j * nw + i, j * nw + i + 1
            c, d = a + nw, b + nw
            faces += [(a, c, d), (a, d, b)]
    return np.array(vertices), np.array(faces)


def wheel(radius: float, width: float, sides: int):
    """A regular polygon of `sides` (circumradius `radius`) in the xy plane, extruded along z."""
    a = np.arange(sides) * 2 * np.pi / sides
    return l_prism(np.column_stack([radius * np.cos(a), radius * np.sin(a)]), width)


def main() -> None:
    write_obj(HERE / "torus.obj", *torus(0.3, 0.1, 32, 16))
    write_obj(HERE / "sphere.obj", *cube_sphere(0.2, 6))
    # an L of two 0.2 m thick legs, 0.6 m tall and 0.4 m wide, centred on its bounding box
    outline = np.array([(0.0, 0.0), (0.4, 0.0), (0.4, 0.2), (0.2, 0.2), (0.2, 0.6), (0.0, 0.6)])
    write_obj(HERE / "lshape.obj", *l_prism(outline - (0.2, 0.3), 0.2))
    # a cloth for heap.toml: 1 m wide, 3 m long, one and a half turns
    write_obj(HERE / "wheel.obj", *wheel(0.4, 0.1, 24))
    write_obj(HERE / "twisted_sheet.obj", *twisted_sheet(1.0, 3.0, 25, 73, 1.5))


if __name__ == "__main__":
    main()

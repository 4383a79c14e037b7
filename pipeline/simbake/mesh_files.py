"""Mesh files: any format trimesh reads, as triangles with one-line errors, and a deforming
body's mesh sequence (one file a frame, one topology).

Shared by the assets (simbake.assets: bodies' and cloths' meshes) and the scene loader
(simbake.scene: a TOML body's ``mesh_sequence`` is read when the scene is, as a USD shot's
deforming collider is).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import SceneError
from .files import check_input_file
from .limits import check_mesh_extent
from .rotations import quat_matrix


def read_triangles(path: Path, file: str | Path, key: str, process: bool):
    """The trimesh.Trimesh in any file trimesh reads, with at least one triangle, or a
    one-line SceneError. process=False keeps the file's vertex order."""
    import trimesh

    check_input_file(path, file, key)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
        if isinstance(mesh, trimesh.Trimesh) and not np.isfinite(mesh.vertices).all():
            # before trimesh's processing drops them, and before a test NaN would confuse
            raise SceneError(file, key, f"{path} has non-finite vertex coordinates (NaN or infinity)")
        if isinstance(mesh, trimesh.Trimesh):
            check_mesh_extent(mesh.vertices, file, key, path)
        if process and isinstance(mesh, trimesh.Trimesh):
            mesh.process()
    except SceneError:
        raise
    except Exception as error:  # trimesh raises many kinds; all mean "cannot read this"
        if isinstance(error, ImportError) and error.name in ("charset_normalizer", "chardet"):
            # trimesh guesses the encoding of a text format that is not UTF-8 with these
            detail = f"not UTF-8 text ({path.suffix or 'this'} files are text; is it binary or damaged?)"
        elif isinstance(error, ImportError):  # a format whose optional reader is not installed
            detail = f"no reader for {path.suffix or 'such'} files in this installation ({error})"
        else:
            detail = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise SceneError(file, key, f"cannot read mesh {path}: {detail}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SceneError(file, key, f"{path} holds no triangles")
    return mesh


def load_mesh(path: Path, file: str | Path, key: str) -> tuple[np.ndarray, np.ndarray]:
    """A closed triangle mesh from any file trimesh reads, or a SceneError."""
    mesh = read_triangles(path, file, key, process=True)
    if not mesh.is_watertight:
        raise SceneError(file, key, f"{path} is not a closed mesh (it has holes or open edges); "
                                    "a rigid body needs a closed surface")
    if not mesh.is_winding_consistent:
        raise SceneError(file, key, f"{path} has inconsistently wound triangles")
    if mesh.volume < 0:
        mesh.invert()  # inside out: turn it the right way
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(mesh.faces, dtype=np.int32)
    return vertices, triangles


def sequence_frame_path(pattern: Path, frame: int) -> Path:
    """A mesh sequence's file for `frame`: the pattern's one printf field (%d, %04d) filled in."""
    return Path(str(pattern) % frame)


def sequence_pattern_problem(pattern: str) -> str | None:
    """What is wrong with a mesh sequence's file pattern, or None: it needs exactly one printf
    integer field (%d, %4d, %04d) and no other %."""
    import re

    if len(re.findall(r"%0?\d*d", pattern)) != 1 or pattern.count("%") != 1:
        return f"must hold one frame-number field such as %04d (frames/body.%04d.obj), got {pattern!r}"
    return None


def read_mesh_sequence(pattern: Path, frames: range, file: str | Path, key: str, position=(0.0, 0.0, 0.0),
                       orientation=(1.0, 0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """A deforming body's surface at each of `frames`, one mesh file a frame (sequence_frame_path):
    vertices (frames, n, 3) float64, the files' coordinates placed by `position` and
    `orientation` (w, x, y, z), read-only, and triangles (m, 3) int32, read-only,
    the same for every frame (the file's vertex order kept), closed and wound outwards at the
    first frame; one-line SceneErrors for a missing or unreadable file, a closed mesh that is
    not, or a frame whose topology differs from the first's."""
    vertices, triangles, first = [], None, None
    for frame in frames:
        path = sequence_frame_path(pattern, frame)
        mesh = read_triangles(path, file, key, process=False)
        faces = np.asarray(mesh.faces, dtype=np.int32)
        if triangles is None:
            if not mesh.is_watertight:
                raise SceneError(file, key, f"{path} (frame {frame}) is not a closed mesh (it has holes or open "
                                            "edges, or vertices repeated per face); a deforming body needs a closed surface")
            if not mesh.is_winding_consistent:
                raise SceneError(file, key, f"{path} (frame {frame}) has inconsistently wound triangles")
            triangles, first = (faces[:, ::-1].copy() if mesh.volume < 0 else faces), (frame, len(mesh.vertices), faces)
        elif len(mesh.vertices) != first[1] or faces.shape != first[2].shape or not np.array_equal(faces, first[2]):
            raise SceneError(file, key, f"{path} (frame {frame}) has {len(mesh.vertices)} vertices and {len(faces)} "
                                        f"triangles, not frame {first[0]}'s {first[1]} and {len(first[2])} in the same "
                                        "order: a deforming body keeps one topology (only its vertices move)")
        vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
    placed = np.stack(vertices) @ quat_matrix(orientation).T + np.asarray(position, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles)
    for a in (placed, triangles):
        a.setflags(write=False)
    return placed, triangles

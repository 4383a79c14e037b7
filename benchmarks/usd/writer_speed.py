"""How fast the cache writer goes, next to the simulation it records (the writer must never
be the bottleneck).

Synthetic frames (no simulation: the writer alone, as simbake.simulate drives it), wall time
of writing and closing: 1,000 rigid bodies as one PointInstancer and as 1,000 Xforms, and a
256 x 256 cloth; .usdc against .usda, one file against --clips. The simulation times quoted
beside them are README.md's figures (the 1,000-box pile, 4.11 s per simulated second; the
257 x 257 drape, 171 s per simulated second). Run: python benchmarks/usd/writer_speed.py
Results: benchmarks/results/writer_speed.md
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from simbake import _core
from simbake.assets import grid_mesh
from simbake.normals import corner_normals
from simbake.usd_clips import ClipsWriter
from simbake.usd_instancer import InstancerGroup
from simbake.usd_writer import BodyPrim, CacheWriter, ClothPrim

ROOT = Path(__file__).resolve().parents[2]
FPS = 24
SIM_SECONDS_PER_FRAME = {"bodies": 4.11 / FPS, "cloth": 171.0 / FPS}


def _bodies(n: int):
    v, t = _core.box_mesh(np.array([0.5, 0.5, 0.5]), 1)
    normals = corner_normals(v, t)
    return [BodyPrim(name=f"box_{i}", points=v, face_vertex_counts=np.full(len(t), 3), face_vertex_indices=t.reshape(-1),
                     normals=normals, interpolation="faceVarying", dynamic=True) for i in range(n)]


def write_bodies(path: Path, frames: int, instanced: bool, clips: int | None) -> float:
    n = 1000
    bodies = _bodies(n)
    settings = dict(fps=FPS, start_frame=1, end_frame=frames, bodies=bodies,
                    instancers=[InstancerGroup("box_instances", tuple(range(n)))] if instanced else [])
    writer = ClipsWriter(path, clip_frames=clips, **settings) if clips else CacheWriter(path, **settings)
    rng = np.random.default_rng(1)
    base = rng.uniform(-10, 10, (n, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    zeros = np.zeros((n, 3))
    start = time.perf_counter()
    with writer:
        for f in range(1, frames + 1):
            writer.write_frame(f, base + 0.01 * f, q, body_velocities=zeros, body_angular_velocities=zeros)
    return time.perf_counter() - start


def write_cloth(path: Path, frames: int, clips: int | None) -> float:
    v, t = grid_mesh((2.0, 2.0), (256, 256))
    cloth = ClothPrim(name="sheet", face_vertex_counts=np.full(len(t), 3), face_vertex_indices=t.reshape(-1))
    settings = dict(fps=FPS, start_frame=1, end_frame=frames, bodies=[], cloths=[cloth])
    writer = ClipsWriter(path, clip_frames=clips, **settings) if clips else CacheWriter(path, **settings)
    normals = np.tile([0.0, 1.0, 0.0], (len(v), 1))
    vel = np.zeros_like(v)
    start = time.perf_counter()
    with writer:
        for f in range(1, frames + 1):
            pts = v + [0.0, -0.01 * f, 0.0]
            writer.write_frame(f, np.zeros((0, 3)), np.zeros((0, 4)), cloth_points=[pts],
                               cloth_velocities=[vel], cloth_normals=[normals])
    return time.perf_counter() - start


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for label, fn, frames, kind in [
            ("1,000 bodies, PointInstancer, .usdc", lambda p, n: write_bodies(p.with_suffix(".usdc"), n, True, None), 300, "bodies"),
            ("1,000 bodies, PointInstancer, .usda", lambda p, n: write_bodies(p.with_suffix(".usda"), n, True, None), 300, "bodies"),
            ("1,000 bodies, PointInstancer, .usdc, --clips 100", lambda p, n: write_bodies(p.with_suffix(".usdc"), n, True, 100), 300, "bodies"),
            ("1,000 bodies, 1,000 Xforms, .usdc", lambda p, n: write_bodies(p.with_suffix(".usdc"), n, False, None), 300, "bodies"),
            ("256 x 256 cloth, .usdc", lambda p, n: write_cloth(p.with_suffix(".usdc"), n, None), 100, "cloth"),
            ("256 x 256 cloth, .usdc, --clips 25", lambda p, n: write_cloth(p.with_suffix(".usdc"), n, 25), 100, "cloth"),
            ("256 x 256 cloth, .usda", lambda p, n: write_cloth(p.with_suffix(".usda"), n, None), 20, "cloth"),
        ]:
            out = tmp / f"run{len(rows)}"
            wall = fn(out, frames)
            per_frame = wall / frames
            rows.append((label, frames, wall, 1 / per_frame, SIM_SECONDS_PER_FRAME[kind] / per_frame))
            print(rows[-1], flush=True)
    lines = ["# Cache writer speed (benchmarks/usd/writer_speed.py)", "",
             "The writer alone on synthetic frames (one process, this 2-vCPU machine class, shared), "
             "against the simulation time per frame of the same scene from README.md's figures.", "",
             "| what | frames | wall (s) | frames written per second | simulation time / writing time |",
             "| --- | --- | --- | --- | --- |"]
    for label, frames, wall, fps, ratio in rows:
        lines.append(f"| {label} | {frames} | {wall:.2f} | {fps:.0f} | {ratio:.0f}x |")
    (ROOT / "benchmarks" / "results" / "writer_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

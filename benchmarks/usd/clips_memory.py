"""Peak memory of the cache writer against shot length: single file against --clips.

Writes synthetic frames (no simulation: the writer alone) of BODIES bodies drawn by one
PointInstancer, as simbake.simulate drives it, for 1,000 and 10,000 frames, each run in its
own process (peak RSS from getrusage). Run: python benchmarks/usd/clips_memory.py [--quick]
Results: benchmarks/results/clips_memory.md
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BODIES = 1000


def run_one(frames: int, clips: int | None, out: Path) -> dict:
    import resource

    import numpy as np

    from simbake.usd_instancer import InstancerGroup
    from simbake.usd_writer import BodyPrim, CacheWriter
    from simbake import _core

    v, t = _core.box_mesh(np.array([0.5, 0.5, 0.5]), 1)
    from simbake.normals import corner_normals

    prims = [BodyPrim(name=f"box_{i}", points=v, face_vertex_counts=np.full(len(t), 3),
                      face_vertex_indices=t.reshape(-1), normals=corner_normals(v, t),
                      interpolation="faceVarying", dynamic=True) for i in range(BODIES)]
    settings = dict(fps=24, start_frame=1, end_frame=frames, bodies=prims,
                    instancers=[InstancerGroup("box_instances", tuple(range(BODIES)))])
    if clips:
        from simbake.usd_clips import ClipsWriter

        writer = ClipsWriter(out, clip_frames=clips, **settings)
    else:
        writer = CacheWriter(out, **settings)
    rng = np.random.default_rng(1)
    base = rng.uniform(-10, 10, (BODIES, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (BODIES, 1))
    zeros = np.zeros((BODIES, 3))
    start = time.perf_counter()
    with writer:
        for frame in range(1, frames + 1):
            writer.write_frame(frame, base + 0.01 * frame, q, body_velocities=zeros, body_angular_velocities=zeros)
    wall = time.perf_counter() - start
    size = out.stat().st_size + sum(p.stat().st_size for p in out.parent.glob(f"{out.stem}.clips/*"))
    return {"frames": frames, "clips": clips, "wall_s": round(wall, 2),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "bytes_on_disk": size}


def main() -> None:
    quick = "--quick" in sys.argv
    runs = [(100, None), (1000, None), (1000, 100)] if quick else \
        [(1000, None), (10000, None), (1000, 1000), (10000, 1000)]
    results = []
    for frames, clips in runs:
        with tempfile.TemporaryDirectory() as tmp:
            code = (f"import json,sys; sys.path.insert(0, {str(ROOT / 'benchmarks' / 'usd')!r}); import clips_memory as m;"
                    f"from pathlib import Path; print(json.dumps(m.run_one({frames}, {clips}, Path({tmp!r}) / 'out.usdc')))")
            line = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
            results.append(json.loads(line.strip().splitlines()[-1]))
            print(results[-1], flush=True)
    if not quick:
        lines = ["# Cache writer memory against shot length (benchmarks/usd/clips_memory.py)", "",
                 f"{BODIES} bodies as one PointInstancer, synthetic frames (the writer alone), one process per run.", "",
                 "| frames | clips | wall (s) | peak RSS (MB) | on disk (MB) |", "| --- | --- | --- | --- | --- |"]
        for r in results:
            lines.append(f"| {r['frames']} | {r['clips'] or 'single file'} | {r['wall_s']} | {r['peak_rss_mb']} | "
                         f"{r['bytes_on_disk'] / 1e6:.1f} |")
        (ROOT / "benchmarks" / "results" / "clips_memory.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

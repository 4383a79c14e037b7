"""Peak memory of a REAL USD-shot bake against shot length, with --clips 1000.

A generated UsdPhysics shot of 1,000 spheres (radius 0.1 m, 2 m apart on a 10x10x10 grid,
zero gravity, one shared drift velocity and spin: no contacts, so the simulation is cheap) is
baked end to end by the command line (`simbake bake SHOT.usda -o OUT.usdc --clips 1000`: load,
simulate, QA, clip layers of overs, topology, manifest), each run in its own child process;
peak RSS is that child's ru_maxrss (resource.getrusage(RUSAGE_CHILDREN) in a fresh parent).

Run:  .venv/bin/python benchmarks/usd/shot_clips_memory.py [FRAMES ...]   (default 1000 10000)
      .venv/bin/python benchmarks/usd/shot_clips_memory.py --time 100     (wall of one short run)
Results: benchmarks/results/shot_clips_memory.md (and .json)
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
CLIPS = 1000


def write_shot(path: Path, frames: int) -> None:
    from pxr import Gf, Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(frames)
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    UsdPhysics.Scene.Define(stage, "/World/PhysicsScene").CreateGravityMagnitudeAttr(0.0)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    for i in range(BODIES):
        x, y, z = i % 10, (i // 10) % 10, i // 100
        ball = UsdGeom.Sphere.Define(stage, f"/World/Ball_{i:04d}")
        ball.CreateRadiusAttr(0.1)
        ball.AddTranslateOp().Set(Gf.Vec3d(2.0 * x, 2.0 * y + 1.0, 2.0 * z))
        prim = ball.GetPrim()
        body = UsdPhysics.RigidBodyAPI.Apply(prim)
        body.CreateVelocityAttr(Gf.Vec3f(0.05, 0.0, 0.02))
        body.CreateAngularVelocityAttr(Gf.Vec3f(0.0, 30.0, 0.0))
        UsdPhysics.CollisionAPI.Apply(prim)
    stage.GetRootLayer().Save()


def run(frames: int, clips: int | None, folder: Path) -> dict:
    """One bake in a child of a fresh parent; its peak RSS and wall."""
    shot = folder / f"balls_{frames}.usda"
    write_shot(shot, frames)
    out = folder / f"balls_{frames}.cache.usdc"
    cmd = [str(Path(sys.executable).with_name("simbake")), "bake", str(shot), "-o", str(out), "-q"]
    if clips:
        cmd += ["--clips", str(clips)]
    code = ("import json, resource, subprocess, sys, time; t = time.perf_counter(); "
            f"subprocess.run({cmd!r}, check=True, stdout=subprocess.DEVNULL); "
            "print(json.dumps({'wall_s': round(time.perf_counter() - t, 1), "
            "'peak_rss_mb': round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, 1)}))")
    line = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    result = json.loads(line.strip().splitlines()[-1])
    disk = out.stat().st_size + sum(p.stat().st_size for p in folder.glob(f"{out.stem}.clips/*"))
    clip_files = len(list(folder.glob(f"{out.stem}.clips/clip.*.usdc")))
    return {"bodies": BODIES, "frames": frames, "clips": clips, "clip_files": clip_files, **result,
            "bytes_on_disk": disk}


def main() -> None:
    args = sys.argv[1:]
    if args[:1] == ["--time"]:
        with tempfile.TemporaryDirectory() as tmp:
            print(run(int(args[1]), CLIPS, Path(tmp)))
        return
    lengths = [int(a) for a in args] or [1000, 10000]
    results = []
    for frames in lengths:
        with tempfile.TemporaryDirectory() as tmp:
            results.append(run(frames, CLIPS, Path(tmp)))
        print(results[-1], flush=True)
    (ROOT / "benchmarks" / "results" / "shot_clips_memory.json").write_text(json.dumps(results, indent=1) + "\n")
    lines = ["# Peak memory of a real USD-shot bake with --clips 1000 (benchmarks/usd/shot_clips_memory.py)", "",
             f"{BODIES} dynamic spheres (a generated UsdPhysics shot, zero gravity, no contacts), baked by "
             "`simbake bake SHOT.usda -o OUT.usdc --clips 1000` (simulation, QA, clip layers of overs); "
             "each run in its own process, peak RSS from getrusage(RUSAGE_CHILDREN). "
             f"Machine: 2 shared cores; {time.strftime('%Y-%m-%d', time.gmtime())}.", "",
             "| frames | clip files | wall (s) | peak RSS (MB) | on disk (MB) |", "| --- | --- | --- | --- | --- |"]
    for r in results:
        lines.append(f"| {r['frames']} | {r['clip_files']} | {r['wall_s']} | {r['peak_rss_mb']} | {r['bytes_on_disk'] / 1e6:.1f} |")
    (ROOT / "benchmarks" / "results" / "shot_clips_memory.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

"""The character shot's cost per frame by stage: skinning, level sets, the cloth's contacts
and the rest of its step, the QA, writing; and the cloth's collision against the deforming
body against the same body held rigid.

    .venv/bin/python benchmarks/cloth/character_cost.py [SHOT] [--frames A:B] [--json OUT.json]

SHOT defaults to assets/scenes/character.usda. One solver thread, in this process, in an
empty level-set cache (SIMBAKE_CACHE_DIR is pointed at a temporary folder), so that the
first bake bakes every frame's level set ("cold"); a second bake of the same frames reads
them from the cache ("warm"). Per stage:
- skinning: reading the deforming collider's surface at every frame of the shot
  (simbake.usd_deforming.read_deformation: UsdSkel's skinning), thread CPU time;
- level sets: the per-frame level sets, written beside the cache before the bake
  (simbake.simulate.deforming_level_set_files: baked cold, read from the cache warm) and
  handed to the core frame by frame (the profile's deforming_level_sets), thread CPU time;
- the core's stages: the profile's wall seconds (one thread; the machine is shared, so the
  load average is printed with them): cloth_contacts (against the body's level sets and
  moving triangles, and the ground), cloth_self_collision (which holds the body's moving
  triangles as obstacles), cloth_forces, cloth_strain, the rest;
- quality, usd_writer: the pipeline's profile (wall).

Held rigid: the same frames with the body replaced by a static Mesh collider at its pose at
the first frame; over the frames where the figure stands still (the shot's first
generate_character.STAND s) both bakes move the same cloth against the same surface, so the
ratio of their cloth contacts and self-collision per frame (at the same substeps) is the cost
of the surface being a deforming one.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CORE_STAGES = ("cloth_contacts", "cloth_self_collision", "cloth_forces", "cloth_strain")


class Timer:
    """Thread CPU time spent in wrapped functions, by name."""

    def __init__(self):
        self.spent: dict[str, float] = {}

    def wrap(self, module, name: str, label: str):
        original = getattr(module, name)

        def timed(*args, **kwargs):
            start = time.thread_time()
            try:
                return original(*args, **kwargs)
            finally:
                self.spent[label] = self.spent.get(label, 0.0) + time.thread_time() - start

        setattr(module, name, timed)
        return original


def bake(shot: Path, work: Path, start: int | None, end: int | None, name: str) -> dict:
    """One bake with one thread: its frames, cloth steps, profile and the wrapped times."""
    import simbake
    from simbake import simulate, usd_scene

    timer = Timer()
    originals = [(usd_scene, "read_deformation", timer.wrap(usd_scene, "read_deformation", "skinning")),
                 (simulate, "deforming_level_set_files",
                  timer.wrap(simulate, "deforming_level_set_files", "level_sets_written"))]
    try:
        cpu = time.thread_time()
        scene = simbake.load_scene(shot, start_frame=start, end_frame=end)
        stats = simbake.bake(scene, work / f"{name}.usdc", threads=1)
        cpu = time.thread_time() - cpu
    finally:
        for module, attr, original in originals:
            setattr(module, attr, original)
    frames = stats.frames
    return {"frames": frames, "substeps": int(stats.substeps), "main_thread_cpu_s": cpu,
            "profile_s": {k: float(v) for k, v in stats.profile.items()}, "wrapped_cpu_s": timer.spent,
            "warnings": list(stats.warnings)}


def rigid_variant(shot: Path, out: Path, frame: int) -> Path:
    """The shot with its skinned body replaced by a static Mesh collider at its pose at `frame`."""
    from pxr import Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

    from benchmarks.cloth.character_check import PosedSurface

    stage = Usd.Stage.Open(str(shot))
    root = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Root))
    body = next(p for p in Usd.PrimRange(root) if p.IsA(UsdGeom.Mesh) and p.HasAPI(UsdPhysics.CollisionAPI))
    points = PosedSurface(stage, str(body.GetPath())).points(frame)
    triangles = UsdGeom.Mesh(body).GetFaceVertexIndicesAttr().Get()
    rel = {}
    for prim in stage.Traverse():
        r = prim.GetRelationship("simbake:cloth:attachTo")
        if r and [str(t) for t in r.GetTargets()] == [str(body.GetPath())]:
            rel[prim.GetPath()] = r
    held = UsdGeom.Mesh.Define(stage, "/World/HeldBody")
    held.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    held.CreateFaceVertexCountsAttr(UsdGeom.Mesh(body).GetFaceVertexCountsAttr().Get())
    held.CreateFaceVertexIndicesAttr(triangles)
    UsdPhysics.CollisionAPI.Apply(held.GetPrim())
    for r in rel.values():
        r.SetTargets([held.GetPath()])
    stage.RemovePrim(root.GetPath())
    stage.GetRootLayer().Export(str(out))
    return out


def per_frame(run: dict) -> dict:
    """Seconds per frame of each stage (see the module's docstring)."""
    f = run["frames"]
    p, w = run["profile_s"], run["wrapped_cpu_s"]
    rest = p.get("cloths", 0.0) - sum(p.get(k, 0.0) for k in CORE_STAGES)
    return {"skinning": w.get("skinning", 0.0) / f,
            "level sets, written beside the cache": w.get("level_sets_written", 0.0) / f,
            "level sets, handed to the core": p.get("deforming_level_sets", 0.0) / f,
            **{k: p.get(k, 0.0) / f for k in CORE_STAGES},
            "rest of the cloth step": rest / f,
            "rigid stages and statistics": (sum(v for k, v in p.items() if k not in
                                                ("cloths", "quality", "usd_writer", "deforming_level_sets")
                                                and not k.startswith("cloth_"))) / f,
            "quality": p.get("quality", 0.0) / f, "usd_writer": p.get("usd_writer", 0.0) / f,
            "main thread CPU": run["main_thread_cpu_s"] / f}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("shot", nargs="?", default=str(ROOT / "assets" / "scenes" / "character.usda"))
    parser.add_argument("--frames", help="START:END (default: the shot's range)")
    parser.add_argument("--json", help="write the figures here")
    args = parser.parse_args()
    start, end = (int(x) for x in args.frames.split(":")) if args.frames else (None, None)
    import importlib.util

    spec = importlib.util.spec_from_file_location("generate_character", ROOT / "assets" / "scenes" / "generate_character.py")
    character = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(character)
    FPS, STAND, START = character.FPS, character.STAND, character.START

    shot = Path(args.shot).resolve()
    result = {"shot": str(shot), "frames": args.frames, "load_average": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        os.environ["SIMBAKE_CACHE_DIR"] = str(work / "levelsets")
        result["cold"] = bake(shot, work, start, end, "cold")
        result["warm"] = bake(shot, work, start, end, "warm")
        # held rigid against deforming, over the standing frames
        standing = (START, START + int(STAND * FPS))
        rigid = rigid_variant(shot, work / "held.usda", START)
        result["standing_deforming"] = bake(shot, work, *standing, "standing_deforming")
        result["standing_rigid"] = bake(rigid, work, *standing, "standing_rigid")
    result["load_average_after"] = os.getloadavg()
    rows = {name: per_frame(result[name]) for name in ("cold", "warm")}
    print(f"{shot.name}, frames {args.frames or 'all'}, one thread; load average {result['load_average'][0]:.1f}"
          f" -> {result['load_average_after'][0]:.1f}")
    print(f"{'stage (s per frame)':42s} {'cold':>9s} {'warm':>9s}")
    for key in rows["cold"]:
        print(f"{key:42s} {rows['cold'][key]:9.4f} {rows['warm'][key]:9.4f}")
    contact = {}
    for name in ("standing_deforming", "standing_rigid"):
        run = result[name]
        contact[name] = {k: run["profile_s"].get(k, 0.0) / run["frames"] for k in ("cloth_contacts", "cloth_self_collision")}
        contact[name]["substeps"] = run["substeps"]
    for k in ("cloth_contacts", "cloth_self_collision"):
        d, r = contact["standing_deforming"][k], contact["standing_rigid"][k]
        print(f"standing frames {standing[0]}:{standing[1]}, {k} per frame: deforming {1e3 * d:.1f} ms, "
              f"held rigid {1e3 * r:.1f} ms ({d / r if r else float('nan'):.2f}x); substeps "
              f"{contact['standing_deforming']['substeps']} and {contact['standing_rigid']['substeps']}")
    result["per_frame"] = rows
    result["standing_per_frame"] = contact
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

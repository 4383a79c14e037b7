"""What colliding with a deforming surface costs against the same surface held rigid (issue 34:
at most 2x): instructions counted by Valgrind's callgrind (deterministic, whatever else runs on
the machine), on one thread.

    .venv/bin/python benchmarks/cloth/deforming_cost.py [--frames 24] [--substeps 5]

The workloads are tests/data/shots/make_deforming.py's deforming sphere (the 25 x 25 sheet
dropped on a sphere that swells and sways, its points time-sampled), and the same shot with the
sphere's mesh held rigid at its first frame: still (a static collider), or moving along the
same sway (a kinematic body keyed at every frame); the same mesh and cloth, each at a fixed
number of substeps a frame (physxScene:timeStepsPerSecond), so all take the same cloth steps.
A still surface's resting contacts are held inside the cloth's implicit solve; a moving one's,
rigid or deforming, are the contact passes' (contact/cloth_body_contact.cpp says why).
Counted inside (callgrind --toggle-collect):

* cloth contacts: ClothBodyContact's stages (the level set queries, the blend of a deforming
  surface's two level sets, friction against its vertices' velocities);
* cloth step: the whole of step_cloth (forces, contacts, strain, self-collision, where the
  sphere's triangles are obstacles: still, or each vertex on its own line).

The per-frame level sets of the deforming surface are baked once beforehand (the level-set
cache is filled by a first run without Valgrind), so neither run counts them; the pipeline's
own time for them is the bake profile's deforming_level_sets. Prints a table and writes it to
benchmarks/results/deforming_cost.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHOTS = ROOT / "tests" / "data" / "shots"
STAGES = {"cloth contacts": "simbake::ClothBodyContact::*", "cloth step": "simbake::step_cloth*"}


def _generator():
    spec = importlib.util.spec_from_file_location("make_deforming", SHOTS / "make_deforming.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_shots(folder: Path, steps_per_second: float) -> dict[str, Path]:
    """The deforming sphere's shot; the same with the sphere held at its first frame (still);
    and the same with that first frame's mesh moving rigidly along the sphere's sway (a
    kinematic body keyed at every frame: moving, not deforming)."""
    import simbake  # noqa: F401  (registers SimbakeClothAPI before the stages are made)
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

    shots = _generator()
    paths = {}
    for name in ("deforming", "still", "moving"):
        path = shots.write_deforming_sphere(folder / f"{name}.usda")
        stage = Usd.Stage.Open(str(path))
        stage.GetPrimAtPath("/World/physicsScene").CreateAttribute(
            "physxScene:timeStepsPerSecond", Sdf.ValueTypeNames.Float).Set(steps_per_second)
        if name != "deforming":
            body = stage.GetPrimAtPath("/World/Body")
            points = UsdGeom.Mesh(body).GetPointsAttr()
            first = points.Get(shots.START)
            points.Clear()
            points.Set(first)
        if name == "moving":  # (the sway, about the first frame's centre)
            UsdPhysics.RigidBodyAPI.Apply(body).CreateKinematicEnabledAttr(True)
            translate = UsdGeom.Xformable(body).AddTranslateOp()
            start = shots.sphere_at(shots.START)[0]
            for frame in range(shots.START, shots.END + 1):
                translate.Set(Gf.Vec3d(*(shots.sphere_at(frame)[0] - start)), frame)
        stage.GetRootLayer().Save()
        paths[name] = path
    return paths


def count(shot: Path, frames: int, pattern: str, folder: Path) -> int:
    """Instructions inside the functions `pattern` names over the bake of frames 1..frames."""
    out = folder / f"{shot.stem}.callgrind"
    run = subprocess.run(["valgrind", "--tool=callgrind", f"--toggle-collect={pattern}", f"--callgrind-out-file={out}",
                          sys.executable, "-m", "simbake", "bake", str(shot), "-o", str(folder / f"{shot.stem}.usdc"),
                          "--frames", f"1:{frames}", "--threads", "1", "-q"],
                         capture_output=True, text=True, check=True)
    return int(re.search(r"Collected : (\d+)", run.stderr)[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--substeps", type=int, default=5, help="per frame (24 fps)")
    args = parser.parse_args()
    rows = ["| counted | still | moving rigidly | deforming | deforming / still | deforming / moving |",
            "| --- | --- | --- | --- | --- | --- |"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        os.environ["SIMBAKE_CACHE_DIR"] = str(folder / "levelsets")
        shots = write_shots(folder, 24.0 * args.substeps)
        for shot in shots.values():  # the level sets baked and cached, uncounted
            subprocess.run([sys.executable, "-m", "simbake", "bake", str(shot), "-o", str(folder / "warm.usdc"),
                            "--frames", f"1:{args.frames}", "--threads", "1", "-q"],
                           check=True, capture_output=True)
        for name, pattern in STAGES.items():
            n = {shot: count(path, args.frames, pattern, folder) for shot, path in shots.items()}
            rows.append(f"| {name} | {n['still']:,} | {n['moving']:,} | {n['deforming']:,} | "
                        f"{n['deforming'] / n['still']:.2f} | {n['deforming'] / n['moving']:.2f} |")
            print(rows[-1], flush=True)
    text = ("# A deforming collider against the same surface held rigid (callgrind instructions)\n\n"
            f"`python benchmarks/cloth/deforming_cost.py --frames {args.frames} --substeps {args.substeps}`: "
            f"tests/data/shots/deforming_sphere.usda, frames 1-{args.frames}, {args.substeps} substeps a frame, "
            "one thread\n\n" + "\n".join(rows) + "\n")
    (ROOT / "benchmarks" / "results" / "deforming_cost.md").write_text(text)


if __name__ == "__main__":
    main()

"""Same scene in, same cache out: bake every shipped scene and USD shot, and compare two sets
of caches by content (every spec, field and time sample, bit for bit).

    .venv/bin/python benchmarks/same_bits.py bake OUT_DIR [--threads N] [--only NAME ...]
    .venv/bin/python benchmarks/same_bits.py compare DIR_A DIR_B

`bake` writes OUT_DIR/<scene>.usdc for every `assets/scenes/*.toml` and `*.usda` (a shot's
cache layer of overs) with `--threads N` (default 1). `compare` opens each pair of caches with
Sdf and compares their layers: the spec paths, every field of every spec, and every time
sample (arrays by their bytes); the layer's customLayerData is compared except the
provenance (simbake's version, the scene's name and hash, the solver settings), which may
differ between builds. It exits 1 and prints the first difference of each cache that
differs. Byte-identical files are not required: `.usdc` files of the same content may be
laid out differently.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "assets" / "scenes"
PROVENANCE = ("version", "scene", "scene_sha256", "solver")


def scene_files(only: list[str] | None = None) -> list[Path]:
    files = sorted(SCENES.glob("*.toml")) + sorted(SCENES.glob("*.usda"))
    return [f for f in files if not only or f.stem in only]


def bake_all(out: Path, threads: int, only: list[str] | None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    simbake = Path(sys.executable).with_name("simbake")
    for scene in scene_files(only):
        start = time.perf_counter()
        subprocess.run([str(simbake), "bake", str(scene), "-o", str(out / f"{scene.stem}.usdc"), "-q",
                        "--threads", str(threads)], check=True, stdout=subprocess.DEVNULL)
        print(f"{scene.name}: {time.perf_counter() - start:.1f} s", flush=True)


def _plain(value):
    """A field or sample value as something == compares exactly (arrays by their bytes)."""
    if hasattr(value, "__len__") and type(value).__module__.startswith("pxr"):
        try:
            array = np.asarray(value)
            if array.dtype != object:
                return (array.dtype.str, array.shape, array.tobytes())
        except (TypeError, ValueError):
            pass
    return value


def _layer_data(layer) -> dict:
    data = dict(layer.customLayerData)
    simbake = dict(data.get("simbake", {}))
    for key in PROVENANCE:
        simbake.pop(key, None)
    data["simbake"] = simbake
    return data


def first_difference(path_a: Path, path_b: Path) -> str | None:
    from pxr import Sdf

    a, b = Sdf.Layer.FindOrOpen(str(path_a)), Sdf.Layer.FindOrOpen(str(path_b))
    if _layer_data(a) != _layer_data(b):
        return "customLayerData differs"
    for key in ("defaultPrim", "startTimeCode", "endTimeCode", "timeCodesPerSecond", "framesPerSecond",
                "subLayerPaths"):
        if _plain(a.pseudoRoot.GetInfo(key) if a.pseudoRoot.HasInfo(key) else None) != \
           _plain(b.pseudoRoot.GetInfo(key) if b.pseudoRoot.HasInfo(key) else None):
            return f"layer metadata {key} differs"
    paths_a, paths_b = [], []
    a.Traverse(Sdf.Path.absoluteRootPath, paths_a.append)
    b.Traverse(Sdf.Path.absoluteRootPath, paths_b.append)
    if sorted(map(str, paths_a)) != sorted(map(str, paths_b)):
        only = sorted(set(map(str, paths_a)) ^ set(map(str, paths_b)))
        return f"spec paths differ: {only[:5]}"
    for path in paths_a:
        if path == Sdf.Path.absoluteRootPath:
            continue
        spec_a, spec_b = a.GetObjectAtPath(path), b.GetObjectAtPath(path)
        if spec_a is None and spec_b is None:
            continue  # a relationship's target path (a Volume's field): no spec of its own
        keys = sorted(set(spec_a.ListInfoKeys()) | set(spec_b.ListInfoKeys()))
        for key in keys:
            if key == "timeSamples":
                continue
            if _plain(spec_a.GetInfo(key)) != _plain(spec_b.GetInfo(key)):
                return f"{path}: field {key} differs"
        if isinstance(spec_a, Sdf.AttributeSpec):
            times = a.ListTimeSamplesForPath(path)
            if list(times) != list(b.ListTimeSamplesForPath(path)):
                return f"{path}: time codes differ"
            for t in times:
                if _plain(a.QueryTimeSample(path, t)) != _plain(b.QueryTimeSample(path, t)):
                    return f"{path}: sample at {t} differs"
    return None


def compare(dir_a: Path, dir_b: Path) -> int:
    names = sorted(p.name for p in dir_a.glob("*.usd[ac]"))
    failed = 0
    for name in names:
        if not (dir_b / name).exists():
            print(f"{name}: missing from {dir_b}")
            failed += 1
            continue
        difference = first_difference(dir_a / name, dir_b / name)
        print(f"{name}: {'same' if difference is None else difference}")
        failed += difference is not None
    print(f"{len(names) - failed} of {len(names)} caches the same")
    return 1 if failed else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake")
    b.add_argument("out", type=Path)
    b.add_argument("--threads", type=int, default=1)
    b.add_argument("--only", nargs="*")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args()
    if args.command == "bake":
        bake_all(args.out, args.threads, args.only)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())

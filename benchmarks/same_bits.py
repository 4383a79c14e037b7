"""Same scene in, same cache out: bake every shipped scene and USD shot, and compare two sets
of caches by content (every spec, field and time sample, bit for bit).

    .venv/bin/python benchmarks/same_bits.py bake OUT_DIR [--threads N] [--only NAME ...]
    .venv/bin/python benchmarks/same_bits.py compare DIR_A DIR_B

`bake` writes OUT_DIR/<scene>.usdc for every `assets/scenes/*.toml` and `*.usda` (a shot's
cache layer of overs) with `--threads N` (default 1). `compare` compares each pair of caches
by content with simbake.cache_compare: the spec paths, every field of every spec, and every
time sample (arrays by their bytes); the layer's customLayerData is compared except the
provenance (simbake's version, the scene's name and hash, the solver settings), which may
differ between builds; and the QA sidecars beside them (every figure of every frame, the
summary and the warnings; not the wall times and the profile, which differ run to run). It
exits 1 and prints the first difference of each cache or sidecar that differs. Byte-identical files are not required: `.usdc` files of the same content may be
laid out differently.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from simbake.cache_compare import first_difference

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "assets" / "scenes"


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


def qa_difference(cache_a: Path, cache_b: Path) -> str | None:
    """The first difference between the QA sidecars of two caches (None: the same, or neither
    has one): figures frame by frame, per-cloth figures, summary, warnings."""
    sidecars = [cache.with_name(cache.stem + ".qa.json") for cache in (cache_a, cache_b)]
    if not any(s.exists() for s in sidecars):
        return None
    if not all(s.exists() for s in sidecars):
        return "QA sidecar missing on one side"
    a, b = (json.loads(s.read_text()) for s in sidecars)
    for key in ("frames", "figures", "cloths", "summary", "warnings"):
        x, y = a.get(key), b.get(key)
        if key == "figures":
            x, y = ({k: v for k, v in d.items() if k != "wall_seconds"} for d in (x, y))
        if key == "summary":
            x, y = ({k: v for k, v in d.items() if k != "wall_seconds"} for d in (x, y))
        if x != y:
            inner = next((k for k in sorted(set(x) | set(y)) if x.get(k) != y.get(k)), None) \
                if isinstance(x, dict) and isinstance(y, dict) else None
            return f"QA {key}{f'[{inner!r}]' if inner else ''} differs"
    return None


def compare(dir_a: Path, dir_b: Path) -> int:
    names = sorted(p.name for p in dir_a.glob("*.usd[ac]"))
    failed = 0
    for name in names:
        if not (dir_b / name).exists():
            print(f"{name}: missing from {dir_b}")
            failed += 1
            continue
        difference = first_difference(dir_a / name, dir_b / name) or qa_difference(dir_a / name, dir_b / name)
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

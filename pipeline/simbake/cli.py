"""The simbake command line.

    simbake bake SCENE.toml [-o OUT.usdc] [--quiet]   progress on stderr, summary at the end
    simbake bake SCENE [--frames START:END]           bake that range in place of the scene's own
    simbake bake SHOT.usda [-o CACHE.usdc] [--shot OUT.usda]   a USD shot: a cache layer of overs
    simbake demo [-o OUT.usdc] [--quiet]              bakes the shipped default scene
    simbake check OUT.usdc                            validates a cache
    simbake preview CACHE.usdc [-o OUT.png|.mp4|.gif] renders it headless (contact sheet or movie)
    simbake report CACHE.usdc [-o OUT.html|.png]      one page of its QA figures
    simbake levelset MESH -o OUT.vdb [--voxel-size H] bakes one mesh's level set
    simbake wedge SCENE --set KEY=V1,V2,... [--seeds N] [-o OUT.usda] [--scheduler tcp://HOST:PORT]
    simbake batch SCENE... [-o DIR] [--scheduler tcp://HOST:PORT]   many bakes on Dask (simbake.wedge_cli)

Bad input ends with one line on stderr naming the file, the key and the problem, exit
status 2, no traceback and no output file. A failed check exits with status 1. Signals,
output failures and the other exit statuses: simbake.guard.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .version import __version__
from .errors import SceneError, SimulationError
from .files import check_input_file, check_output_path



def demo_scene() -> Path:
    """assets/scenes/demo.toml of the checkout, or the copy installed beside the package."""
    here = Path(__file__).resolve().parent
    for root in (here.parents[1], here):
        candidate = root / "assets" / "scenes" / "demo.toml"
        if candidate.is_file():
            return candidate
    raise SceneError("demo.toml", "", "the shipped demo scene is missing from this installation")


def _progress(enabled: bool):
    """A tqdm bar on stderr when it is a terminal and not --quiet; else a no-op callback."""
    if not enabled or not sys.stderr.isatty():
        return None, lambda done, total: None
    from tqdm import tqdm

    bar = tqdm(total=None, unit="frame", file=sys.stderr, leave=False)

    def update(done: int, total: int) -> None:
        bar.total = total
        bar.update(done - bar.n)

    return bar, update


def _default_output(scene_path: str, scene) -> str:
    """SCENE.usdc here; a USD shot's cache SHOT.cache.usdc (never the shot itself)."""
    stem = Path(scene_path).stem
    return f"{stem}.cache.usdc" if scene.shot is not None else f"{stem}.usdc"


def _print_scene_warnings(scene) -> None:
    """What loading a USD shot left out (joints, ...), once per prim path."""
    for line in scene.warnings:
        print(f"simbake: warning: {line}", file=sys.stderr)


def _bake(scene_path: str, output: str | None, quiet: bool, preview: bool = False,
          shot: str | None = None, instancing: str = "auto", clips: int | None = None,
          threads: int = 0, frames: str | None = None) -> int:
    from .loading import load_scene

    start, end = parse_frames(scene_path, frames) if frames is not None else (None, None)
    scene = load_scene(scene_path, start_frame=start, end_frame=end)  # before the core loads
    _print_scene_warnings(scene)
    from .simulate import bake

    output = output or _default_output(scene_path, scene)
    bar, update = _progress(not quiet)
    try:
        stats = bake(scene, output, on_frame=update, instancing=instancing, clips=clips, threads=threads,
                     **({"shot": shot} if shot else {}))
    finally:
        if bar is not None:
            bar.close()
    print(f"baked {stats.summary()}")
    if preview:
        from .preview import write_preview
        from .report import write_report

        movie, _ = write_preview(stats.output)
        print(f"previewed -> {movie}")
        print(f"reported -> {write_report(stats.output)}")
    for line in stats.warnings:
        print(f"simbake: warning: {line}", file=sys.stderr)
    return 0


def parse_frames(scene_path: str, text: str) -> tuple[int, int]:
    """--frames START:END (inclusive, whole frame numbers, START <= END)."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, end = int(parts[0]), int(parts[1])
    except ValueError:
        raise SceneError(scene_path, "--frames", f"must be START:END, two whole frame numbers, got {text!r}") from None
    if end < start:
        raise SceneError(scene_path, "--frames", f"END must be >= START, got {text!r}")
    return start, end


def _check(path: str, strict: bool = False) -> int:
    from .check import check_cache

    problems = check_cache(path, strict=strict)
    for problem in problems:
        print(problem)
    if problems:
        print(f"{path}: {len(problems)} problem(s)", file=sys.stderr)
        return 1
    print(f"{path}: ok")
    return 0


def _levelset(mesh: str, output: str, voxel_size: float | None) -> int:
    from .assets import automatic_voxel_size, check_voxel_count, load_mesh, write_level_set

    out = Path(output)
    check_output_path(out, (".vdb",), inputs=[Path(mesh)])
    if voxel_size is not None and not (math.isfinite(voxel_size) and voxel_size > 0):
        raise SceneError(mesh, "--voxel-size", f"must be a finite number > 0, got {voxel_size}")
    check_input_file(Path(mesh), mesh, "mesh")
    from . import _core

    vertices, triangles = load_mesh(Path(mesh), mesh, "mesh")
    h = voxel_size or automatic_voxel_size(vertices)
    if not h > 0:
        raise SceneError(mesh, "mesh", "is flat (no extent along some axis): a level set needs an inside")
    key = "--voxel-size" if voxel_size else ""  # an automatic size is the mesh's, not the option's
    check_voxel_count(vertices, h, mesh, key)
    try:
        grid = _core.LevelSet.bake(vertices, triangles, h)
    except ValueError as error:
        raise SceneError(mesh, key, str(error)) from None
    write_level_set(grid, out, {"simbake:mesh": Path(mesh).name})
    print(f"baked {mesh}: voxel size {h:.6g} m, {grid.active_voxel_count} active voxels -> {out}")
    return 0


def _preview(cache: str, output: str | None, frames: str | None, camera: str, size: str | None,
             wedges: bool = False) -> int:
    from .preview import parse_size, write_preview

    if wedges:
        from .wedge_preview import write_wedge_sheet

        out, count = write_wedge_sheet(cache, output, frames=frames, size=parse_size(size) if size else None)
        print(f"previewed {count} take(s) of {cache} -> {out}")
        return 0

    out, count = write_preview(cache, output, frames=frames, camera=camera,
                               size=parse_size(size) if size else None)
    print(f"previewed {count} frame(s) of {cache} -> {out}")
    return 0


def _report(cache: str, output: str | None) -> int:
    from .report import write_report
    from .wedge_report import is_wedge, write_wedge_report

    if is_wedge(cache):
        print(f"reported {cache} -> {write_wedge_report(cache, output)}")
        return 0

    print(f"reported {cache} -> {write_report(cache, output)}")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simbake", description="Bake rigid bodies into USD caches.")
    p.add_argument("--version", action="version", version=f"simbake {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="simulate a scene file into a USD cache")
    b.add_argument("scene", help="scene file (.toml) or USD shot (.usd, .usda, .usdc)")
    b.add_argument("-o", "--output", help="output cache (.usdc default, .usda); default SCENE.usdc "
                                          "(a USD shot: SHOT.cache.usdc) here")
    b.add_argument("--shot", help="USD shot only: also write this stage, the cache sublayered over the input")
    b.add_argument("--instancing", choices=("auto", "always", "never"), default="auto",
                   help="TOML scenes: bodies sharing one shape as a PointInstancer: auto (from 100 bodies), always, never")
    b.add_argument("--clips", type=int, default=None, metavar="N",
                   help="write frames into value-clip layers of N frames each in OUT.clips/, stitched by OUT")
    b.add_argument("--threads", type=int, default=0, metavar="N",
                   help="worker threads of the solver (default 0: every CPU); the cache is the same at any count")
    b.add_argument("--frames", metavar="START:END",
                   help="bake these frames (inclusive), in place of the scene's or stage's own range; "
                        "the initial state is written at START")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    b.add_argument("--preview", action="store_true",
                   help="also write CACHE.mp4 (simbake preview) and CACHE.report.html (simbake report)")
    d = sub.add_parser("demo", help="bake the shipped default scene")
    d.add_argument("-o", "--output", default="demo.usdc", help="output cache (default demo.usdc)")
    d.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    c = sub.add_parser("check", help="validate a USD cache")
    c.add_argument("cache")
    c.add_argument("--strict", action="store_true",
                   help="a USD shot's cache: also every finding of OpenUSD's validators on the input")
    pv = sub.add_parser("preview", help="render a cache headless: a contact sheet (.png) or a movie (.mp4, .gif)")
    pv.add_argument("cache")
    pv.add_argument("-o", "--output", help="OUT.png (contact sheet), OUT.mp4 or OUT.gif (movie); default CACHE.mp4")
    pv.add_argument("--frames", help="A:B[:STEP] or A; default: every frame (movie), 8 evenly spaced (sheet)")
    pv.add_argument("--camera", default="auto", help="auto (frames the whole animation) or a Camera prim's path")
    pv.add_argument("--size", help="WxH of each frame; default 960x540 (movie), 480x270 (sheet)")
    pv.add_argument("--wedges", action="store_true",
                    help="a wedge stage (simbake wedge): a contact sheet (.png), one row per take")
    r = sub.add_parser("report", help="one page of a cache's QA figures, profile, settings and frames")
    r.add_argument("cache")
    r.add_argument("-o", "--output", help="REPORT.html (default CACHE.report.html) or REPORT.png")
    ls = sub.add_parser("levelset", help="bake a closed mesh into an OpenVDB level set")
    ls.add_argument("mesh")
    ls.add_argument("-o", "--output", required=True, help="output .vdb")
    ls.add_argument("--voxel-size", type=float, default=None, help="voxel size (m); default automatic")
    from .wedge_cli import add_parsers

    add_parsers(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    from .guard import run

    return run(lambda: _main(argv))


def _main(argv: list[str] | None) -> int:
    args = parser().parse_args(argv)
    try:
        if args.command == "bake":
            return _bake(args.scene, args.output, args.quiet, args.preview, args.shot, args.instancing, args.clips,
                         args.threads, args.frames)
        if args.command == "demo":
            return _bake(str(demo_scene()), args.output, args.quiet)
        if args.command == "check":
            return _check(args.cache, args.strict)
        if args.command == "report":
            return _report(args.cache, args.output)
        if args.command == "preview":
            return _preview(args.cache, args.output, args.frames, args.camera, args.size, args.wedges)
        if args.command in ("wedge", "batch"):
            from .wedge_cli import run

            return run(args)
        return _levelset(args.mesh, args.output, args.voxel_size)
    except SceneError as error:
        print(f"simbake: error: {error}", file=sys.stderr)
        return 2
    except SimulationError as error:
        print(f"simbake: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("simbake: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

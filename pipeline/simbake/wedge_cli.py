"""The command lines of wedges and batches (simbake.cli adds them):

    simbake wedge SCENE --set KEY=V1,V2,... [--set ...] [--seeds N] [-o OUT.usda]
                  [--scheduler tcp://HOST:PORT] [--workers N] [--threads N] [--retries N]
    simbake batch SCENE... [-o DIR] [--scheduler ...] [--workers N] [--threads N] [--retries N]

Each prints what it runs on (the Dask workers and the dashboard's address), one line per
take as it ends, and a summary. Exit status 0 when every take baked, 1 when any failed (the
others are written), 2 on bad input (nothing baked, nothing written).
"""

from __future__ import annotations

import argparse
import sys

from .errors import SceneError
from .farm import DEFAULT_RETRIES


def _farm_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="a Dask scheduler whose workers (dask worker) bake the takes; default: a local "
                        "cluster of worker processes on this machine")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per CPU)")
    p.add_argument("--threads", type=int, default=1, metavar="N",
                   help="solver threads of each bake (default 1: the takes run side by side)")
    p.add_argument("--retries", type=int, default=DEFAULT_RETRIES, metavar="N",
                   help=f"runs of a take after its worker died (local cluster; default {DEFAULT_RETRIES})")
    p.add_argument("-q", "--quiet", action="store_true", help="no line per take, only the summary")


def add_parsers(sub) -> None:
    w = sub.add_parser("wedge", help="bake every combination of scene values (and seeds) on Dask, "
                                     "gathered into one USD with a variant set")
    w.add_argument("scene", help="scene file (.toml) or USD shot (.usd, .usda, .usdc)")
    w.add_argument("--set", dest="sets", action="append", required=True, metavar="KEY=V1,V2,...",
                   help="a scene key path (bodies.ball.restitution, cloths.sheet.stretch_stiffness) or a "
                        "shot's attribute (/World/ball.physics:mass) and its values; repeat for more keys")
    w.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="seeds 0..N-1 of each combination (seed 0: the scene as set; others move dynamic "
                        "bodies and cloths by up to 1 mm and 0.5 degrees)")
    w.add_argument("-o", "--output", help="the wedge stage (.usda); takes in OUT.takes/ beside it; "
                                          "default SCENE.wedge.usda here")
    _farm_options(w)
    b = sub.add_parser("batch", help="bake many scenes on Dask, each as simbake bake would")
    b.add_argument("scenes", nargs="+", help="scene files (.toml) and USD shots")
    b.add_argument("-o", "--output-dir", default=".", help="folder of the caches (default here)")
    _farm_options(b)


def _printer(quiet: bool):
    def on_take(result, done: int, total: int) -> None:
        if not quiet:
            print(f"[{done}/{total}] {result.line()}", flush=True)

    def on_client(client) -> None:
        from .farm import describe_client

        print(f"running on {describe_client(client)}", flush=True)

    return on_take, on_client


def _sets(scene: str, texts: list[str]) -> dict:
    from .wedge_takes import parse_set

    variations: dict = {}
    for text in texts:
        key, values = parse_set(text, scene)
        if key in variations:
            raise SceneError(scene, f"--set {key}", "given twice; list every value in one --set KEY=V1,V2,...")
        variations[key] = values
    return variations


def _wedge(args) -> int:
    from .wedge_run import default_output, wedge

    on_take, on_client = _printer(args.quiet)
    results = wedge(args.scene, _sets(args.scene, args.sets), output=args.output, seeds=args.seeds,
                    threads=args.threads, workers=args.workers, scheduler=args.scheduler,
                    retries=args.retries, on_take=on_take, on_client=on_client)
    baked = [r for r in results if r.baked]
    failed = [r for r in results if not r.baked]
    for result in failed:
        print(f"simbake: error: {result.name} ({result.label}): {result.error}", file=sys.stderr)
    if not baked:
        print("simbake: no take baked; nothing written", file=sys.stderr)
        return 1
    output = args.output or default_output(args.scene)
    print(f"wedged {len(baked)} of {len(results)} take(s) -> {output} (variant set wedge, default "
          f"{baked[0].name}; caches in {baked[0].stage.parent})" + (f"; {len(failed)} failed" if failed else ""))
    return 1 if failed else 0


def _batch(args) -> int:
    from .wedge_run import batch

    on_take, on_client = _printer(args.quiet)
    results = batch(args.scenes, output_dir=args.output_dir, threads=args.threads, workers=args.workers,
                    scheduler=args.scheduler, retries=args.retries, on_take=on_take, on_client=on_client)
    failed = [r for r in results if not r.baked]
    for result in failed:
        print(f"simbake: error: {result.error}", file=sys.stderr)
    print(f"baked {len(results) - len(failed)} of {len(results)} scene(s) into {args.output_dir}"
          + (f"; {len(failed)} failed" if failed else ""))
    return 1 if failed else 0


def run(args) -> int:
    """simbake wedge / batch; SceneError (bad input) goes up to the CLI (exit 2)."""
    return _wedge(args) if args.command == "wedge" else _batch(args)

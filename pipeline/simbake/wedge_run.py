"""Wedges and batches: many bakes on Dask (simbake.farm), gathered where a lead finds them.

``wedge(scene, {"cloths.sheet.stretch_stiffness": [100, 1000]}, seeds=2, output="w.usda")``
bakes every take (simbake.wedge_takes) as its own task, each into ``w.takes/TAKE.usdc`` with
its QA sidecar (a USD shot's take also ``TAKE.over.usda``, its override layer, and
``TAKE.shot.usda``, the cache over it), and writes ``w.usda``, a variant set ``wedge`` with one
variant per baked take (simbake.wedge_stage). ``batch([a.toml, shot.usda], output_dir=d)``
bakes each scene as ``simbake bake`` would, into ``d/a.usdc`` and ``d/shot.cache.usdc``.

A bad value fails its take alone, with its one-line error; the other takes go on. Bad
input to the command itself (an unknown key or body, an unreadable scene, an output that
would replace a file simbake did not write) is refused before any bake (SceneError).

Files: the takes are baked into a hidden folder beside the output (``.w.takes.<pid>-<token>.tmp``),
each file written atomically (simbake.files); when every task has ended, the temp files of
any bake whose worker died are removed from it, it gets a manifest (``wedge.json``) and is
renamed to ``w.takes`` (an earlier ``w.takes`` written by simbake wedge is replaced whole;
any other folder of that name is refused), then ``w.usda`` is written. When no take bakes,
nothing is written. A batch writes its caches in place (as ``simbake bake``) and, at the end,
removes the temp files of its outputs that no live process owns.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from .errors import OutputError, SceneError, SimulationError
from .farm import DEFAULT_RETRIES, check_options, dask_client, run_tasks
from .files import check_output_path, is_stale_temp, is_temp, temp_path
from .loading import is_usd_scene
from .wedge_takes import Take, TakeResult, check_keys, perturbable, plan_takes, take_scene

WEDGE_SUFFIXES = (".usda", ".usdc", ".usd")
MANIFEST = "wedge.json"
MANIFEST_VERSION = 1

OnTake = Callable[[TakeResult, int, int], None]     # (result, done, total)
OnClient = Callable[[Any], None]                    # the Dask client, once connected


# --------------------------------------------------------------------------------------
# On the workers
# --------------------------------------------------------------------------------------

def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@contextlib.contextmanager
def _quiet():
    """A worker prints nothing of its own: trimesh's log lines and NumPy's warnings go."""
    from .guard import quiet_libraries

    quiet_libraries()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _figures(stats) -> dict:
    return {"frames": stats.frames, "wall_seconds": stats.wall_seconds,
            "max_penetration": stats.max_penetration, "warnings": len(stats.warnings)}


def _error_line(error: Exception, replace: dict[str, str]) -> str:
    text = (str(error).strip().splitlines() or [type(error).__name__])[0]
    for old, new in replace.items():
        text = text.replace(old, new)
    return text


def bake_take(scene_file: str, take: Take, folder: str, threads: int, types: Mapping[str, str]) -> TakeResult:
    """One take baked into `folder` (a Dask task): TAKE.usdc and its QA sidecar (a shot's
    take also TAKE.over.usda and TAKE.shot.usda). A bad value or a failed bake is the
    result's one-line error, naming the scene file (not the take's override layer)."""
    from .simulate import bake

    folder = Path(folder)
    result = TakeResult(name=take.name, label=take.label(), seed=take.seed, settings=dict(take.settings),
                        worker=_worker_name())
    cache = folder / f"{take.name}.usdc"
    shot = folder / f"{take.name}.shot.usda" if is_usd_scene(scene_file) else None
    try:
        with _quiet():
            scene = take_scene(scene_file, take, folder, types)
            stats = bake(scene, cache, threads=threads, **({"shot": shot} if shot else {}))
    except (SceneError, SimulationError, OutputError) as error:
        result.error = _error_line(error, {str(folder / f"{take.name}.over.usda"): scene_file})
        return result
    result.cache, result.qa, result.stage = cache, stats.qa, shot or cache
    result.stats, result.figures = stats, _figures(stats)
    return result


def bake_scene(scene_file: str, output: str, threads: int) -> TakeResult:
    """One scene of a batch baked to `output` (a Dask task), as `simbake bake` would."""
    from .loading import load_scene
    from .simulate import bake

    result = TakeResult(name=scene_file, label="", worker=_worker_name())
    try:
        with _quiet():
            stats = bake(load_scene(scene_file), output, threads=threads)
    except (SceneError, SimulationError, OutputError) as error:
        result.error = _error_line(error, {})
        return result
    result.cache = result.stage = Path(output)
    result.qa, result.stats, result.figures = stats.qa, stats, _figures(stats)
    return result


# --------------------------------------------------------------------------------------
# Running tasks and gathering results
# --------------------------------------------------------------------------------------

def _run(client, scheduler: str | None, workers: int | None, retries: int, function: Callable,
         tasks: Sequence[tuple[str, tuple]], blank: Mapping[str, TakeResult],
         on_take: OnTake | None, on_client: OnClient | None) -> dict[str, TakeResult]:
    """Run the tasks on `client` (or a client of our own); results by name. A task that
    raised, or whose workers kept dying, is its blank result with the error."""
    results: dict[str, TakeResult] = {}

    def done(name: str, result: TakeResult | None, error: str | None) -> None:
        if result is None:
            result = blank[name]
            result.error = error
        results[name] = result
        if on_take is not None:
            on_take(result, len(results), len(tasks))

    with contextlib.nullcontext(client) if client is not None else \
            dask_client(scheduler, workers, retries) as active:
        if on_client is not None:
            on_client(active)
        run_tasks(active, function, tasks, done)
    return results


def _check_threads(threads: int, file: str) -> None:
    from .simulate import MAX_THREADS

    if isinstance(threads, bool) or not isinstance(threads, int) or not 0 <= threads <= MAX_THREADS:
        raise SceneError(file, "--threads", f"must be a whole number in [0, {MAX_THREADS}], got {threads!r}")


# --------------------------------------------------------------------------------------
# The takes folder
# --------------------------------------------------------------------------------------

def _is_inside(path: Path, folder: Path) -> bool:
    path, folder = Path(os.path.realpath(path)), Path(os.path.realpath(folder))
    return folder in path.parents


def _check_takes_folder(final: Path, inputs: Sequence[Path]) -> None:
    """OUT.takes may be replaced only when simbake wedge wrote it, and holds no input."""
    if os.path.lexists(final) and not (final.is_dir() and (final / MANIFEST).is_file()):
        raise SceneError(final, "", "exists and was not written by simbake wedge (no wedge.json in it); "
                                    "move it away or give another output (-o)")
    for source in inputs:
        if _is_inside(source, final):
            raise SceneError(final, "", f"holds the input {source}, which the wedge would replace; "
                                        "give another output (-o)")


class Staging:
    """The hidden folder the takes are baked into, renamed to `final` when complete."""

    def __init__(self, final: Path):
        self.final = Path(final)
        self._remove_stale()
        self.path = temp_path(self.final, suffix="")
        self.path.mkdir()

    def _remove_stale(self) -> None:
        """Staging folders of this output left by wedges that were killed (pid gone)."""
        for entry in self.final.parent.iterdir():
            if is_stale_temp(entry.name, (self.final.name,)):
                shutil.rmtree(entry, ignore_errors=True)

    def sweep(self) -> list[str]:
        """Remove the temp files (and folders) of bakes whose worker died; every task has
        ended, so nothing is writing here. Returns their names."""
        removed = []
        for entry in self.path.iterdir():
            if is_temp(entry.name):
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
                removed.append(entry.name)
        return removed

    def publish(self, manifest: dict) -> None:
        """The manifest written, then the folder renamed into place (an earlier one replaced)."""
        (self.path / MANIFEST).write_text(json.dumps(manifest, indent=1, default=str) + "\n")
        old = None
        if os.path.lexists(self.final):
            old = temp_path(self.final, suffix="")
            os.replace(self.final, old)
        os.replace(self.path, self.final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def discard(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)

    def moved(self, path: Path | None) -> Path | None:
        """Where a file baked into the staging folder is once published."""
        return None if path is None else self.final / Path(path).name


def _manifest(scene_file: str, results: Sequence[TakeResult]) -> dict:
    return {"simbake_wedge": MANIFEST_VERSION, "scene": str(Path(scene_file).absolute()),
            "takes": [{"name": r.name, "label": r.label, "seed": r.seed, "settings": r.settings,
                       "error": r.error, "cache": r.cache.name if r.cache else None} for r in results]}


def _relocate(result: TakeResult, staging: Staging) -> None:
    result.cache, result.qa, result.stage = (staging.moved(result.cache), staging.moved(result.qa),
                                             staging.moved(result.stage))
    if result.stats is not None:
        result.stats.output, result.stats.qa = result.cache, result.qa


# --------------------------------------------------------------------------------------
# wedge and batch
# --------------------------------------------------------------------------------------

@dataclass
class WedgePlan:
    scene_file: str
    output: Path
    takes_dir: Path
    takes: list[Take]
    seeds: int
    types: dict                         # a shot's attribute types, by key


def _scene_file(scene) -> str:
    """A scene file's name as the user gave it (a Scene: the file it was loaded from)."""
    if hasattr(scene, "source") and hasattr(scene, "path"):
        return scene.source or str(scene.path)
    return os.fspath(scene)


def default_output(scene_file: str) -> Path:
    """SCENE.wedge.usda in the working directory."""
    return Path(f"{Path(scene_file).stem}.wedge.usda")


def plan_wedge(scene, variations: Mapping[str, Sequence[Any]], output=None, seeds: int = 1, threads: int = 1,
               workers: int | None = None, retries: int = DEFAULT_RETRIES, scheduler: str | None = None) -> WedgePlan:
    """Every check a wedge makes before baking (SceneError, exit 2): the scene, the keys, the
    takes, the outputs."""
    from .loading import load_scene

    scene_file = _scene_file(scene)
    base = load_scene(scene_file)
    if seeds != 1 and not perturbable(base):
        raise SceneError(scene_file, "--seeds", "the scene has no dynamic body or cloth for a seed to move")
    _check_threads(threads, scene_file)
    check_options(scene_file, workers, retries, scheduler)
    types = check_keys(scene_file, list(variations))
    takes = plan_takes(variations, seeds, scene_file)
    output = Path(output) if output is not None else default_output(scene_file)
    check_output_path(output, WEDGE_SUFFIXES, inputs=base.input_files())
    takes_dir = output.with_name(f"{output.stem}.takes")
    _check_takes_folder(takes_dir, base.input_files())
    return WedgePlan(scene_file, output, takes_dir, takes, seeds, types)


def wedge(scene, variations: Mapping[str, Sequence[Any]], client=None, *, output=None, seeds: int = 1,
          threads: int = 1, workers: int | None = None, scheduler: str | None = None,
          retries: int = DEFAULT_RETRIES, on_take: OnTake | None = None,
          on_client: OnClient | None = None) -> list[TakeResult]:
    """Bake every take of `variations` x `seeds` of `scene` (a scene file, or a Scene loaded
    from one) on Dask and gather them into `output` (default SCENE.wedge.usda here); returns
    the takes' results in order (`.stats`, the BakeStats, or `.error`). `client`: a Dask
    client to use (else a local cluster of `workers` processes, or the `scheduler`'s).
    `threads`: each bake's solver threads."""
    plan = plan_wedge(scene, variations, output, seeds, threads, workers, retries, scheduler)
    blank = {t.name: TakeResult(name=t.name, label=t.label(), seed=t.seed, settings=dict(t.settings))
             for t in plan.takes}
    staging = Staging(plan.takes_dir)
    try:
        tasks = [(t.name, (plan.scene_file, t, str(staging.path), threads, plan.types)) for t in plan.takes]
        by_name = _run(client, scheduler, workers, retries, bake_take, tasks, blank, on_take, on_client)
        results = [by_name[t.name] for t in plan.takes]
        staging.sweep()
        if not any(r.baked for r in results):
            staging.discard()
            return results
        staging.publish(_manifest(plan.scene_file, results))
    except BaseException:
        staging.discard()
        raise
    for result in results:
        _relocate(result, staging)
    from .wedge_stage import write_wedge_stage

    write_wedge_stage(plan.output, Path(plan.scene_file).name, [k for k in variations], plan.seeds, results)
    return results


def batch_output(scene_file: str, folder: Path) -> Path:
    """Where a batch writes a scene's cache: SCENE.usdc, a USD shot's SHOT.cache.usdc."""
    stem = Path(scene_file).stem
    return Path(folder) / (f"{stem}.cache.usdc" if is_usd_scene(scene_file) else f"{stem}.usdc")


def _check_batch(scene_files: Sequence[str], folder: Path) -> list[Path]:
    if not scene_files:
        raise SceneError("batch", "", "give one or more scene files")
    if not folder.is_dir():
        raise SceneError(folder, "", "is not a directory (-o names the folder the caches go into)")
    outputs = [batch_output(s, folder) for s in scene_files]
    inputs = [Path(s) for s in scene_files]
    for scene_file, out in zip(scene_files, outputs):
        if outputs.count(out) > 1:
            raise SceneError(scene_file, "", f"another scene of the batch also bakes to {out.name}; "
                                             "rename one or bake them in two batches")
        check_output_path(out, (".usdc",), inputs=inputs)
    return outputs


def _remove_batch_temps(outputs: Sequence[Path]) -> None:
    """Temps of the batch's outputs (cache, QA sidecar, level-set folder) whose process is gone."""
    from .qa import qa_path

    for out in outputs:
        names = {out.name, qa_path(out).name, f"{out.stem}.vdb"}
        for entry in out.parent.iterdir():
            if is_stale_temp(entry.name, names):
                shutil.rmtree(entry, ignore_errors=True) if entry.is_dir() else entry.unlink(missing_ok=True)


def batch(scenes: Sequence, client=None, *, output_dir=None, threads: int = 1, workers: int | None = None,
          scheduler: str | None = None, retries: int = DEFAULT_RETRIES, on_take: OnTake | None = None,
          on_client: OnClient | None = None) -> list[TakeResult]:
    """Bake each scene file on Dask into `output_dir` (default here) as `simbake bake` would
    (SCENE.usdc, a shot's SHOT.cache.usdc); a scene that fails fails alone. Returns the
    results in the scenes' order."""
    scene_files = [_scene_file(s) for s in scenes]
    folder = Path(output_dir) if output_dir is not None else Path(".")
    _check_threads(threads, "batch")
    check_options("batch", workers, retries, scheduler)
    outputs = _check_batch(scene_files, folder)
    names = [f"{i:03d}-{Path(s).stem}" for i, s in enumerate(scene_files)]
    blank = {n: TakeResult(name=s, label="") for n, s in zip(names, scene_files)}
    tasks = [(n, (s, str(o), threads)) for n, s, o in zip(names, scene_files, outputs)]
    try:
        by_name = _run(client, scheduler, workers, retries, bake_scene, tasks, blank, on_take, on_client)
    finally:
        _remove_batch_temps(outputs)
    return [by_name[n] for n in names]

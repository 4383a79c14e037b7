"""Running many bakes at once on Dask distributed: a local cluster by default, or a farm's.

Each bake is one Dask task; a worker runs one task at a time (one Dask thread per worker
process) and the bake uses its own solver thread count. Without a scheduler address a
``LocalCluster`` of worker processes is started on this machine (and closed at the end);
with ``tcp://HOST:PORT`` the tasks go to that scheduler, whose workers were started with
``dask worker`` (or by dask-jobqueue) and see the same files at the same paths.

A worker that dies during a task (killed, out of memory, its machine lost) makes the
scheduler run the task again elsewhere, at most ``retries`` more times (the scheduler's
``distributed.scheduler.allowed-failures``: set here for a local cluster; a farm's scheduler
has its own, 3 by default); past that the task ends with Dask's KilledWorker, reported as
that bake's failure. Tasks are handed to the scheduler only as workers have threads free
for them, since the scheduler counts every task a dead worker held, queued or running,
against its bound. A task raising an exception is not run again (a bake is deterministic:
it would fail the same way); bake functions report their expected failures as results.

Dask is imported here only, and only when a wedge or batch runs.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import time
import uuid
from typing import Any, Callable, Iterator, Sequence

from .errors import SceneError

DEFAULT_RETRIES = 2                 # runs of a task after its worker died, beyond the first
MAX_RETRIES = 100
MAX_WORKERS = 1024                  # processes of a local cluster
CONNECT_TIMEOUT = "20s"             # to reach a farm's scheduler
POLL_SECONDS = 0.02                 # between looks at the running tasks
INSTALL_HINT = "install the wedge extra: pip install 'simbake[wedge]' (make install does)"


def _distributed():
    try:
        import dask
        import distributed
    except ImportError:
        raise SceneError("dask", "", f"simbake wedge and batch run on Dask distributed; {INSTALL_HINT}") from None
    return dask, distributed


def check_options(file: str, workers: int | None, retries: int, scheduler: str | None = None) -> None:
    """--workers (None: one per CPU; a local cluster's alone) and --retries, before anything starts."""
    if scheduler is not None and workers is not None:
        raise SceneError(file, "--workers", "sets a local cluster's size; a farm's workers are started with "
                                            "`dask worker` (leave --workers out with --scheduler)")
    for key, value, lo, hi in (("--workers", workers, 1, MAX_WORKERS), ("--retries", retries, 0, MAX_RETRIES)):
        if value is None and key == "--workers":
            continue
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise SceneError(file, key, f"must be a whole number in [{lo}, {hi}], got {value!r}")


def default_workers() -> int:
    """Worker processes of a local cluster: one per CPU this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None,
                retries: int = DEFAULT_RETRIES) -> Iterator[Any]:
    """A Dask client: to the farm's `scheduler`, or to a new local cluster of `workers`
    processes (closed when the block ends, even on an error)."""
    dask, distributed = _distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as error:
            raise SceneError(scheduler, "--scheduler", f"cannot connect to the Dask scheduler: {error}") from None
        with contextlib.closing(client):
            yield client
        return
    workers = default_workers() if workers is None else workers
    with dask.config.set({"distributed.scheduler.allowed-failures": retries}):
        # the workers' own log lines stay out of the terminal (a bake's failure comes back as
        # its result; on a busy machine a worker closing logs its last missed heartbeat)
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0", silence_logs=logging.CRITICAL)
    try:
        with distributed.Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def describe_client(client) -> str:
    """'2 workers (2 threads), dashboard http://...': what the bakes run on."""
    info = client.scheduler_info()
    workers = info.get("workers", {})
    threads = sum(w.get("nthreads", 0) for w in workers.values())
    link = client.dashboard_link if info.get("services", {}).get("dashboard") else "none (install bokeh)"
    shared = any(w.get("nthreads", 1) > 1 for w in workers.values())
    return (f"{len(workers)} Dask worker(s) ({threads} thread(s)) at {client.scheduler.address}; dashboard {link}"
            + ("; some workers have several threads and bake side by side in one process: start them with "
               "`dask worker --nthreads 1`" if shared else ""))


def _outcome(future) -> tuple[Any, str | None]:
    """(result, None) of a finished task, or (None, its failure in one line)."""
    if future.status == "finished":
        return future.result(), None
    if future.status == "cancelled":
        return None, "cancelled before it ended (by the scheduler, or another client)"
    error = future.exception()
    if type(error).__name__ == "KilledWorker":
        return None, (f"its worker died {getattr(error, 'allowed_failures', 0) + 1} time(s) baking it "
                      "(killed or out of memory); not tried again")
    first = (str(error).strip().splitlines() or [""])[0]
    return None, f"internal error: {type(error).__name__}: {first}"


class _Capacity:
    """Tasks the cluster runs at once: its workers' threads (at least one), asked of the
    scheduler at most once a second (workers join and leave)."""

    def __init__(self, client):
        self.client, self.value, self.asked = client, 1, -math.inf

    def __call__(self) -> int:
        if time.monotonic() - self.asked > 1.0:
            self.value = max(1, sum(self.client.nthreads().values()))
            self.asked = time.monotonic()
        return self.value


def run_tasks(client, function: Callable, tasks: Sequence[tuple[str, tuple]],
              on_result: Callable[[str, Any, str | None], None]) -> None:
    """Run `function(*args)` for each (name, args) and call on_result(name, result, error) as
    each ends, in the order they end: `error` is a one-line description when the task raised
    or its workers kept dying, else None.

    No more tasks are given to the scheduler than the workers have threads (topped up as
    tasks end and workers join): a task waiting on a worker would be counted as a victim of
    that worker's death, and bounded retries would fail takes that never ran."""
    _, distributed = _distributed()
    token = uuid.uuid4().hex[:8]
    waiting, names, capacity = list(reversed(tasks)), {}, _Capacity(client)
    running = distributed.as_completed(loop=client.loop)
    try:
        while waiting or not running.is_empty():
            while waiting and running.count() < capacity():
                name, args = waiting.pop()
                future = client.submit(function, *args, key=f"simbake-{name}-{token}", pure=False, retries=0)
                names[future.key] = name
                running.add(future)
            ended = running.next_batch(block=False)
            for future in ended:
                on_result(names[future.key], *_outcome(future))
            if not ended:
                time.sleep(POLL_SECONDS)
    finally:
        client.cancel(list(running.futures))  # an interrupted run leaves nothing queued on a farm

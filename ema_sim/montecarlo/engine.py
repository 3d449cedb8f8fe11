"""The engine: a campaign's tasks on Dask distributed, a local cluster by default or any scheduler.

The runs ``0 … N−1`` are cut into tasks of ``batch`` runs (:func:`~ema_sim.montecarlo.runs.run_block`:
many model instances in one compiled call each). Without ``scheduler`` a :class:`distributed.LocalCluster`
is started with one single-threaded worker process per core (nothing to start by hand); with it, the
tasks go to that scheduler (``dask scheduler`` + ``dask worker`` processes, a dask-jobqueue or
Kubernetes cluster: anything that gives a ``tcp://host:port`` address). Each task's rows are written
as it finishes (:func:`~ema_sim.montecarlo.output.write_block`), so an interrupted campaign keeps what
it finished and ``resume`` submits only the rest. A run's values depend only on (seed, run index),
so the rows are the same on any cluster, in any order, with any batch.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ema_sim.errors import EmaError
from ema_sim.montecarlo import output
from ema_sim.montecarlo.campaign import Campaign
from ema_sim.montecarlo.runs import Block, run_block


@dataclass
class EngineResult:
    """What running the tasks gave.

    Parameters
    ----------
    tasks : int
        Tasks submitted this time.
    skipped : int
        Tasks already on disk (``resume``).
    wall_s : float
        From start to the last part written (cluster start included).
    compute_s : float
        From the first submission to the last part written.
    workers : list of str
        Addresses of the workers that ran this time's tasks.
    scheduler : str
        The scheduler's address.
    """

    tasks: int
    skipped: int
    wall_s: float
    compute_s: float
    workers: list[str] = field(default_factory=list)
    scheduler: str = ""


def cores() -> int:
    """The cores this process may run on.

    Returns
    -------
    int
        At least 1.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def blocks(runs: int, batch: int) -> list[tuple[int, int]]:
    """The tasks of a campaign: ``[start, stop)`` of ``batch`` runs (the last may be shorter).

    Parameters
    ----------
    runs : int
        Number of runs.
    batch : int
        Runs per task.

    Returns
    -------
    list of tuple
        The tasks in run order.
    """
    return [(s, min(s + batch, runs)) for s in range(0, runs, batch)]


def _client(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    from distributed import Client, LocalCluster  # noqa: PLC0415 - Dask (0.3 s of import) only when a campaign runs

    if not logging.getLogger().isEnabledFor(logging.INFO):  # distributed logs at INFO by its own config
        logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None  # type: ignore[no-untyped-call]
        except OSError as exc:
            raise EmaError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
    n = workers or cores()
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,  # type: ignore[no-untyped-call]
                           dashboard_address=":0", silence_logs=logging.ERROR)  # any free port
    return Client(cluster), cluster  # type: ignore[no-untyped-call]


def run_tasks(c: Campaign, out: Path, *, runs: int, seed: int, scheduler: str | None = None,
              workers: int | None = None, resume: bool = False,
              progress: Callable[[float], None] | None = None) -> EngineResult:
    """Run every task of the campaign not yet on disk and write each as it finishes.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory (:mod:`~ema_sim.montecarlo.output`).
    runs : int
        Number of runs.
    seed : int
        The seed.
    scheduler : str, optional
        A Dask scheduler's address (default: a local cluster).
    workers : int, optional
        Worker processes of the local cluster (default: one per core).
    resume : bool
        Complete the campaign ``out`` holds.
    progress : callable, optional
        Called with the fraction of runs done after each task.

    Returns
    -------
    EngineResult
        Tasks, times and workers.
    """
    t0 = time.perf_counter()
    if runs < 1:
        raise EmaError(f"--runs must be at least 1, got {runs}")
    if workers is not None and workers < 1:
        raise EmaError(f"--workers must be at least 1, got {workers}")
    output.write_manifest(out, c, seed, runs, resume=resume)
    todo_all = blocks(runs, c.batch)
    done = output.finished(out) if resume else set()
    todo = [b for b in todo_all if b[0] not in done]
    done_runs = sum(b[1] - b[0] for b in todo_all if b[0] in done)
    result = EngineResult(len(todo), len(todo_all) - len(todo), 0.0, 0.0)
    if not todo:
        result.wall_s = time.perf_counter() - t0
        return result
    from distributed import as_completed  # noqa: PLC0415 - Dask only on a cluster (see _client)

    client, cluster = _client(scheduler, workers)
    try:
        result.scheduler = str(client.scheduler.address)
        text = c.to_json()
        t1 = time.perf_counter()
        # a local cluster's workers fill the cores, so each runs its kernels on one thread (4.6-5.2 s of worker
        # time for 10,000 LOADA runs against 7.7 s with numba's thread per core in each); another scheduler's
        # workers keep numba's default
        threads = 1 if cluster is not None else None
        futures = [client.submit(run_block, text, seed, a, b, threads, pure=False,
                                 key=f"{c.name}-{seed}-{a:09d}-{b:09d}") for a, b in todo]
        seen: set[str] = set()
        for fut in as_completed(futures):  # type: ignore[no-untyped-call]
            block: Block = fut.result()
            output.write_block(out, block)
            seen.add(block.worker)
            done_runs += block.stop - block.start
            fut.release()
            if progress is not None:
                progress(done_runs / runs)
        result.compute_s = time.perf_counter() - t1
        result.workers = sorted(seen)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    result.wall_s = time.perf_counter() - t0
    return result

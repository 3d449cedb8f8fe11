"""Independent fits of one identification on Dask: candidate fits of a round, the physics' shifted starts.

A round of the effects search fits its few most promising candidates against the same current model
(:func:`ema_sim.identify.stepwise.search`), and HOAD3's physics fits two more starts from the same point
(:func:`ema_sim.identify.physical.fit_physical`); each fit is deterministic and independent of the others, so
they run at once on Dask workers and the search takes their results in its own order, the same result as
one after another. By default the workers are a :class:`distributed.LocalCluster` of
:data:`DEFAULT_WORKERS` threads in this process, started in the background when identification begins (in
half a second): the fits share the record, the runs it keeps and this process's BLAS, and their
simulations release the GIL, so while one fit solves or judges in Python another's kernels fill the
cores. Worker processes on two cores ran slower than one process (93.6 s against 85.9 s on the 30 s HOAD3
record): each held a copy of the record and its own kernel threads, and they contended for the cores.
``scheduler`` sends the fits to a running Dask scheduler instead (``ema identify --scheduler ADDRESS``),
whose workers load the kernels numba cached on disk (``cache=True``; ``python -m ema_sim.warmup`` compiles
them all) and run one tiny simulation when they join, before the first fit reaches them. Every fit runs with
one BLAS thread (:func:`one_blas_thread`), here and on any worker, so a fit is the same to the last bit
wherever it ran.

A record under :data:`MIN_SAMPLES` fitted samples is fitted in the calling process: its rounds are short.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, Protocol, overload

import numpy as np
from threadpoolctl import threadpool_limits

from ema_sim.errors import EmaError
from ema_sim.models.second_order import SecondOrder

DEFAULT_WORKERS = 2
"""Worker threads of the local cluster."""
MIN_SAMPLES = 40_000
"""Fitted residual entries (samples × outputs) below which the fits stay in the calling process: a 10 s
record of two outputs at 1 kHz (20,000) is fitted in a few seconds, in short fits the search mostly needs one
after another (a second worker thread gained nothing measurable even on a 90 s record)."""
ENV_WORKERS = "EMA_IDENTIFY_WORKERS"
"""Environment override of the local cluster's size (0: no cluster, every fit in the calling process)."""


BLAS_THREADS = 1
"""BLAS threads while a fit runs, wherever it runs (:func:`one_blas_thread`)."""


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with one BLAS thread: fits whose linear algebra is the same sums on every machine.

    The fits' matrices are a record long and a dozen parameters wide, too small for OpenBLAS's threads to pay:
    idle, they spin for the next call and take the cores from the simulator's threads. The escalated HOAD3 record (30 s
    at 1 kHz, ``loada`` declared, escalated) took 80.1 s and 151.7 CPU-s with OpenBLAS's default of one thread
    per core, and 52.0 s and 86.2 CPU-s with one. One thread also makes the result the same to the last bit
    whatever the machine's cores and on any Dask worker (which Dask starts with one BLAS thread).
    """
    with threadpool_limits(limits=BLAS_THREADS, user_api="blas"):
        yield


class TaskFuture(Protocol):
    """A fit submitted to the workers (a Dask future): its value, or cancelled when no longer needed."""

    def result(self) -> Any:
        """What the remote function returned, unpickled (its type is the function's: Dask does not carry it)."""

    def cancel(self) -> object:
        """Cancel the fit (its value is no longer needed)."""


class DaskClient(Protocol):
    """What the identification uses of a Dask ``distributed.Client``."""

    def submit(self, fn: Callable[..., object], /, *args: object, pure: bool = ...) -> TaskFuture:
        """Run ``fn(*args)`` on a worker.

        Parameters
        ----------
        fn : callable
            The function.
        *args : object
            Its arguments (scattered data stays on the workers).
        pure : bool
            Whether equal calls may share one result.
        """

    @overload
    def scatter(self, data: list[object], /, *, broadcast: bool = ...) -> list[object]: ...
    @overload
    def scatter(self, data: object, /, *, broadcast: bool = ...) -> object: ...
    def scatter(self, data: object, /, *, broadcast: bool = ...) -> object:
        """Send ``data`` to the workers once; the handle stands for it in later calls.

        Parameters
        ----------
        data : object
            The data (a list: one handle per item).
        broadcast : bool
            To every worker.
        """

    def run(self, fn: Callable[[], object], /) -> object:
        """Run ``fn()`` on every worker.

        Parameters
        ----------
        fn : callable
            The function.
        """

    def close(self) -> object:
        """Disconnect from the scheduler."""


class DaskCluster(Protocol):
    """What the identification uses of a Dask ``distributed.LocalCluster``: closing it."""

    def close(self) -> object:
        """Stop the cluster's scheduler and workers."""


def _warm() -> None:
    """Load the identification simulator's kernels from numba's cache in a worker process (one tiny batch)."""
    model = SecondOrder("left_wing", n=2)
    t = np.arange(0.0, 0.1, 0.001)
    model.run(t, np.where(t < 0.02, 0.0, 1.0), np.zeros_like(t))


class Pool:
    """Where a round's independent fits run: a Dask client (started in the background) or the calling process.

    Parameters
    ----------
    scheduler : str, optional
        A running Dask scheduler's address; without it a local cluster of ``workers`` threads.
    workers : int, optional
        Threads of the local cluster (default :data:`DEFAULT_WORKERS`, or :data:`ENV_WORKERS`); 0 or 1 fits
        in the calling process, one after another.
    """

    def __init__(self, scheduler: str | None = None, workers: int | None = None) -> None:
        if workers is None:
            workers = int(os.environ.get(ENV_WORKERS, DEFAULT_WORKERS))
        self.scheduler = scheduler or ""
        self.workers = workers
        self._client: DaskClient | None = None
        self._cluster: DaskCluster | None = None
        self._error: BaseException | None = None
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self.failed = ""
        """Why the local cluster could not be used (empty: it could, or none was asked for)."""

    @property
    def enabled(self) -> bool:
        """Whether fits go to Dask (a scheduler given, or a local cluster of at least two workers)."""
        return bool(self.scheduler) or self.workers >= 2

    def start(self) -> None:
        """Start the cluster (or connect to the scheduler) in the background; :meth:`client` waits for it."""
        if not self.enabled or self._thread is not None:
            return
        self._thread = threading.Thread(target=self._connect, name="ema-identify-dask", daemon=True)
        self._thread.start()

    def _connect(self) -> None:
        try:
            from distributed import Client, LocalCluster  # noqa: PLC0415 - only when fits go to Dask

            if not logging.getLogger().isEnabledFor(logging.INFO):
                logging.getLogger("distributed").setLevel(logging.ERROR)
            if self.scheduler:
                try:
                    # waits up to Dask's connect timeout (distributed.comm.timeouts.connect, 30 s by default)
                    client: DaskClient = Client(self.scheduler)  # type: ignore[no-untyped-call]
                except OSError as exc:
                    raise EmaError(f"cannot reach the Dask scheduler at {self.scheduler}: {exc}") from None
            else:
                self._cluster = LocalCluster(  # type: ignore[no-untyped-call]
                    n_workers=1, threads_per_worker=self.workers, processes=False, dashboard_address=":0",
                    silence_logs=logging.ERROR)
                self._client = Client(self._cluster)  # type: ignore[no-untyped-call]
                return
            self._client = client
            client.run(_warm)
        except Exception as exc:  # reported to the caller that waits for the client
            self._error = exc
        finally:
            self._ready.set()

    def client(self) -> DaskClient | None:
        """The Dask client once it is up (None when fits stay in the calling process).

        A local cluster that cannot start leaves every fit in the calling process (:attr:`failed` says why).

        Raises
        ------
        EmaError
            The scheduler given could not be reached.
        """
        if not self.enabled:
            return None
        self.start()
        self._ready.wait()
        if self._error is not None:
            if self.scheduler:
                raise self._error if isinstance(self._error, EmaError) else EmaError(
                    f"cannot use the Dask scheduler at {self.scheduler}: {self._error}")
            self.failed = f"the local Dask cluster did not start ({self._error}): every fit ran in this process"
            self.workers = 0  # the same result, one fit after another
            return None
        return self._client

    def submit(self, fn: Callable[..., object], *args: object) -> TaskFuture | object:
        """``fn(*args)`` on a worker (a Dask future), or its result computed here when fits stay here.

        Parameters
        ----------
        fn : callable
            A module-level function (pickled by reference).
        *args : object
            Its arguments (pickled).

        Returns
        -------
        object
            A future whose ``result()`` is the value, or the value itself.
        """
        client = self.client()
        if client is None:
            return fn(*args)
        return client.submit(fn, *args, pure=False)

    def close(self) -> None:
        """Close the client and the local cluster (a scheduler given is left running)."""
        if self._thread is not None:
            self._ready.wait()
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None


def result(value: object) -> Any:
    """The value of what :meth:`Pool.submit` returned (a future's result, or the value itself).

    Parameters
    ----------
    value : object
        A Dask future or a value.

    Returns
    -------
    object
        The value.
    """
    done = getattr(value, "result", None)
    return done() if callable(done) else value


SERIAL = Pool(workers=0)
"""Every fit in the calling process."""

"""A round's candidate fits on Dask workers (:mod:`ema_sim.identify.parallel`): the same result as one by one.

The workers are the default local cluster's two threads in this process, sharing its record and kept runs, or a
real two-process :class:`distributed.LocalCluster` given as a scheduler (their own numba kernels, loaded from the
disk cache, and OpenBLAS started with two threads, which every fit brings down to one:
:func:`ema_sim.identify.parallel.one_blas_thread`), on a short record whose search fits several candidates a
round; every added effect, verdict, final parameter, the residual and the count of simulations must be those of
the fits made one after another in this process, to the last bit. They take minutes on the shared two-core
machine, so they are marked slow; the tests after them are their fast siblings.
"""

from __future__ import annotations

from dataclasses import astuple
from pathlib import Path

import dask
import numpy as np
import pytest
from distributed import LocalCluster
from identgen import make_record

from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify import identification
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.parallel import Pool, one_blas_thread
from ema_sim.identify.record import prepare
from ema_sim.io.csv import write_csv

WING = load_channel("left_wing")


@pytest.mark.slow
@pytest.mark.parametrize("where", ["threads", "processes"])
def test_candidate_fits_on_workers_give_the_serial_result(monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    data = make_record({"time_delay": 0.006, "compliance": 0.3, "lag_filter/feedback": 25.0}, seed=21,
                       duration_s=6.0)
    serial = identify(prepare(data, WING), search=Search(max_effects=2, discover_terms=False))
    monkeypatch.setattr(identification, "MIN_SAMPLES", 0)  # a short record on the cluster all the same
    if where == "threads":
        spread = identify(prepare(data, WING), search=Search(max_effects=2, discover_terms=False, workers=2))
    else:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": {
                **dask.config.get("distributed.nanny.pre-spawn-environ"), "OPENBLAS_NUM_THREADS": "2"}}):
            cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
        with cluster:
            spread = identify(prepare(data, WING), search=Search(max_effects=2, discover_terms=False,
                                                                    scheduler=cluster.scheduler_address))
    assert [v.reason for v in serial.verdicts] == [v.reason for v in spread.verdicts]
    assert len(serial.verdicts) >= 4  # rounds of several candidates: fits that ran at once
    assert [(s.effect, s.where) for s in serial.steps] == [(s.effect, s.where) for s in spread.steps]
    assert astuple(spread.final.params) == astuple(serial.final.params)
    assert np.array_equal(spread.final.residual, serial.final.residual)
    assert serial.problem.simulations == spread.problem.simulations


def test_unreachable_scheduler_is_one_clear_error(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    data = make_record({}, seed=2, duration_s=2.0)
    path = tmp_path / "rec.csv"
    write_csv(path, {"time_s": data.time_s, "command_deg": data.command_deg, "position_deg": data.position_deg,
                     "hinge_moment_inlb": data.hinge_moment_inlb}, {"channel": "left_wing"})
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):  # the user's setting, not 30 s
        code = main(["identify", str(path), "--scheduler", "tcp://127.0.0.1:9", "-q"])
    assert code == 2
    err = capsys.readouterr().err
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err
    assert len(err.strip().splitlines()) == 1


def test_serial_pool_runs_here() -> None:
    pool = Pool(workers=1)
    assert not pool.enabled
    assert pool.client() is None
    assert pool.submit(sum, [1, 2]) == 3



def test_a_fit_runs_with_one_blas_thread_and_the_callers_count_comes_back() -> None:
    from threadpoolctl import threadpool_info  # noqa: PLC0415 - only this test reads the pools

    def blas_threads() -> set[int]:
        return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}

    before = blas_threads()
    with one_blas_thread():
        assert blas_threads() == {1}
    assert blas_threads() == before


def test_a_round_sends_to_its_workers_only_the_fits_the_early_stop_would_not_skip() -> None:
    from ema_sim.identify.effects import BY_KEY  # noqa: PLC0415 - the vocabulary, for candidates
    from ema_sim.identify.screening import Candidate  # noqa: PLC0415
    from ema_sim.identify.stepwise import STOP_FACTOR, likely_needed  # noqa: PLC0415

    keys = list(BY_KEY)[:4]

    def cands(*drops: float) -> list[Candidate]:
        return [Candidate(BY_KEY[k], {}, False, d, 0.0) for k, d in zip(keys, drops, strict=False)]

    # the 90 s record's third round: free play 5.0e7, non-linear compliance 3.4e7, the feedback filter 1.4e4
    assert [c.predicted_drop for c in likely_needed(cands(5.0e7, 3.4e7, 1.4e4))] == [5.0e7, 3.4e7]
    # the first round's: a larger drop later in the ranking does not stop the ones before it
    assert len(likely_needed(cands(1.08e8, 1.02e8, 1.1e9))) == 3
    edge = cands(STOP_FACTOR * 10.0, 10.0)
    assert len(likely_needed(edge)) == 2  # exactly the factor: the search would still fit it
    assert len(likely_needed(cands(STOP_FACTOR * 10.0 + 1e-6, 10.0))) == 1
    assert likely_needed([]) == []

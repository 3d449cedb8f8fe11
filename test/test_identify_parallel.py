"""A round's candidate fits on Dask workers (:mod:`ema_sim.identify.parallel`): the same result as one by one.

The workers are a real two-process :class:`distributed.LocalCluster` (their own numba kernels, loaded from the
disk cache, and this process's BLAS thread count: :func:`ema_sim.identify.parallel.blas_environ`), on a short
record whose search fits several candidates a round; every added effect, verdict, final parameter and the
residual must be those of the fits made one after another in this process, to the last bit. It takes minutes
on the shared two-core machine, so it is marked slow; the two tests after it are its fast siblings.
"""

from __future__ import annotations

from dataclasses import astuple
from pathlib import Path

import dask
import numpy as np
import pytest
from identgen import make_record

from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify import identification
from ema_sim.identify.identification import identify
from ema_sim.identify.parallel import Pool
from ema_sim.io.csv import write_csv

WING = load_channel("left_wing")


@pytest.mark.slow
def test_candidate_fits_on_workers_give_the_serial_result(monkeypatch: pytest.MonkeyPatch) -> None:
    data = make_record({"time_delay": 0.006, "compliance": 0.3, "lag_filter/feedback": 25.0}, seed=21,
                       duration_s=6.0)
    serial = identify(data, WING, max_effects=2, discover_terms=False)
    monkeypatch.setattr(identification, "MIN_SAMPLES", 0)  # a short record on the cluster all the same
    spread = identify(data, WING, max_effects=2, discover_terms=False, workers=2)
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

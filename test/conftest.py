"""Shared fixtures: small input records on the 200 Hz frame grid."""

from __future__ import annotations

import numpy as np
import pytest

FRAME_S = 0.005


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A module whose tests start processes runs in one pytest-xdist worker, its tests one after another.

    ``make test`` runs the suite on two workers (``--dist loadgroup``): other tests go to whichever worker
    is free. The ROS tests measure frame rates, drops and latencies of real processes, so two of one
    module never run against each other; the Monte Carlo tests share their module's real Dask cluster.
    """
    for item in items:
        if item.get_closest_marker("ros") is not None or item.module.__name__.endswith("test_montecarlo"):
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))


def frames(duration_s: float) -> np.ndarray:
    """Frame instants over ``duration_s``."""
    return np.arange(round(duration_s / FRAME_S)) * FRAME_S


@pytest.fixture
def rich_inputs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steps (one rate-limited), a 3 Hz sine and a reversing load: exercises every stage."""
    t = frames(6.0)
    cmd = np.where(t < 0.5, 0.0, np.where(t < 1.5, 1.0, np.where(t < 3.0, 21.0, 0.0)))
    cmd = cmd + np.where(t >= 4.0, 0.8 * np.sin(2 * np.pi * 3.0 * (t - 4.0)), 0.0)
    hm = 300.0 * np.sign(np.sin(2 * np.pi * 0.4 * t + 0.3))
    return t, cmd, hm

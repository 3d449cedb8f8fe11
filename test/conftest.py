"""Shared fixtures: small input records on the 200 Hz frame grid."""

from __future__ import annotations

import os

import numpy as np
import pytest

from ema_sim.io.contract import STRICT_ENV
from ema_sim.suite import DOMAIN_RANGE_ENV

FRAME_S = 0.005

os.environ[STRICT_ENV] = "1"

if os.environ.get("PYTEST_XDIST_WORKER"):
    _worker = int(os.environ["PYTEST_XDIST_WORKER"].removeprefix("gw"))
    _span = 100 // max(int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")), 1)
    os.environ[DOMAIN_RANGE_ENV] = f"{1 + _worker * _span}-{(_worker + 1) * _span}"
    """Each pytest-xdist worker picks its ROS domains from a range of its own: two workers' nodes never meet."""
"""Every report a test builds (in this process or in a command it starts) is checked against its published
schema, and a mismatch fails the test (``ema_sim.io.contract.check``)."""


SHARED_FIXTURES = {"test_montecarlo": "scheduler", "test_identify_rig": "rig"}
"""Module → its expensive module fixture (a real Dask cluster; the rig records identified through the CLI): the
tests that use it run in one worker, so it is built once; the module's other tests go to whichever worker is free."""


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which reads the groups into the test ids
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A module's tests that start processes run in one pytest-xdist worker, one after another.

    ``make test`` runs the suite on two workers (``--dist loadgroup``): other tests go to whichever worker
    is free. The ROS tests measure frame rates, drops and latencies of real processes, so two of one
    module never run against each other; the tests that share a module's :data:`SHARED_FIXTURES` (the Monte
    Carlo tests' real Dask cluster, the rig records identified once) run where it was built.
    """
    for item in items:
        module = item.module.__name__.rpartition(".")[2]
        shared = SHARED_FIXTURES.get(module)
        if item.get_closest_marker("ros") is not None or (shared is not None and shared in item.fixturenames):
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

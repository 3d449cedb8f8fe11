"""Figure 26's stage 14, the feedback delay: a ring of the LVDT's past readings, written as the model steps.

A delay from motion to reading (HOAD3's 2 ms) needs the reading of ``t − delay`` at any ``t``: each instance keeps
its readings with their times and rates in a ring of :data:`HISTORY_SIZE` entries spaced so that the delay spans
at most half of it, and reads back by interpolating on the rate (:func:`history_read`).
"""

from __future__ import annotations

from ema_sim.models.arrays import FloatArray
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import TIME_EPS_S, jit

HISTORY_SIZE = 1024
"""Entries of stage 14's history ring: the delay spans at most half of them (:func:`history_spacing_s`)."""
NEVER_S = -1e30
"""The time of the history entries trim writes: the held state, forever before the record."""


@jit
def history_spacing_s(p: FloatArray) -> float:
    """Closest spacing of stage 14's history entries: the delay then spans at most half the ring.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    float
        Seconds.
    """
    return float(2.0 * p[P.feedback_delay_s] / HISTORY_SIZE)


@jit
def history_write(p: FloatArray, y: FloatArray, hist: FloatArray, t: float, value: float, rate: float,
                  force: bool) -> None:
    """Stage 14: record the reading at ``t`` (at most every :func:`history_spacing_s`, unless ``force``).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State (its history head and last time advance).
    hist : numpy.ndarray
        The instance's ring ``(entries, 3)``: time, reading, rate.
    t : float
        Now (s).
    value : float
        The reading (deg).
    rate : float
        Its rate (°/s).
    force : bool
        Record even closer than the spacing (an instant a delayed sample will ask for).
    """
    if p[P.feedback_delay_s] <= 0.0:
        return
    if t <= y[X.history_last_s] + TIME_EPS_S:
        j = int(y[X.history_head])
    elif force or t >= y[X.history_last_s] + history_spacing_s(p):
        j = int(y[X.history_head]) + 1
        if j >= hist.shape[0]:
            j = 0
    else:
        return
    hist[j, 0] = t
    hist[j, 1] = value
    hist[j, 2] = rate
    y[X.history_head] = j
    y[X.history_last_s] = t


@jit
def history_read(y: FloatArray, hist: FloatArray, t: float) -> float:
    """Stage 14: the reading at ``t`` (in the past), cubic Hermite between the recorded entries.

    Parameters
    ----------
    y : numpy.ndarray
        State (its history head).
    hist : numpy.ndarray
        The instance's ring.
    t : float
        The instant asked for (s).

    Returns
    -------
    float
        The reading then (deg); the oldest entry's before the ring's start.
    """
    size = hist.shape[0]
    j = int(y[X.history_head])
    newer = -1
    for _ in range(size):
        if hist[j, 0] <= t + TIME_EPS_S:
            break
        newer = j
        j = j - 1 if j > 0 else size - 1
    else:
        return float(hist[newer, 1])
    t0, t1 = hist[j, 0], hist[newer, 0] if newer >= 0 else hist[j, 0]
    if newer < 0 or abs(t - t0) <= TIME_EPS_S or t1 - t0 <= TIME_EPS_S:
        return float(hist[j, 1])
    h = t1 - t0
    s = (t - t0) / h
    s2 = s * s
    s3 = s2 * s
    return float((2.0 * s3 - 3.0 * s2 + 1.0) * hist[j, 1] + (s3 - 2.0 * s2 + s) * h * hist[j, 2]
                 + (-2.0 * s3 + 3.0 * s2) * hist[newer, 1] + (s3 - s2) * h * hist[newer, 2])

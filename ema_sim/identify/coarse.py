"""A coarse copy of a record for screening an escalation: its outputs decimated, its model run at half rate.

An escalation to HOAD3's physics (:mod:`ema_sim.identify.physical`) that cannot pay should cost little. Its
screen runs the physics on a coarse copy of the record: every :func:`decimation`-th sample of the outputs is
compared (:data:`DECIMATED_HZ`: still four samples a cycle of HOAD3's 29.5 Hz linkage mode) and the model is
integrated at :data:`COARSE_RATE_HZ` instead of HOAD3's own 10 kHz, while the inputs keep every breakpoint of
the record (a step lands at its own instant, so the delays mean the same). A run costs a third to a half of
a fine one (0.0054–0.0089 s against 0.0196–0.0202 s on 30 s at 1 kHz, measured on a loaded two-core machine).

The coarse model's own discretization raises its error a little (on a 30 s HOAD3 record at the fitted
parameters: 1.78 against 0.78 per weighted sample at 10 kHz), which is far below what a screen decides on;
the decision whether the physics can pay is taken on the fine model's error at the coarse fit's end.

Why not fit on segments of the record (the excitation's steps and reversals, the model trimmed at each)?
HOAD3 remembers: the dead band and friction hold the actuator where it stopped, the integral and figure 33's
hysteresis hold their state, so a segment started from a trim leaves 0.01–0.02° on a surface whose floor is
0.001° (measured: 200–470 per weighted sample on six segments, at parameters that leave 0.78 on the whole
record run from its start). Only a run from the record's start knows that state.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

import numpy as np

from ema_sim.identify.problem import Problem
from ema_sim.io.measured import MeasuredData
from ema_sim.models.arrays import FloatArray

DECIMATED_HZ = 250.0
"""Output samples a second the coarse copy compares."""
COARSE_RATE_HZ = 5000.0
"""Integration rate of the coarse runs (HOAD2/HOAD3 run at 10 kHz)."""


def decimation(problem: Problem) -> int:
    """How many samples the coarse copy takes one of (1 for a record at or below :data:`DECIMATED_HZ`).

    Parameters
    ----------
    problem : Problem
        The record.
    """
    return max(1, round(problem.sample_hz / DECIMATED_HZ))


def _every(data: MeasuredData, every: int) -> MeasuredData:
    """Every ``every``-th sample of a record (every per-sample column)."""
    changes: dict[str, Any] = {}
    for f in fields(data):
        value = getattr(data, f.name)
        if isinstance(value, np.ndarray) and value.shape[:1] == data.time_s.shape:
            changes[f.name] = value[::every]
    changes["extra"] = {k: v[::every] for k, v in data.extra.items()}
    return replace(data, **changes)


def coarse_problem(problem: Problem) -> Problem | None:
    """The record's coarse copy: every :func:`decimation`-th sample, driven by the record's own inputs.

    Parameters
    ----------
    problem : Problem
        The whole record.

    Returns
    -------
    Problem or None
        The copy (its noise floors, fitted span, command timing, sensor range and stamps the record's); None
        when decimating saves nothing or the record's residual has terms projected out (discovery's).
    """
    every = decimation(problem)
    if every <= 1 or problem.projections or problem.weights:
        return None
    sub = Problem(_every(problem.data, every), problem.channel, step_s=problem.step_s, settle_s=problem.settle_s,
                  noise=problem.noise, command_sampled=problem.command_sampled,
                  output_range=dict(problem.output_range))
    sub.settle_s = problem.settle_s  # the record's own fitted span, not one measured again on the copy
    sub.mask = sub.time_s >= problem.settle_s
    sub.drive_like(problem)
    if problem.timing_s > 0.0:
        sub.set_timing(problem.timing_s, {o: r[::every] for o, r in problem.timing_rates.items()})
    return sub


def on_coarse(problem: Problem, coarse: Problem, residual: FloatArray) -> FloatArray:
    """A weighted residual of the whole record on the coarse copy's samples (output after output, as it stacks).

    Parameters
    ----------
    problem : Problem
        The whole record.
    coarse : Problem
        Its coarse copy (:func:`coarse_problem`).
    residual : numpy.ndarray
        The record's weighted residual (:meth:`Problem.weighted_residual`).

    Returns
    -------
    numpy.ndarray
        Its entries on the coarse copy's fitted samples.
    """
    fitted = np.flatnonzero(problem.mask)
    every = decimation(problem)
    idx = np.flatnonzero(coarse.mask) * every
    pos = np.searchsorted(fitted, idx)
    ok = (pos < fitted.size) & (fitted[np.minimum(pos, fitted.size - 1)] == idx)
    blocks = residual.reshape(len(problem.outputs), fitted.size)
    return np.asarray(blocks[:, pos[ok]].ravel(), dtype=float)

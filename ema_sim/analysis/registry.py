"""Every section-2 test of ``ema analyze``, in report order, and the readers the recogniser asks.

The pipeline runs :data:`TESTS` in this order (a later test may use an earlier one's results: the
crosstalk threshold comes from a static threshold, free play takes out a measured compliance, a
sweep's slew check uses rate-limited steps); the report writes them in the same order. The reader
tuples are the recogniser's questions for each shape of stretch, most specific first; the last one
of the edge and moving tuples always answers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ema_sim.analysis.section2 import (
    calibration_fit,
    compliance,
    crosstalk,
    cycles,
    dither,
    free_play,
    frequency_response,
    hysteresis,
    moves,
    regeneration,
    sine_dwell,
    steps,
    threshold,
    timing,
)
from ema_sim.analysis.section2.base import Section2Test
from ema_sim.analysis.section2.segments import EdgeRun, HeldStretch, MoveRun, MovingStretch, Reading

TESTS: tuple[Section2Test[Any], ...] = (
    steps.TEST, timing.TEST, frequency_response.TEST, cycles.TEST, sine_dwell.SINE_DWELL, moves.TEST,
    calibration_fit.TEST, threshold.STATIC, threshold.DYNAMIC, crosstalk.TEST, dither.TEST, compliance.TEST,
    hysteresis.TEST, free_play.TEST, regeneration.TEST,
)

EDGE_READERS: tuple[Callable[[EdgeRun], Reading | None], ...] = (
    calibration_fit.read_staircase, timing.read_square, regeneration.read_regen, steps.read_steps,
)
MOVE_READERS: tuple[Callable[[MoveRun], Reading | None], ...] = (calibration_fit.read_staircase, moves.read_profile)
MOVING_READERS: tuple[Callable[[MovingStretch], Reading | None], ...] = (
    threshold.read_growing_tone, sine_dwell.read_sine, crosstalk.read_triangle, frequency_response.read_sweep,
    moves.read_ramp, frequency_response.read_schroeder, frequency_response.read_broadband,
)
HELD_READERS: tuple[Callable[[HeldStretch], Reading | None], ...] = (
    crosstalk.read_hold, free_play.read_load_reversal, compliance.read_load_steps, hysteresis.read_load_sine,
)

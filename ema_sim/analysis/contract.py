"""The ``ema analyze --json`` document as a typed contract: the TypedDicts its JSON Schema is generated from.

A document holds one entry per record: its header (channel, rate, span, outputs, noise floor and resolution,
the command's timing, the slope), then one key per section-2 test of :data:`ema_sim.analysis.registry.TESTS`
(a list of that test's results, or one result or ``null`` for the tests that give one per record), then the
second-order fits, what was not computed and why, and the notes. Each test's own result is an open object (the
test's page in the docs describes its keys); the keys named here are closed. :func:`analyze_schema` is the
schema published as ``docs/schema/analyze.schema.json``.
"""

from __future__ import annotations

from functools import cache
from typing import Literal, NotRequired, TypedDict

from ema_sim.io.contract import schema_of

__all__ = ["AnalyzeReport", "RecordReport", "analyze_schema"]

Num = float | None
PerOutput = dict[str, Num]
Results = list[dict[str, object]]
OneResult = dict[str, object] | None


class RecordReport(TypedDict):
    """One record's figures: its header, every section-2 test's results, the fits and what was not computed."""

    data: str
    channel: str
    samples: int
    samples_resampled: NotRequired[int]
    """The grid's samples when the record was resampled (``samples`` counts them as logged)."""
    sample_hz: Num
    duration_s: Num
    outputs: list[str]
    unit: str
    metadata: dict[str, object]
    noise_deg: PerOutput
    resolution_deg: PerOutput
    noise: dict[str, dict[str, object]]
    command: dict[str, object]
    tests: Results
    slew: dict[str, object]
    steps: Results
    slew_rates: OneResult
    timing: OneResult
    frequency_response: Results
    periodic: Results
    sine_dwell: Results
    profiled_moves: Results
    command_error: Results
    static_threshold: Results
    dynamic_threshold: Results
    crosstalk: Results
    dither: Results
    compliance: Results
    hysteresis: Results
    free_play: Results
    regeneration: OneResult
    second_order_fits: Results
    not_computed: dict[str, str]
    notes: list[str]


class Rw13Check(TypedDict):
    """Section 3.3's worked example of the hysteretic damping constant, recomputed."""

    area_inlb: float
    peak_in: float
    h_lb_per_in: float


class AnalyzeReport(TypedDict):
    """``ema analyze``'s document: every record's section-2 results and what holds across them."""

    tool: Literal["ema analyze"]
    version: str
    records: list[RecordReport]
    second_order_spread: dict[str, object] | None
    command_error_bounds: dict[str, object] | None
    uncertainty_method: str
    rw13_check: Rw13Check


@cache
def analyze_schema() -> dict[str, object]:
    """The JSON Schema of :class:`AnalyzeReport` (published as ``docs/schema/analyze.schema.json``)."""
    return schema_of(AnalyzeReport, "ema analyze report")

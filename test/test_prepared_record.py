"""One record prepared once: ``ema analyze`` and ``ema identify`` start from the same facts, measured once.

:func:`ema_sim.analysis.estimation.prepared.prepare` reads the columns and measures the noise, the command's
timing, the slew, the stamps, the saturation and the travel; the analysis reports them as they were measured,
identification's record and :class:`~ema_sim.identify.problem.Problem` take them from it without measuring again.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from identgen import make_record

from ema_sim.analysis.estimation import prepared as shared
from ema_sim.analysis.estimation import slew as slew_fit
from ema_sim.analysis.pipeline import analyze_record
from ema_sim.config import load_channel
from ema_sim.errors import DataError
from ema_sim.identify import record as identify_record
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.problem import Problem

WING = load_channel("left_wing")


@pytest.fixture(scope="module")
def data():
    return make_record({"time_delay": 0.008}, seed=4, duration_s=4.0)


def test_the_prepared_facts_are_those_each_tool_measured_on_its_own(data):
    p = shared.prepare(data, WING)
    assert list(p.outputs) == ["position_deg", "surface_deg"]
    assert all(p.outputs[o] is getattr(data, o) for o in p.outputs)  # read, not copied
    y = data.position_deg
    sigma = max(p.noise["position_deg"].sigma, slew_fit.MIN_NOISE)
    alone = slew_fit.measure(data.time_s - data.time_s[0], data.command_deg, y, sigma)
    assert p.slew == alone
    ra = analyze_record(data)
    assert ra.slew == p.slew
    assert ra.noise == p.noise
    assert ra.command == p.hold
    assert ra.channel == p.channel


def test_identification_takes_noise_and_slew_from_the_prepared_record_without_measuring_again(data, monkeypatch):
    record = identify_record.prepare(data, WING)
    assert record.noise is record.prepared.noise
    problem = Problem(record.data, record.channel, prepared=record.prepared)
    assert problem.noise is record.prepared.noise

    def measured_again(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the slew was measured again")

    monkeypatch.setattr(slew_fit, "measure", measured_again)
    assert problem.measured_slew is record.prepared.slew
    result = identify(record, search=Search(max_effects=0, escalate=False, discover_terms=False))
    assert result.problem.measured_slew is record.prepared.slew


def test_a_record_with_no_output_and_one_that_never_moves_get_one_clear_error(data):
    with pytest.raises(DataError, match="needs a position_deg or surface_deg column"):
        shared.prepare(replace(data, position_deg=None, surface_deg=None), WING)
    still = replace(data, surface_deg=None, position_deg=np.full_like(data.time_s, 1.5))
    shared.prepare(still, WING)  # ema analyze reads a record whose output rests (a load test, say)
    with pytest.raises(DataError, match="position_deg never changes"):
        identify_record.prepare(still, WING)

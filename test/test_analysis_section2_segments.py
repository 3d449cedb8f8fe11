"""`analysis/section2/segments.py`: what a run of command edges says about itself, on held signals built by hand."""

import numpy as np
import pytest

from ema_sim.analysis.records.series import edges
from ema_sim.analysis.section2.segments import EdgeRun, Segment

DT_S = 0.001


def _run(levels, hold_s=0.5):
    x = np.repeat(np.asarray(levels, float), round(hold_s / DT_S))
    return EdgeRun(tuple(edges(x, DT_S)), DT_S)


def test_a_square_wave_about_zero_alternates_with_equal_jumps_between_two_levels():
    run = _run([0.0, 2.0, -2.0, 2.0, -2.0, 2.0, 0.0])  # half edges at both ends
    assert run.n == 6
    assert run.distinct_levels == 3
    assert run.alternating_equal
    assert run.same_direction == 0.0
    assert run.amplitude_deg == pytest.approx(2.0)  # half the median inner jump of 4
    assert np.allclose(run.holds_s, 0.5)
    assert run.inner_holds_s.size == 5  # the last hold may run on: left out


def test_a_staircase_goes_one_way_through_many_levels_and_is_no_square_wave():
    run = _run([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    assert run.same_direction == 1.0
    assert run.distinct_levels == 6
    assert not run.alternating_equal
    assert np.allclose(run.jumps, 1.0)


def test_unequal_alternating_jumps_are_no_square_wave():
    assert not _run([0.0, 2.0, -1.0, 3.0, -2.0]).alternating_equal


def test_a_segment_reports_its_time_span():
    t = np.arange(1000) * DT_S + 10.0
    d = Segment("step", 100, 600, "edges", {"amp_deg": 1.0}).as_dict(t)
    assert d == {"kind": "step", "start_s": pytest.approx(10.1), "end_s": pytest.approx(10.599),
                 "evidence": "edges", "params": {"amp_deg": 1.0}}

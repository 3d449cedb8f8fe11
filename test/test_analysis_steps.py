"""Step metrics, step fits, slew rates and command-to-surface timing against the simulated truth."""

from dataclasses import replace

import numpy as np
import pytest
from analysis_data import delayed, measured

from ema_sim.analysis.estimation.second_order_fit import response
from ema_sim.analysis.pipeline import analyze_record
from ema_sim.analysis.section2.steps import slew_rates

STEPS = "steps:amps_deg=0.5/1/20"


def overshoot_pct(zeta):
    return 100 * np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))


@pytest.mark.parametrize(("wn", "zeta", "delay", "seed"), [(56.5, 0.65, 0.004, 1), (70.0, 0.5, 0.006, 2)])
def test_small_steps_fit_the_truth_and_large_ones_are_rate_limited(wn, zeta, delay, seed):
    ra = analyze_record(measured("loac", STEPS, wn_rad_s=wn, zeta=zeta, delay_s=delay, seed=seed))
    small = [s for s in ra.results["steps"] if abs(s.command_step_deg) < 5]
    large = [s for s in ra.results["steps"] if abs(s.command_step_deg) > 5]
    assert len(small) == 4
    assert len(large) == 2
    for s in small:
        assert not s.rate_limited
        f = s.fit
        assert f.wn_rad_s.value == pytest.approx(wn, rel=0.02)
        assert f.zeta.value == pytest.approx(zeta, rel=0.03)
        assert f.delay_s.value == pytest.approx(delay, abs=3e-4)
        assert abs(f.wn_rad_s.value - wn) < 5 * f.wn_rad_s.sigma + 0.002 * wn
        assert s.overshoot_pct == pytest.approx(overshoot_pct(zeta), abs=1.5)
        assert f.hand is not None
        assert f.hand.wn_rad_s == pytest.approx(wn, rel=0.15)  # a hand calculation: close, not exact
        assert s.delay_s == pytest.approx(delay, abs=1.5e-3)  # first motion of a 0.5° step: σ ≈ 0.45 ms
    for s in large:
        assert s.rate_limited
        assert s.fit is None
        assert "rate within 5 %" in s.rate_reason
    # Table 1's unloaded slew rate is the model's rate limit.
    assert slew_rates(ra.results["steps"]).large_dps == pytest.approx(115.8, rel=0.005)
    assert slew_rates(ra.results["steps"]).small_steps_deg == [0.5, 1.0]
    assert slew_rates(ra.results["steps"]).large_steps_deg == [20.0]
    # Linear peak rate of a 1° step: max of the impulse response.
    tt = np.linspace(0, 0.2, 20001)
    wd = wn * np.sqrt(1 - zeta**2)
    peak = np.max(wn**2 / wd * np.exp(-zeta * wn * tt) * np.sin(wd * tt))
    assert slew_rates(ra.results["steps"]).small_dps == pytest.approx(peak, rel=0.03)


def test_rise_time_matches_the_second_order_response():
    ra = analyze_record(measured("loac", "step:amp_deg=1", noise_deg=0.001))
    t = np.linspace(0, 0.3, 30001)
    # Unit step response from the closed form.
    wn, z = 56.5, 0.65
    wd = wn * np.sqrt(1 - z * z)
    y = 1 - np.exp(-z * wn * t) * (np.cos(wd * t) + z * wn / wd * np.sin(wd * t))
    rise = t[np.argmax(y >= 0.9)] - t[np.argmax(y >= 0.1)]
    assert ra.results["steps"][0].rise_s == pytest.approx(rise, abs=0.0015)
    assert abs(response(np.array([0.0]), wn, z)[0]) == pytest.approx(1.0)


@pytest.mark.parametrize(("delay", "feedback_delay"), [(0.004, 0.002), (0.0065, 0.001)])
def test_timing_of_a_square_wave_gives_both_legs(delay, feedback_delay):
    """Section 2.3: 1 Hz square wave at 10 % of travel; the FMU receives the LVDT later by feedback_delay."""
    data = measured("loac", "square:freq_hz=1,amp_deg=4.3,cycles=5", delay_s=delay, seed=3)
    late = replace(data, position_deg=delayed(data.time_s, data.position_deg, feedback_delay))
    ra = analyze_record(late)
    assert [s.kind for s in ra.recognition.segments] == ["square"]
    tm = ra.results["timing"][0]
    assert tm.motion_signal == "surface_deg"
    assert len(tm.edges) == 10
    assert tm.command_to_motion_s == pytest.approx(delay, abs=3e-4)
    assert tm.motion_to_feedback_s == pytest.approx(feedback_delay, abs=3e-4)
    assert tm.total_s == pytest.approx(delay + feedback_delay, abs=4e-4)


def test_timing_without_a_surface_sensor_says_what_it_cannot_measure():
    data = replace(measured("loac", "square:freq_hz=1,amp_deg=4.3,cycles=3"), surface_deg=None)
    tm = analyze_record(data).results["timing"][0]
    assert tm.motion_signal == "position_deg"
    assert tm.motion_to_feedback_s is None
    assert "no external surface angle" in tm.notes[0]
    assert tm.command_to_motion_s == pytest.approx(0.004, abs=3e-4)

"""`analysis/section2/frequency_response.py`'s cycle fits and slew check on sweeps whose answer is known."""

import numpy as np
import pytest

from ema_sim.analysis.section2.frequency_response import check_slew, sweep_cycles

FS_HZ = 1000.0


def _sweep(f0=0.5, f1=8.0, duration_s=12.0, amp_deg=5.0):
    t = np.arange(0.0, duration_s, 1.0 / FS_HZ)
    phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / duration_s * t**2)
    return t, amp_deg * np.sin(phase)


def _rate_limited(u, rate_dps):
    y = np.empty_like(u)
    y[0] = u[0]
    step = rate_dps / FS_HZ
    for k in range(1, u.size):
        y[k] = y[k - 1] + np.clip(u[k] - y[k - 1], -step, step)
    return y


def test_each_cycle_of_a_pure_gain_reads_the_gain_and_no_harmonic():
    t = np.arange(0.0, 3.0, 1.0 / FS_HZ)
    u = 2.0 * np.sin(2 * np.pi * 2.0 * t + 0.3)
    cycles = sweep_cycles(t, u, 0.5 * u)
    assert len(cycles) == 5  # six upward crossings of the median in 3 s at 2 Hz
    for c in cycles:
        assert c.freq_hz == pytest.approx(2.0, rel=0.01)
        assert abs(c.y1 / c.u1) == pytest.approx(0.5, rel=1e-6)
        assert abs(np.angle(c.y1 / c.u1)) < 1e-6
        assert c.h3_y < 1e-3
        assert c.amplitude_deg == pytest.approx(2.0, rel=0.01)
        assert c.command_rate_dps == pytest.approx(2 * np.pi * 2.0 * 2.0, rel=0.01)


def test_a_rate_limited_output_is_found_saturated_where_the_command_outruns_the_limit():
    t, u = _sweep()
    check = check_slew(t, u, _rate_limited(u, 60.0))
    assert check.saturated_from_hz is not None
    # the command's peak rate 2π f A reaches 60 °/s at f = 1.9 Hz; the clipping shows from about there
    assert 1.0 < check.saturated_from_hz < 3.0
    assert check.third_harmonic_excess >= 0.005
    # a full triangle of rate R and amplitude a = R/(4f): its fundamental 8a/π² peaks at 2πf·8a/π² = 4R/π
    assert check.output_rate_ceiling_dps == pytest.approx(4.0 * 60.0 / np.pi, rel=0.03)
    assert check.measured_slew_dps == check.output_rate_ceiling_dps
    assert check.command_peak_rate_dps == pytest.approx(2 * np.pi * 8.0 * 5.0, rel=0.02)


def test_a_linear_output_on_the_same_sweep_is_not_called_saturated():
    t, u = _sweep()
    check = check_slew(t, u, 0.8 * u)
    assert check.saturated_from_hz is None
    assert check.measured_slew_dps is None
    assert check.slew_source == "none measured"

"""`analysis/section2/crosstalk.py` on records whose answer is known by construction."""

import numpy as np
import pytest

from ema_sim.analysis.section2.crosstalk import crosstalk_noise

FS_HZ = 1000.0


def _held(tone_deg, noise_deg, drift_dps=0.01, seed=3):
    t = np.arange(0.0, 5.0, 1.0 / FS_HZ)
    rng = np.random.default_rng(seed)
    y = 2.0 + drift_dps * t + tone_deg * np.sin(2 * np.pi * 7.0 * t) + noise_deg * rng.standard_normal(t.size)
    return t, np.full_like(t, 2.0), y


def test_a_held_command_leaves_the_tone_and_the_noise_and_takes_out_the_drift():
    t, u, y = _held(0.05, 0.002)
    r = crosstalk_noise(t, u, y, 0.002, output="position", threshold_deg=None, threshold_source="none",
                        volts_per_deg=0.24)
    assert r.kind == "static (command held)"
    expected_rms = np.hypot(0.05 / np.sqrt(2.0), 0.002)  # the 7 Hz tone's rms and the noise, the drift removed
    assert r.rms_deg == pytest.approx(expected_rms, rel=0.02)
    assert r.excess_rms_deg == pytest.approx(0.05 / np.sqrt(2.0), rel=0.02)
    assert r.peak_to_peak_deg == pytest.approx(0.1, abs=0.015)
    assert r.dominant_hz == pytest.approx(7.0, abs=0.3)
    assert abs(np.mean(r.residual)) < 1e-3  # drift and offset gone
    assert r.independence is None
    assert r.rates_dps is None
    d = r.as_dict()
    assert d["peak_to_peak_v"] == pytest.approx(r.peak_to_peak_deg * 0.24)
    assert d["rms_v"] == pytest.approx(r.rms_deg * 0.24)


def test_noise_at_the_sensor_floor_is_no_excess():
    t, u, y = _held(0.0, 0.002)
    r = crosstalk_noise(t, u, y, 0.002, output="position", threshold_deg=0.1, threshold_source="test",
                        volts_per_deg=0.24)
    assert r.rms_deg == pytest.approx(0.002, rel=0.05)
    assert r.excess_rms_deg < 0.0007  # sqrt of a difference of two nearly equal squares
    assert r.threshold_deg == 0.1

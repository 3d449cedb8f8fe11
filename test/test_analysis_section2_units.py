"""Unit tests of the section-2 tests' own computations on synthetic records whose answer is known by hand.

Each reads a short array, never a simulation: the bus peak and its margin (regeneration), a delayed
second-order response's first motion (timing: it starts quadratically, ``ωn²·s²/2``), a limit cycle's
frequency and peak to peak on a held output (dither), a dead zone's half width from growing triangles
(static threshold: output swing = command swing − 2·d), a three-segment compliance curve, and when a
periodic test counts as rate-limited.
"""

import math

import numpy as np
import pytest

from ema_sim.analysis.estimation.slew import Slew
from ema_sim.analysis.section2 import compliance, cycles, dither, regeneration, threshold, timing


def test_bus_peak_nominal_and_margin():
    t = np.arange(0.0, 1.0, 1e-3)
    bus = np.full(t.size, 150.0)
    bus[400] = 171.5
    r = regeneration.bus_peak(t, bus)
    assert r.nominal_v == 150.0
    assert r.peak_v == 171.5
    assert r.peak_time_s == pytest.approx(0.4)
    assert r.rise_v == pytest.approx(21.5)
    assert r.margin_v == pytest.approx(185.0 - 171.5)
    assert r.as_dict()["within_limit"] is True
    assert regeneration.bus_peak(t, bus, limit_v=170.0).as_dict()["within_limit"] is False


@pytest.mark.parametrize("delay_s", [0.004, 0.0065])
def test_first_motion_of_a_delayed_second_order_step(delay_s):
    wn, zeta, amp = 40.0, 0.7, 1.0
    fs = 2000.0
    t = np.arange(0.0, 0.6, 1.0 / fs)
    edge = int(0.1 * fs)
    s = np.maximum(t - t[edge] - delay_s, 0.0)
    wd = wn * math.sqrt(1 - zeta**2)
    y = amp * (1 - np.exp(-zeta * wn * s) * (np.cos(wd * s) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * s)))
    got = timing.first_motion(t, y, edge, 0.0, amp, noise=1e-4)
    assert got == pytest.approx(t[edge] + delay_s, abs=2.5e-4)  # half a sample


def test_first_motion_is_none_when_the_output_never_leaves():
    t = np.arange(0.0, 0.5, 1e-3)
    assert timing.first_motion(t, np.zeros_like(t), 100, 0.0, 1.0, noise=1e-3) is None


def test_dither_finds_a_3_hz_limit_cycle_and_its_size():
    rng = np.random.default_rng(7)
    fs = 200.0
    t = np.arange(0.0, 20.0, 1.0 / fs)
    y = 2.0 + 0.05 * np.sin(2 * np.pi * 3.0 * t) + rng.normal(0.0, 0.003, t.size)
    d = dither.detect_dither(t, y, output="position_deg", noise=0.003)
    assert d is not None
    assert d.detected
    assert d.freq_hz == pytest.approx(3.0, abs=0.01)
    assert d.fundamental_amplitude_deg == pytest.approx(0.05, rel=0.02)
    assert d.peak_to_peak_deg == pytest.approx(0.1, rel=0.05)  # 0.1° peak to peak, as the AIL tests saw


def test_dither_says_no_on_noise_alone_and_on_a_short_stretch():
    rng = np.random.default_rng(8)
    fs = 200.0
    t = np.arange(0.0, 20.0, 1.0 / fs)
    d = dither.detect_dither(t, rng.normal(0.0, 0.003, t.size), output="position_deg")
    assert d is not None
    assert not d.detected
    assert d.peak_db_above_floor < dither.DETECT_DB
    assert dither.detect_dither(t[:400], np.zeros(400), output="position_deg") is None  # 2 s < 4 periods of 1 Hz
    flat = dither.detect_dither(t, np.full(t.size, 1.0), output="position_deg")
    assert flat is not None
    assert not flat.detected
    assert "does not move" in flat.reason


def _growing_triangle(fs=100.0, half_period_s=5.0, step_deg=0.02, count=10):
    """A 0.1 Hz triangle whose amplitude grows by ``step_deg`` every half cycle (0.02°, 0.04°, ...)."""
    turns = [0.0] + [(-1) ** k * step_deg * k for k in range(1, count + 1)]
    t_turn = np.arange(len(turns)) * half_period_s
    t = np.arange(0.0, t_turn[-1] + 1e-9, 1.0 / fs)
    return t, np.interp(t, t_turn, turns)


def test_static_threshold_of_a_dead_zone_is_its_half_width():
    t, u = _growing_triangle()
    d = 0.05
    y = np.sign(u) * np.maximum(np.abs(u) - d, 0.0)
    r = threshold.static_threshold(t, u, y, noise=1e-4, output="surface_deg", volts_per_deg=0.1)
    assert r is not None
    assert r.onset_deg == pytest.approx(d, rel=0.05)
    assert r.gain == pytest.approx(1.0, rel=0.05)
    # it follows (output swing ≥ half the command's) once swing − 2·d ≥ swing/2, i.e. swing ≥ 4·d = 0.2°: the
    # swings are 0.02°·(2k+1) (from ±0.02k to ∓0.02(k+1)), first ≥ 0.2° at k = 5, 0.22°, half of it 0.11°
    assert r.follow_deg == pytest.approx(0.11, abs=1e-9)
    ideal = threshold.static_threshold(t, u, u, noise=1e-4, output="surface_deg", volts_per_deg=0.1)
    assert ideal is not None
    assert ideal.onset_deg == pytest.approx(0.0, abs=0.002)
    assert threshold.static_threshold(t[:300], u[:300], u[:300], noise=1e-4, output="x", volts_per_deg=0.1) is None


def test_rate_limited_needs_two_moves_and_a_majority():
    assert cycles.rate_limited(Slew(100.0, 100.0, 100.0, 1.0, moves=2, seen=4))
    assert not cycles.rate_limited(Slew(100.0, 100.0, None, None, moves=1, seen=1))
    assert not cycles.rate_limited(Slew(100.0, 100.0, 100.0, 1.0, moves=2, seen=5))
    assert not cycles.rate_limited(Slew(None, None, None, None, moves=0, seen=3))


def test_three_segment_compliance_is_recovered_with_its_knots_and_stiffness():
    force = np.arange(-400.0, 401.0, 10.0)
    truth = compliance.ThreeSegment((100.0, 250.0), (0.002, 0.0005, 0.0012), 0.01, 0.0)
    defl = truth(force)
    # by hand at +300 lb: 0.01 + 100·0.002 + 150·0.0005 + 50·0.0012 = 0.345°
    assert float(truth(np.array([300.0]))[0]) == pytest.approx(0.345)
    fit = compliance.fit_three_segments(force, defl)
    assert fit is not None
    assert fit.knots_lb == pytest.approx((100.0, 250.0))
    assert fit.slopes_deg_per_lb == pytest.approx((0.002, 0.0005, 0.0012), rel=1e-9)
    assert fit.offset_deg == pytest.approx(0.01, abs=1e-12)
    assert fit.rms_deg < 1e-12
    arm = 1.7317
    stiff = fit.stiffness_lb_per_in(arm)
    assert stiff[0] == pytest.approx(1.0 / (0.002 * math.pi / 180.0 * arm), rel=1e-9)
    assert compliance.fit_three_segments(np.array([-10.0, 0.0, 10.0]), np.zeros(3)) is None

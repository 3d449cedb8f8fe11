"""Unit tests of ``ema_sim.analysis.estimation`` on synthetic signals whose answer is known by hand.

Spectra (white noise's level, a pure gain's cross-spectrum, Welch's overlap correction), tone fits,
the response at a periodic command's harmonics (a first-order lag at its corner: −3.01 dB, −45°),
settling against the command (a first-order lag settles into 2 % after T·ln 50; ζ = 0.5 overshoots
by exp(−πζ/√(1−ζ²)) = 16.3 %), the slope of rate-limited moves, and the quality words.
"""

import math

import numpy as np
import pytest

from ema_sim.analysis.estimation import harmonics, settling, slew, spectra
from ema_sim.analysis.estimation.quality import QUALITY_WORDS, Measurement, worst
from ema_sim.analysis.estimation.sine_fit import dominant_frequency, fit_sine, sine_at
from ema_sim.analysis.records.periodic import find_periodic

# --------------------------------------------------------------------------- spectra


def test_welch_of_white_noise_is_flat_at_two_sigma_squared_over_fs():
    rng = np.random.default_rng(1)
    fs, sigma = 200.0, 0.5
    x = rng.normal(0.0, sigma, 200_000)
    sp = spectra.welch(x, x, fs, window_s=2.0)
    inner = (sp.freq_hz > 1.0) & (sp.freq_hz < 90.0)
    # one-sided density of white noise: 2σ²/fs, whatever the window (Hann normalised by Σw²)
    assert np.mean(sp.gxx[inner]) == pytest.approx(2 * sigma**2 / fs, rel=0.02)
    assert sp.window_s == pytest.approx(2.0)
    assert sp.freq_hz[1] == pytest.approx(0.5)


def test_welch_cross_spectrum_of_a_gain_and_its_coherence():
    rng = np.random.default_rng(2)
    x = rng.normal(size=20_000)
    ys = np.vstack([3.0 * x, -x + 0.0])
    sp = spectra.welch(x, ys, 100.0, window_s=5.0)
    band = sp.freq_hz > 0
    h = sp.gxy[:, band] / sp.gxx[band]
    np.testing.assert_allclose(h[0], 3.0, rtol=1e-9)
    np.testing.assert_allclose(h[1], -1.0, rtol=1e-9)
    coh = spectra.coherence(sp.gxx[band], sp.gyy[0, band], sp.gxy[0, band])
    np.testing.assert_allclose(coh, 1.0, atol=1e-9)
    # a response independent of the command has low coherence
    other = spectra.welch(x, rng.normal(size=x.size), 100.0, window_s=5.0)
    assert np.median(spectra.coherence(other.gxx, other.gyy[0], other.gxy[0])[1:]) < 0.05


def test_coherence_is_zero_where_a_spectrum_vanishes():
    z = np.zeros(3)
    assert spectra.coherence(z, np.ones(3), np.ones(3, complex)).tolist() == [0.0, 0.0, 0.0]


def test_effective_averages_without_overlap_and_with_half_overlap():
    assert spectra.effective_averages(10, 100, 100) == pytest.approx(10.0)
    w = np.hanning(400)
    rho = float(np.sum(w[:200] * w[200:]) / np.sum(w * w))
    assert rho == pytest.approx(1 / 6, abs=0.005)  # Hann at 50 % overlap (Welch 1967)
    expected = 50 / (1 + 2 * (1 - 1 / 50) * rho**2)
    assert spectra.effective_averages(50, 400, 200) == pytest.approx(expected, rel=1e-12)


def test_random_error_formula():
    # √(1−γ²)/(|γ|·√(2ν)) at γ² = 0.5, ν = 2: 1/2
    assert float(spectra.random_error(np.array([0.5]), 2.0)[0]) == pytest.approx(0.5)
    # a perfect coherence is capped, so the error is small but not zero
    assert 0.0 < float(spectra.random_error(np.array([1.0]), 10.0)[0]) < 0.01


def test_log_grid_and_default_windows():
    g = spectra.log_grid(0.1, 10.0, per_decade=10)
    assert g[0] == pytest.approx(0.1)
    assert g[-1] == pytest.approx(10.0)
    assert g.size == 21
    np.testing.assert_allclose(g[1:] / g[:-1], 10 ** 0.1)
    assert spectra.default_windows(100.0, 10.0) == (50.0, 25.0, 12.5, 6.25, 3.125)
    # never shorter than 20 periods of the top frequency
    assert spectra.default_windows(100.0, 1.0) == (50.0, 25.0)


def test_dft_at_equals_the_fft_on_its_bins():
    rng = np.random.default_rng(3)
    x = rng.normal(size=256)
    fs = 64.0
    full = np.fft.fft(x)
    got = spectra.dft_at(x, fs, 2.0, 0.25, 8)  # bins 8..15 (df = fs/256 = 0.25)
    np.testing.assert_allclose(got, full[8:16], rtol=1e-9, atol=1e-9)


def test_composite_spectra_recover_a_gain_on_the_grid():
    rng = np.random.default_rng(4)
    fs = 100.0
    x = rng.normal(size=30_000)
    grid = spectra.log_grid(0.5, 20.0, 20)
    cs = spectra.composite(x, np.vstack([0.5 * x]), fs, grid, spectra.default_windows(x.size / fs, 20.0, 3))
    np.testing.assert_allclose(cs.gxy[0] / cs.gxx[0], 0.5, rtol=1e-9)
    assert cs.averages.shape == (1, grid.size)
    assert np.all(cs.averages > 1.0)


# --------------------------------------------------------------------------- sine fits


def test_fit_sine_recovers_frequency_amplitude_phase_and_offset():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 4.0, 1e-3)
    y = 0.2 + 0.8 * np.sin(2 * np.pi * 3.7 * t + 0.6) + rng.normal(0, 0.01, t.size)
    s = fit_sine(t, y)
    assert s is not None
    assert s.freq_hz == pytest.approx(3.7, abs=2e-4)
    assert s.amplitude == pytest.approx(0.8, abs=2e-3)
    assert s.phase_rad == pytest.approx(0.6, abs=5e-3)
    assert s.offset == pytest.approx(0.2, abs=2e-3)
    assert s.r2 > 0.999
    np.testing.assert_allclose(s(t), y, atol=0.05)


def test_sine_at_a_known_frequency_is_exact_and_the_flat_signal_gives_none():
    t = np.linspace(0.0, 2.0, 501)
    y = -1.5 * np.cos(2 * np.pi * 2.0 * t)  # = 1.5·sin(ωt − π/2)
    s = sine_at(t, y, 2.0)
    assert s.amplitude == pytest.approx(1.5, rel=1e-9)
    assert s.phase_rad == pytest.approx(-np.pi / 2, abs=1e-9)
    assert s.r2 == pytest.approx(1.0)
    assert fit_sine(t, np.full(t.size, 3.0)) is None
    assert fit_sine(t[:5], y[:5]) is None


def test_dominant_frequency_picks_the_largest_tone_in_its_band():
    t = np.arange(0.0, 10.0, 0.01)
    y = np.sin(2 * np.pi * 2.0 * t) + 0.3 * np.sin(2 * np.pi * 11.0 * t)
    assert dominant_frequency(t, y) == pytest.approx(2.0, abs=0.02)
    assert dominant_frequency(t, y, f_min=5.0) == pytest.approx(11.0, abs=0.02)
    assert dominant_frequency(t, y, f_min=60.0) is None


# --------------------------------------------------------------------------- harmonics


def _square_harmonics_record(corner_hz: float, delay_s: float = 0.0):
    """A command of harmonics 1, 3, 5 of 1 Hz (a square's 1, 1/3, 1/5) and its first-order lag's exact output."""
    fs = 200.0
    t = np.arange(0.0, 8.0, 1.0 / fs)
    u = np.zeros_like(t)
    y = np.zeros_like(t)
    for k in (1, 3, 5):
        w = 2 * np.pi * k
        h = 1.0 / (1.0 + 1j * w / (2 * np.pi * corner_hz)) * np.exp(-1j * w * delay_s)
        u += np.sin(w * t) / k
        y += abs(h) * np.sin(w * t + np.angle(h)) / k
    return t, u, y, fs


def test_harmonic_response_of_a_first_order_lag_at_its_corner():
    t, u, y, fs = _square_harmonics_record(corner_hz=3.0)
    periods = find_periodic(t, u, tol=1e-6)
    assert len(periods) == 1
    p = periods[0]
    assert p.period_s == pytest.approx(1.0, rel=1e-3)
    assert set(p.harmonics) == {1, 3, 5}
    hs = harmonics.harmonic_response(t, t, u, y, p, fs, held=False)
    by_k = {h.k: h for h in hs}
    assert sorted(by_k) == [1, 3, 5]
    corner = by_k[3]
    assert corner.freq_hz == pytest.approx(3.0, rel=1e-3)
    assert corner.gain_db == pytest.approx(-10 * math.log10(2), abs=0.02)  # −3.01 dB
    assert corner.phase_deg == pytest.approx(-45.0, abs=0.2)
    assert corner.coherence == pytest.approx(1.0, abs=1e-6)
    assert corner.quality == "ok"
    assert by_k[1].gain_db == pytest.approx(-10 * math.log10(1 + (1 / 3) ** 2), abs=0.02)
    assert by_k[5].phase_deg == pytest.approx(-math.degrees(math.atan(5 / 3)), abs=0.2)
    # the −3 dB point of the fundamental-referenced gain lies between harmonics 3 and 5
    bw = harmonics.bandwidth(hs)
    assert bw.quality == "ok"
    assert 3.0 < bw.value < 5.0
    assert bw.sigma == pytest.approx(1.0)


def test_lag_at_the_fundamental_reads_a_pure_delay():
    t, u, y, fs = _square_harmonics_record(corner_hz=1e9, delay_s=0.02)
    (p,) = find_periodic(t, u, tol=1e-6)
    hs = harmonics.harmonic_response(t, t, u, y, p, fs, held=False, saturated="rate-limited")
    assert all(h.quality == "saturated" for h in hs)
    lag = harmonics.lag_at_fundamental(hs, stamp_s=0.001)
    assert lag.value == pytest.approx(0.02, abs=2e-4)
    assert lag.sigma == pytest.approx(0.001 / math.sqrt(12), rel=0.05)


def _harmonic(k, gain_db, coherence=1.0, phase_deg=0.0):
    return harmonics.Harmonic(k, float(k), 1.0 / k, gain_db, 0.0, phase_deg, 0.0, coherence, "ok")


def test_bandwidth_interpolates_in_log_frequency_and_says_why_not():
    bw = harmonics.bandwidth([_harmonic(1, 0.0), _harmonic(3, -1.0), _harmonic(5, -6.0)])
    # −3 dB crossed 2/5 of the way from ln 3 to ln 5
    assert bw.value == pytest.approx(3.0 * (5 / 3) ** 0.4, rel=1e-12)
    assert bw.sigma == pytest.approx(1.0)
    assert harmonics.bandwidth([_harmonic(1, 0.0)]).value is None
    flat = harmonics.bandwidth([_harmonic(1, 0.0), _harmonic(3, -1.0)])
    assert flat.value is None
    assert "stays within 3 dB" in flat.statement
    noisy = harmonics.bandwidth([_harmonic(1, 0.0), _harmonic(3, -1.0, coherence=0.2)])
    assert noisy.value is None
    assert noisy.quality == "not_determined"
    assert "coherence" in noisy.statement


def test_lag_at_fundamental_from_its_phase():
    lag = harmonics.lag_at_fundamental([_harmonic(1, 0.0, phase_deg=-36.0)])
    assert lag.value == pytest.approx(0.1)  # −(−36°)/360°/1 Hz
    assert harmonics.lag_at_fundamental([_harmonic(3, 0.0)]).value is None
    assert harmonics.lag_at_fundamental([_harmonic(1, 0.0, coherence=0.1)]).quality == "not_determined"


# --------------------------------------------------------------------------- settling


def _read(y, t, commanded=1.0, change=1.0, noise=0.0, counts=None):
    return settling.read(t, y, 0, y.size, commanded=commanded, change=change, noise=noise, counts=counts)


def test_a_first_order_lag_settles_into_two_percent_after_t_ln_50():
    tau = 0.05
    t = np.arange(0.0, 1.0, 1e-4)
    r = _read(1.0 - np.exp(-t / tau), t)
    assert r.band == pytest.approx(0.02)
    assert r.settled
    assert r.settling_command_s == pytest.approx(tau * math.log(50), abs=2e-4)
    assert r.overshoot_command_pct == pytest.approx(0.0)
    assert abs(r.error_left) < 1e-6


def test_an_underdamped_second_order_overshoots_by_the_textbook_share():
    zeta, wn = 0.5, 40.0
    wd = wn * math.sqrt(1 - zeta**2)
    t = np.arange(0.0, 1.0, 1e-4)
    y = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    r = _read(y, t)
    assert r.overshoot_command_pct == pytest.approx(100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), abs=0.01)
    assert r.overshoot_final_pct == pytest.approx(r.overshoot_command_pct, abs=0.01)


def test_a_servo_that_stops_short_is_unsettled_against_the_command_but_flat_against_itself():
    t = np.arange(0.0, 1.0, 1e-3)
    r = _read(0.95 * (1 - np.exp(-t / 0.02)), t)
    assert not r.settled
    assert r.settling_command_s is None
    assert r.error_left == pytest.approx(-0.05, abs=1e-6)
    assert r.settling_final_s is not None
    assert "unsettled" in r.statement


def test_the_band_is_the_largest_of_its_three_floors():
    assert settling.band_for(10.0, 0.001, None) == pytest.approx(0.2)
    assert settling.band_for(1.0, 0.01, None) == pytest.approx(0.04)
    assert settling.band_for(1.0, 0.0, 0.1) == pytest.approx(0.15)


def test_transitions_average_their_readings():
    t = np.arange(0.0, 1.0, 1e-3)
    reads = [_read(1.0 - np.exp(-t / tau), t) for tau in (0.04, 0.05, 0.06)]
    tr = settling.Transitions("rising", reads)
    assert tr.settled == 3
    m = tr.settling_command
    assert m.quality == "ok"
    assert m.value == pytest.approx(np.mean([r.settling_command_s for r in reads]))
    short = settling.Transitions("rising", [*reads, _read(0.9 * (1 - np.exp(-t / 0.05)), t)])
    assert short.settling_command.value is None
    assert "unsettled at 1 of 4" in short.settling_command.statement


# --------------------------------------------------------------------------- slew


def _rate_limited(rate_up, rate_down, fs=1000.0):
    """Steps of ±10° through a pure rate limiter: ramps at exactly the limit between rests."""
    t = np.arange(0.0, 4.0, 1.0 / fs)
    u = np.where((t >= 0.5) & (t < 2.0), 10.0, 0.0)
    y = np.zeros_like(t)
    for i in range(1, t.size):
        dt = t[i] - t[i - 1]
        y[i] = y[i - 1] + np.clip(u[i] - y[i - 1], -rate_down * dt, rate_up * dt)
    return t, u, y


def test_slew_reads_the_slope_of_rate_limited_moves_per_direction():
    t, u, y = _rate_limited(100.0, 80.0)
    s = slew.measure(t, u, y, noise=0.0)
    assert s.moves == 2
    assert s.up == pytest.approx(100.0, rel=1e-6)
    assert s.down == pytest.approx(80.0, rel=1e-6)
    assert s.rate == pytest.approx(90.0, rel=1e-6)
    assert s.sigma == pytest.approx(10.0, rel=1e-6)  # std(ddof=1) of (100, 80) is 10·√2, over √2 moves
    assert s.as_dict()["rate_limited_moves"] == 2


def test_a_linear_response_and_a_followed_triangle_are_no_rate_limit():
    fs = 1000.0
    t = np.arange(0.0, 4.0, 1.0 / fs)
    u = np.where((t >= 0.5) & (t < 2.0), 10.0, 0.0)
    y = np.zeros_like(t)
    a = math.exp(-1 / (fs * 0.05))
    for i in range(1, t.size):
        y[i] = a * y[i - 1] + (1 - a) * u[i - 1]
    lag = slew.measure(t, u, y)
    assert lag.moves == 0
    assert lag.seen >= 2
    assert lag.rate is None
    tri = 10.0 * np.abs(((t / 1.0) % 2.0) - 1.0)  # a triangle the output follows exactly
    assert slew.measure(t, tri, tri).moves == 0
    assert slew.measure(t[:5], u[:5], y[:5]).seen == 0


# --------------------------------------------------------------------------- quality


def test_worst_ranks_the_quality_words():
    assert worst() == "ok"
    assert worst("ok", "saturated") == "saturated"
    assert worst("saturated", "on_bound", "ok") == "on_bound"
    assert worst("on_bound", "not_determined") == "not_determined"
    assert worst("on_bound", "non_causal") == "non_causal"
    assert worst("non_causal", "not_determined") == "not_determined"
    assert set(QUALITY_WORDS) == {"ok", "on_bound", "not_determined", "saturated", "non_causal"}
    m = Measurement(1.5, 0.1, "ok", "1.5 ± 0.1")
    assert m.as_dict() == {"value": 1.5, "sigma": 0.1, "quality": "ok", "statement": "1.5 ± 0.1"}

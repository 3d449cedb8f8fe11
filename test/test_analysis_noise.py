"""Noise floor, residual tests and the coloured-residual covariance, against known statistics."""

import numpy as np
import pytest
from scipy.signal import lfilter

from ema_sim.analysis.estimation.noise import (
    autocorrelation,
    input_independence,
    noise_floor,
    output_noise,
    whiteness,
)
from ema_sim.analysis.estimation.second_order_fit import fit_step
from ema_sim.analysis.estimation.uncertainty import coloured_covariance
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import simulate


def ar1(rng, n, rho, sigma):
    e = lfilter([1.0], [1.0, -rho], rng.normal(0.0, 1.0, n))
    return e / np.std(e) * sigma


@pytest.mark.parametrize("sigma", [0.001, 0.004, 0.02])
def test_noise_floor_sees_the_white_noise_under_a_moving_signal(sigma):
    rng = np.random.default_rng(11)
    t = np.arange(20_000) / 1000.0
    signal = 2.0 * np.sin(2 * np.pi * 1.5 * t) + np.where(t > 7.0, 1.0, 0.0)  # a tone and a step
    assert noise_floor(signal + rng.normal(0, sigma, t.size)) == pytest.approx(sigma, rel=0.05)


def test_a_sensor_at_its_saturation_half_the_time_does_not_halve_the_noise_floor():
    """A 0.7 Hz tone of ±9° read by a sensor that clips at ±6°: over 40 % of the samples read exactly ±6 (no
    noise on them). The white floor on its own drops towards zero; the output's floor leaves the flat
    stretches out and sees the sensor's 0.005°. A still, noisy output with no flat run is unchanged."""
    rng = np.random.default_rng(4)
    t = np.arange(30_000) / 800.0
    clipped = np.clip(9.0 * np.sin(2 * np.pi * 0.7 * t) + rng.normal(0, 0.005, t.size), -6.0, 6.0)
    assert np.mean(np.abs(clipped) == 6.0) > 0.4
    assert noise_floor(clipped) < 0.7 * 0.005
    floor = output_noise(clipped)
    assert floor.resolution is None
    assert floor.sigma == pytest.approx(0.005, rel=0.1)
    plain = rng.normal(0, 0.002, t.size)
    assert output_noise(plain).sigma == noise_floor(plain)


def test_autocorrelation_of_an_ar1_sequence_decays_geometrically():
    rng = np.random.default_rng(2)
    rho = autocorrelation(ar1(rng, 200_000, 0.8, 1.0), 3)
    assert rho == pytest.approx([1.0, 0.8, 0.64, 0.512], abs=0.01)


def test_whiteness_accepts_white_noise_and_rejects_coloured():
    rng = np.random.default_rng(3)
    white = [whiteness(rng.normal(size=5000)).white for _ in range(20)]
    assert sum(white) >= 17  # a 5 % test
    coloured = whiteness(ar1(rng, 5000, 0.3, 1.0))
    assert not coloured.white
    assert coloured.p_value < 1e-6


def test_input_independence_finds_a_residual_that_still_holds_the_input():
    rng = np.random.default_rng(4)
    u = np.cumsum(rng.normal(size=10_000))
    clean = rng.normal(size=10_000)
    assert input_independence(clean, u).independent
    leaky = clean + 0.5 * np.concatenate([[0.0], np.diff(u)])
    test = input_independence(leaky, u)
    assert not test.independent
    assert test.peak_lag == 0


def test_coloured_covariance_reduces_to_the_white_one_for_white_residuals():
    rng = np.random.default_rng(5)
    jac = rng.normal(size=(4000, 3))
    cov = coloured_covariance(jac, rng.normal(0, 0.1, 4000))
    assert cov.sigma == pytest.approx(cov.sigma_white, rel=0.1)


@pytest.mark.parametrize("rho", [0.0, 0.9])
def test_step_fit_uncertainty_matches_the_monte_carlo_spread(rho):
    """30 noise realisations: the corrected σ must match the spread; the white σ is 3× short at ρ = 0.9."""
    _, rec, _ = simulate("sloac", parse_maneuver("step:amp_deg=1,lead_s=0.2,hold_s=1.0,back=false"))
    t, u, y = rec.time_s, rec.command_deg[0], rec.position_deg[0]
    wn, sig, sig_w = [], [], []
    for seed in range(30):
        rng = np.random.default_rng(100 + seed)
        fit = fit_step(t, u, y + ar1(rng, t.size, rho, 0.005), test="mc", output_name="position_deg",
                       wn0=50.0, zeta0=0.7, delay0=0.004)
        wn.append(fit.wn_rad_s.value)
        sig.append(fit.wn_rad_s.sigma)
        sig_w.append(fit.wn_rad_s.sigma_white)
    spread = np.std(wn, ddof=1)
    assert np.mean(wn) == pytest.approx(56.5, abs=3 * spread / np.sqrt(30) + 0.05)
    assert np.mean(sig) == pytest.approx(spread, rel=0.35)
    if rho > 0:
        assert np.mean(sig_w) < spread / 2.5

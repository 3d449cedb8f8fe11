"""Frequency response and its second-order fit against the truth of the simulated actuator."""

from dataclasses import replace

import numpy as np
import pytest
from analysis_data import measured

from ema_sim.analysis.estimation import frf
from ema_sim.analysis.estimation import second_order_fit as sof
from ema_sim.analysis.pipeline import Options, analyze_record
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import simulate

SWEEP = "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60"
SCHROEDER = "schroeder:f0_hz=0.2,f1_hz=18,amp_deg=1,period_s=20,periods=2"


def analytic_bandwidth(wn, zeta):
    f = np.geomspace(0.5, 50, 200_000)
    g = np.abs(sof.response(f, wn, zeta))
    return f[np.argmax(g < 10 ** (-3 / 20))]


@pytest.mark.parametrize(("wn", "zeta", "delay"), [(56.5, 0.65, 0.004), (40.0, 0.45, 0.007)])
def test_sweep_fit_recovers_the_truth(wn, zeta, delay):
    data = measured("sloac", SWEEP, wn_rad_s=wn, zeta=zeta, delay_s=delay, seed=1)
    ra = analyze_record(data)
    fr = next(f for f in ra.results["frequency_response"] if f.response.output == "position_deg")
    assert fr.kind == "sweep"
    fit = fr.fit
    assert fit.wn_rad_s.value == pytest.approx(wn, rel=0.01)
    assert fit.zeta.value == pytest.approx(zeta, rel=0.02)
    assert fit.delay_s.value == pytest.approx(delay, abs=2.5e-4)
    assert fit.gain.value == pytest.approx(1.0, abs=0.003)
    assert 0 < fit.wn_rad_s.sigma < 0.01 * wn
    assert fit.wn_rad_s.sigma >= fit.wn_rad_s.sigma_white * 0.5
    assert fr.bandwidth_hz == pytest.approx(analytic_bandwidth(wn, zeta), rel=0.02)
    # Gain and phase at the chosen frequencies against the true response.
    for row in fr.at:
        h = sof.response(np.array([row["freq_hz"]]), wn, zeta, delay)[0]
        assert row["gain_db"] == pytest.approx(20 * np.log10(abs(h)), abs=0.1)
        assert row["phase_deg"] == pytest.approx(np.degrees(np.angle(h)) - (360 if np.angle(h) > 0 else 0), abs=1.0)


def test_schroeder_fit_is_sharper_still():
    data = measured("sloac", SCHROEDER, wn_rad_s=48.0, zeta=0.55, delay_s=0.005, seed=2)
    ra = analyze_record(data)
    fr = next(f for f in ra.results["frequency_response"] if f.response.output == "position_deg")
    assert fr.kind == "schroeder"
    assert "harmonics of 1/20 s over 2 whole period" in fr.response.method
    assert fr.fit.wn_rad_s.value == pytest.approx(48.0, rel=0.005)
    assert fr.fit.zeta.value == pytest.approx(0.55, rel=0.01)
    assert fr.fit.delay_s.value == pytest.approx(0.005, abs=1e-4)


def test_noisy_output_says_where_the_coherence_drops():
    data = measured("loada", SWEEP.replace("amp_deg=1", "amp_deg=0.4"), noise_deg=0.15, seed=3)
    ra = analyze_record(data, Options(at_hz=(1.0, 5.0, 16.0)))
    fr = ra.results["frequency_response"][0]
    above, note = fr.low_coherence_above_hz, fr.coherence_note
    assert above is not None
    assert 5.0 < above < 18.0
    assert note.startswith("coherence < 0.8 above")
    assert [bool(row.get("note")) for row in fr.at] == [False, False, True]
    # The fit keeps to the coherent points and still lands near the low-noise estimate.
    quiet_ra = analyze_record(measured("loada", SWEEP.replace("amp_deg=1", "amp_deg=0.4"), seed=3))
    quiet = quiet_ra.results["frequency_response"][0].fit
    assert fr.fit.wn_rad_s.value == pytest.approx(quiet.wn_rad_s.value, rel=0.05)
    assert fr.fit.wn_rad_s.sigma > 3 * quiet.wn_rad_s.sigma


def test_model_overlay_of_the_generating_model_is_the_measurement():
    data = measured("loada", SWEEP, noise_deg=0.0)
    ra = analyze_record(data, Options(model="loada"))
    fr = ra.results["frequency_response"][0]
    assert fr.overlay is not None
    assert np.allclose(fr.overlay.h, fr.response.h, rtol=1e-6)
    other = analyze_record(data, Options(model="loadf")).results["frequency_response"][0].overlay
    assert not np.allclose(other.h, fr.response.h, rtol=1e-2)  # LOADF leads: a different curve


def test_non_uniform_200hz_record_is_resampled_and_still_fits():
    """A bag-like record: 200 Hz with ±0.4 ms jitter on the time stamps."""
    data = measured("sloac", SWEEP, seed=4)
    rng = np.random.default_rng(4)
    idx = np.arange(0, data.time_s.size, 5)
    t = data.time_s[idx] + rng.uniform(-4e-4, 4e-4, idx.size)
    t[0] = data.time_s[0]
    sub = replace(data, time_s=t, command_deg=data.command_deg[idx], position_deg=data.position_deg[idx],
                  surface_deg=data.surface_deg[idx], hinge_moment_inlb=data.hinge_moment_inlb[idx],
                  command_v=None, position_v=None)
    ra = analyze_record(sub)
    assert any("samples taken as uniform at 200 Hz" in n for n in ra.notes)
    fit = ra.results["frequency_response"][0].fit
    assert fit.wn_rad_s.value == pytest.approx(56.5, rel=0.02)
    assert fit.zeta.value == pytest.approx(0.65, rel=0.03)
    assert fit.delay_s.value == pytest.approx(0.004, abs=5e-4)


def test_record_with_a_gap_is_resampled_with_the_command_held():
    data = measured("loada", "steps:amps_deg=1", seed=5)
    keep = (data.time_s < 0.9) | (data.time_s > 1.2)  # 300 ms missing from the hold
    sub = replace(data, **{k: getattr(data, k)[keep] for k in ("time_s", "command_deg", "position_deg", "surface_deg",
                                                              "hinge_moment_inlb", "command_v", "position_v")})
    ra = analyze_record(sub)
    assert any("resampled at 1000 Hz, command held" in n for n in ra.notes)
    assert ra.data.time_s.size == data.time_s.size
    assert np.array_equal(np.unique(ra.data.command_deg), [0.0, 1.0])
    assert ra.results["steps"][0].fit.wn_rad_s.value == pytest.approx(57.8, rel=0.02)


def test_zoh_factor_is_half_a_sample_of_delay():
    f = np.array([10.0])
    z = frf.zoh_factor(f, 1000.0)[0]
    assert np.degrees(np.angle(z)) == pytest.approx(-360 * 10 * 0.0005)
    assert abs(z) == pytest.approx(np.sinc(0.01))


def test_discretization_matches_the_exact_linear_model():
    _, rec, _ = simulate("sloac", parse_maneuver("steps:amps_deg=1/0.5"), delay_s=0.0043)
    y = sof.simulate(rec.command_deg[0], 0.001, 56.5, 0.65, 0.0043)
    assert np.max(np.abs(y - rec.position_deg[0])) < 1e-9


def test_hand_calculation_inverts_its_own_formulas():
    wn, zeta = 56.5, 0.65
    rise = (1 - 0.4167 * zeta + 2.917 * zeta**2) / wn
    hand = sof.hand_calculation(rise, 4 / (zeta * wn))
    assert hand.wn_rad_s == pytest.approx(wn)
    assert hand.zeta == pytest.approx(zeta)
    assert sof.hand_calculation(0.0, 1.0) is None


@pytest.mark.parametrize("freq", [2.0, 7.5])
def test_sine_dwell_gain_and_phase(freq):
    ra = analyze_record(measured("sloac", f"sine:freq_hz={freq:g},amp_deg=0.4,cycles=30", seed=6))
    (dwell,) = [d for d in ra.results["sine_dwell"] if d.output == "position_deg"]
    h = sof.response(np.array([freq]), 56.5, 0.65, 0.004)[0]
    assert dwell.gain_db == pytest.approx(20 * np.log10(abs(h)), abs=0.05)
    assert dwell.phase_deg == pytest.approx(np.degrees(np.angle(h)), abs=0.5)

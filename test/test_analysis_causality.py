"""A servo never leads its command: the lag measured each way, the timing decision, and the flags on figures."""

import numpy as np
import pytest
from scipy.signal import lfilter

from ema_sim.analysis.estimation import causal
from ema_sim.analysis.estimation.frf import FrequencyResponse
from ema_sim.analysis.estimation.harmonics import Harmonic, lag_at_fundamental
from ema_sim.analysis.estimation.second_order_fit import fit_step, simulate
from ema_sim.analysis.pipeline import Options, analyze_record
from ema_sim.analysis.records import causality
from ema_sim.analysis.records.command_hold import detect_command_hold
from ema_sim.analysis.records.series import uniform_record
from ema_sim.analysis.section2.frequency_response import FrequencyResult
from ema_sim.io.measured import MeasuredData

FINE_S = 1e-4


def _servo(demand: np.ndarray, tau_s: float) -> np.ndarray:
    """A first-order servo (equivalent delay ``tau_s``) following ``demand`` on a fine grid."""
    a = np.exp(-FINE_S / tau_s)
    return lfilter([1.0 - a], [1.0, -a], demand, zi=[a * demand[0]])[0]


def _profile(t: np.ndarray, period_s: float, amp: float, ramp_s: float) -> np.ndarray:
    """A profiled square: ramps of ``ramp_s`` (smooth, cosine velocity) between two levels, rests between."""
    phase = np.mod(t, period_s)
    half = period_s / 2.0

    def ramp(x: np.ndarray) -> np.ndarray:
        s = np.clip(x / ramp_s, 0.0, 1.0)
        return s - np.sin(2 * np.pi * s) / (2 * np.pi)

    return amp * np.where(phase < half, ramp(phase), 1.0 - ramp(phase - half))


def _log(fine_t: np.ndarray, demand: np.ndarray, y: np.ndarray, rate_hz: float, *, sampled: bool,
         seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Log at ``rate_hz``: the demand sampled at the stamp, or held (the actuator saw the held staircase)."""
    rng = np.random.default_rng(seed)
    k = np.arange(int(fine_t[-1] * rate_hz) - 1)
    t = k / rate_hz
    idx = np.round(t / FINE_S).astype(int)
    u = demand[idx]
    noise = rng.normal(0.0, 1e-4, idx.size)
    if sampled:
        return t, u, y[idx] + noise
    return t, u, y + noise  # the caller ran the servo on the held staircase and sampled it at the stamps


def test_a_first_order_servo_lags_a_held_command_by_its_time_constant_and_half_a_sample_more_if_sampled():
    """The lag of rest-to-rest moves: held, the servo's own equivalent delay; sampled, half a sample more."""
    rate, tau = 100.0, 0.02
    fine = np.arange(0.0, 12.0, FINE_S)
    t = np.arange(0.0, 11.9, 1.0 / rate)
    steps = np.where(np.mod(t, 2.0) < 1.0, 1.0, 0.0)
    held = steps[np.clip(np.searchsorted(t, fine, side="right") - 1, 0, t.size - 1)]
    y = _servo(held, tau)[np.round(t / FINE_S).astype(int)]
    lags_held, lags_sampled = causality.move_lags(t, steps, y, 1e-3)
    assert lags_held.size >= 10
    # the trapezoid over a sampled exponential overestimates its area by about T²/(12·tau): 0.4 ms here
    assert np.median(lags_held) == pytest.approx(tau + (1.0 / rate) ** 2 / (12 * tau), abs=1.5e-4)
    assert np.median(lags_sampled - lags_held) == pytest.approx(0.5 / rate, rel=1e-6)
    c = causality.measure(t, steps, y, 1e-3)
    assert c.method == "moves"
    assert not c.held_leads
    assert not c.sampled_leads


def test_a_fast_servo_on_a_sampled_profile_refutes_the_hold_and_the_decision_says_sampled():
    """Gentle profiles leave no step-like onset to test; the servo would lead a held command: sampled."""
    rate, tau = 100.0, 0.002
    fine = np.arange(0.0, 20.0, FINE_S)
    demand = _profile(fine, 2.0, 5.0, 0.3)
    y = _servo(demand, tau)
    t, u, yl = _log(fine, demand, y, rate, sampled=True)
    hold = detect_command_hold(t, u, yl, 1e-4)
    assert hold.onset_sampled is None  # the onsets alone cannot tell
    assert hold.causality is not None
    assert hold.causality.held_leads
    assert hold.causality.lag_sampled_s == pytest.approx(tau, abs=1e-3)
    assert hold.sampled is True
    assert hold.leads == ""


def test_a_slow_servo_on_a_profile_leaves_the_timing_undecided_and_analyze_gives_both():
    """Nothing refutes either assumption: undecided, and ema analyze lists each timing figure both ways."""
    rate, tau = 100.0, 0.03
    fine = np.arange(0.0, 20.0, FINE_S)
    demand = _profile(fine, 2.0, 5.0, 0.3)
    y = _servo(demand, tau)
    t, u, yl = _log(fine, demand, y, rate, sampled=True)
    hold = detect_command_hold(t, u, yl, 1e-4)
    assert hold.sampled is None
    assert "undecided" in hold.statement
    ra = analyze_record(MeasuredData(time_s=t, command_deg=u, position_deg=yl, source="slow"), Options())
    assert ra.other_timing
    phases = [f for f in ra.other_timing if f["quantity"] == "phase_deg"]
    assert phases
    for f in phases:  # the sampled command is half a sample earlier: its phase lags more
        assert f["sampled"] < f["held"]


def test_a_lead_beyond_its_uncertainty_is_flagged_never_ok():
    """Phases above zero and negative delays beyond their standard errors get ``non_causal`` and the causes."""
    assert causal.phase_leads(1.8, 0.08)
    assert not causal.phase_leads(0.1, 0.08)
    assert not causal.phase_leads(-3.0, 0.01)
    assert causal.delay_leads(-0.003, 0.0005)
    assert not causal.delay_leads(-0.0005, 0.0005)
    assert "never leads" in causal.phase_note(1.8, 0.08, 0.5)
    h = Harmonic(1, 0.5, 5.0, 0.0, 0.01, 1.8, 0.08, 1.0, "non_causal", "")
    lag = lag_at_fundamental([h])
    assert lag.quality == "non_causal"
    assert lag.value is not None
    assert lag.value < 0


def test_a_sampled_profile_forced_held_gets_its_harmonic_phases_flagged():
    """The issue's case: a profiled square sampled at 100 Hz, analysed as held, leads by half a sample minus
    the servo's lag; every such harmonic is ``non_causal``, and the record's causality line says why."""
    rate, tau = 100.0, 0.002
    fine = np.arange(0.0, 20.0, FINE_S)
    demand = _profile(fine, 2.0, 5.0, 0.3)
    y = _servo(demand, tau)
    t, u, yl = _log(fine, demand, y, rate, sampled=True)
    data = MeasuredData(time_s=t, command_deg=u, position_deg=yl, source="forced")
    ra = analyze_record(data, Options(command="held"))
    assert "lead" in ra.command.leads
    harmonics = [h for r in ra.results.get("periodic", []) for h in r.harmonics]
    assert harmonics
    leading = [h for h in harmonics if h.phase_deg > 2 * h.phase_sigma_deg and h.phase_deg > 0]
    assert leading
    assert all(h.quality == "non_causal" for h in leading)
    detected = analyze_record(data, Options())
    assert detected.command.sampled is True
    assert all(h.phase_deg < 0 or h.quality == "non_causal"
               for r in detected.results.get("periodic", []) for h in r.harmonics)


def test_resampling_a_held_command_does_not_delay_it():
    """Stamps that drift (a gap-free logger whose period wanders) are resampled; a held staircase is taken at
    the level it has half a step later, so its changes land within half a step of where they were logged."""
    rng = np.random.default_rng(3)
    dt = np.full(1500, 0.01) + rng.uniform(-0.001, 0.001, 1500)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    u = np.where(np.mod(t, 1.0) < 0.5, 1.0, 0.0)
    data = MeasuredData(time_s=t, command_deg=u, position_deg=u.copy())
    out = uniform_record(data)
    assert "resampled" in out.metadata
    assert "not resampled" not in out.metadata["resampled"]
    logged = t[np.flatnonzero(np.diff(u)) + 1]
    logged = logged[logged < out.time_s[-1] - 0.02]
    grid = out.time_s[np.flatnonzero(np.diff(out.command_deg)) + 1]
    shift = np.array([grid[np.argmin(np.abs(grid - x))] - x for x in logged])
    assert np.all(np.abs(shift) <= 0.5 * 0.0111)
    assert abs(float(np.mean(shift))) < 0.001


def test_a_sampled_step_fit_whose_delay_sits_on_its_lead_bound_says_why() -> None:
    """An output logged ahead of its sampled demand drives the fit's delay to the search's lower bound: the note
    says that bound is the earliest a sampled command can have changed and names a lead's causes."""
    dt = 0.01
    t = np.arange(0.0, 3.0, dt)
    cmd = np.where(t >= 0.5, 2.0, 0.0)
    y = simulate(cmd, dt, 60.0, 0.8, 0.0)
    ahead = np.concatenate([y[2:], [y[-1], y[-1]]])  # the output two samples early: a lead no servo has
    fit = fit_step(t, cmd, ahead, test="step", output_name="position", sampled=True)
    assert fit.actuator_delay_s < 0.0
    assert fit.quality in ("on_bound", "non_causal")
    assert "leads its command" in fit.quality_note or "leads the command" in fit.quality_note
    assert "sampled" in fit.quality_note


def test_a_measured_response_whose_coherent_points_lead_is_not_causal_whatever_its_fit_says() -> None:
    """A frequency response that leads at coherent points gets ``non_causal`` and the causes, on top of its fit's."""
    f = np.geomspace(0.5, 5.0, 20)
    phase = np.where((f > 2.5) & (f < 3.2), 1.0, -10.0 * f)  # a few points a degree ahead of the command
    h = 10 ** (-0.1 / 20) * np.exp(1j * np.radians(phase))
    fr = FrequencyResponse("position_deg", "sweep", f, h, np.full(f.size, 0.99), np.full(f.size, np.radians(0.2)),
                           0.0, 30.0)
    result = FrequencyResult("frequency_response", fr, None, "", [], None, "", None, None, (0.5, 5.0),
                             bandwidth_quality="on_bound", bandwidth_quality_note="gain within 3 dB")
    assert result.quality == "not_determined"  # no fit: the worst of all
    assert "lead the command" in result.leads
    assert "a servo never leads its command" in result.as_dict()["quality_note"]
    clean = FrequencyResult("frequency_response", FrequencyResponse("position_deg", "sweep", f, 10 ** (-0.1 / 20)
                                                                    * np.exp(-1j * np.radians(10.0 * f)),
                                                                    np.full(f.size, 0.99),
                                                                    np.full(f.size, np.radians(0.2)), 0.0, 30.0),
                            None, "", [], None, "", None, None, (0.5, 5.0), bandwidth_quality="on_bound")
    assert clean.leads == ""
    assert clean.quality == "not_determined"


def _delayed_servo_log(demand_of_t, delay_s: float, tau_s: float, span_s: float = 12.0, rate_hz: float = 1000.0):
    """``demand_of_t`` sampled at ``rate_hz`` and held, through a delay and a first-order servo, logged with noise."""
    fine = np.arange(0.0, span_s, FINE_S)
    t = np.arange(0.0, span_s - 0.01, 1.0 / rate_hz)
    u = demand_of_t(t)
    held = u[np.clip(np.searchsorted(t, fine - delay_s, side="right") - 1, 0, t.size - 1)]
    y = _servo(held, tau_s)[np.round(t / FINE_S).astype(int)]
    return t, u, y + np.random.default_rng(3).normal(0.0, 1e-3, t.size)


def _chirp(t: np.ndarray) -> np.ndarray:
    return np.sin(2 * np.pi * (0.5 * t + 0.5 * (6.0 / 12.0) * t**2))  # 0.5 → 6.5 Hz over 12 s


def test_a_chirp_through_a_long_delay_lags_by_the_delay_and_the_servo_s_lag_never_leads():
    """40 ms of transport delay and a 20 ms servo: about 60 ms, beyond the ±30 samples the search once had."""
    t, u, y = _delayed_servo_log(_chirp, 0.040, 0.020)
    c = causality.measure(t, u, y, 3e-3)
    assert c.method == "windows"
    assert c.measured
    assert c.lag_sampled_s == pytest.approx(0.060, abs=0.006)
    assert not c.sampled_leads
    assert not c.held_leads


def test_a_sine_dwell_lagging_beyond_the_old_search_is_never_taken_for_a_lead():
    """An 8 Hz dwell lagging 50 ms aligns as well with the opposite sign 12.5 ms early, and one period later:
    the lag is known only modulo the period, so the dwell decides nothing (and claims no lead)."""
    t, u, y = _delayed_servo_log(lambda x: np.sin(2 * np.pi * 8.0 * x), 0.025, 0.025)
    c = causality.measure(t, u, y, 3e-3)
    assert not c.sampled_leads
    assert not c.held_leads
    assert not c.measured  # every window is ambiguous: nothing decided


def test_an_output_that_leads_a_chirp_is_still_caught():
    t, u, y = _delayed_servo_log(_chirp, 0.0, 0.002)
    lead = 25  # samples: the output logged 25 ms early
    c = causality.measure(t[:-lead], u[:-lead], y[lead:], 3e-3)
    assert c.measured
    assert c.lag_sampled_s == pytest.approx(-0.023, abs=0.004)
    assert c.sampled_leads

"""Issue 14: ``ema analyze`` on records shaped like small industrial EMAs' bench logs and the suite's bags.

Every record here is generated to have the shape that misled the tool (:mod:`rig_data`: 70–100 Hz
jittery integer-millisecond stamps, positions in counts of 0.01, profiled trapezoid demands,
sampled commands, ±80° travel, no hinge moment; :func:`suite_bag`: a bag whose EMAC side went
through the AIL test environment, with small steps and the bus voltage).
"""

import json
from dataclasses import replace

import numpy as np
import pytest
from rig_data import Actuator, rig_record, sine_sweep, square_wave, trapezoid_moves

from ema_sim.analysis.estimation.linearity import amplitude_change
from ema_sim.analysis.estimation.noise import detect_resolution, output_noise
from ema_sim.analysis.estimation.second_order_fit import fit_step
from ema_sim.analysis.pipeline import Options, analyze_record
from ema_sim.analysis.plots import has_load, write_plots
from ema_sim.analysis.records.command_hold import detect_command_hold
from ema_sim.analysis.report import to_json, to_markdown
from ema_sim.cli import main
from ema_sim.io.measured import MeasuredData


def kinds(ra):
    return [s.kind for s in ra.recognition.segments]


# ---------------------------------------------------------------------------------------------- 1: the crash
def one_mm_square_file(tmp_path, **kw):
    """A linear actuator's log: a 1 mm square wave, time in ms, positions in counts of 0.01 mm, tab separated."""
    t, u = square_wave(1.0, 0.5, 4)
    d = rig_record(t, u, act=Actuator(delay_s=0.0), rate_hz=80.0, seed=1, **kw)
    path = tmp_path / "square_1mm.tsv"
    rows = [f"{round(1e3 * a)}\t{b:.2f}\t{c:.2f}" for a, b, c in zip(d.time_s, d.command_deg, d.position_deg,
                                                                     strict=True)]
    path.write_text("time\tdemand\tactual\n" + "\n".join(rows) + "\n")
    return path


def test_a_square_wave_whose_delay_fit_sits_on_its_zero_bound_is_reported_not_a_crash(tmp_path):
    """The demand changed 1.5 ms before each log sample and the actuator has no delay: a held-command fit
    wants a negative delay and ends on its 0 bound, where the Jacobian used to evaluate τ = −h."""
    path = one_mm_square_file(tmp_path)
    out = tmp_path / "a.json"
    rc = main(["analyze", str(path), "--columns", "time_ms=time,command_mm=demand,position_mm=actual",
               "--command", "held", "--json", str(out), "--report", str(tmp_path / "rep")])
    assert rc == 0
    rec = json.loads(out.read_text())["records"][0]
    assert rec["unit"] == "mm"
    on_bound = [s for s in rec["steps"] if s["fit"] and s["fit"]["quality"] == "on_bound"]
    assert on_bound, "the aligned sampling puts some fits on the 0 bound"
    for s in on_bound:
        f = s["fit"]
        assert f["delay_s"]["value"] == pytest.approx(0.0, abs=1e-9)
        assert np.isfinite(f["wn_rad_s"]["sigma"])
        assert "delay on its lower bound 0" in f["quality_note"]
        assert "--command sampled" in f["quality_note"]
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "**on a bound**" in md
    assert "Positions are in mm as logged" in md


def test_a_fit_on_its_bound_has_a_jacobian_inside_the_bounds():
    t = np.arange(0, 1.0, 0.0125)
    u = np.where(t >= 0.2, 1.0, 0.0)
    y = np.where(t >= 0.2, 1 - np.exp(-(t - 0.2 + 0.006) * 40.0) * (1 + 40.0 * (t - 0.2 + 0.006)), 0.0)
    fit = fit_step(t, u, y, test="early", output_name="position_deg")
    assert fit.delay_s.value == pytest.approx(0.0, abs=1e-9)
    assert fit.quality == "on_bound"
    assert np.isfinite([fit.wn_rad_s.sigma, fit.zeta.sigma, fit.delay_s.sigma]).all()
    sampled = fit_step(t, u, y, test="early", output_name="position_deg", sampled=True)
    assert -0.0125 <= sampled.delay_s.value < 0.0
    assert sampled.rms < fit.rms


# ---------------------------------------------------------------------------------------------- 2: trapezoids
@pytest.mark.parametrize(("targets", "speed", "accel", "dwell"), [
    ([20, -20, 20, -20, 80, -80, 0], 40.0, 150.0, 1.0),  # moves to ±80° (rotary travel)
    ([10, -10] * 6, 30.0, 200.0, 0.4),  # back and forth: a steady tone with dwells
])
def test_trapezoid_demands_are_profiled_moves_not_triangles_sines_or_crosstalk(targets, speed, accel, dwell):
    act = Actuator(wn_rad_s=40.0, zeta=0.7, delay_s=0.002)
    t, u = trapezoid_moves(targets, speed_dps=speed, accel_dps2=accel, dwell_s=dwell)
    ra = analyze_record(rig_record(t, u, act=act, rate_hz=80.0, seed=4))
    assert kinds(ra) == ["profile"]
    assert ra.results["crosstalk"] == []
    assert ra.results["sine_dwell"] == []
    (p,) = ra.results["profiled_moves"]
    assert len(p.moves) == len(targets)
    assert [round(m.jump_deg) for m in p.moves] == list(np.diff([0, *targets]))
    assert all(m.speed_dps == pytest.approx(speed, rel=0.03) for m in p.moves)
    # A type-1 second order follows a ramp 2ζ/ωn + τ behind.
    assert p.lag_s == pytest.approx(2 * act.zeta / act.wn_rad_s + act.delay_s, rel=0.1)
    assert not any(m.saturated for m in p.moves)
    text = "\n".join(to_markdown([ra], {}).splitlines())
    assert "Crosstalk" not in text
    assert "ABOVE" not in text


def test_a_move_faster_than_the_actuator_is_saturated_with_the_measured_slew():
    t, u = trapezoid_moves([40, -40, 0], speed_dps=150.0, accel_dps2=2000.0, dwell_s=0.8)
    ra = analyze_record(rig_record(t, u, act=Actuator(rate_dps=100.0), rate_hz=90.0, seed=5))
    (p,) = ra.results["profiled_moves"]
    assert p.quality == "saturated"
    fast = [m for m in p.moves if abs(m.jump_deg) >= 40]
    assert all(m.saturated and m.output_rate_dps == pytest.approx(100.0, rel=0.05) for m in fast)


def test_tracking_error_on_a_triangle_is_not_crosstalk():
    """A back-and-forth profile with no dwell is a triangle; the actuator's lag behind it is not crosstalk."""
    t, u = trapezoid_moves([10, -10] * 6, speed_dps=60.0, accel_dps2=3000.0, dwell_s=0.0)
    ra = analyze_record(rig_record(t, u, act=Actuator(rate_dps=50.0), rate_hz=100.0, seed=6))
    assert "triangle" in kinds(ra)
    (c,) = ra.results["crosstalk"]
    assert c.quality == "not_determined"
    assert c.verdict == "not judged"
    assert "tracking error" in c.quality_note


# ---------------------------------------------------------------------------------------------- 3: bounds, saturation
def test_a_sweep_that_saturates_the_rate_reports_no_small_signal_bandwidth():
    """±5° to 5 Hz asks for 157 °/s of an actuator that slews 100 °/s."""
    t, u = sine_sweep(5.0, 0.2, 5.0, 60.0)
    ra = analyze_record(rig_record(t, u, rate_hz=77.0, seed=7), Options(command="sampled"))
    (fr,) = ra.results["frequency_response"]
    assert fr.slew.command_peak_rate_dps == pytest.approx(157.0, rel=0.06)
    assert fr.slew.saturated_from_hz is not None
    assert fr.bandwidth_quality == "saturated"
    assert "rate saturation, not the small-signal bandwidth" in fr.bandwidth_quality_note
    assert fr.fit_band_hz[1] <= fr.slew.saturated_from_hz
    quiet = analyze_record(rig_record(*sine_sweep(1.0, 0.2, 5.0, 60.0), rate_hz=77.0, seed=7),
                           Options(command="sampled"))
    (fr1,) = quiet.results["frequency_response"]
    assert fr1.slew.saturated_from_hz is None
    assert fr1.bandwidth_quality == "ok"
    # Sampled (not held): no hold divided out, so no half sample (6.5 ms) of phase lead pushes the delay below 0.
    assert fr1.fit.wn_rad_s.value == pytest.approx(40.0, rel=0.1)
    assert fr1.fit.zeta.value == pytest.approx(0.7, rel=0.05)
    assert 0.0 <= fr1.fit.delay_s.value <= 0.004


def test_a_natural_frequency_above_nyquist_is_on_its_bound_not_a_result():
    """A 50 Hz log of an actuator whose ωn (300 rad/s, 48 Hz) lies above its Nyquist frequency (25 Hz)."""
    t, u = sine_sweep(0.5, 0.2, 10.0, 40.0)
    data = rig_record(t, u, act=Actuator(wn_rad_s=300.0, zeta=0.6, delay_s=0.0, rate_dps=1000.0), rate_hz=50.0,
                      jitter_s=0.0005, counts=0.001, sampled=False, seed=8)
    (fr,) = analyze_record(data, Options(command="held")).results["frequency_response"]
    assert fr.fit.quality in ("on_bound", "not_determined")
    if fr.fit.quality == "on_bound":
        assert "Nyquist" in fr.fit.quality_note or "bound" in fr.fit.quality_note
    summary = "\n".join(to_markdown([analyze_record(data, Options(command="held"))], {}).splitlines())
    assert "**on a bound**" in summary or "**not determined**" in summary


# ---------------------------------------------------------------------------------------------- 4: counts
def test_a_count_toggling_at_random_is_no_limit_cycle_and_the_floor_is_the_counts():
    rng = np.random.default_rng(9)
    t = np.arange(0, 20, 1 / 80.0)
    pos = np.full(t.size, 12.34)
    pos[rng.random(t.size) < 0.08] += 0.01  # one count up now and then
    data = MeasuredData(time_s=t, command_deg=np.full(t.size, 12.34), position_deg=pos)
    assert detect_resolution(pos) == 0.01
    nf = output_noise(pos)
    assert nf.sigma >= 0.01 / np.sqrt(12) - 1e-12
    ra = analyze_record(data)
    assert ra.resolution_deg["position_deg"] == 0.01
    assert ra.noise_deg["position_deg"] >= 0.01 / np.sqrt(12) - 1e-12
    (d,) = ra.results["dither"]
    assert not d.detected
    doc = to_json([ra])["records"][0]
    assert doc["resolution_deg"] == {"position_deg": 0.01}
    assert doc["noise"]["position_deg"]["limited_by_resolution"] is True
    header = to_markdown([ra], {})
    assert "position_deg 0.01°" in header


def test_a_real_limit_cycle_in_counts_is_still_found():
    t = np.arange(0, 20, 1 / 80.0)
    pos = np.round((3.0 + 0.04 * np.sign(np.sin(2 * np.pi * 2.5 * t))) / 0.01) * 0.01
    ra = analyze_record(MeasuredData(time_s=t, command_deg=np.full(t.size, 3.0), position_deg=pos))
    (d,) = ra.results["dither"]
    assert d.detected
    assert d.freq_hz == pytest.approx(2.5, rel=0.01)
    assert d.peak_to_peak_deg == pytest.approx(0.08, abs=0.01)


def test_a_continuous_signal_has_no_resolution():
    rng = np.random.default_rng(10)
    y = np.sin(np.linspace(0, 20, 4000)) + rng.normal(0, 0.003, 4000)
    assert detect_resolution(y) is None
    staircase = np.repeat(np.arange(0.0, 45.0, 5.0), 300)
    assert detect_resolution(staircase, 100.0) is None  # a command's staircase step is no count


# ---------------------------------------------------------------------------------------------- 5: timing
def test_a_sampled_command_is_detected_and_first_motion_comes_with_its_bounds():
    t, u = square_wave(1.3, 0.5, 8)
    sampled = analyze_record(rig_record(t, u, rate_hz=77.0, sampled=True, seed=3))
    assert sampled.command.sampled is True
    (tm,) = sampled.results["timing"]
    assert tm.quality == "not_determined"
    lo, hi = tm.bounds_s
    assert hi - lo <= tm.sample_s + 1e-9
    assert lo <= 0.004  # the actuator's own 2 ms inside them (to the first-motion fit's 2 ms at 77 Hz)
    assert hi >= 0.002
    md = to_markdown([sampled], {})
    assert "sampled (not held)" in md
    assert "the actuator's first motion lies" in md
    held = analyze_record(rig_record(t, u, rate_hz=77.0, sampled=False, seed=3))
    assert held.command.sampled is False
    (tm_h,) = held.results["timing"]
    assert tm_h.quality == "ok"
    assert tm_h.command_to_motion_s == pytest.approx(0.002, abs=0.003)


def test_a_gentle_demand_cannot_tell_held_from_sampled():
    t, u = trapezoid_moves([20, -20], speed_dps=30.0, accel_dps2=100.0, dwell_s=0.5)
    d = rig_record(t, u, rate_hz=80.0, seed=11)
    nf = output_noise(d.position_deg)
    hold = detect_command_hold(d.time_s, d.command_deg, d.position_deg, nf.sigma, nf.resolution)
    assert hold.sampled is None
    assert not hold.assumed_sampled


def test_jittery_stamps_are_straightened_and_drifting_ones_resampled():
    t, u = square_wave(1.0, 0.5, 3)
    ra = analyze_record(rig_record(t, u, rate_hz=90.0, seed=12))
    assert any("samples taken as uniform at 90 Hz" in n for n in ra.notes)
    drift = analyze_record(rig_record(t, u, rate_hz=90.0, seed=12, drift=True))
    assert any("resampled at" in n for n in drift.notes)


# ---------------------------------------------------------------------------------------------- 7: plots
def test_each_result_is_its_own_image_and_no_empty_load_panel(tmp_path):
    t, u = trapezoid_moves([20, -20, 0], speed_dps=40.0, accel_dps2=150.0, dwell_s=1.0)
    steps = analyze_record(rig_record(*square_wave(1.3, 0.5, 2), rate_hz=80.0, seed=2))
    data = rig_record(t, u, rate_hz=80.0, seed=13)
    moves = analyze_record(replace(data, hinge_moment_inlb=np.zeros(data.time_s.size)))
    assert not has_load(moves)
    plots = write_plots([steps, moves], tmp_path)
    n_steps = len(steps.results["steps"])
    assert n_steps >= 4
    assert {f"r0_steps{j}" for j in range(n_steps)} <= set(plots)
    assert "r1_profiled_moves0" in plots
    md = to_markdown([steps, moves], plots)
    for j in range(n_steps):
        assert f"(r0_steps{j}.png)" in md


def _stepped_servo(accel_limit_dps2: float) -> MeasuredData:
    """Steps of 0.5° and 2° through a second order (ωn 60, ζ 0.7, 4 ms delay) whose acceleration is clipped."""
    dt, sub = 1e-3, 10
    t = np.arange(0.0, 8.0, dt)
    u = np.array([0.0, 0.5, 0.0, 2.0, 0.0, -0.5, 0.0, -2.0])[t.astype(int)]
    x = v = 0.0
    y = np.empty_like(t)
    h = dt / sub
    for k in range(t.size):
        target = u[max(k - 4, 0)]
        for _ in range(sub):
            a = float(np.clip(3600.0 * (target - x) - 84.0 * v, -accel_limit_dps2, accel_limit_dps2))
            v += a * h
            x += v * h
        y[k] = x
    y += np.random.default_rng(2).normal(0.0, 0.002, t.size)
    return MeasuredData(time_s=t, command_deg=u, position_deg=y, source="stepped")


def test_a_larger_step_slowed_by_an_acceleration_limit_is_said_not_linear_and_a_linear_servo_is_not():
    """No rate test sees an acceleration limit (the rate never plateaus): the 2° steps' fits differ from the
    0.5° steps' beyond their uncertainty, and the step says its fit is that amplitude's equivalent."""
    limited = analyze_record(_stepped_servo(2000.0), Options()).results["steps"]
    big = [s for s in limited if abs(s.command_step_deg) == 2.0 and s.fit is not None]
    assert big
    assert all("not linear over the amplitudes" in s.fit_note for s in big)
    linear = analyze_record(_stepped_servo(1e9), Options()).results["steps"]
    assert [s for s in linear if s.fit is not None and abs(s.command_step_deg) == 2.0]
    assert all(s.fit_note == "fitted" for s in linear if s.fit is not None)


def test_the_smallest_steps_fit_against_its_twin_is_linear_and_against_a_slowed_larger_step_is_not():
    steps = [s for s in analyze_record(_stepped_servo(2000.0), Options()).results["steps"] if s.fit is not None]
    small = [s for s in steps if abs(s.command_step_deg) == 0.5]
    big = next(s for s in steps if abs(s.command_step_deg) == 2.0)
    assert amplitude_change(small[0].fit, small[0].amplitude_deg, small[1].fit) == ""
    said = amplitude_change(small[0].fit, small[0].amplitude_deg, big.fit)
    assert said.startswith("not linear over the amplitudes: ωn 54.8 and delay 9.")
    assert "at the 0.5° step" in said

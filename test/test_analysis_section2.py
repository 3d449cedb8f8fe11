"""Section-2 analyses against known truth: command error, compliance, hysteresis, free play, thresholds,
crosstalk, dither and regeneration."""

from dataclasses import replace

import numpy as np
import pytest
from analysis_data import measured

from ema_sim.analysis.pipeline import Options, analyze_record, analyze_records
from ema_sim.analysis.section2.hysteresis import hysteretic_damping_constant
from ema_sim.calibration import command_error
from ema_sim.config import load_channel
from ema_sim.io.measured import MeasuredData

STAIRCASE = "staircase:step_deg=5,max_deg=40,hold_s=3"
LOAD_STEPS = "steps:step_inlb=222.5,max_inlb=1780,hold_s=2"


# ---------------------------------------------------------------------------------------------- command error
@pytest.mark.parametrize(("kb", "offset"), [(0.006, -0.03), (-0.004, 0.02)])
def test_staircase_gives_the_command_error(kb, offset):
    ra = analyze_record(measured("loada", STAIRCASE, kb=kb, offset_deg=offset, quantization_deg=0.0, seed=7))
    (cal,) = ra.results["command_error"]
    # Direct: settled surface minus command recovers the model's own command-error stage.
    assert cal.direct.kb == pytest.approx(kb, abs=5e-5)
    assert cal.direct.offset_deg == pytest.approx(offset, abs=1e-3)
    assert cal.direct_sigma[0] < 5e-5
    # Curves: the third-order curves reproduce the channel's calibration and its command error.
    ch = load_channel("left_wing")
    assert cal.command_curve.coefficients() == pytest.approx(ch.command_cal.coefficients(), rel=1e-6, abs=1e-9)
    v = np.linspace(-9, 9, 19)
    assert np.max(np.abs(cal.feedback_curve(v) - ch.feedback_cal(v))) < 2e-3
    truth = command_error(ch.command_cal, ch.feedback_cal, cal.nominal_deg)
    assert cal.curve_error.kb == pytest.approx(truth.kb, abs=5e-5)
    assert cal.curve_error.offset_deg == pytest.approx(truth.offset_deg, abs=1e-3)
    # Four-corner bounds of one calibration: ±(|Kb|·δ + |offset|).
    lo, hi = cal.bounds_deg
    top = abs(cal.error.kb) * 40 + abs(cal.error.offset_deg)
    assert hi[-1] == pytest.approx(top)
    assert lo[-1] == pytest.approx(-top)


def test_staircase_without_volts_gives_the_direct_error_only():
    data = replace(measured("loada", STAIRCASE, kb=0.006, quantization_deg=0.0), command_v=None, position_v=None)
    (cal,) = analyze_record(data).results["command_error"]
    assert cal.curve_error is None
    assert cal.error.kb == pytest.approx(0.006, abs=5e-5)
    assert "no command_v/position_v" in cal.notes[0]


# ---------------------------------------------------------------------------------------------- compliance
@pytest.mark.parametrize(("command", "kcp", "compliance", "free_play"),
                         [(15.0, 0.008, 0.5, 0.2), (10.0, 0.02, 0.3, 0.171)])
def test_load_staircase_gives_both_compliance_curves(command, kcp, compliance, free_play):
    ra = analyze_record(measured("loada", f"hold:value_deg={command:g},hold_s=67", LOAD_STEPS, kcp_per_kinlb=kcp,
                                 compliance_deg_per_kinlb=compliance, free_play_deg=free_play, seed=8))
    (c,) = ra.results["compliance"]
    lvdt_truth = command * kcp  # K_CP scales the command with the aiding load: °/1000 in·lb
    total_truth = lvdt_truth + compliance
    assert c.lvdt.slope_deg_per_kinlb == pytest.approx(lvdt_truth, rel=0.03)
    assert c.total.slope_deg_per_kinlb == pytest.approx(total_truth, rel=0.02)
    assert c.share_outside == pytest.approx(compliance / total_truth, abs=0.01)
    assert c.total.gap_deg == pytest.approx(free_play, abs=0.005)
    assert abs(c.lvdt.gap_deg) < 0.005
    # Three segments: the free-play region is the steep one; the outer slopes are the compliance.
    m = c.total.mean
    per_lb = total_truth * 1e-3 * c.crank_arm_in
    assert m.slopes_deg_per_lb[2] == pytest.approx(per_lb, rel=0.1)
    assert m.slopes_deg_per_lb[0] > 1.5 * m.slopes_deg_per_lb[2]
    force = np.linspace(-1000, 1000, 41)
    assert np.all(c.total.upper(force[force > 0]) >= c.total.lower(force[force > 0]) - 1e-12)
    assert np.all(c.total.upper.slopes_deg_per_lb >= np.array(m.slopes_deg_per_lb) - 1e-12)


def test_compliance_without_a_surface_sensor_is_lvdt_only():
    data = replace(measured("loada", "hold:value_deg=15,hold_s=67", LOAD_STEPS, kcp_per_kinlb=0.008), surface_deg=None)
    (c,) = analyze_record(data).results["compliance"]
    assert c.total is None
    assert c.share_outside is None
    assert "no external surface angle" in c.notes[0]


def test_no_hinge_moment_no_loaded_analyses():
    data = replace(measured("loada", "hold:value_deg=0,hold_s=10"), hinge_moment_inlb=None)
    ra = analyze_record(data)
    assert ra.not_computed["compliance"] == "no hinge moment: compliance not computed"
    assert ra.not_computed["hysteresis"] == "no hinge moment: hysteretic damping not computed"


# ---------------------------------------------------------------------------------------------- hysteresis
def test_rw13_arithmetic():
    assert hysteretic_damping_constant(4.88, 0.02155) == pytest.approx(3344.84, abs=0.01)


def hysteretic_record(h_lb_per_in, peak_in, omega_rad_s, amp_inlb=1780.0, noise_deg=0.0033, seed=9):
    """A surface on a spring with hysteretic damping, F = (k + i·h)·x, under a sinusoidal load."""
    crank = load_channel("right_wing").crank_arm_in
    f0 = amp_inlb / crank
    mag = f0 / peak_in
    k = np.sqrt(mag**2 - h_lb_per_in**2)
    lag = np.arctan2(h_lb_per_in, k)
    fs = 200.0
    t = np.arange(0.0, 3 * 2 * np.pi / omega_rad_s + 2.0, 1 / fs)
    load = amp_inlb * np.sin(omega_rad_s * t)
    x_in = peak_in * np.sin(omega_rad_s * t - lag)
    rng = np.random.default_rng(seed)
    surf = np.degrees(x_in / crank) + rng.normal(0, noise_deg, t.size)
    pos = rng.normal(0, noise_deg, t.size)
    return MeasuredData(time_s=t, command_deg=np.zeros_like(t), position_deg=pos, surface_deg=surf,
                        hinge_moment_inlb=load, metadata={"channel": "right_wing"}, source="rw13-like")


def test_hysteresis_loop_reproduces_rw13():
    """The report's rw13: ±1780 in·lb at 0.0785 rad/s, A = 4.88 in·lb, Pk = 0.02155 in."""
    ra = analyze_record(hysteretic_record(3344.84, 0.02155, 0.0785))
    assert [s.kind for s in ra.recognition.segments] == ["load_sine"]
    (h,) = ra.results["hysteresis"]
    assert len(h.cycles) == 3
    assert 2 * np.pi * h.freq_hz == pytest.approx(0.0785, rel=1e-3)
    assert h.area_inlb == pytest.approx(4.88, rel=0.02)
    assert h.peak_in == pytest.approx(0.02155, rel=0.01)
    assert h.h_lb_per_in == pytest.approx(3344.84, rel=0.03)


def test_hysteresis_loop_is_frequency_invariant():
    """Section 3.2.2: the loop of hysteretic damping does not change with frequency (0.785 rad/s)."""
    (h,) = analyze_record(hysteretic_record(1500.0, 0.03, 0.785)).results["hysteresis"]
    assert h.h_lb_per_in == pytest.approx(1500.0, rel=0.03)


def test_second_order_model_has_no_hysteretic_damping():
    ra = analyze_record(measured("loada", "hold:value_deg=0,hold_s=122", "sine:amp_inlb=1780,freq_hz=0.025,cycles=3",
                                 compliance_deg_per_kinlb=0.5, seed=10))
    (h,) = ra.results["hysteresis"]
    assert h.peak_in == pytest.approx(np.radians(0.5 * 1.78 + 0.1) * 1.7317, rel=0.05)
    assert h.h_lb_per_in < 0.02 * 3344.84


# ---------------------------------------------------------------------------------------------- free play
@pytest.mark.parametrize("width", [0.2, 0.171])
def test_load_reversal_gives_the_free_play(width):
    ra = analyze_record(measured("loada", "hold:value_deg=0,hold_s=11", "reversal:inlb=50,period_s=2,reversals=4",
                                 free_play_deg=width, seed=11))
    (fp,) = ra.results["free_play"]
    assert len(fp.reversals) >= 4
    assert fp.width_deg == pytest.approx(width, abs=0.004)


def test_free_play_with_compliance_takes_the_elastic_part_out():
    data = measured("loada", "hold:value_deg=0,hold_s=11", "reversal:inlb=200,period_s=2,reversals=4",
                    compliance_deg_per_kinlb=0.5, seed=12)
    raw = analyze_record(data).results["free_play"][0]
    assert raw.width_deg == pytest.approx(0.2 + 0.5 * 0.4, abs=0.005)
    assert "includes the elastic deflection" in raw.notes[-1]
    net = analyze_record(data, Options(compliance_deg_per_kinlb=0.5)).results["free_play"][0]
    assert net.width_deg == pytest.approx(0.2, abs=0.005)


def test_free_play_needs_the_surface():
    data = replace(measured("loada", "hold:value_deg=0,hold_s=11", "reversal:inlb=50"), surface_deg=None)
    assert "LVDT cannot see it" in analyze_record(data).not_computed["free_play"]


# ---------------------------------------------------------------------------------------------- thresholds
@pytest.mark.parametrize("dead_zone", [0.05, 0.08])
def test_static_threshold_is_the_dead_zone(dead_zone):
    ra = analyze_record(measured("loada", "static_threshold:amp_max_deg=0.3,cycles=6", threshold_deg=dead_zone,
                                 quantization_deg=0.0, seed=13))
    (s,) = ra.results["static_threshold"]
    assert s.onset_deg == pytest.approx(dead_zone, rel=0.12)
    assert s.follow_deg == pytest.approx(2 * dead_zone, rel=0.3)
    assert s.as_dict()["onset_v"] == pytest.approx(s.onset_deg * 0.23577, rel=1e-3)


@pytest.mark.parametrize("dead_zone", [0.05, 0.08])
def test_dynamic_threshold_onset_is_the_dead_zone(dead_zone):
    ra = analyze_record(measured("loada", "dynamic_threshold:amp0_deg=0,amp1_deg=0.3,ramp_s=30",
                                 threshold_deg=dead_zone, quantization_deg=0.0, seed=14))
    (d,) = ra.results["dynamic_threshold"]
    assert d.freq_hz == pytest.approx(5.0)
    assert d.onset_deg == pytest.approx(dead_zone, rel=0.2)
    assert d.follow_deg > d.onset_deg


# ---------------------------------------------------------------------------------------------- crosstalk, dither
def square_noise(t, pp, freq_hz):
    return 0.5 * pp * np.sign(np.sin(2 * np.pi * freq_hz * t + 0.3))


def test_static_crosstalk_against_the_threshold():
    """Section 2.2.1: 0.02 V (≈ 0.086°) of noise on the held right wing, below its threshold."""
    data = measured("loada", "hold:value_deg=0,hold_s=10", channel="right_wing", noise_deg=0.002, seed=15)
    noisy = replace(data, position_deg=data.position_deg + square_noise(data.time_s, 0.08, 4.0))
    (c,) = analyze_record(noisy).results["crosstalk"]
    assert c.peak_to_peak_deg == pytest.approx(0.08 + 6 * 0.002, abs=0.008)
    assert c.excess_rms_deg == pytest.approx(0.04, rel=0.05)
    assert c.dominant_hz == pytest.approx(4.0, rel=0.02)
    assert c.below_threshold
    assert c.threshold_deg == pytest.approx(0.0075 * load_channel("right_wing").deg_per_in)
    louder = replace(data, position_deg=data.position_deg + square_noise(data.time_s, 0.4, 4.0))
    assert not analyze_record(louder).results["crosstalk"][0].below_threshold


def test_dynamic_crosstalk_rides_on_the_triangle():
    data = measured("loada", "triangle:freq_hz=0.5,amp_deg=2.15,cycles=5", noise_deg=0.002, seed=16)
    quiet = analyze_record(data).results["crosstalk"][0]
    noisy = replace(data, position_deg=data.position_deg + square_noise(data.time_s, 0.06, 7.0))
    c = analyze_record(noisy).results["crosstalk"][0]
    assert c.kind.startswith("dynamic")
    assert quiet.excess_rms_deg < 0.004
    assert c.excess_rms_deg == pytest.approx(0.03, rel=0.15)
    assert c.dominant_hz == pytest.approx(7.0, rel=0.02)


def limit_cycle(t, pp, freq_hz):
    """A PWM-like dither: a clipped triangle, not a sine."""
    tri = 2 * np.abs(2 * ((t * freq_hz) % 1.0) - 1) - 1
    return 0.5 * pp * np.clip(1.25 * tri, -1, 1)


@pytest.mark.parametrize(("freq", "pp"), [(3.0, 0.1), (4.7, 0.05)])
def test_dither_frequency_and_size(freq, pp):
    data = measured("loada", "hold:value_deg=2,hold_s=20", noise_deg=0.003, seed=17)
    dithering = replace(data, position_deg=data.position_deg + limit_cycle(data.time_s, pp, freq))
    ra = analyze_record(dithering)
    (d,) = ra.results["dither"]
    assert d.detected
    assert d.freq_hz == pytest.approx(freq, rel=0.005)
    assert d.peak_to_peak_deg == pytest.approx(pp, rel=0.06)
    quiet = analyze_record(data).results["dither"][0]
    assert not quiet.detected
    assert quiet.statement.startswith("no limit cycle")


# ---------------------------------------------------------------------------------------------- regeneration
@pytest.mark.parametrize(("spike", "within"), [(22.0, True), (41.0, False)])
def test_regeneration_bus_peak_against_185_volts(spike, within):
    data = measured("loada", "regen:sweep_s=20", seed=18)
    t = data.time_s
    rng = np.random.default_rng(18)
    # The bus rises for a few milliseconds at every deceleration (each command edge), most at the fastest.
    edges = np.flatnonzero(np.diff(data.command_deg) != 0) + 1
    bus = 150.0 + rng.normal(0, 0.3, t.size)
    for k, i in enumerate(edges):
        bump = spike * (0.5 + 0.5 * k / len(edges)) * np.exp(-np.clip(t - t[i] - 0.02, 0, None) / 0.005)
        bus += np.where(t >= t[i] + 0.02, bump, 0.0)
    ra = analyze_record(replace(data, bus_v=bus))
    g = ra.results["regeneration"][0]
    assert [s.kind for s in ra.recognition.segments] == ["regen"]
    assert g.nominal_v == pytest.approx(150.0, abs=0.5)
    assert g.peak_v == pytest.approx(150 + spike, abs=1.5)
    assert (g.peak_v <= 185.0) is within
    assert analyze_record(data).not_computed["regeneration"].startswith("no bus voltage column")


def test_records_of_one_channel_share_their_threshold_and_compliance():
    thr = measured("loada", "static_threshold:amp_max_deg=0.3,cycles=6", threshold_deg=0.05, quantization_deg=0.0)
    hold = measured("loada", "hold:value_deg=0,hold_s=10", noise_deg=0.002)
    noisy = replace(hold, position_deg=hold.position_deg + square_noise(hold.time_s, 0.08, 4.0))
    comp = measured("loada", "hold:value_deg=0,hold_s=67", LOAD_STEPS, compliance_deg_per_kinlb=0.5)
    rev = measured("loada", "hold:value_deg=0,hold_s=11", "reversal:inlb=200,period_s=2,reversals=4",
                   compliance_deg_per_kinlb=0.5)
    r_thr, r_hold, r_comp, r_rev = analyze_records([thr, noisy, comp, rev])
    (c,) = r_hold.results["crosstalk"]
    assert c.threshold_deg == pytest.approx(r_thr.results["static_threshold"][0].onset_deg)
    assert "static threshold measured in" in c.threshold_source
    assert not c.below_threshold  # 0.09° of noise against a 0.048° threshold
    (fp,) = r_rev.results["free_play"]
    assert fp.width_deg == pytest.approx(0.2, abs=0.005)
    assert fp.compliance_deg_per_kinlb == pytest.approx(r_comp.results["compliance"][0].total.slope_deg_per_kinlb)


def test_a_quantized_still_output_has_no_limit_cycle():
    data = measured("loada", "hold:value_deg=3,hold_s=10", noise_deg=0.0)
    still = replace(data, position_deg=np.round(data.position_deg / 0.02125) * 0.02125)
    (d,) = analyze_record(still).results["dither"]
    assert not d.detected
    assert d.statement == "no limit cycle: the output does not move (peak to peak < 0.0001°)"

"""The high-order family (section 3.2, figures 30–36): specifications, trim, implementations, elements."""

import math

import numpy as np
import pytest
from conftest import FRAME_S, frames

from ema_sim.analysis.section2.hysteresis import hysteretic_damping_constant
from ema_sim.analysis.studies import acceptance as acc
from ema_sim.analysis.studies import hysteresis_study as hyst
from ema_sim.analysis.studies.model_error import figure40
from ema_sim.config import load_channel
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models import Flags, create
from ema_sim.models import noise as nz
from ema_sim.models.high_order import HighOrderParams, Hoac1, Hoad3, P, equilibrium
from ema_sim.models.high_order import gear_train as gt

K_T_D1, K_T_F1, K_T_K1 = P.total_d1_in, P.total_f1_lbf, P.total_k1_lbf_per_in  # kernel slots, renamed with units

ARM_IN = 1.7317
DEG_PER_IN = math.degrees(1.0) / ARM_IN
HIGH_ORDER = ("hoac1", "hoad2", "hoad3")
QUIET = {"noise": False}  # deterministic: noise switched off, everything else as configured


def build(name, channel="left_wing", **kwargs):
    return create(name, channel, **({} if name == "hoac1" else QUIET), **kwargs)


def held(model, t, cmd, hm=None, *, samples=None, end=None):
    """Trim at the first input, then run the record."""
    model.trim(cmd[0], 0.0 if hm is None else hm[0])
    end = t[-1] + FRAME_S if end is None else end
    return model.run(t, cmd, hm, sample_times=t if samples is None else samples, end_s=end)


def lbf(force):
    """Hinge moment (in·lb) of a force at the actuator."""
    return force * ARM_IN


# ------------------------------------------------------------------------------------- trim
@pytest.mark.parametrize("name", HIGH_ORDER)
@pytest.mark.parametrize(
    ("position", "load", "powered"),
    [(0.0, 0.0, True), (12.3, 900.0, True), (-30.0, -1780.0, True), (5.0, 3000.0, True), (40.0, 200.0, True),
     (-8.0, 1500.0, False)],
)
def test_trim_is_an_exact_equilibrium_at_any_position_and_load(name, position, load, powered):
    model = build(name)
    model.set_power(powered)
    start = model.trim(position_deg=position, hinge_moment_inlb=load)
    quant = 0.0 if name == "hoac1" else 0.005 * 4.3  # half a 5 mV step each side, in degrees
    assert abs(start.position_deg[0] - position) <= quant + 1e-9
    u = model.trim_command(np.array([position]), np.array([load]))
    t = frames(1.0)
    rec = model.run(t, np.full_like(t, u[0]), np.full_like(t, load), sample_times=np.arange(0, 1000) / 1000.0,
                    end_s=1.0)
    for column in ("position_deg", "surface_deg", "rate_dps", "current_a", "bus_v"):
        assert np.ptp(getattr(rec, column)) <= 1e-9, column
    assert np.max(np.abs(rec.rate_dps)) == 0.0
    if powered and load != 0.0:
        assert rec.current_a[0, 0] == pytest.approx(-load / ARM_IN / model.params[0].force_per_amp_lbf, rel=1e-9)
        assert not rec.flags[0, 0] & Flags.PWM_DEAD_BAND  # a loaded actuator holds outside the dead band
    if not powered:
        assert rec.flags[0, 0] & Flags.BRAKE
        assert rec.current_a[0, 0] == 0.0


def test_an_unloaded_actuator_rests_in_its_pwm_dead_band_and_a_loaded_one_does_not():
    """Section 4.3's mechanism: small errors draw no current unloaded, but move a loaded actuator."""
    t = frames(1.0)
    step = np.where(t >= 0.2, 0.02, 0.0)  # one D/A step of command
    quiet = build("hoad3", quantization_v=0.0)
    rec = held(quiet, t, step)
    assert np.all(rec.flags[0] & Flags.PWM_DEAD_BAND)
    assert np.ptp(rec.position_deg) == 0.0
    assert np.max(np.abs(rec.current_a)) == 0.0
    loaded = build("hoad3", quantization_v=0.0)
    rec = held(loaded, t, step, np.full_like(t, -1000.0))
    assert not np.any(rec.flags[0, 50:] & Flags.PWM_DEAD_BAND)
    assert 0.01 < rec.position_deg[0, -1] - rec.position_deg[0, 0] < 0.03  # to within the stiction band
    # The dead band is ≈ ±0.04° of servo error (a 0.02° command is well inside; 0.1° is not).
    rec = held(build("hoad3", quantization_v=0.0), t, np.where(t >= 0.2, 0.1, 0.0))
    assert 0.05 < rec.position_deg[0, -1] - rec.position_deg[0, 0] < 0.1


# ------------------------------------------------------------------------- HOAC1: table 1 and A2
def test_hoac1_slews_at_3_5_in_s_unloaded():
    slew = acc.slew_rate_in_s("hoac1")
    assert 3.5 <= slew <= 3.5 * 1.03  # table 1: 3.5 in/s = 115.8 °/s


@pytest.mark.parametrize(
    ("channel", "force", "rate"),
    [("left_wing", 500.0, 3.5), ("left_rudder", 526.0, 3.3), ("cowl_door", 2000.0, 3.1)],
)
def test_hoac1_force_versus_rate_at_125_v(channel, force, rate):
    """Table A2: 3.5 in/s at 500 lbf (wings), 3.3 at 526 lbf (rudders), 3.1 at 2,000 lbf (cowl), 125 V."""
    measured = acc.slew_rate_in_s("hoac1", channel, opposing_lbf=force, supply_v=125.0)
    assert rate <= measured < acc.slew_rate_in_s("hoac1", channel)


def test_hoac1_stall_force_is_at_least_2500_lbf_at_125_v():
    """Table 1/A2: 2,500 lbf stall at 125 V; a larger load backdrives the actuator at its current limit."""
    stall = acc.stall_force_lbf("hoac1", resolution=20.0)
    assert 2500.0 <= stall < 2800.0
    t = acc._frames(0.5)
    model = Hoac1(bus_supply_v=125.0)
    hm = np.full_like(t, -lbf(stall + 100.0))
    rec = held(model, t, np.where(t >= 0.1, 5.0, 0.0), hm, end=0.5)
    assert rec.position_deg[0, -1] < 0.5
    assert rec.flags[0, -1] & Flags.CURRENT_LIMIT


def test_hoac1_backlash_and_static_stiffness_meet_table_1():
    """Brake on: reversing a small load shows the backlash; two large loads the stiffness."""
    mech = acc.backlash_and_stiffness("hoac1")
    assert mech["backlash_in"] == pytest.approx(0.002, rel=1e-3)  # the configured gear backlash
    assert mech["backlash_in"] <= 0.005  # table 1
    assert mech["actuator_lbf_per_in"] == pytest.approx(500_000.0, rel=1e-3)
    assert mech["actuator_lbf_per_in"] >= 400_000.0  # table 1
    assert 400_000.0 <= mech["installed_lbf_per_in"] < mech["actuator_lbf_per_in"]  # backup structure in series


def test_hoac1_brake_holds_more_than_4000_lbf_when_unpowered():
    assert acc.brake_holds("hoac1", force_lbf=4000.0)
    assert not acc.brake_holds("hoac1", force_lbf=4700.0)  # beyond its 4,500 lbf rating it slips


def test_hoac1_minus_3_db_bandwidth_is_at_least_7_5_hz():
    bandwidth = acc.bandwidth_hz("hoac1")
    assert 7.5 <= bandwidth < 12.0


def test_hoac1_bus_regeneration_stays_under_185_v():
    """Section 2.5: a 5 % FS square wave from 0.1 to 5 Hz; regeneration lifts the 150 V bus."""
    peak, low = acc.regeneration_peak_v("hoac1")
    assert 150.5 < peak < 185.0
    assert low < 148.0  # and the motoring current pulls it down


def test_every_acceptance_figure_passes_on_the_rudder():
    figures = acc.acceptance("hoac1", "right_rudder")
    assert len(figures) == 9
    assert all(f.passed for f in figures), acc.format_acceptance(figures)


def test_hoac1_is_converged_halving_the_tolerance_changes_it_negligibly(rich_inputs):
    t, cmd, hm = rich_inputs
    samples = np.arange(0, 6000) / 1000.0
    a = held(Hoac1(), t, cmd, hm, samples=samples, end=6.0)
    fine = Hoac1(rtol=Hoac1.default_rtol / 2, atol=Hoac1.default_atol / 2)
    b = held(fine, t, cmd, hm, samples=samples, end=6.0)
    assert fine.events > 100  # dead band, stiction, backlash contact, limits: every one located
    assert np.max(np.abs(a.position_deg - b.position_deg)) < 1e-7
    assert np.max(np.abs(a.surface_deg - b.surface_deg)) < 1e-7
    assert np.max(np.abs(a.current_a - b.current_a)) < 1e-5


# ------------------------------------------------------------------------- HOAD2 and HOAD3
def test_hoad2_converges_on_hoac1_as_its_rate_rises():
    """Figure 40: HOAC1 against HOAD2 at 10, 20, 50 and 100 kHz, flight/test elements left out.

    The mean error falls with the step; the largest errors are where the surface knocks across its
    backlash, an impact oscillation that is sensitive to every detail of the integration.
    """
    rows = figure40()
    errors = [r.mean_abs_deg for r in rows]
    assert errors[0] > errors[1] > errors[2] > errors[3]
    assert errors[0] / errors[3] > 3.0
    assert errors[0] < 0.01  # at 10 kHz, well under a D/A step (0.02°) on average
    assert rows[0].max_abs_deg > rows[-1].max_abs_deg


def test_hoad_command_and_feedback_are_quantized_at_5_mv_through_the_calibration():
    cfg = load_channel("left_wing")
    model = build("hoad2")
    t = frames(3.0)
    rec = held(model, t, 0.3 * t, samples=np.arange(0, 3000) / 1000.0, end=3.0)
    volts = cfg.position_deg_to_v(rec.position_deg[0])
    assert np.allclose(volts / 0.005, np.round(volts / 0.005), atol=1e-6)  # feedback on the 5 mV grid
    x_in, _ = model._command_in(np.array([[0.0123, 0.3, -7.7]]))
    cmd_volts = cfg.deg_to_v(x_in[0] * DEG_PER_IN)
    assert np.allclose(cmd_volts / 0.005, np.round(cmd_volts / 0.005), atol=1e-9)  # command on the grid
    assert np.max(np.abs(x_in[0] * DEG_PER_IN - [0.0123, 0.3, -7.7])) <= 0.5 * 0.005 * 4.3


@pytest.mark.parametrize("channel", ["left_wing", "right_rudder"])
@pytest.mark.parametrize("kwargs", [{}, {"quantization_v": 0.0}, {"noise": False},
                                    {"noise": False, "quantization_v": 0.0}])
def test_command_path_kernel_is_the_calibration_curves_to_the_last_bit(channel, kwargs):
    """Stage 2 is compiled for speed; it must stay the Cubic curve, its 8 Newton steps and its slope exactly."""
    model = create("hoad3", channel, **kwargs)
    cal = load_channel(channel).command_cal
    u = np.random.default_rng(4).uniform(-32.0, 32.0, (1, 20_000))
    dpi, quant = model.params[0].deg_per_in, model.params[0].quantization_v
    if quant > 0.0 or model.noise:
        volts = cal(u)
        volts = quant * np.floor(volts / quant + 0.5) if quant > 0.0 else volts
        deg = cal.inverse(volts) if quant > 0.0 else u
        want = deg / dpi, 1.0 / (cal.slope(deg) * dpi)
    else:
        want = u / dpi, np.zeros_like(u)
    x_in, slope = model._command_in(u)
    assert np.array_equal(x_in, want[0])
    assert np.array_equal(slope, want[1])


def test_hoad_noise_is_seeded_reproducible_switchable_and_at_its_measured_level():
    t = frames(2.0)
    cmd = np.ones_like(t)

    def position(**kw):
        return held(create("hoad2", quantization_v=0.0, **kw), t, cmd, samples=np.arange(0, 2000) / 1000.0,
                    end=2.0).position_deg[0]

    a, b, c = position(seed=7), position(seed=7), position(seed=8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    off = position(noise=False)
    assert np.ptp(off[500:]) < 1e-9
    # The feedback noise rides on the reading at its configured rms (2 mV ≈ 0.0085°).
    rms_deg = np.std(a[1000:] - off[1000:])
    assert rms_deg == pytest.approx(0.002 * 4.25, rel=0.2)


def test_noise_draws_are_standard_normal_and_streams_independent():
    state = np.array([nz.splitmix64(11)], dtype=np.uint64)
    x = np.array([nz.normal(state) for _ in range(100_000)])
    assert abs(x.mean()) < 0.01
    assert x.std() == pytest.approx(1.0, abs=0.01)
    assert np.mean(np.abs(x) > 2.0) == pytest.approx(0.0455, abs=0.003)  # the tails are right too
    assert np.mean(np.abs(x) > 3.5) == pytest.approx(4.65e-4, abs=2.5e-4)
    state = np.array([nz.splitmix64(12)], dtype=np.uint64)
    other = np.array([nz.normal(state) for _ in range(20_000)])
    assert abs(np.corrcoef(other, x[:20_000])[0, 1]) < 0.03  # neighbouring seeds: unrelated streams
    assert abs(np.corrcoef(x[1:20_001], x[:20_000])[0, 1]) < 0.03  # and no memory from draw to draw


@pytest.mark.parametrize("name", ["hoad3", "hoac1"])
def test_frame_stepping_equals_one_run_noise_included(name, rich_inputs):
    t, cmd, hm = rich_inputs
    kwargs = {"seed": 3} if name == "hoad3" else {}
    a = create(name, **kwargs)
    a.trim(cmd[0], hm[0])
    stepped = np.array([a.step(c, h, FRAME_S).position_deg[0] for c, h in zip(cmd, hm, strict=True)])
    b = create(name, **kwargs)
    b.trim(cmd[0], hm[0])
    ran = b.run(t, cmd, hm, sample_times=t + FRAME_S, end_s=t[-1] + FRAME_S).position_deg[0]
    assert np.max(np.abs(stepped - ran)) < 1e-9


def test_hoad_batch_instances_are_independent_and_equal_single_runs(rich_inputs):
    t, cmd, hm = rich_inputs
    base = HighOrderParams.from_channel(load_channel("left_wing"), "hoad3")
    params = [base.replace(pwm_dead_band_v=v, command_delay_s=d) for v, d in ((0.0, 0.0), (5.7, 0.004), (12.0, 0.02))]
    batch = Hoad3(n=3, params=params, seed=[5, 6, 7])
    batch.trim(cmd[0], hm[0])
    rec = batch.run(t, cmd, hm, end_s=6.0)
    for i, p in enumerate(params):
        single = Hoad3(params=p, seed=5 + i)
        single.trim(cmd[0], hm[0])
        mine = single.run(t, cmd, hm, end_s=6.0)
        assert np.array_equal(mine.surface_deg[0], rec.surface_deg[i])
    assert np.ptp(rec.surface_deg[:, -200]) > 0


def test_hoad3_delays_are_4_ms_to_motion_and_2_ms_more_to_feedback():
    """Section 2.3 (a 10 %-of-travel step): command to first motion 4 ms, motion to feedback 2 ms."""
    model = build("hoad3", quantization_v=0.0)
    t = frames(0.6)
    samples = 0.49 + np.arange(0, 3000) / 100_000.0
    model.trim(0.0)
    rec = model.run(t, np.where(t >= 0.5, 4.3, 0.0), sample_times=samples, end_s=0.6)

    def first(column):
        return samples[np.argmax(np.abs(column[0] - column[0, 0]) > 1e-9)] - 0.5

    motion = first(rec.surface_deg)
    assert 0.004 <= motion <= 0.0045
    assert first(rec.position_deg) - motion == pytest.approx(0.002, abs=1e-4)


@pytest.mark.parametrize("which", ["command_delay_s", "feedback_delay_s"])
def test_hoad3_delays_between_two_steps_blend_them(which):
    """A delay between two of the 10 kHz steps gives the outputs between those of the two whole-step delays,
    in proportion (the mean over the step of the delayed input), so identification can fit it by least squares;
    a whole number of steps is the plain delay. On a 4.3° step, 0.03 ms past a whole step moves the response 30 %
    of the way to the next step's."""
    t = frames(0.6)
    samples = 0.49 + np.arange(0, 3000) / 100_000.0
    cmd = np.where(t >= 0.5, 4.3, 0.0)

    def run(delay):
        model = build("hoad3", quantization_v=0.0, **{which: delay})
        model.trim(0.0)
        rec = model.run(t, cmd, sample_times=samples, end_s=0.6)
        return rec.position_deg[0], rec.surface_deg[0]

    base = 0.004 if which == "command_delay_s" else 0.002
    lo, hi, mid = run(base), run(base + 1e-4), run(base + 0.3e-4)
    column = 0 if which == "feedback_delay_s" else 1  # the feedback delay moves only the LVDT reading
    moving = samples < 0.53  # the first 30 ms of the response, before the drive's dead band settles it
    gap = (lo[column] - hi[column])[moving]
    assert np.max(np.abs(gap)) > 0.005  # one step of delay matters on this step
    share = np.dot((lo[column] - mid[column])[moving], gap) / np.dot(gap, gap)
    assert share == pytest.approx(0.3, abs=0.03)
    assert np.max(np.abs((lo[column] - mid[column])[moving] - share * gap)) < 0.05 * np.max(np.abs(gap))
    if which == "feedback_delay_s":
        np.testing.assert_array_equal(mid[1], lo[1])  # measurement only: the surface does not see it


@pytest.mark.parametrize(("channel", "loads", "outside"), [("right_wing", 1780.0, 0.81), ("left_rudder", 470.0, 0.69)])
def test_hoad3_compliance_curves_follow_section_2_8_and_3_2_1(channel, loads, outside):
    """Figure 33: free play in the steep first segment; most of the compliance outside the servo loop."""
    params = HighOrderParams.from_channel(load_channel(channel), "hoad3")
    total, actuator = params.curves(0.0)
    t = gt.three_segment_breakpoints(*total)
    a = gt.three_segment_breakpoints(*actuator)
    assert 2 * t[2] * DEG_PER_IN == pytest.approx(load_channel(channel).free_play_deg, rel=1e-3)  # 0.2°
    steps = np.arange(1, 9) * loads / 8.0 / ARM_IN  # the 2.8.2 staircase, up to the test load
    d_total = gt.three_segment_curve(steps, t[0], t[1], t[2], t[3], t[7], t[8], t[9])
    d_actuator = gt.three_segment_curve(steps, a[0], a[1], a[2], a[3], a[7], a[8], a[9])
    assert np.all(1.0 - d_actuator / d_total > outside)
    # nonlinear below ≈ 10 % of the maximum (test load / 0.3): the softest segments end there
    assert total[1] * ARM_IN == pytest.approx(loads / 0.3 * 0.1, rel=0.01)
    if channel == "right_wing":  # rw13's amplitude at the 1,780 in·lb test load
        assert d_total[-1] == pytest.approx(0.02155, rel=0.002)
    upper, _ = params.curves(1.0)
    lower, _ = params.curves(-1.0)
    assert upper[2:] < total[2:] < lower[2:]  # upper bound = most compliant
    # A Monte Carlo batch picks a bound per instance: the most compliant deflects most under load.
    batch = create("hoad3", channel, n=3, bound=["lower", 0.0, "upper"], noise=False)
    deflection = batch.trim(0.0, loads).surface_deg - batch.trim(0.0, 0.0).surface_deg
    assert deflection[0] < deflection[1] < deflection[2]


def test_hoad3_with_the_servo_on_the_lvdt_barely_sees_what_the_surface_does():
    """The powered compliance test (2.8.2): the loop corrects in-loop compliance, not the linkages."""
    t = frames(8.0)
    steps = np.clip(np.floor((t - 0.2) / 0.5), 0, 4) * 445.0  # 0 → 1,780 in·lb in 445 in·lb steps
    rec = held(build("hoad3", "right_wing", quantization_v=0.0), t, np.zeros_like(t), steps)
    deflection = rec.surface_deg[0, -1] - rec.surface_deg[0, 0]
    lvdt = abs(rec.position_deg[0, -1] - rec.position_deg[0, 0])
    model = build("hoad3", "right_wing", quantization_v=0.0)
    model.set_power(False)  # the hydraulic test: brakes on, what the LVDT curve is made from
    braked = held(model, t, np.zeros_like(t), steps)
    lvdt_braked = braked.position_deg[0, -1] - braked.position_deg[0, 0]
    assert lvdt_braked > 0.08  # the actuator's own compliance at 1,780 in·lb (figure 16's LVDT curve)
    assert lvdt < 0.1 * lvdt_braked  # the loaded servo integrates it away: stiffness up "significantly"
    assert deflection > 0.9 * (braked.surface_deg[0, -1] - braked.surface_deg[0, 0] - lvdt_braked)


def test_hoad3_rw13_hysteresis_loop_gives_back_h():
    """Section 3.2.2: ±1,780 in·lb at 0.0785 rad/s, motor and control logic removed (brake holds).

    The loop (force at the actuator against deflection at the actuator) has area ≈ 4.88 in·lb and
    amplitude ≈ 0.02155 in, so h = A/(π·Pk²) ≈ 3,344.84 lb/in; the same h holds at 0.785 rad/s.
    """
    assert hysteretic_damping_constant(4.88, 0.02155) == pytest.approx(3344.84, abs=0.01)  # the report's arithmetic
    for omega in hyst.RW13_OMEGA_RAD_S:
        loop = hyst.rw13_loop(omega, points_per_cycle=2000)
        assert np.max(np.abs(loop.force_lbf)) == pytest.approx(1780.0 / ARM_IN, rel=1e-6)
        assert loop.amplitude_in == pytest.approx(0.02155, rel=0.005)
        assert loop.area_inlb == pytest.approx(4.88, rel=0.05)
        assert loop.h_lbf_per_in == pytest.approx(3344.84, rel=0.06)
    plain = hyst.rw13_loop(0.0785, hysteresis=False, points_per_cycle=2000)
    assert plain.area_inlb < 0.1 * 4.88  # friction and structural damping alone make a thin loop


def test_hoad3_hysteresis_barely_changes_the_frequency_response():
    """Figure 37: with h/ω at each dwell frequency the response moves by a fraction of a dB and degree."""
    with_h, without = hyst.frequency_effect(np.array([1.0, 4.0, 8.0, 12.0, 20.0]))
    assert np.max(np.abs(with_h.gain_db - without.gain_db)) < 0.3
    assert np.max(np.abs(with_h.phase_deg - without.phase_deg)) < 2.0
    assert np.max(np.abs(with_h.phase_deg - without.phase_deg)) > 0.0  # it is there, it is small


def test_hysteretic_average_stiffness_is_the_spring_for_a_linear_curve():
    curve = gt.three_segment_breakpoints(100.0, 200.0, 50_000.0, 50_000.0, 50_000.0)
    assert gt.hysteresis_average_stiffness(1000.0, curve) == pytest.approx(50_000.0, rel=1e-6)
    soft = gt.three_segment_breakpoints(25.0, 342.6, 8272.0, 36348.0, 70000.0)
    k_avg = gt.hysteresis_average_stiffness(1027.9, soft)
    assert soft[4] < k_avg < soft[6]


# ------------------------------------------------------------------------- power, flags, errors
@pytest.mark.parametrize("name", HIGH_ORDER)
def test_power_off_engages_the_brake_and_power_on_resumes(name):
    model = build(name)
    model.trim(0.0, -800.0)
    s = model.step(0.0, -800.0, 0.05)
    assert s.current_a[0] != 0.0
    assert s.bus_v[0] > 100.0
    model.set_power(False)
    held_at = model.step(5.0, -800.0, 0.2)
    assert held_at.active() & Flags.BRAKE
    assert held_at.current_a[0] == 0.0
    assert held_at.bus_v[0] == 0.0
    assert held_at.rate_dps[0] == 0.0
    # The brake takes the load where the motor held it (the gear train does not move); commands wait.
    assert held_at.position_deg[0] == pytest.approx(s.position_deg[0], abs=0.025)
    model.set_power(True)
    for _ in range(100):
        s = model.step(5.0, -800.0, 0.01)
    assert not s.active() & Flags.BRAKE
    assert s.position_deg[0] == pytest.approx(5.0, abs=0.06)
    with pytest.raises(EmaError, match="power must be on or off"):
        model.set_power(0.5)


def test_flags_report_current_rate_position_and_free_play():
    t = frames(1.0)
    rec = held(build("hoad2"), t, np.where(t >= 0.1, 60.0, 0.0))
    seen = np.bitwise_or.reduce(rec.flags[0])
    for flag in (Flags.CURRENT_LIMIT, Flags.RATE_LIMIT, Flags.POSITION_LIMIT, Flags.PWM_DEAD_BAND,
                 Flags.FREE_PLAY_STOP, Flags.STALL):
        assert seen & flag, flag
    assert rec.position_deg[0, -1] == pytest.approx(43.0, abs=0.1)


def test_unknown_parameters_and_bad_options_are_clear_errors():
    with pytest.raises(UnknownNameError, match="high-order parameter 'pwm_deadband'"):
        create("hoad3", pwm_deadband=1.0)
    with pytest.raises(EmaError, match="compliance bound"):
        create("hoad3", bound=2.0)
    with pytest.raises(UnknownNameError, match="known: lower, mean, upper"):
        create("hoad3", bound="typical")
    with pytest.raises(EmaError, match="must be positive"):
        create("hoac1", lvdt_filter_hz=0.0)
    with pytest.raises(EmaError, match="belong to HOAD3"):
        create("hoad2", hysteresis=True)
    with pytest.raises(EmaError, match="no flight/test environment"):
        create("hoac1", command_delay_s=0.004)


@pytest.mark.parametrize("name", HIGH_ORDER)
def test_non_finite_inputs_are_held_and_counted(name):
    model = build(name)
    model.trim(1.0)
    before = model.step(1.0, 0.0, 0.05)
    after = model.step(float("nan"), float("inf"), 0.05)
    assert np.isfinite(after.position_deg).all()
    assert after.position_deg[0] == pytest.approx(before.position_deg[0], abs=1e-9)
    assert model.rejected_inputs == 2


def test_equilibrium_puts_an_overload_on_the_stop():
    model = build("hoad3")
    p = model._P[0]
    eq = equilibrium(p, 0.0, 6000.0, True)  # 3,465 lbf aiding: beyond what the motor holds
    assert eq["xm"] == pytest.approx(43.0 / DEG_PER_IN)
    assert p[K_T_D1] == pytest.approx(p[K_T_F1] / p[K_T_K1])

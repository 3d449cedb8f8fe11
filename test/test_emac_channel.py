import math

import numpy as np
import pytest

from ema_sim.config import load_channel, scaling
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings, InputStatus, parse_failure
from ema_sim.errors import ConfigError, SpecError
from ema_sim.models import Flags, create


def channel(name="left_wing", **kw):
    return EmacChannel(create("loada", name), EmacSettings(**kw))


def drive(ch, deg, frames, hm=0.0):
    ch.set_command(ch.scaling.command_deg_to_v(deg))
    ch.set_load(hm)
    fb = None
    for _ in range(frames):
        fb = ch.step(0.0)
    return fb


def test_starts_braked_then_follows_commands_in_volts():
    ch = channel()
    assert ch.last.braked
    fb = drive(ch, 2.0, 200)
    assert not fb.braked
    assert fb.position_deg == pytest.approx(2.0, abs=0.05)
    # the left wing's degrees-to-volts relation is inverse: a positive deflection reads negative volts
    assert fb.position_v < 0.0
    assert fb.position_v == pytest.approx(scaling("left_wing").feedback_deg_to_v(fb.position_deg))
    assert math.isnan(fb.current_a)  # no motor in a second-order model: unknown, not invented


def test_bad_commands_are_rejected_or_clamped_and_never_reach_the_model():
    good, bad = channel(), channel()
    for ch in (good, bad):
        drive(ch, 1.0, 50)
    for value in (math.nan, math.inf, -math.inf, "junk"):
        assert bad.set_command(value) is InputStatus.REJECTED
    assert bad.set_load(math.nan) is InputStatus.REJECTED
    for _ in range(50):
        a, b = good.step(0.0), bad.step(0.0)
        assert a.position_deg == b.position_deg  # held at the last good command, bit for bit
    assert bad.counters["rejected_commands"] == 4
    assert bad.counters["rejected_loads"] == 1
    assert bad.set_command(25.0) is InputStatus.CLAMPED
    assert bad.command_v == 10.0
    assert bad.set_load(1e9) is InputStatus.CLAMPED
    assert bad.counters["clamped_loads"] == 1
    bad.set_load(0.0)
    fb = None
    for _ in range(400):
        fb = bad.step(0.0)
    assert np.isfinite([fb.position_deg, fb.surface_deg, fb.position_v]).all()
    assert fb.position_deg == pytest.approx(bad.scaling.command_v_to_deg(10.0), abs=0.5)


def test_watchdog_engages_the_brake_on_stale_commands_and_holds_the_surface():
    ch = channel(watchdog_timeout_s=0.05)
    drive(ch, 3.0, 100)
    held = ch.last.position_deg
    ch.set_command(ch.scaling.command_deg_to_v(-5.0))
    fb = ch.step(0.06)  # the command is older than the watchdog allows
    assert fb.braked
    assert fb.flags & Flags.BRAKE
    for _ in range(50):
        fb = ch.step(0.2)
    assert fb.position_deg == held
    assert ch.counters["watchdog_trips"] == 1
    for _ in range(200):
        fb = ch.step(0.0)
    assert not fb.braked
    assert fb.position_deg == pytest.approx(-5.0, abs=0.1)


def test_brake_holds_the_position_but_free_play_still_shows_on_the_surface():
    ch = channel()
    drive(ch, 0.0, 50)
    ch.motor_power_on = False
    fbs = []
    for hm in (300.0, -300.0, 300.0):
        ch.set_load(hm)
        fbs.append(ch.step(0.0))
    assert all(f.braked for f in fbs)
    assert len({f.position_deg for f in fbs}) == 1
    width = load_channel("left_wing").free_play_deg
    assert fbs[0].surface_deg - fbs[1].surface_deg == pytest.approx(width, abs=1e-9)


@pytest.mark.parametrize(("failure", "expect"), [
    ("stuck", lambda pos, start: pos == pytest.approx(start, abs=1e-12)),
    ("power_loss", lambda pos, start: pos == pytest.approx(start, abs=1e-12)),
    ("hard_over", lambda pos, _: pos == pytest.approx(43.0, abs=0.01)),
    ("hard_over:direction=-1", lambda pos, _: pos == pytest.approx(-43.0, abs=0.01)),
    ("zero", lambda pos, _: abs(pos) < 0.05),
])
def test_failures_switch_at_run_time(failure, expect):
    ch = channel()
    start = drive(ch, 4.0, 200).position_deg
    ch.set_failure(failure)
    fb = drive(ch, 8.0, 400)
    assert expect(fb.position_deg, start)
    assert fb.braked == (failure == "power_loss")
    ch.set_failure("none")
    assert drive(ch, 8.0, 300).position_deg == pytest.approx(8.0, abs=0.1)


def test_stall_an_opposing_hinge_moment_beyond_the_stall_force_stops_the_surface():
    free, stalled = channel(), channel()
    stalled.set_failure("stall:load_factor=1.25")
    a = drive(free, 10.0, 200)
    b = drive(stalled, 10.0, 200)
    assert a.position_deg == pytest.approx(10.0, abs=0.1)
    cfg = load_channel("left_wing")
    assert b.hinge_moment_inlb == pytest.approx(-1.25 * cfg.stall_force_lbf * cfg.crank_arm_in)
    assert b.position_deg < 0.5  # it cannot move against the load (section 1.3's flight-1 rudder)


def test_crosstalk_noise_rides_on_the_feedback_only_while_others_move():
    quiet = EmacChannel(create("loada", "right_wing"), crosstalk_noise_pp_v=0.02)
    drive(quiet, 0.0, 400)
    at_rest = [quiet.step(0.0, activity=0.0).position_v for _ in range(200)]
    moving = [quiet.step(0.0, activity=1.0) for _ in range(4000)]
    assert np.ptp(at_rest) == 0.0
    volts = np.array([f.position_v for f in moving])
    assert np.ptp(volts) == pytest.approx(0.02, rel=0.05)
    assert np.std(volts) == pytest.approx(0.02 / math.sqrt(12), rel=0.05)
    assert np.ptp([f.position_deg for f in moving]) == 0.0  # the surface did not move


def test_activity_meter_reads_slewing_other_channels():
    meter = ActivityMeter(0.005)
    slew = 27.0
    meter.observe("left_wing", 0.0, slew)
    meter.observe("left_wing", slew * 0.005, slew)
    assert meter.activity == pytest.approx(1.0)
    meter.observe("left_wing", slew * 0.005, slew)
    assert meter.activity == 0.0


def test_settings_and_failures_are_validated():
    with pytest.raises(ConfigError, match="watchdog_timeout_s"):
        EmacSettings.from_parameters({"watchdog_timeout_s": -1.0})
    with pytest.raises(ConfigError, match="motor_power_on"):
        EmacSettings.from_parameters({"motor_power_on": "maybe"})
    with pytest.raises(SpecError, match="direction"):
        parse_failure("hard_over:direction=3")
    assert parse_failure("stall").load_factor == 1.25


def test_activity_of_the_other_channels_only():
    meter = ActivityMeter(0.005)
    for ch, dv in (("left_wing", 0.135), ("right_wing", 0.0)):
        meter.observe(ch, 0.0, 27.0)
        meter.observe(ch, dv, 27.0)
    assert meter.activity_except("right_wing") == pytest.approx(1.0)
    assert meter.activity_except("left_wing") == 0.0

import numpy as np
import pytest

from ema_sim.errors import SpecError, UnknownNameError
from ema_sim.signals import LOADS, MANEUVERS, parse_load, parse_maneuver
from ema_sim.signals.maneuvers import Schroeder, Sweep


@pytest.mark.parametrize("kind", sorted(MANEUVERS))
def test_every_maneuver_round_trips_its_spec_and_starts_quiet(kind):
    man = parse_maneuver(kind)
    assert parse_maneuver(man.spec()) == man
    t = np.arange(0.0, man.duration_s, 0.005)
    cmd = man.command_deg(t)
    assert np.all(np.isfinite(cmd))
    assert man.duration_s > 0
    end = man.command_deg(np.array([man.duration_s]))[0]
    assert man.command_deg(np.array([man.duration_s + 5.0]))[0] == pytest.approx(end)


@pytest.mark.parametrize("kind", sorted(LOADS))
def test_every_load_round_trips_its_spec(kind):
    load = parse_load(kind)
    assert parse_load(load.spec()) == load
    assert np.all(np.isfinite(load.hinge_moment_inlb(np.linspace(0, 30, 100), np.ones(100))))


def test_step_comes_after_a_quiet_lead_in_and_returns():
    man = parse_maneuver("step:amp_deg=1")
    t = np.arange(0, man.duration_s, 0.005)
    cmd = man.command_deg(t)
    assert np.all(cmd[t < man.lead_s] == 0.0)
    assert np.all(cmd[(t >= man.lead_s) & (t < man.lead_s + man.hold_s)] == 1.0)
    assert cmd[-1] == 0.0


def test_sweep_frequency_runs_from_f0_to_f1_in_the_time_given():
    man = parse_maneuver("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60")
    assert isinstance(man, Sweep)
    assert man.duration_s == pytest.approx(61.0)
    # Instantaneous frequency from the phase derivative equals the stated law.
    t = np.linspace(1.5, 60.5, 500)
    f_num = np.gradient(man.phase_rad(t), t) / (2 * np.pi)
    assert np.allclose(f_num[1:-1], man.frequency_hz(t)[1:-1], rtol=1e-3)
    assert man.frequency_hz(1.0) == pytest.approx(0.2)
    assert man.frequency_hz(61.0) == pytest.approx(18.0)
    cmd = man.command_deg(np.arange(0, 61, 0.001))
    assert np.max(np.abs(cmd)) == pytest.approx(1.0, abs=1e-3)


def test_schroeder_puts_equal_power_on_its_harmonics_and_nothing_else():
    man = parse_maneuver("schroeder:f0_hz=0.5,f1_hz=5,amp_deg=1,period_s=10,periods=1,lead_s=0")
    assert isinstance(man, Schroeder)
    fs = 200.0
    t = np.arange(0, 10.0, 1 / fs)
    x = man.command_deg(t)
    assert np.max(np.abs(x)) == pytest.approx(1.0, abs=0.02)
    spec = np.abs(np.fft.rfft(x))
    k = man.harmonics
    assert k[0] == 5
    assert k[-1] == 50
    on = spec[k]
    assert np.ptp(on) / on.mean() < 1e-6
    off = np.delete(spec, k)
    assert off.max() < 1e-6 * on.mean()
    # The point of Schroeder phases: a low peak factor.
    crest = np.max(np.abs(x)) / np.sqrt(np.mean(x**2))
    assert crest < 2.0


def test_ramp_runs_at_the_stated_rate():
    man = parse_maneuver("ramp:rate_dps=0.005,peak_deg=2")
    assert man.duration_s == pytest.approx(1.0 + 800.0)
    t = np.array([1.0, 101.0, 401.0, 801.0])
    assert np.allclose(man.command_deg(t), [0.0, 0.5, 2.0, 0.0])


def test_staircases_visit_both_limits_and_return():
    man = parse_maneuver("staircase:step_deg=10,max_deg=20,hold_s=1")
    assert man.levels_deg.tolist() == [0, 10, 20, 10, 0, -10, -20, -10, 0]
    load = parse_load("steps:step_inlb=222.5,max_inlb=1780,hold_s=2,lead_s=0")
    assert load.levels_inlb.max() == 1780.0
    assert load.levels_inlb.min() == -1780.0
    assert np.allclose(np.diff(load.levels_inlb)[:8], 222.5)


def test_gradient_load_follows_the_command():
    load = parse_load("gradient:inlb_per_deg=-40,bias_inlb=10")
    assert np.allclose(load.hinge_moment_inlb([0.0, 1.0], [2.0, -1.0]), [-70.0, 50.0])


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("step:amp=1", "unknown field 'amp'"),
        ("sine:freq_hz=fast", "field 'freq_hz' must be a number"),
        ("sine:cycles=2.5", "field 'cycles' must be an integer"),
        ("sine:freq_hz=0", "field 'freq_hz' must be > 0"),
        ("sweep:f0_hz=5,f1_hz=1", "f1_hz"),
        ("step:amp_deg", "expected field=value"),
        ("step:amp_deg=1,amp_deg=2", "given twice"),
        ("step:back=maybe", "field 'back' must be true or false"),
        ("sine:amp_deg=nan", "field 'amp_deg' must be finite"),
    ],
)
def test_malformed_maneuver_specs_name_the_bad_field(spec, message):
    with pytest.raises(SpecError, match=message):
        parse_maneuver(spec)


def test_unknown_kinds_list_the_known_ones():
    with pytest.raises(UnknownNameError, match=r"known: .*sweep"):
        parse_maneuver("chirp:f0_hz=1")
    with pytest.raises(UnknownNameError, match=r"known: .*reversal"):
        parse_load("wind")

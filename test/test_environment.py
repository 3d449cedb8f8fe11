import math
import re

import numpy as np
import pytest

from ema_sim.config import config_dir, load_channel, ros_parameters
from ema_sim.environment import (
    FirstOrderLag,
    Noise,
    Profile,
    Quantizer,
    SignalPath,
    TransportDelay,
    load_profile,
    profile_names,
)
from ema_sim.errors import ConfigError, UnknownNameError

T = 0.005


def run(element, xs):
    return np.array([element.step(x) for x in xs])


def test_whole_frame_delay_is_exact():
    x = np.arange(20.0)
    y = run(TransportDelay(0.010, T), x)
    assert np.array_equal(y[2:], x[:-2])
    assert np.array_equal(y[:2], [0.0, 0.0])  # steady state at the reset value


def test_fractional_delay_is_linear_interpolation_so_a_ramp_lags_by_exactly_the_delay():
    x = np.arange(50.0)
    y = run(TransportDelay(0.007, T, initial=0.0), x)
    assert y[10:] == pytest.approx(x[10:] - 0.007 / T, abs=1e-12)


def test_lag_step_response_and_unity_dc_gain():
    lag = FirstOrderLag(50.0, T)
    y = run(lag, np.ones(40))
    n = np.arange(1, 41)
    assert y == pytest.approx(1.0 - np.exp(-2 * math.pi * 50.0 * T * n), rel=1e-12)
    assert y[-1] == pytest.approx(1.0, abs=1e-12)


def test_quantizer_rounds_to_5_mv_and_saturates_at_full_scale():
    q = Quantizer(0.005)
    assert q.step(0.0124) == pytest.approx(0.010)
    assert q.step(0.0126) == pytest.approx(0.015)
    assert q.step(-0.0124) == pytest.approx(-0.010)
    assert q.step(12.3) == 10.0
    assert np.array_equal(q.step(np.array([0.0024, -30.0])), [0.0, -10.0])


def test_noise_is_seeded_and_has_its_rms():
    a = run(Noise(0.003, seed=7, stream=(1, 0)), np.zeros(20000))
    b = run(Noise(0.003, seed=7, stream=(1, 0)), np.zeros(20000))
    c = run(Noise(0.003, seed=7, stream=(2, 0)), np.zeros(20000))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.std(a) == pytest.approx(0.003, rel=0.03)
    assert abs(np.mean(a)) < 1e-4


def test_zero_parameters_make_every_element_the_identity():
    x = np.random.default_rng(0).normal(size=200)
    path = SignalPath([FirstOrderLag(0.0, T), Quantizer(0.0), TransportDelay(0.0, T), Noise(0.0)])
    assert not path.active
    assert np.array_equal(run(path, x), x)


def test_elements_step_arrays_of_channels_like_scalars():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(100, 3))
    vec = SignalPath([FirstOrderLag(50.0, T, np.zeros(3)), Quantizer(0.005), TransportDelay(0.012, T, np.zeros(3))])
    out = np.array([vec.step(row) for row in x])
    for j in range(3):
        scalar = SignalPath([FirstOrderLag(50.0, T), Quantizer(0.005), TransportDelay(0.012, T)])
        assert np.allclose(out[:, j], run(scalar, x[:, j]), atol=1e-15)


def test_noise_is_its_generators_stream_in_order_whatever_the_block_it_draws():
    """Draws are made a block at a time for speed: scalars and arrays still take the stream in order."""
    noise = Noise(0.003, seed=43, stream=(2, 0))
    got = [noise.step(0.0) for _ in range(1500)]
    got += list(noise.step(np.zeros(700)))
    got += [noise.step(0.0) for _ in range(10)]
    want = 0.003 * np.random.default_rng([43, 2, 0]).standard_normal(2210)
    assert np.array_equal(np.asarray(got), want)


def test_quantizer_rounds_scalars_like_arrays_and_saturates():
    q = Quantizer(0.005, full_scale_v=10.0)
    x = np.random.default_rng(3).uniform(-10.1, 10.1, 5000)
    assert np.array_equal([q.step(float(v)) for v in x], q.step(x))
    assert q.step(12.0) == 10.0
    assert q.step(-12.0) == -10.0
    assert math.isnan(q.step(math.nan))


def test_profiles_reproduce_the_reported_loop_delays():
    model_delay = load_channel("left_wing").section("second_order")["delay_s"]
    ail, flight = load_profile("ail"), load_profile("flight")
    assert ail.command.delay_s + model_delay == pytest.approx(0.030)   # section 4.3: ≈ 30 ms in the AIL set-up
    assert flight.command.delay_s + model_delay == pytest.approx(0.011)  # ≈ 11 ms worst case in flight
    for p in (ail, flight):
        for path in (p.command, p.feedback):
            assert path.lag_hz == 50.0
            assert path.quantization_v == 0.005
    assert ail.command.noise_rms_v > flight.command.noise_rms_v > 0.0
    assert {"none", "ail", "flight"} <= set(profile_names())


def test_none_profile_passes_everything_through_exactly():
    p = load_profile("none")
    x = np.random.default_rng(2).normal(size=300)
    assert np.array_equal(run(p.command_path(T), x), x)
    assert np.array_equal(run(p.feedback_path(T), x), x)


def test_ail_command_path_delays_a_step_by_26_ms_and_filters_it():
    path = load_profile("ail").without("noise").command_path(T)
    y = run(path, np.r_[np.zeros(5), np.ones(40)])
    first = int(np.argmax(y > 0))
    assert first * T == pytest.approx(5 * T + 0.026, abs=T)  # delayed by 26 ms (5.2 frames, interpolated)
    assert y[-1] == pytest.approx(1.0, abs=0.0025)           # quantized to 5 mV


def test_elements_switch_off_one_at_a_time_or_per_path():
    ail = load_profile("ail")
    quiet = ail.without("noise")
    assert quiet.command.noise_rms_v == quiet.feedback.noise_rms_v == 0.0
    assert quiet.command.delay_s == ail.command.delay_s
    one = ail.without("command.delay")
    assert one.command.delay_s == 0.0
    assert one.feedback == ail.feedback
    bare = ail.without("lag", "quantization", "delay", "noise")
    assert bare.command_path(T).describe() == "pass-through"
    assert load_profile("ail", disable=["lag"]).command.lag_hz == 0.0
    with pytest.raises(UnknownNameError, match="environment element 'dither'"):
        ail.without("dither")


def test_feedback_path_order_noise_before_quantization():
    names = [e.name for e in load_profile("ail").feedback_path(T).elements]
    assert names == ["noise", "quantization", "lag"]  # feedback delay is 0 in the AIL profile
    names = [e.name for e in load_profile("ail").command_path(T).elements]
    assert names == ["lag", "quantization", "delay", "noise"]


def test_bad_profiles_are_one_clear_error():
    with pytest.raises(UnknownNameError, match="unknown profile 'lab'"):
        load_profile("lab")
    with pytest.raises(ConfigError, match="lag_hz must be a finite number"):
        Profile.from_parameters({"command": {"lag_hz": -1.0}})
    with pytest.raises(ConfigError, match="unknown parameter 'lag'"):
        Profile.from_parameters({"feedback": {"lag": 50.0}})


@pytest.mark.parametrize("name", ["ail", "flight", "emac"])
def test_suite_parameter_files_carry_units_in_every_name(name):
    unit = re.compile(r"_(deg|v|inlb|s|hz)$")
    plain = {"profile", "seed", "failure", "faults", "motor_power_on", "resync_commands"}  # names, specs, seeds

    def walk(mapping):
        for key, value in mapping.items():
            yield from walk(value) if isinstance(value, dict) else [key]

    params = ros_parameters(config_dir() / f"{name}.yaml")
    assert [k for k in walk(params) if k not in plain and not unit.search(k)] == []

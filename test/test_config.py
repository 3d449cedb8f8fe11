import re
from dataclasses import replace

import numpy as np
import pytest

from ema_sim import parameters as pm
from ema_sim.calibration import command_error
from ema_sim.config import CHANNELS, ChannelConfig, config_dir, load_channel, parse_channel, ros_parameters
from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.models.high_order.params import HighOrderParams
from ema_sim.models.second_order.params import SecondOrderParams

UNIT = re.compile(
    r"_(deg|v|inlb|inlbs2|s|hz|in|in_s|dps|lbf|lbf_per_in|rad_s|dps_per_lb|per_kinlb|deg_per_kinlb|a|ohm"
    r"|per_s|per_s2|a_per_in_s|v_per_a|v_s_per_rad|mh|uf|in_per_rev|lbf_s_per_in|ratio)$"
)
DIMENSIONLESS = {"channel", "surface", "zeta", "kb", "command_cal_v", "feedback_cal_deg"}


@pytest.mark.parametrize("channel", CHANNELS)
def test_every_channel_loads_with_report_values(channel):
    cfg = load_channel(channel)
    assert cfg.channel == channel
    assert cfg.slew_rate_dps == pytest.approx(115.8)
    assert cfg.slew_rate_dps / cfg.slew_rate_in_s == pytest.approx(cfg.deg_per_in, rel=1e-3)
    assert cfg.stall_force_lbf == 2500.0
    assert cfg.full_scale_v == 10.0
    inertia = {"wing": 3.896, "rudder": 0.3261, "cowl": 3.006}[cfg.surface]
    assert cfg.surface_inertia_inlbs2 == inertia
    # ±10 V is the full stroke: the feedback curve reaches the position limits at full scale.
    assert abs(cfg.v_to_deg(cfg.full_scale_v)) == pytest.approx(cfg.position_max_deg, abs=0.1)


def test_three_of_four_surfaces_have_an_inverse_degree_to_volt_relation():
    signs = {ch: load_channel(ch).command_cal.sign for ch in CHANNELS if ch != "cowl_door"}
    assert sorted(signs.values()) == [-1, -1, -1, 1]
    assert signs["right_rudder"] == 1  # section 4.4.1: both wings and the left rudder are inverse


@pytest.mark.parametrize("channel", CHANNELS)
def test_command_error_in_config_matches_its_calibration_curves(channel):
    cfg = load_channel(channel)
    fit = command_error(cfg.command_cal, cfg.feedback_cal, np.linspace(-40, 40, 81))
    so = cfg.section("second_order")
    assert so["kb"] == pytest.approx(fit.kb, abs=2e-4)
    assert so["offset_deg"] == pytest.approx(fit.offset_deg, abs=2e-3)


@pytest.mark.parametrize("channel", CHANNELS)
def test_every_parameter_name_carries_its_unit(channel):
    params = ros_parameters(config_dir() / f"{channel}.yaml")

    def walk(mapping):
        for key, value in mapping.items():
            if isinstance(value, dict):
                yield from walk(value)
            else:
                yield key

    bad = [k for k in walk(params) if k not in DIMENSIONLESS and not UNIT.search(k)]
    assert bad == []


def test_unknown_channel_lists_the_known_ones():
    with pytest.raises(UnknownNameError, match="known: cowl_door, left_rudder, left_wing"):
        load_channel("tail")


def test_malformed_channel_parameters_name_the_problem():
    good = ros_parameters(config_dir() / "left_wing.yaml")
    bad = dict(good, crank_arm_in="long")
    with pytest.raises(ConfigError, match="crank_arm_in"):
        parse_channel(bad)
    missing = {k: v for k, v in good.items() if k != "stroke_in"}
    with pytest.raises(ConfigError, match="stroke_in"):
        parse_channel(missing)


def _leaves(mapping, prefix=""):
    for key, value in mapping.items():
        if isinstance(value, dict):
            yield from _leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


@pytest.mark.parametrize("channel", CHANNELS)
def test_each_value_appears_once_in_a_channel_file(channel):
    params = ros_parameters(config_dir() / f"{channel}.yaml")
    # a value a model family takes from the channel's data is not repeated in the family's section
    for cls, section in ((SecondOrderParams, "second_order"), (HighOrderParams, "high_order")):
        linked = {name for name, m in pm.metas(cls).items() if m.channel is not None}
        assert linked
        keys = {path.rsplit(".", 1)[-1] for path, _ in _leaves(params[section])}
        assert not linked & keys, (section, linked & keys)
    # the channel's data are declared once, every one of them (ChannelConfig), and nothing else is at the top
    top = {k for k, v in params.items() if not isinstance(v, dict)}
    assert top == set(pm.metas(ChannelConfig))


@pytest.mark.parametrize("channel", CHANNELS)
def test_the_second_order_rate_limit_is_the_channels_unloaded_slew(channel):
    cfg = load_channel(channel)
    assert SecondOrderParams.from_channel(cfg).rate_limit_dps == cfg.slew_rate_dps == 115.8  # table 1
    assert SecondOrderParams.from_channel(replace(cfg, slew_rate_dps=100.0)).rate_limit_dps == 100.0
    assert SecondOrderParams.from_channel(cfg, rate_limit_dps=90.0).rate_limit_dps == 90.0


def test_the_channel_is_checked_by_its_declaration():
    good = ros_parameters(config_dir() / "left_wing.yaml")
    cases = {
        "position_min_deg must be below position_max_deg": {"position_min_deg": 43.0},
        "surface must be one of wing, rudder, cowl": {"surface": "flap"},
        "crank_arm_in must be positive": {"crank_arm_in": 0.0},
        "command_cal_v needs 4 values, got 3": {"command_cal_v": [0.0, 1.0, 0.0]},
        "feedback_cal_deg must be finite": {"feedback_cal_deg": [0.0, float("nan"), 0.0, 0.0]},
        "free_play_deg must not exceed 3": {"free_play_deg": 4.0},
        "unknown parameter 'slew_dps'": {"slew_dps": 1.0},
        "command and feedback curves disagree in sign": {"command_cal_v": [0.0, 0.2357, 0.0, 0.0]},
    }
    for message, change in cases.items():
        with pytest.raises(ConfigError, match=message):
            parse_channel({**good, **change}, "left_wing.yaml")
    cfg = parse_channel(good)
    assert cfg == load_channel("left_wing")
    assert cfg.command_cal.coefficients() == list(good["command_cal_v"])

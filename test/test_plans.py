import pytest

from ema_sim.config import CHANNELS
from ema_sim.errors import SpecError, UnknownNameError
from ema_sim.signals.plans import DYNAMIC_LIMIT_S, PRESETS, SURFACES4, build_plan, channel_list


@pytest.mark.parametrize("test", sorted(PRESETS))
@pytest.mark.parametrize("channel", ["left_wing", "right_rudder"])
def test_every_section_2_test_builds_and_dynamic_ones_fit_in_60_s(test, channel):
    plan = build_plan(test, channels=[channel])
    assert plan.duration_s > 0
    if plan.dynamic:
        assert plan.duration_s <= DYNAMIC_LIMIT_S
    meta = plan.metadata()
    for key in ("test", "maneuver", "load", "channel"):
        assert meta[key]


@pytest.mark.parametrize("observed", SURFACES4)
@pytest.mark.parametrize("test", ["static_crosstalk", "dynamic_crosstalk"])
def test_crosstalk_matrices_tables_2_and_3(test, observed):
    plan = build_plan(f"{test}:observed={observed}")
    assert plan.channel == observed
    assert set(plan.channels) == set(SURFACES4)  # the cowl door is not in the matrices
    kind = {"static_crosstalk": "hold", "dynamic_crosstalk": "triangle"}[test]
    assert plan.channels[observed].maneuver.kind == kind
    assert all(plan.channels[c].maneuver.kind == "square" for c in SURFACES4 if c != observed)
    assert plan.duration_s <= 11.0  # section 2.2: 10 s tests


def test_loads_follow_the_surface():
    wing = build_plan("compliance", channels=["left_wing"]).channels["left_wing"].load
    rudder = build_plan("compliance", channels=["left_rudder"]).channels["left_rudder"].load
    assert wing.max_inlb == 1780.0  # section 2.8
    assert rudder.max_inlb == 470.0
    assert build_plan("hysteresis", channels=["right_rudder"]).channels["right_rudder"].load.amp_inlb == 400.0
    assert build_plan("compliance:position_deg=15").channels["left_wing"].maneuver.value_deg == 15.0


def test_a_bare_maneuver_names_its_test_and_channels_default_to_left_wing():
    plan = build_plan(maneuver="sweep:amp_deg=0.4,sweep_s=55")
    assert plan.test == "sweep"
    assert plan.channel == "left_wing"
    assert plan.command_deg("right_wing", [1.0, 2.0]).tolist() == [0.0, 0.0]  # undriven channels hold 0°
    assert build_plan(maneuver="sine").test == "custom"
    assert channel_list(["all"]) == list(CHANNELS)


def test_limits_and_bad_specs():
    with pytest.raises(SpecError, match="limits dynamic tests to 60 s"):
        build_plan(maneuver="sweep")  # 1 s lead + 60 s sweep
    assert build_plan(maneuver="sweep", duration_s=60).duration_s == 60.0
    assert build_plan("ramp").duration_s > 400  # slow ramps are not dynamic tests
    with pytest.raises(UnknownNameError, match="unknown test 'wobble'"):
        build_plan("wobble")
    with pytest.raises(SpecError, match="observed must be one of"):
        build_plan("static_crosstalk:observed=cowl_door")
    with pytest.raises(SpecError, match="unknown field 'speed'"):
        build_plan("steps:speed=3")
    with pytest.raises(UnknownNameError, match="unknown channel 'tail'"):
        build_plan("steps", channels=["tail"])

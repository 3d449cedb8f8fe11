"""Every parameter's slot, unit and range come from its one declaration (ema_sim.parameters)."""

import math
from dataclasses import fields, replace

import numpy as np
import pytest

from ema_sim import parameters as pm
from ema_sim.config import CHANNELS, ChannelConfig, load_channel
from ema_sim.environment import ELEMENTS as ENV_ELEMENTS
from ema_sim.environment import PathSpec, Profile
from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.identify.effects import FREE
from ema_sim.models import create, model_class, model_names
from ema_sim.models.high_order import params as high_order
from ema_sim.models.high_order.params import KERNEL_EXTRA, HighOrderParams
from ema_sim.models.linear import LoesParams
from ema_sim.models.second_order.params import P, SecondOrderParams
from ema_sim.switches import ELEMENTS, element_names, model_overrides

PARAMETER_SETS = (ChannelConfig, SecondOrderParams, HighOrderParams, LoesParams, PathSpec)
# The unit a name's suffix promises, for every suffix the configuration uses.
SUFFIX_UNITS = {
    "_rad_s": "rad/s", "_hz": "Hz", "_s": "s", "_deg": "deg", "_dps": "deg/s", "_dps2": "deg/s²",
    "_dps_per_lb": "deg/s/lbf",
    "_in": "in", "_in_s": "in/s", "_inlb": "in·lb", "_inlbs2": "in·lb·s²", "_lbf": "lbf", "_lbf_per_in": "lbf/in",
    "_lbf_s_per_in": "lbf·s/in", "_lb_per_in": "lbf/in", "_per_kinlb": "1/(1000 in·lb)",
    "_deg_per_kinlb": "deg/(1000 in·lb)", "_v": "V", "_a": "A", "_ohm": "Ω", "_mh": "mH", "_uf": "µF",
    "_v_per_a": "V/A", "_a_per_in_s": "A/(in/s)", "_v_s_per_rad": "V·s/rad", "_in_per_rev": "in/rev",
    "_per_s": "1/s", "_per_s2": "1/s²", "_ratio": "-",
}
KERNEL_SUFFIXES = (*SUFFIX_UNITS, "_h", "_f", "_lbs2_per_in", "_lbf_per_a", "_per_in", "_in_per_lbf", "_per_v",
                   "_per_v2", "_per_v3")


def _suffix_unit(name):
    best = max((s for s in SUFFIX_UNITS if name.endswith(s)), key=len, default=None)
    return None if best is None else SUFFIX_UNITS[best]


@pytest.mark.parametrize("cls", PARAMETER_SETS)
def test_every_field_is_declared_once_with_unit_range_and_description(cls):
    parameters = [f for f in fields(cls) if pm.CARRIED_KEY not in f.metadata]  # carried data: no parameters
    assert len(parameters) == len(pm.metas(cls)) >= len(fields(cls)) - 1
    for f in parameters:
        m = pm.meta_of(f)  # raises for a field declared without metadata
        assert m.unit, f.name
        assert m.description, f.name
        assert m.min <= m.max, f.name
        assert m.off is not None or m.element is None, f"{f.name}: an element name needs a switch-off value"
        if m.uncertainty is not None:
            assert m.uncertainty_source, f.name
    assert cls.__doc__.count(" : ") >= len(parameters)  # the docstring's Parameters are generated from them


@pytest.mark.parametrize("cls", PARAMETER_SETS)
def test_the_unit_in_a_name_is_the_declared_unit(cls):
    for name, m in pm.metas(cls).items():
        want = _suffix_unit(name)
        if want is not None:
            assert m.unit == want, f"{name}: name says {want}, metadata says {m.unit}"
        else:
            assert m.unit == "-", f"{name}: a name without a unit suffix is a ratio ('-'), not {m.unit}"


def test_kernel_slots_are_generated_from_the_declared_names_in_order():
    assert P._fields == tuple(f.name for f in fields(SecondOrderParams))  # second order: one slot per field
    assert tuple(P) == tuple(range(len(fields(SecondOrderParams))))
    declared = tuple(m.kernel for m in pm.metas(HighOrderParams).values() if m.kernel is not None)
    assert high_order.P._fields == (*declared, *KERNEL_EXTRA)
    assert tuple(high_order.P) == tuple(range(len(high_order.P)))
    for name in high_order.P._fields:
        assert name == "figure33" or name.endswith(KERNEL_SUFFIXES), f"kernel slot {name} has no unit in its name"


@pytest.mark.parametrize("channel", ["left_wing", "right_rudder"])
def test_kernel_vectors_hold_each_parameter_converted_in_its_declared_slot(channel):
    cfg = load_channel(channel)
    so = SecondOrderParams.from_channel(cfg)
    v = so.kernel_vector()
    for name in P._fields:
        assert v[getattr(P, name)] == getattr(so, name)
    ho = HighOrderParams.from_channel(cfg, "hoad3")
    v = ho.kernel_vector(figure33=True)
    for name, m in pm.metas(HighOrderParams).items():
        if m.kernel is None:
            continue
        conv = m.to_kernel
        want = conv(ho) if callable(conv) else getattr(ho, name) * conv
        assert v[getattr(high_order.P, m.kernel)] == want, name
    assert v[high_order.P.lvdt_filter_rad_s] == pytest.approx(2 * math.pi * ho.lvdt_filter_hz)
    assert v[high_order.P.inductance_h] == pytest.approx(ho.inductance_mh * 1e-3)
    assert v[high_order.P.position_max_in] == pytest.approx(ho.position_max_deg * ho.crank_arm_in / math.degrees(1.0))


@pytest.mark.parametrize("name", ["loada", "second_order", "hoad3", "hoac1", "hoalm", "loes"])
def test_the_listing_reads_slot_unit_range_and_defaults_from_the_metadata(name):
    cls = model_class(name)
    listing = cls.parameters("left_wing")
    info = pm.metas(cls.params_class)
    assert [p.name for p in listing] == list(info)
    defaults = cls.default_params(load_channel("left_wing"))
    for p in listing:
        m = info[p.name]
        assert (p.unit, p.min, p.max, p.min_exclusive, p.description) == (m.unit, m.min, m.max, m.min_exclusive,
                                                                         m.description)
        assert p.switchable == (m.off is not None)
        assert p.element == m.element
        assert p.default == getattr(defaults, p.name)
        layout = cls.params_layout
        assert p.slot == (None if layout is None or m.kernel is None else getattr(layout, m.kernel))
    assert cls.parameters()[0].default is None


def test_yaml_paths_of_the_listing_reach_the_values():
    listing = {p.name: p for p in model_class("hoad2").parameters("left_wing")}
    assert listing["quantization_v"].path == "high_order.hoad2.quantization_v"
    assert listing["total_breakpoints_lbf"].path == "high_order.hoad3.total_breakpoints_lbf"
    assert listing["crank_arm_in"].path == "crank_arm_in"  # the channel's physical data
    cfg = load_channel("left_wing")
    for p in listing.values():
        if "." not in p.path:  # from the channel's physical data
            assert getattr(cfg, p.path) == p.default, p.name
            continue
        node = cfg.sections
        for key in p.path.split("."):
            node = node[key]
        assert node == p.default or tuple(node) == p.default, p.path


def test_identification_bounds_are_the_declared_ranges():
    for name, free in FREE.items():
        m = pm.metas(SecondOrderParams)[name]
        assert (free.low, free.high) == (m.min, m.max), name


@pytest.mark.parametrize("cls", [SecondOrderParams, HighOrderParams])
def test_the_one_validator_rejects_every_value_outside_its_declared_range(cls):
    cfg = load_channel("left_wing")
    base = cls.from_channel(cfg)
    for name, m in pm.metas(cls).items():
        value = getattr(base, name)
        if m.size > 1:
            bad = (float("nan"),) * m.size
        elif m.min > -math.inf:
            bad = m.min - (1.0 if m.min == 0.0 else abs(m.min) * 0.5) if not m.min_exclusive else m.min
        elif m.max < math.inf:
            bad = m.max * 2.0 + 1.0
        else:
            bad = float("nan")
        if m.off is not None and bad == m.off:
            continue
        with pytest.raises(ConfigError, match=name):
            cls.validate(replace(base, **{name: bad}))
        if m.off is not None:
            cls.validate(replace(base, **{name: m.off}))  # the switch-off value is always allowed
        del value


def test_one_loader_for_every_set_names_unknown_and_missing_parameters():
    cfg = load_channel("left_wing")
    with pytest.raises(ConfigError, match="unknown parameter 'wn' in second_order"):
        pm.load(SecondOrderParams, {"wn": 1.0}, origin="x", family="second-order", section="second_order")
    with pytest.raises(ConfigError, match="second_order is missing"):
        pm.load(SecondOrderParams, {}, origin="x", family="second-order", section="second_order")
    with pytest.raises(UnknownNameError, match="high-order parameter 'kp'"):
        HighOrderParams.from_channel(cfg, kp=1.0)
    section = {**cfg.section("high_order"), "hoad2": {"total_breakpoints_lbf": [1, 2]}}
    with pytest.raises(ConfigError, match=r"unknown parameter 'total_breakpoints_lbf' in high_order\.hoad2"):
        pm.load(HighOrderParams, section, origin="x", family="high-order", section="high_order")
    with pytest.raises(ConfigError, match=r"must be a number, got '5\.0e6'"):  # what YAML 1.1 makes of 5.0e6
        pm.load(SecondOrderParams, {**cfg.section("second_order"), "wn_rad_s": "5.0e6"}, origin="x",
                family="second-order", source=cfg)
    with pytest.raises(ConfigError, match="needs 3 values"):
        HighOrderParams.from_channel(cfg, total_mean_stiffness_lbf_per_in=(1.0, 2.0))
    assert HighOrderParams.from_channel(cfg, "hoac1").command_delay_s == 0.0  # HOAC1: no flight/test environment
    assert HighOrderParams.from_channel(cfg, "hoad2").feedback_delay_s == 0.0
    assert HighOrderParams.from_channel(cfg, "hoad3").feedback_delay_s == 0.002
    with pytest.raises(ConfigError, match="lag_hz must be a finite number"):
        Profile.from_parameters({"command": {"lag_hz": -1.0}})


def test_basic_second_order_is_every_switchable_stage_at_its_declared_off_value():
    basic = SecondOrderParams.basic(load_channel("left_wing"))
    for name, off in pm.switched_off(SecondOrderParams).items():
        assert getattr(basic, name) == off, name
    assert basic.rate_limit_dps == math.inf


def test_switchable_elements_are_declared_by_each_parameter_set():
    assert ENV_ELEMENTS == ("lag", "quantization", "delay", "noise")
    assert ELEMENTS[-1] == "dead_band"
    assert ELEMENTS[:-1] == ENV_ELEMENTS
    assert model_class("hoad3").elements() == ("dead_band", "quantization", "noise")
    assert model_class("loada").elements() == ("quantization",)
    assert model_class("hoalm").elements() == ()  # linearized: its nonlinear elements are gone
    assert model_overrides("hoad3", element_names(["noise,dead_band", "command.delay"])) == {
        "pwm_dead_band_v": 0.0, "command_noise_v": 0.0, "feedback_noise_v": 0.0}
    assert model_overrides("loada", ["quantization", "noise"]) == {"quantization_deg": 0.0}
    assert model_overrides("sloac", ["quantization"]) == {}
    off = create("hoad3", **model_overrides("hoad3", ["noise"]))
    quiet = create("hoad3", noise=False)
    t = np.arange(200) * 0.005
    a = off.run(t, np.where(t > 0.1, 1.0, 0.0), sample_times=t, end_s=1.0)
    b = quiet.run(t, np.where(t > 0.1, 1.0, 0.0), sample_times=t, end_s=1.0)
    assert np.array_equal(a.position_deg, b.position_deg)  # noise parameters off = the noise option off


def test_every_model_lists_its_parameters_for_every_channel():
    for channel in CHANNELS:
        for name in model_names():
            listing = model_class(name).parameters(channel)
            assert all(p.default is not None for p in listing), (channel, name)


@pytest.mark.parametrize("cls", [SecondOrderParams, HighOrderParams])
def test_a_value_from_the_channel_shares_the_channels_one_declaration(cls):
    channel = pm.metas(ChannelConfig)
    linked = {name: m for name, m in pm.metas(cls).items() if m.channel is not None}
    assert {"position_min_deg", "position_max_deg", "surface_inertia_inlbs2"} <= set(linked)
    for name, m in linked.items():
        src = channel[m.channel]
        assert m.source is ChannelConfig, name
        assert (m.unit, m.min, m.max, m.min_exclusive, m.size, m.uncertainty) == (
            src.unit, src.min, src.max, src.min_exclusive, src.size, src.uncertainty), name
        assert m.kernel is not None, name  # what the family adds: its kernel slot
    assert pm.relations(cls).count(("position_min_deg", "<", "position_max_deg")) == 1  # from the channel


def test_the_position_limit_check_is_declared_once_and_holds_for_the_channel_and_both_families():
    assert ChannelConfig.RELATIONS == (("position_min_deg", "<", "position_max_deg"),)
    assert "RELATIONS" not in vars(SecondOrderParams)
    assert all("position_min_deg" not in r for r in HighOrderParams.RELATIONS)
    cfg = load_channel("left_wing")
    with pytest.raises(ConfigError, match="channel parameter position_min_deg must be below position_max_deg"):
        pm.validate(replace(cfg, position_min_deg=50.0), "channel")
    with pytest.raises(ConfigError, match="second-order parameter position_min_deg must be below position_max_deg"):
        SecondOrderParams.from_channel(cfg, position_min_deg=50.0)
    with pytest.raises(ConfigError, match="high-order parameter position_min_deg must be below position_max_deg"):
        HighOrderParams.from_channel(cfg, position_max_deg=-50.0)
    so = SecondOrderParams.from_channel(cfg)
    with pytest.raises(ConfigError, match="position_min_deg must be below"):
        so.replace(position_max_deg=-44.0)


def test_a_text_parameter_is_one_of_its_choices():
    cfg = load_channel("left_wing")
    m = pm.metas(ChannelConfig)["surface"]
    assert m.choices == ("wing", "rudder", "cowl")
    assert pm.coerce("surface", m, "rudder", "x", "channel") == "rudder"
    with pytest.raises(ConfigError, match="surface must be one of wing, rudder, cowl, got 'flap'"):
        pm.coerce("surface", m, "flap", "x", "channel")
    with pytest.raises(ConfigError, match="channel parameter channel must be one of left_wing, right_wing"):
        pm.validate(replace(cfg, channel="tail"), "channel")
    assert [p.default for p in pm.describe(ChannelConfig, defaults=cfg)][:2] == ["left_wing", "wing"]


def test_carried_data_are_loaded_as_given_and_listed_nowhere():
    cfg = load_channel("left_wing")
    assert "sections" not in pm.metas(ChannelConfig)
    assert {"second_order", "high_order", "loes"} <= set(cfg.sections)
    assert all(p.name != "sections" for p in pm.describe(ChannelConfig))
    assert "sections" not in ChannelConfig.__doc__.split("Parameters\n----------")[1]

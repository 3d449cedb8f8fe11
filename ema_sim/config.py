"""Per-channel configuration: the ROS 2 parameter files under ``config/``, read without ROS.

Each channel file holds ``/**/emac_<channel>: ros__parameters: {...}`` so the EMAC node can take it with
``--params-file`` (in any namespace); offline tools read the same mapping here. Nested sections (``second_order``,
``high_order``...) belong to the model family that uses them.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache, cached_property
from pathlib import Path
from typing import Any, ClassVar, SupportsFloat

import yaml
from numpy.typing import ArrayLike

from ema_msgs_py import contract
from ema_msgs_py.contract import Scaling, scaling_of
from ema_sim import parameters as pm
from ema_sim.calibration import Cubic, FloatArray
from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.jsontypes import JsonObject

CHANNELS: tuple[str, ...] = contract.CHANNELS
GENERIC = "generic"
"""The channel reported for a record of no X-43A channel: a generic actuator, its travel measured from the record."""
STAND_IN = "left_wing"
"""The configuration a generic actuator is run with: its nominal second-order values start the fits; its travel is
replaced by the record's, and no X-43A table applies."""
"""The five EMAC channels (section 1.4), as the topic contract names them: one ``config/<channel>.yaml`` each."""

RAD2DEG = 180.0 / math.pi


def config_dir() -> Path:
    """Where the YAML files are: ``$EMA_SIM_CONFIG``, the source tree, or the installed share dir."""
    env = os.environ.get("EMA_SIM_CONFIG")
    candidates = [Path(env)] if env else []
    candidates.append(Path(__file__).resolve().parents[1] / "config")
    candidates.append(Path(sys.prefix) / "share" / "ema_sim" / "config")
    try:  # a colcon/ament install
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415 - only in a ROS install (colcon), absent from a pip venv

        candidates.append(Path(get_package_share_directory("ema_sim")) / "config")
    except Exception:
        pass
    for path in candidates:
        if (path / "left_wing.yaml").is_file():
            return path
    raise ConfigError(f"no ema_sim config directory found (looked in {', '.join(map(str, candidates))})")


SURFACES: tuple[str, ...] = ("wing", "rudder", "cowl")
"""The kinds of surface the channels move."""
POS: JsonObject = {"min": 0.0, "min_exclusive": True}
"""A positive quantity."""


@pm.documented
@dataclass(frozen=True)
class ChannelConfig:
    """Physical and signal data of one EMAC channel (tables 1, A2; sections 1.4, 2.4, 2.6).

    Each value is declared once here (:func:`ema_sim.parameters.param`): the model families' parameters
    that come from the channel are :func:`~ema_sim.parameters.linked` to these declarations. The model
    families' own sections (``second_order``, ``high_order``, ``loes``...) are carried as given.
    """

    channel: str = pm.param("-", "the EMAC channel (section 1.4)", choices=CHANNELS)
    surface: str = pm.param("-", "the kind of surface it moves (its hinge-moment model)", choices=SURFACES)
    surface_inertia_inlbs2: float = pm.param("in·lb·s²", "surface inertia Is (table A2 inertial load)", **POS)
    stroke_in: float = pm.param("in", "ball-screw stroke (table 1)", **POS)
    slew_rate_in_s: float = pm.param("in/s", "unloaded slew rate at the ball screw (table 1)", **POS)
    slew_rate_dps: float = pm.param("deg/s", "unloaded slew rate of the surface (table 1)", min=1.0, max=2000.0)
    crank_arm_in: float = pm.param("in", "servo crank arm: force ↔ hinge moment, travel ↔ angle (tables 1, A2)",
                                   **POS)
    stall_force_lbf: float = pm.param("lbf", "stall force at 125 Vdc (table 1)", **POS)
    rated_force_lbf: float = pm.param("lbf", "force of table A2's force-versus-rate point at 125 Vdc", **POS)
    rated_rate_in_s: float = pm.param("in/s", "rate of table A2's force-versus-rate point at 125 Vdc", **POS)
    backlash_in: float = pm.param("in", "backlash specification (table 1: ≤ 0.005 in)", min=0.0)
    static_stiffness_lbf_per_in: float = pm.param("lbf/in", "static stiffness specification (table 1)", **POS)
    position_min_deg: float = pm.param("deg", "lower position limit, the mechanical stop (3.1.2.1)")
    position_max_deg: float = pm.param("deg", "upper position limit, the mechanical stop (3.1.2.1)")
    free_play_deg: float = pm.param(
        "deg", "free play width of the surface (2.4, 3.1.2.3)", min=0.0, max=3.0, uncertainty=(0.171, 0.200),
        uncertainty_source="section 2.4: 0.171° and 0.179° on vehicle 1, ≈ 0.200° on vehicles 2 and 3")
    full_scale_v: float = pm.param("V", "full scale of the command and feedback signals (1.4: ±10 V)", **POS)
    command_cal_v: tuple[float, float, float, float] = pm.param(
        "V", "command curve, degrees → volts: V = c0 + c1·deg + c2·deg² + c3·deg³ (2.6, 3.1.2.2)", size=4)
    feedback_cal_deg: tuple[float, float, float, float] = pm.param(
        "deg", "feedback curve, volts → degrees: deg = c0 + c1·V + c2·V² + c3·V³ (2.6, 3.1.2.2)", size=4)
    sections: Mapping[str, Mapping[str, object]] = pm.carried(
        "the model families' sections (``second_order``, ``high_order``, ``loes``...)", default_factory=dict)

    RELATIONS: ClassVar[tuple[pm.Relation, ...]] = (("position_min_deg", "<", "position_max_deg"),)

    @cached_property
    def command_cal(self) -> Cubic:
        """The command curve, degrees → volts."""
        return Cubic(*self.command_cal_v)

    @cached_property
    def feedback_cal(self) -> Cubic:
        """The feedback curve, volts → degrees."""
        return Cubic(*self.feedback_cal_deg)

    @property
    def deg_per_in(self) -> float:
        """Surface degrees per inch of ball-screw travel at the crank arm (small-angle)."""
        return RAD2DEG / self.crank_arm_in

    def section(self, name: str) -> dict[str, Any]:
        """A model family's parameter section (a copy; empty when the file has none)."""
        return dict(self.sections.get(name, {}))

    def deg_to_v(self, deg: ArrayLike) -> FloatArray:
        """Command volts the FMU sends for a surface command in degrees (command curve)."""
        return self.command_cal(deg)

    def v_to_deg(self, volts: ArrayLike) -> FloatArray:
        """Surface degrees the FMU reads from LVDT feedback volts (feedback curve)."""
        return self.feedback_cal(volts)

    def command_v_to_deg(self, volts: ArrayLike) -> FloatArray:
        """The surface command in degrees that a command voltage stands for (inverse command curve)."""
        return self.command_cal.inverse(volts)

    def position_deg_to_v(self, deg: ArrayLike) -> FloatArray:
        """The LVDT feedback voltage that reads back as ``deg`` (inverse feedback curve)."""
        return self.feedback_cal.inverse(deg)


def ros_parameters(path: Path) -> dict[str, Any]:
    """The ``ros__parameters`` mapping of a ROS 2 parameter file with one node entry."""
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path}: cannot read ({exc})") from exc
    if not isinstance(doc, dict) or len(doc) != 1:
        raise ConfigError(f"{path}: expected one node entry with ros__parameters")
    (entry,) = doc.values()
    if not isinstance(entry, dict) or not isinstance(entry.get("ros__parameters"), dict):
        raise ConfigError(f"{path}: expected <node>: ros__parameters: {{...}}")
    params: JsonObject = entry["ros__parameters"]
    return params


def finite_parameter(params: Mapping[str, object], key: str, origin: str) -> float:
    """``params[key]`` as a finite float, or one :class:`ConfigError` that names the file and the key."""
    if key not in params:
        raise ConfigError(f"{origin}: missing parameter {key!r}")
    raw = params[key]
    try:
        if not isinstance(raw, SupportsFloat | str):
            raise TypeError
        value = float(raw)
    except (TypeError, ValueError):
        raise ConfigError(f"{origin}: parameter {key!r} must be a number, got {params[key]!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"{origin}: parameter {key!r} must be finite")
    return value


def parse_channel(params: Mapping[str, object], origin: str = "<params>") -> ChannelConfig:
    """A channel's parameter mapping as a :class:`ChannelConfig`, loaded and validated by its declaration.

    Parameters
    ----------
    params : mapping
        The ``ros__parameters`` of a channel file (or the node's declared values, nested).
    origin : str
        Where they come from, for messages.

    Returns
    -------
    ChannelConfig
        The validated channel.
    """
    values = {k: v for k, v in params.items() if not isinstance(v, Mapping)}
    sections = {k: dict(v) for k, v in params.items() if isinstance(v, Mapping)}
    cfg = pm.load(ChannelConfig, values, origin=origin, family="channel", carry={"sections": sections})
    if cfg.command_cal.sign != cfg.feedback_cal.sign:
        raise ConfigError(f"{origin}: command and feedback curves disagree in sign")
    return cfg


@cache
def load_channel(channel: str = "left_wing") -> ChannelConfig:
    """The configuration of one of the five channels from ``config/<channel>.yaml``."""
    if channel not in CHANNELS:
        raise UnknownNameError("channel", channel, CHANNELS)
    path = config_dir() / f"{channel}.yaml"
    return parse_channel(ros_parameters(path), origin=str(path))


@cache
def scaling(channel: str) -> Scaling:
    """The degree↔volt scaling of one of the five channels, from ``config/<channel>.yaml`` (the contract's form)."""
    return scaling_of(load_channel(channel))

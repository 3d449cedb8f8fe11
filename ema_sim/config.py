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
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from ema_sim.calibration import Cubic
from ema_sim.errors import ConfigError, UnknownNameError

CHANNELS: tuple[str, ...] = ("left_wing", "right_wing", "left_rudder", "right_rudder", "cowl_door")
"""The five EMAC channels (section 1.4)."""

RAD2DEG = 180.0 / math.pi


def config_dir() -> Path:
    """Where the YAML files are: ``$EMA_SIM_CONFIG``, the source tree, or the installed share dir."""
    env = os.environ.get("EMA_SIM_CONFIG")
    candidates = [Path(env)] if env else []
    candidates.append(Path(__file__).resolve().parents[1] / "config")
    candidates.append(Path(sys.prefix) / "share" / "ema_sim" / "config")
    try:  # a colcon/ament install
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        candidates.append(Path(get_package_share_directory("ema_sim")) / "config")
    except Exception:
        pass
    for path in candidates:
        if (path / "left_wing.yaml").is_file():
            return path
    raise ConfigError(f"no ema_sim config directory found (looked in {', '.join(map(str, candidates))})")


@dataclass(frozen=True)
class ChannelConfig:
    """Physical and signal data of one EMAC channel (tables 1, A2; sections 1.4, 2.4, 2.6)."""

    channel: str
    surface: str
    surface_inertia_inlbs2: float
    stroke_in: float
    slew_rate_in_s: float
    slew_rate_dps: float
    crank_arm_in: float
    stall_force_lbf: float
    rated_force_lbf: float
    rated_rate_in_s: float
    backlash_in: float
    static_stiffness_lbf_per_in: float
    position_min_deg: float
    position_max_deg: float
    free_play_deg: float
    full_scale_v: float
    command_cal: Cubic
    feedback_cal: Cubic
    sections: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @property
    def deg_per_in(self) -> float:
        """Surface degrees per inch of ball-screw travel at the crank arm (small-angle)."""
        return RAD2DEG / self.crank_arm_in

    def section(self, name: str) -> dict[str, Any]:
        """A model family's parameter section (a copy; empty when the file has none)."""
        return dict(self.sections.get(name, {}))

    def deg_to_v(self, deg: Any) -> Any:
        """Command volts the FMU sends for a surface command in degrees (command curve)."""
        return self.command_cal(deg)

    def v_to_deg(self, volts: Any) -> Any:
        """Surface degrees the FMU reads from LVDT feedback volts (feedback curve)."""
        return self.feedback_cal(volts)

    def command_v_to_deg(self, volts: Any) -> Any:
        """The surface command in degrees that a command voltage stands for (inverse command curve)."""
        return self.command_cal.inverse(volts)

    def position_deg_to_v(self, deg: Any) -> Any:
        """The LVDT feedback voltage that reads back as ``deg`` (inverse feedback curve)."""
        return self.feedback_cal.inverse(deg)


_SCALARS = (
    "surface_inertia_inlbs2", "stroke_in", "slew_rate_in_s", "slew_rate_dps", "crank_arm_in",
    "stall_force_lbf", "rated_force_lbf", "rated_rate_in_s", "backlash_in",
    "static_stiffness_lbf_per_in", "position_min_deg", "position_max_deg", "free_play_deg",
    "full_scale_v",
)


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
    params: dict[str, Any] = entry["ros__parameters"]
    return params


def finite_parameter(params: Mapping[str, Any], key: str, origin: str) -> float:
    """``params[key]`` as a finite float, or one :class:`ConfigError` that names the file and the key."""
    if key not in params:
        raise ConfigError(f"{origin}: missing parameter {key!r}")
    try:
        value = float(params[key])
    except (TypeError, ValueError):
        raise ConfigError(f"{origin}: parameter {key!r} must be a number, got {params[key]!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"{origin}: parameter {key!r} must be finite")
    return value


def parse_channel(params: Mapping[str, Any], origin: str = "<params>") -> ChannelConfig:
    """Validate a channel's parameter mapping into a :class:`ChannelConfig`."""
    values: dict[str, Any] = {key: finite_parameter(params, key, origin) for key in _SCALARS}
    try:
        command_cal = Cubic.from_list(params["command_cal_v"])
        feedback_cal = Cubic.from_list(params["feedback_cal_deg"])
    except (KeyError, ValueError) as exc:
        raise ConfigError(f"{origin}: calibration curves: {exc}") from exc
    if values["position_min_deg"] >= values["position_max_deg"]:
        raise ConfigError(f"{origin}: position_min_deg must be below position_max_deg")
    if command_cal.sign != feedback_cal.sign:
        raise ConfigError(f"{origin}: command and feedback curves disagree in sign")
    sections = {k: dict(v) for k, v in params.items() if isinstance(v, dict)}
    return ChannelConfig(
        channel=str(params.get("channel", "?")),
        surface=str(params.get("surface", "?")),
        command_cal=command_cal,
        feedback_cal=feedback_cal,
        sections=sections,
        **values,
    )


@cache
def load_channel(channel: str = "left_wing") -> ChannelConfig:
    """The configuration of one of the five channels from ``config/<channel>.yaml``."""
    if channel not in CHANNELS:
        raise UnknownNameError("channel", channel, CHANNELS)
    path = config_dir() / f"{channel}.yaml"
    return parse_channel(ros_parameters(path), origin=str(path))

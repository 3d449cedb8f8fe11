"""Parameters of the aircraft-in-the-loop vehicle and flight computer (``config/ail_vehicle.yaml``).

A ROS 2 parameter file of the ``fmu`` node, read here without ROS; the node merges its ROS overrides
over the same mapping (:func:`AilConfig.from_parameters`). Every value is illustrative (the report
publishes no X-43A aerodynamics or control laws); the file says why each was chosen.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from ema_sim.config import CHANNELS, config_dir, finite_parameter, load_channel, ros_parameters
from ema_sim.errors import ConfigError, UnknownNameError

CONFIG_NAME = "ail_vehicle.yaml"
AERO_INPUTS = ("feedback", "surface")
"""What drives the simulated aerodynamics: the FMU-side LVDT feedback (closed-loop AIL) or the true surface."""
SURFACE_LOADS = ("aerodynamic", "bungee")
"""What loads the real surfaces: the hinge-moment model (flight) or a bungee / nothing (AIL, on the ground)."""
WINGS = ("left_wing", "right_wing")


def _numbers(cls: type, values: Mapping[str, Any], origin: str) -> dict[str, float]:
    """Every field of a dataclass of floats from ``values``: present, finite, nothing unknown."""
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ConfigError(f"{origin}: unknown parameter {unknown[0]!r} (known: {', '.join(names)})")
    return {name: finite_parameter(values, name, origin) for name in names}


@dataclass(frozen=True)
class VehicleParams:
    """Rigid-body short period and roll about a trimmed flight condition (degrees and seconds)."""

    trim_alpha_deg: float
    trim_theta_deg: float
    trim_elevon_deg: float
    z_alpha_per_s: float
    z_elevon_per_s: float
    m_alpha_per_s2: float
    m_q_per_s: float
    m_elevon_per_s2: float
    l_p_per_s: float
    l_aileron_per_s2: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], origin: str = "vehicle") -> VehicleParams:
        """Validated: the sign conventions the autopilot relies on hold."""
        out = cls(**_numbers(cls, values, origin))
        if out.m_elevon_per_s2 >= 0.0:
            raise ConfigError(f"{origin}: m_elevon_per_s2 must be negative (a trailing-edge-down elevon "
                              "pitches the nose down)")
        if out.l_aileron_per_s2 <= 0.0:
            raise ConfigError(f"{origin}: l_aileron_per_s2 must be positive ((left − right)/2 rolls right)")
        return out


@dataclass(frozen=True)
class AutopilotParams:
    """Attitude hold in pitch and roll with trim (gains in degrees of surface per unit of error)."""

    trim_elevon_deg: float
    pitch_attitude_gain_deg_per_deg: float
    pitch_integral_gain_per_s: float
    pitch_rate_gain_s: float
    roll_attitude_gain_deg_per_deg: float
    roll_integral_gain_per_s: float
    roll_rate_gain_s: float
    elevon_limit_deg: float
    aileron_limit_deg: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], origin: str = "autopilot") -> AutopilotParams:
        """Validated: gains and limits are not negative."""
        out = cls(**_numbers(cls, values, origin))
        for f in fields(out):
            if f.name != "trim_elevon_deg" and getattr(out, f.name) < 0.0:
                raise ConfigError(f"{origin}: {f.name} must not be negative")
        return out


@dataclass(frozen=True)
class HingeMomentParams:
    """Aerodynamic hinge moment of one surface kind: ``h0 + hα·α + hδ·δ`` (in·lb)."""

    h0_inlb: float
    h_alpha_inlb_per_deg: float
    h_delta_inlb_per_deg: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], origin: str) -> HingeMomentParams:
        """Validated."""
        return cls(**_numbers(cls, values, origin))

    def at(self, alpha_deg: float, delta_deg: float) -> float:
        """The hinge moment at angle of attack ``alpha_deg`` and surface deflection ``delta_deg``."""
        return self.h0_inlb + self.h_alpha_inlb_per_deg * alpha_deg + self.h_delta_inlb_per_deg * delta_deg


@dataclass(frozen=True)
class Setup:
    """What a test-environment profile means for the vehicle loop (``setup.<profile>``)."""

    aero_input: str
    surface_load: str
    bungee_inlb: float = 0.0

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], origin: str) -> Setup:
        """Validated."""
        unknown = sorted(set(values) - {"aero_input", "surface_load", "bungee_inlb"})
        if unknown:
            raise ConfigError(f"{origin}: unknown parameter {unknown[0]!r}")
        try:
            out = cls(str(values["aero_input"]), str(values["surface_load"]), float(values.get("bungee_inlb", 0.0)))
        except KeyError as exc:
            raise ConfigError(f"{origin}: missing parameter {exc.args[0]!r}") from None
        except (TypeError, ValueError):
            raise ConfigError(f"{origin}: bungee_inlb must be a number") from None
        out.validate(origin)
        return out

    def validate(self, origin: str = "setup") -> None:
        """One clear error for a bad choice."""
        if self.aero_input not in AERO_INPUTS:
            raise UnknownNameError(f"{origin} aero_input", self.aero_input, AERO_INPUTS)
        if self.surface_load not in SURFACE_LOADS:
            raise UnknownNameError(f"{origin} surface_load", self.surface_load, SURFACE_LOADS)
        if not math.isfinite(self.bungee_inlb):
            raise ConfigError(f"{origin}: bungee_inlb must be finite")

    def describe(self) -> str:
        """One line for logs and metadata."""
        load = "aerodynamic hinge moments" if self.surface_load == "aerodynamic" else (
            f"bungee {self.bungee_inlb:g} in·lb on the wings" if self.bungee_inlb else "unloaded")
        seen = "LVDT feedback (FMU side)" if self.aero_input == "feedback" else "true surface angle"
        return f"aerodynamics driven by the {seen}; surfaces {load}"


@dataclass(frozen=True)
class AilConfig:
    """The whole ``fmu`` parameter set."""

    frame_hz: float
    vehicle: VehicleParams
    autopilot: AutopilotParams
    hinge_moment: dict[str, HingeMomentParams]
    """Surface kind (``wing``, ``rudder``, ``cowl``: the channel file's ``surface``) → hinge-moment model."""
    held_deg: dict[str, float]
    setups: dict[str, Setup]
    sim_model: str
    settle_s: float
    source: str = ""

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], origin: str = "<params>") -> AilConfig:
        """Validate the ``ros__parameters`` mapping of ``config/ail_vehicle.yaml``."""
        def section(name: str) -> Mapping[str, Any]:
            value = params.get(name)
            if not isinstance(value, Mapping):
                raise ConfigError(f"{origin}: {name} must be a mapping")
            return value

        try:
            frame_hz = float(params.get("frame_hz", 200.0))
            settle_s = float(section("measure").get("settle_s", 0.0))
        except (TypeError, ValueError):
            raise ConfigError(f"{origin}: frame_hz and measure.settle_s must be numbers") from None
        if not (math.isfinite(frame_hz) and frame_hz > 0.0 and math.isfinite(settle_s) and settle_s >= 0.0):
            raise ConfigError(f"{origin}: frame_hz must be positive and measure.settle_s not negative")
        hinge = {kind: HingeMomentParams.from_mapping(values, f"{origin}: hinge_moment.{kind}")
                 for kind, values in section("hinge_moment").items()}
        for ch in CHANNELS:
            kind = load_channel(ch).surface
            if kind not in hinge:
                raise ConfigError(f"{origin}: hinge_moment has no model for {kind!r} surfaces ({ch})")
        held: dict[str, float] = {}
        for ch, value in section("held_deg").items():
            if ch not in CHANNELS or ch in WINGS:
                raise ConfigError(f"{origin}: held_deg: {ch!r} is not a channel the autopilot leaves alone "
                                  f"({', '.join(c for c in CHANNELS if c not in WINGS)})")
            try:
                held[ch] = float(value)
            except (TypeError, ValueError):
                raise ConfigError(f"{origin}: held_deg.{ch} must be a number") from None
        setups = {name: Setup.from_mapping(values, f"{origin}: setup.{name}")
                  for name, values in section("setup").items()}
        return cls(
            frame_hz=frame_hz,
            vehicle=VehicleParams.from_mapping(section("vehicle"), f"{origin}: vehicle"),
            autopilot=AutopilotParams.from_mapping(section("autopilot"), f"{origin}: autopilot"),
            hinge_moment=hinge,
            held_deg={ch: held.get(ch, 0.0) for ch in CHANNELS if ch not in WINGS},
            setups=setups,
            sim_model=str(section("open_loop").get("sim_model", "loada")),
            settle_s=settle_s,
            source=origin,
        )

    def setup(self, profile: str, *, aero_input: str | None = None, surface_load: str | None = None,
              bungee_inlb: float | None = None) -> Setup:
        """The setup of a profile (one clear error when the file has none), with any of its choices changed.

        A bungee implies ``surface_load="bungee"``.
        """
        if profile not in self.setups:
            raise UnknownNameError("vehicle setup (setup.<profile> in the fmu parameters)", profile, self.setups)
        out = self.setups[profile]
        if aero_input:
            out = replace(out, aero_input=aero_input)
        if surface_load:
            out = replace(out, surface_load=surface_load)
        if bungee_inlb is not None:
            out = replace(out, surface_load="bungee", bungee_inlb=float(bungee_inlb))
        out.validate(f"setup.{profile}")
        return out


def config_path(path: str | Path | None = None) -> Path:
    """The parameter file: ``path`` or ``config/ail_vehicle.yaml``."""
    return Path(path) if path is not None else config_dir() / CONFIG_NAME


def load_ail_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> AilConfig:
    """Read (and validate) the vehicle and flight-computer parameters; ``overrides`` merge over the file."""
    p = config_path(path)
    params = ros_parameters(p)
    if overrides:
        params = deep_merged(params, overrides)
    return AilConfig.from_parameters(params, str(p))


def deep_merged(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Nested mappings merged, ``override`` winning (as the nodes merge ROS parameters over a file)."""
    out = dict(base)
    for key, value in override.items():
        old = out.get(key)
        out[key] = deep_merged(old, value) if isinstance(value, Mapping) and isinstance(old, Mapping) else value
    return out

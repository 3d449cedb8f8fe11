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

from ema_sim import parameters as pm
from ema_sim.config import CHANNELS, config_dir, finite_parameter, load_channel, ros_parameters
from ema_sim.errors import ConfigError, UnknownNameError

CONFIG_NAME = "ail_vehicle.yaml"
AERO_INPUTS = ("feedback", "surface")
"""What drives the simulated aerodynamics: the FMU-side LVDT feedback (closed-loop AIL) or the true surface."""
SURFACE_LOADS = ("aerodynamic", "bungee")
"""What loads the real surfaces: the hinge-moment model (flight) or a bungee / nothing (AIL, on the ground)."""
WINGS = ("left_wing", "right_wing")

# The mappings below are the vehicle file's sections as YAML (or ROS parameters) gave them; every value
# is checked where it is read (a wrong one is one ConfigError naming it).


def _numbers(cls: type, values: Mapping[str, object], origin: str) -> dict[str, float]:
    """Every field of a dataclass of floats from ``values``: present, finite, nothing unknown."""
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ConfigError(f"{origin}: unknown parameter {unknown[0]!r} (known: {', '.join(names)})")
    return {name: finite_parameter(values, name, origin) for name in names}


@dataclass(frozen=True)
class VehicleParams:
    """Rigid-body short period and roll about a trimmed flight condition (degrees and seconds)."""

    trim_alpha_deg: float = pm.param("deg", "trimmed angle of attack the run starts at")
    trim_theta_deg: float = pm.param("deg", "trimmed pitch attitude the run starts at")
    trim_elevon_deg: float = pm.param("deg", "symmetric wing deflection that trims the vehicle")
    z_alpha_per_s: float = pm.param("1/s", "short period: α' = Zα·α + q + Zδ·δe, the lift-curve term Zα")
    z_elevon_per_s: float = pm.param("1/s", "short period: the elevon's lift on the flight path Zδ")
    m_alpha_per_s2: float = pm.param("1/s²", "short period: q' = Mα·α + Mq·q + Mδ·δe, the static stability Mα")
    m_q_per_s: float = pm.param("1/s", "short period: the pitch damping Mq")
    m_elevon_per_s2: float = pm.param("1/s²", "short period: the elevon's control power Mδ (negative)")
    l_p_per_s: float = pm.param("1/s", "roll: p' = Lp·p + Lδa·δa, the roll damping Lp")
    l_aileron_per_s2: float = pm.param("1/s²", "roll: the differential wings' control power Lδa (positive)")

    @classmethod
    def from_mapping(cls, values: Mapping[str, object], origin: str = "vehicle") -> VehicleParams:
        """Validated: the sign conventions the autopilot relies on hold.

        Parameters
        ----------
        values : Mapping[str, object]
            The ``vehicle`` section: every field, finite, nothing else.
        origin : str, optional
            Where the values come from, for the error message.

        Returns
        -------
        VehicleParams
            The parameters.

        Raises
        ------
        ConfigError
            A missing, unknown or non-finite value, or a sign the autopilot cannot fly with.
        """
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

    trim_elevon_deg: float = pm.param("deg", "the flight computer's trim: the pitch integrator's start")
    pitch_attitude_gain_deg_per_deg: float = pm.param("deg/deg", "pitch attitude gain Kθ (degrees of elevon)")
    pitch_integral_gain_per_s: float = pm.param("1/s", "pitch attitude integral gain")
    pitch_rate_gain_s: float = pm.param("s", "pitch rate gain Kq (degrees of elevon per deg/s)")
    roll_attitude_gain_deg_per_deg: float = pm.param("deg/deg", "roll attitude gain Kφ (degrees of aileron)")
    roll_integral_gain_per_s: float = pm.param("1/s", "roll attitude integral gain")
    roll_rate_gain_s: float = pm.param("s", "roll rate gain Kp (degrees of aileron per deg/s)")
    elevon_limit_deg: float = pm.param("deg", "elevon authority about trim")
    aileron_limit_deg: float = pm.param("deg", "aileron authority")

    @classmethod
    def from_mapping(cls, values: Mapping[str, object], origin: str = "autopilot") -> AutopilotParams:
        """Validated: gains and limits are not negative.

        Parameters
        ----------
        values : Mapping[str, object]
            The ``autopilot`` section: every field, finite, nothing else.
        origin : str, optional
            Where the values come from, for the error message.

        Returns
        -------
        AutopilotParams
            The parameters.

        Raises
        ------
        ConfigError
            A missing, unknown, non-finite or negative value.
        """
        out = cls(**_numbers(cls, values, origin))
        for f in fields(out):
            if f.name != "trim_elevon_deg" and getattr(out, f.name) < 0.0:
                raise ConfigError(f"{origin}: {f.name} must not be negative")
        return out


@dataclass(frozen=True)
class HingeMomentParams:
    """Aerodynamic hinge moment of one surface kind: ``h0 + hα·α + hδ·δ`` (in·lb)."""

    h0_inlb: float = pm.param("in·lb", "hinge moment at zero angle of attack and deflection")
    h_alpha_inlb_per_deg: float = pm.param("in·lb/deg", "hinge moment per degree of angle of attack")
    h_delta_inlb_per_deg: float = pm.param("in·lb/deg", "hinge moment per degree of the surface's deflection")

    @classmethod
    def from_mapping(cls, values: Mapping[str, object], origin: str) -> HingeMomentParams:
        """Validated: the three coefficients, finite, nothing else.

        Parameters
        ----------
        values : Mapping[str, object]
            One ``hinge_moment.<kind>`` section.
        origin : str
            Where the values come from, for the error message.

        Returns
        -------
        HingeMomentParams
            The model.

        Raises
        ------
        ConfigError
            A missing, unknown or non-finite value.
        """
        return cls(**_numbers(cls, values, origin))

    def at(self, alpha_deg: float, delta_deg: float) -> float:
        """The hinge moment at an angle of attack and a surface deflection.

        Parameters
        ----------
        alpha_deg : float
            Angle of attack, deg.
        delta_deg : float
            Surface deflection, deg.

        Returns
        -------
        float
            Hinge moment, in·lb (positive aids positive deflection).
        """
        return self.h0_inlb + self.h_alpha_inlb_per_deg * alpha_deg + self.h_delta_inlb_per_deg * delta_deg


@dataclass(frozen=True)
class Setup:
    """What a test-environment profile means for the vehicle loop (``setup.<profile>``)."""

    aero_input: str = pm.param("-", "what drives the aerodynamics: the LVDT feedback or the true surface angle",
                               choices=AERO_INPUTS)
    """One of :data:`AERO_INPUTS`."""
    surface_load: str = pm.param("-", "the surfaces' load: aerodynamic hinge moments or a bungee",
                                 choices=SURFACE_LOADS)
    """One of :data:`SURFACE_LOADS`."""
    bungee_inlb: float = pm.param("in·lb", "the bungee's hinge moment on each wing (surface_load bungee)",
                                  default=0.0)
    """The bungee's hinge moment on each wing (``surface_load="bungee"``), in·lb."""

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], origin: str) -> Setup:
        """Validated (:meth:`validate`).

        Parameters
        ----------
        values : Mapping[str, object]
            One ``setup.<profile>`` section: ``aero_input``, ``surface_load`` and optionally ``bungee_inlb``.
        origin : str
            Where the values come from, for the error message.

        Returns
        -------
        Setup
            The set-up.

        Raises
        ------
        ConfigError
            A missing or unknown key, or a bungee that is not a finite number.
        UnknownNameError
            An unknown ``aero_input`` or ``surface_load``.
        """
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
        """One clear error for a bad choice.

        Parameters
        ----------
        origin : str, optional
            Where the set-up comes from, for the error message.

        Raises
        ------
        UnknownNameError
            An unknown ``aero_input`` or ``surface_load``.
        ConfigError
            A bungee that is not finite.
        """
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
class HeldCommand:
    """The declaration of one ``held_deg.<channel>`` value (a channel the autopilot leaves alone)."""

    held_deg: float = pm.param("deg", "command of a channel the autopilot leaves alone (rudders, cowl door)",
                               default=0.0)
    """Its command, deg."""


@dataclass(frozen=True)
class FrameParams:
    """The declaration of the file's top-level ``frame_hz``."""

    frame_hz: float = pm.param("Hz", "the FMU frame rate", default=200.0, min=0.0, min_exclusive=True)
    """The FMU frame rate, Hz."""


@dataclass(frozen=True)
class MeasureParams:
    """The declaration of the ``measure`` section."""

    settle_s: float = pm.param("s", "time left out before measuring (the engagement transient)", default=0.0,
                               min=0.0)
    """Time left out before measuring, s."""


@dataclass(frozen=True)
class AilConfig:
    """The whole ``fmu`` parameter set."""

    frame_hz: float
    """The FMU frame rate, Hz."""
    vehicle: VehicleParams
    """The vehicle."""
    autopilot: AutopilotParams
    """The flight computer's control law."""
    hinge_moment: dict[str, HingeMomentParams]
    """Surface kind (``wing``, ``rudder``, ``cowl``: the channel file's ``surface``) → hinge-moment model."""
    held_deg: dict[str, float]
    """Commands of the channels the autopilot leaves alone (rudders, cowl door), deg."""
    setups: dict[str, Setup]
    """Test-environment profile → vehicle set-up."""
    sim_model: str
    """Open loop: the simulation's model actuator."""
    settle_s: float
    """Time left out before measuring (the engagement transient), s."""
    source: str = ""
    """The file the parameters came from."""

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], origin: str = "<params>") -> AilConfig:
        """Validate the ``ros__parameters`` mapping of ``config/ail_vehicle.yaml``.

        Parameters
        ----------
        params : Mapping[str, object]
            The mapping (the node's ROS overrides merged over the file).
        origin : str, optional
            Where it comes from, for the error messages.

        Returns
        -------
        AilConfig
            The parameter set.

        Raises
        ------
        ConfigError
            A section, value or channel that is missing or malformed.
        """
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

        Parameters
        ----------
        profile : str
            The test-environment profile.
        aero_input : str, optional
            Replaces the set-up's ``aero_input``.
        surface_load : str, optional
            Replaces the set-up's ``surface_load``.
        bungee_inlb : float, optional
            A bungee on the wings, in·lb; implies ``surface_load="bungee"``.

        Returns
        -------
        Setup
            The set-up, validated.

        Raises
        ------
        UnknownNameError
            The file has no set-up for ``profile``, or a choice is unknown.
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
    """The parameter file.

    Parameters
    ----------
    path : str or Path, optional
        An explicit file.

    Returns
    -------
    Path
        ``path``, or ``config/ail_vehicle.yaml``.
    """
    return Path(path) if path is not None else config_dir() / CONFIG_NAME


def load_ail_config(path: str | Path | None = None, overrides: Mapping[str, object] | None = None) -> AilConfig:
    """Read (and validate) the vehicle and flight-computer parameters.

    Parameters
    ----------
    path : str or Path, optional
        The parameter file (default ``config/ail_vehicle.yaml``).
    overrides : Mapping[str, object], optional
        Nested values merged over the file's (:func:`deep_merged`).

    Returns
    -------
    AilConfig
        The parameter set.

    Raises
    ------
    ConfigError
        The file cannot be read or holds a bad value.
    """
    p = config_path(path)
    params = ros_parameters(p)
    if overrides:
        params = deep_merged(params, overrides)
    return AilConfig.from_parameters(params, str(p))


def deep_merged(base: Mapping[str, object], override: Mapping[str, object]) -> dict[str, object]:
    """Nested mappings merged, ``override`` winning (as the nodes merge ROS parameters over a file).

    Parameters
    ----------
    base : Mapping[str, object]
        The file's mapping.
    override : Mapping[str, object]
        Values that replace ``base``'s, key by key, nested mappings merged in turn.

    Returns
    -------
    dict[str, object]
        A new mapping (neither argument changes).
    """
    out = dict(base)
    for key, value in override.items():
        old = out.get(key)
        out[key] = deep_merged(old, value) if isinstance(value, Mapping) and isinstance(old, Mapping) else value
    return out

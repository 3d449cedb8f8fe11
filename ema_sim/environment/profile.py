"""Test-environment profiles: what sits between the FMU and the EMACs in each direction (section 4.3).

A profile is two paths of elements, in the order the signal meets them:

command  (FMU → EMAC)  50 Hz lag (FMU software) → 5 mV quantization (FMU D/A) → transport delay → noise (harness)
feedback (EMAC → FMU)  noise (harness) → transport delay → 5 mV quantization (FMU A/D) → 50 Hz lag (FMU software)

Profiles are ROS 2 parameter files for the ``testenv`` node: ``config/flight.yaml``, ``config/ail.yaml``;
``none`` is the built-in pass-through. Any element can be switched off with :meth:`Profile.without`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import SupportsFloat, SupportsInt

import yaml

from ema_sim import parameters as pm
from ema_sim.config import config_dir, ros_parameters
from ema_sim.environment.elements import FirstOrderLag, Noise, Quantizer, SignalPath, TransportDelay
from ema_sim.errors import ConfigError, UnknownNameError

PATHS: tuple[str, ...] = ("command", "feedback")
BUILTIN = ("none",)
FAMILY = "test-environment"


@pm.documented
@dataclass(frozen=True)
class PathSpec:
    """Parameters of one direction; each declares the element a zero switches off."""

    lag_hz: float = pm.param("Hz", "FMU first-order lag filter corner (4.3: 50 Hz)", min=0.0, off=0.0, element="lag",
                             default=0.0)
    quantization_v: float = pm.param("V", "FMU D/A or A/D quantization (4.3: 5 mV)", min=0.0, off=0.0,
                                     element="quantization", default=0.0)
    delay_s: float = pm.param("s", "transport delay of the harness (4.3: 30 ms FMU to first motion in the AIL)",
                              min=0.0, off=0.0, element="delay", default=0.0)
    noise_rms_v: float = pm.param("V", "harness and interface noise rms (4.3, measured, not published)", min=0.0,
                                  off=0.0, element="noise", default=0.0)

    @classmethod
    def from_mapping(cls, values: Mapping[str, object], origin: str) -> PathSpec:
        """Validate a ``command:`` or ``feedback:`` mapping.

        Parameters
        ----------
        values : mapping
            Parameter name → value.
        origin : str
            Where it comes from, for messages.

        Returns
        -------
        PathSpec
            The validated path.
        """
        return pm.load(cls, values, origin=origin, family=FAMILY, section="path")

    def without(self, element: str) -> PathSpec:
        """This path with ``element`` switched off.

        Parameters
        ----------
        element : str
            One of :data:`ELEMENTS`.

        Returns
        -------
        PathSpec
            The changed copy.
        """
        return replace(self, **pm.switched_off(PathSpec, [element]))

    def as_dict(self) -> dict[str, float]:
        """Parameter name → value.

        Returns
        -------
        dict
            Every parameter.
        """
        return {f.name: getattr(self, f.name) for f in fields(self)}


ELEMENTS: tuple[str, ...] = pm.elements(PathSpec)
"""Element names, for :meth:`Profile.without` (``"delay"``, or one path: ``"command.delay"``)."""


@dataclass(frozen=True)
class Profile:
    """A named test environment: the command and the feedback path, and the noise seed."""

    name: str = "none"
    command: PathSpec = field(default_factory=PathSpec)
    feedback: PathSpec = field(default_factory=PathSpec)
    full_scale_v: float = 10.0
    seed: int = 0
    disabled: tuple[str, ...] = ()

    @classmethod
    def none(cls) -> Profile:
        """Pass-through in both directions: the FMU talks to the EMACs directly."""
        return cls()

    @classmethod
    def from_parameters(cls, params: Mapping[str, object], origin: str = "<params>") -> Profile:
        """A profile from its ROS parameters (``profile``, ``seed``, ``command.*``, ``feedback.*``).

        Parameters
        ----------
        params : mapping
            The ``ros__parameters`` of a ``testenv`` parameter file.
        origin : str
            Where they come from, for messages.

        Returns
        -------
        Profile
            The validated profile.
        """
        seed_raw, full_scale_raw = params.get("seed", 0), params.get("full_scale_v", 10.0)
        try:
            if not isinstance(seed_raw, SupportsInt | str):
                raise TypeError(f"seed must be an integer, got {seed_raw!r}")
            if not isinstance(full_scale_raw, SupportsFloat | str):
                raise TypeError(f"full_scale_v must be a number, got {full_scale_raw!r}")
            seed = int(seed_raw)
            full_scale = float(full_scale_raw)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{origin}: {exc}") from None
        paths: dict[str, PathSpec] = {}
        for name in PATHS:
            section = params.get(name, {})
            if not isinstance(section, Mapping):
                raise ConfigError(f"{origin}: {name} must be a mapping of element parameters")
            paths[name] = PathSpec.from_mapping(section, f"{origin}: {name}")
        return cls(name=str(params.get("profile", Path(origin).stem)), full_scale_v=full_scale, seed=seed,
                   command=paths["command"], feedback=paths["feedback"])

    def without(self, *elements: str) -> Profile:
        """This profile with elements switched off: ``"noise"`` (both paths) or ``"feedback.noise"``.

        Parameters
        ----------
        *elements : str
            Element names (:data:`ELEMENTS`), bare or with their path.

        Returns
        -------
        Profile
            The changed copy (``disabled`` lists them).
        """
        out = self
        for item in elements:
            path, _, element = item.rpartition(".")
            if element not in ELEMENTS or (path and path not in PATHS):
                known = [*ELEMENTS, *(f"{p}.{e}" for p in PATHS for e in ELEMENTS)]
                raise UnknownNameError("environment element", item, known)
            for name in [path] if path else PATHS:
                out = replace(out, **{name: getattr(out, name).without(element)})
            out = replace(out, disabled=(*out.disabled, item))
        return out

    def with_seed(self, seed: int) -> Profile:
        """The same profile with another noise seed.

        Parameters
        ----------
        seed : int
            The seed.

        Returns
        -------
        Profile
            The changed copy.
        """
        return replace(self, seed=int(seed))

    def command_path(self, frame_s: float, stream: int = 0, initial_v: float = 0.0) -> SignalPath:
        """FMU → EMAC for one channel.

        Parameters
        ----------
        frame_s : float
            The frame (s).
        stream : int
            The channel's noise stream (keeps each channel's noise independent).
        initial_v : float
            The steady command it starts at (V).

        Returns
        -------
        SignalPath
            Lag, quantization, delay, noise.
        """
        spec = self.command
        path = SignalPath([
            FirstOrderLag(spec.lag_hz, frame_s),
            Quantizer(spec.quantization_v, self.full_scale_v),
            TransportDelay(spec.delay_s, frame_s),
            Noise(spec.noise_rms_v, self.seed, (stream, 0)),
        ])
        path.reset(initial_v)
        return path

    def feedback_path(self, frame_s: float, stream: int = 0, initial_v: float = 0.0) -> SignalPath:
        """EMAC → FMU for one channel.

        Parameters
        ----------
        frame_s : float
            The frame (s).
        stream : int
            The channel's noise stream.
        initial_v : float
            The steady feedback it starts at (V).

        Returns
        -------
        SignalPath
            Noise, delay, quantization, lag.
        """
        spec = self.feedback
        path = SignalPath([
            Noise(spec.noise_rms_v, self.seed, (stream, 1)),
            TransportDelay(spec.delay_s, frame_s),
            Quantizer(spec.quantization_v, self.full_scale_v),
            FirstOrderLag(spec.lag_hz, frame_s),
        ])
        path.reset(initial_v)
        return path

    def current_delay(self, frame_s: float) -> TransportDelay:
        """Motor current feedback rides the feedback harness: same transport delay, nothing else.

        Parameters
        ----------
        frame_s : float
            The frame (s).

        Returns
        -------
        TransportDelay
            The feedback path's delay.
        """
        return TransportDelay(self.feedback.delay_s, frame_s)

    def describe(self) -> dict[str, str]:
        """Human-readable summary for logs and bag metadata."""
        return {
            "profile": self.name,
            "command_path": self.command_path(0.005).describe(),
            "feedback_path": self.feedback_path(0.005).describe(),
            "disabled": ",".join(self.disabled) or "none",
            "seed": str(self.seed),
        }


def profile_names() -> list[str]:
    """Built-in and configured profiles (``config/*.yaml`` whose node is ``testenv``)."""
    names = list(BUILTIN)
    for path in sorted(config_dir().glob("*.yaml")):
        if _is_profile(path):
            names.append(path.stem)
    return names


def _is_profile(path: Path) -> bool:
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except Exception:
        return False
    return isinstance(doc, dict) and list(doc) == ["testenv"]


def load_profile(name_or_path: str | Path, *, disable: Iterable[str] = ()) -> Profile:
    """A profile by name (``none``, ``flight``, ``ail``) or from a parameter file path.

    Parameters
    ----------
    name_or_path : str or Path
        Profile name or a ``testenv`` parameter file.
    disable : iterable of str
        Elements to switch off (:meth:`Profile.without`).

    Returns
    -------
    Profile
        The profile.
    """
    text = str(name_or_path)
    if text == "none":
        profile = Profile.none()
    else:
        path = Path(text)
        if not (path.suffix in (".yaml", ".yml") and path.is_file()):
            path = config_dir() / f"{text}.yaml"
            if not (path.is_file() and _is_profile(path)):
                raise UnknownNameError("profile", text, profile_names())
        profile = Profile.from_parameters(ros_parameters(path), str(path))
    disable = [d for d in disable if d]
    return profile.without(*disable) if disable else profile

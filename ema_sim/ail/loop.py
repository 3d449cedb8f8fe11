"""The aircraft-in-the-loop run offline: the node suite's lockstep frame order, without ROS, at full speed.

Each frame *k* does what the lockstep suite does (``ema launch --fmu --lockstep --emac-box``), in the
same order and with the same objects, so both give the same numbers for the same seed:

1. the EMACs' feedback at *kT* (at *k* = 0 the trimmed state at rest, brake on) goes through the test
   environment's feedback path of each channel (:meth:`~ema_sim.environment.Profile.feedback_path`);
2. :class:`~ema_sim.ail.fmu.Fmu` computes the frame's commands and hinge moments;
3. the commands go through the command path (:meth:`~ema_sim.environment.Profile.command_path`);
4. every :class:`~ema_sim.emac.EmacChannel` (the node's channel logic around the registry model) steps
   one frame, in channel order, with the EMAC box's crosstalk meter, giving the feedback at *(k+1)T*.

Environment elements are switched off by name (:mod:`ema_sim.switches`): the test environment's ``delay``,
``lag``, ``quantization``, ``noise`` (or one path's, ``command.delay``...), and in the actuator model
``dead_band`` (the PWM dead band); ``quantization`` and ``noise`` also switch off the model's own 5 mV
stage and measured noise (HOAD2/HOAD3; LOADA's 0.020° D/A stage), which stand for the same converters
and harness.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ema_sim.ail.fmu import Fmu, FrameInputs, FrameOutputs
from ema_sim.ail.params import AilConfig, Setup, load_ail_config
from ema_sim.ail.vehicle import STATES
from ema_sim.config import CHANNELS, config_dir, load_channel, ros_parameters, scaling
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings
from ema_sim.environment import Profile, SignalPath, load_profile
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models import create, model_names
from ema_sim.switches import element_names, environment_elements, model_overrides

FloatArray = NDArray[np.float64]
SIGNALS: tuple[str, ...] = (
    "fmu_command_v", "fmu_command_deg", "command_v", "command_deg", "position_v", "position_deg", "surface_deg",
    "rate_dps", "current_a", "bus_v", "hinge_moment_inlb", "aero_hinge_moment_inlb", "fmu_position_v",
    "fmu_position_deg", "seen_deg",
)
"""Recorded per channel at each frame: FMU-side and EMAC-side command, EMAC-side LVDT feedback (volts,
and degrees through the feedback curve, crosstalk included), true surface, rate, motor current and bus,
the applied and the aerodynamic hinge moments, the FMU-side feedback, and the deflections the simulated
aerodynamics used."""


def emac_settings() -> tuple[EmacSettings, dict[str, float]]:
    """The EMAC node's settings and crosstalk levels from ``config/emac.yaml`` (as the node reads them).

    Returns
    -------
    tuple[EmacSettings, dict[str, float]]
        The settings, and each channel's crosstalk noise, V peak to peak.
    """
    params = ros_parameters(config_dir() / "emac.yaml").get("emac", {})
    settings = EmacSettings.from_parameters({k: v for k, v in params.items() if not isinstance(v, dict)}, "emac")
    crosstalk = params.get("crosstalk", {})
    return settings, {ch: float(crosstalk.get(f"{ch}_pp_v", 0.0)) for ch in CHANNELS}


@dataclass(frozen=True)
class AilOptions:
    """One run of the loop."""

    profile: str = "ail"
    """The test environment's profile (``config/<profile>.yaml``) and the vehicle set-up of that name."""
    model: str = "hoad3"
    """The actuator model in every EMAC."""
    open_loop: bool = False
    """The simulation flies its own model actuators (2.10, 4.3)."""
    duration_s: float = 20.0
    """Length of the run, s."""
    seed: int | None = None
    """Test-environment noise seed (default: the profile's)."""
    disable: tuple[str, ...] = ()
    """Elements switched off by name (:mod:`ema_sim.switches`)."""
    setup: Setup | None = None
    """Override of the profile's vehicle setup (``setup.<profile>`` of the parameter file)."""
    sim_model: str | None = None
    """Open loop: the simulation's model actuator (default the file's ``open_loop.sim_model``)."""
    config: AilConfig | None = None
    """The vehicle's parameter set (default ``config/ail_vehicle.yaml``)."""
    environment: Profile | None = None
    """An explicit test environment instead of the named profile's (a Monte Carlo run's dispersed elements;
    ``disable`` still applies to it)."""
    model_overrides: Mapping[str, float] = field(default_factory=dict)
    """Model keywords (parameters, ``seed``) on top of the elements switched off."""


@dataclass
class AilRun:
    """A recorded run: one row per FMU frame (the command over the frame, the state at its start)."""

    time_s: FloatArray
    """Frame start times from zero, s."""
    signals: dict[str, dict[str, FloatArray]]
    """channel → signal (:data:`SIGNALS`) → values."""
    vehicle: dict[str, FloatArray]
    """State name (:data:`~ema_sim.ail.vehicle.STATES`) → values."""
    metadata: dict[str, str] = field(default_factory=dict)
    """How the run was made (profile, model, set-up, paths, seed...), as text."""
    wall_s: float = 0.0
    """Wall time the loop took, s."""

    def channel(self, ch: str) -> dict[str, FloatArray]:
        """One channel's signals.

        Parameters
        ----------
        ch : str
            The channel.

        Returns
        -------
        dict[str, FloatArray]
            Signal name (:data:`SIGNALS`) → values.
        """
        return self.signals[ch]

    def csv_columns(self, channel: str = "left_wing") -> dict[str, FloatArray]:
        """Data-contract columns of ``channel`` (the EMAC side, as a rig's DAU records it), and more.

        Then every channel's signals as ``<channel>.<signal>`` and the vehicle states (columns the contract
        reader ignores).

        Parameters
        ----------
        channel : str, optional
            The channel whose signals take the contract's column names.

        Returns
        -------
        dict[str, FloatArray]
            Column name → values, ``time_s`` first; signals with a NaN (not measured) are left out.

        Raises
        ------
        UnknownNameError
            ``channel`` is not in the run.
        """
        if channel not in self.signals:
            raise UnknownNameError("channel", channel, self.signals)
        main = self.signals[channel]
        cols: dict[str, FloatArray] = {"time_s": self.time_s}
        for name in ("command_deg", "position_deg", "surface_deg", "hinge_moment_inlb", "current_a", "command_v",
                     "position_v", "bus_v", "rate_dps"):
            if np.all(np.isfinite(main[name])):
                cols[name] = main[name]
        for ch, sig in self.signals.items():
            for name in SIGNALS:
                if np.all(np.isfinite(sig[name])):
                    cols[f"{ch}.{name}"] = sig[name]
        cols.update(self.vehicle)
        return cols


def _profile(options: AilOptions) -> Profile:
    env = environment_elements(options.disable)
    profile = (options.environment.without(*env) if options.environment is not None
               else load_profile(options.profile, disable=env))
    return profile.with_seed(options.seed) if options.seed is not None else profile


class _Loop:
    """The EMACs and the test environment of one run, stepped frame by frame (the module docstring's order)."""

    def __init__(self, options: AilOptions, cfg: AilConfig, profile: Profile, overrides: dict[str, float]) -> None:
        self.frame_s = 1.0 / cfg.frame_hz
        settings, crosstalk = emac_settings()
        if abs(settings.frame_hz - cfg.frame_hz) > 1e-9:
            raise EmaError(f"the FMU frame ({cfg.frame_hz:g} Hz) differs from the EMAC's ({settings.frame_hz:g} Hz)")
        self.units = {ch: EmacChannel(create(options.model, load_channel(ch), **overrides), settings,
                                      crosstalk_noise_pp_v=crosstalk[ch], stream=CHANNELS.index(ch))
                      for ch in CHANNELS}
        self.coupled = any(u.crosstalk.active for u in self.units.values())
        self.slew = {ch: load_channel(ch).slew_rate_dps * scaling(ch).volts_per_deg for ch in CHANNELS}
        self.meter = ActivityMeter(self.frame_s)
        self.profile = profile
        self.fb_paths: dict[str, SignalPath] = {}
        self.cmd_paths: dict[str, SignalPath] = {}
        self.feedback = {ch: u.last for ch, u in self.units.items()}
        self._observe()  # the EMAC box and the channel nodes both observe the trimmed state first

    def _observe(self) -> None:
        if self.coupled:
            for ch, fb in self.feedback.items():
                self.meter.observe(ch, fb.position_v, self.slew[ch])

    def fmu_feedback(self) -> dict[str, float]:
        """Step 1: the EMACs' feedback through each channel's feedback path."""
        out = {}
        for ch in CHANNELS:
            v = self.feedback[ch].position_v
            if ch not in self.fb_paths:
                self.fb_paths[ch] = self.profile.feedback_path(self.frame_s, CHANNELS.index(ch), v)
            out[ch] = float(self.fb_paths[ch].step(v))
        return out

    def command(self, command_v: dict[str, float], load_inlb: dict[str, float]) -> dict[str, float]:
        """Step 3: the commands through the command paths into the EMACs, with the frame's loads."""
        emac_cmd = {}
        for ch in CHANNELS:
            v = command_v[ch]
            if ch not in self.cmd_paths:
                self.cmd_paths[ch] = self.profile.command_path(self.frame_s, CHANNELS.index(ch), v)
            emac_cmd[ch] = float(self.cmd_paths[ch].step(v))
            self.units[ch].set_command(emac_cmd[ch])
            self.units[ch].set_load(load_inlb[ch])
        return emac_cmd

    def step(self) -> None:
        """Step 4: every EMAC channel one frame, in channel order, with the box's crosstalk meter."""
        self.feedback = {ch: self.units[ch].step(0.0, self.meter.activity_except(ch)) for ch in CHANNELS}
        self._observe()


def _record(rec: dict[str, dict[str, FloatArray]], k: int, loop: _Loop, out: FrameOutputs, fmu_fb: dict[str, float],
            emac_cmd: dict[str, float]) -> None:
    for ch in CHANNELS:
        r, fb, sc = rec[ch], loop.feedback[ch], scaling(ch)
        r["fmu_command_v"][k] = out.command_v[ch]
        r["fmu_command_deg"][k] = out.command_deg[ch]
        r["command_v"][k] = emac_cmd[ch]
        r["command_deg"][k] = sc.command_v_to_deg(emac_cmd[ch])
        r["position_v"][k] = fb.position_v
        r["position_deg"][k] = sc.feedback_v_to_deg(fb.position_v)
        r["surface_deg"][k] = fb.surface_deg
        r["rate_dps"][k] = fb.rate_dps
        r["current_a"][k] = fb.current_a
        r["bus_v"][k] = fb.bus_v
        r["hinge_moment_inlb"][k] = out.hinge_moment_inlb[ch]
        r["aero_hinge_moment_inlb"][k] = out.aero_hinge_moment_inlb[ch]
        r["fmu_position_v"][k] = fmu_fb[ch]
        r["fmu_position_deg"][k] = sc.feedback_v_to_deg(fmu_fb[ch])
        r["seen_deg"][k] = out.seen_deg[ch]


def run_ail(options: AilOptions, progress: Callable[[float], None] | None = None) -> AilRun:
    """Run the loop (see the module docstring).

    Parameters
    ----------
    options : AilOptions
        What to run.
    progress : Callable[[float], None], optional
        Called with the fraction done about once a second, and with 1.0 at the end.

    Returns
    -------
    AilRun
        One row per FMU frame.

    Raises
    ------
    UnknownNameError
        An unknown model, profile or element name.
    EmaError
        A duration that is not a positive number, or an FMU frame that differs from the EMAC's.
    """
    if options.model not in model_names():
        raise UnknownNameError("model", options.model, model_names())
    if not (math.isfinite(options.duration_s) and options.duration_s > 0.0):
        raise EmaError(f"duration must be a positive number of seconds, got {options.duration_s!r}")
    disabled = element_names(options.disable)
    cfg = options.config or load_ail_config()
    setup = options.setup or cfg.setup(options.profile)
    profile = _profile(AilOptions(**{**options.__dict__, "disable": disabled}))
    overrides = {**options.model_overrides, **model_overrides(options.model, disabled)}
    loop = _Loop(options, cfg, profile, overrides)
    fmu = Fmu(cfg, setup, open_loop=options.open_loop, sim_model=options.sim_model)
    n = max(1, round(options.duration_s * cfg.frame_hz))
    rec = {ch: {name: np.empty(n) for name in SIGNALS} for ch in CHANNELS}
    veh = {name: np.empty(n) for name in STATES}
    emac_cmd: dict[str, float] | None = None
    started = time.perf_counter()
    next_report = started + 1.0
    for k in range(n):
        fmu_fb = loop.fmu_feedback()
        out = fmu.frame(FrameInputs(fmu_fb, {ch: loop.feedback[ch].surface_deg for ch in CHANNELS}, emac_cmd))
        emac_cmd = loop.command(out.command_v, out.hinge_moment_inlb)
        _record(rec, k, loop, out, fmu_fb, emac_cmd)
        for name, value in zip(STATES, out.vehicle.values(), strict=True):
            veh[name][k] = value
        loop.step()
        if progress is not None and time.perf_counter() >= next_report:
            next_report += 1.0
            progress((k + 1) / n)
    wall = time.perf_counter() - started
    if progress is not None:
        progress(1.0)
    frame_s = loop.frame_s
    meta = {
        "test": "ail", "profile": options.profile, "model": options.model,
        "mode": "open loop" if options.open_loop else "closed loop",
        "sim_model": fmu.sim_model if options.open_loop else "",
        "disabled": ",".join(disabled) or "none", "seed": str(profile.seed), "duration_s": f"{n * frame_s:g}",
        "frame_hz": f"{cfg.frame_hz:g}", "setup": setup.describe(), "vehicle_config": cfg.source,
        "command_path": profile.command_path(frame_s).describe(),
        "feedback_path": profile.feedback_path(frame_s).describe(),
        "model_overrides": ",".join(f"{k}={v}" for k, v in overrides.items()) or "none",
    }
    return AilRun(np.arange(n, dtype=np.float64) * frame_s, rec, veh, meta, wall)

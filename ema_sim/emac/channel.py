"""One EMAC channel: input checks, watchdog and brake, failures, crosstalk, around any model.

The FMU's command arrives in volts and is turned into the surface command through the channel's
command curve (the degrees the FMU meant, the data contract's ``command_deg``); the LVDT position goes
back in volts through the feedback curve. Between them the model integrates at its own rate, one
FMU frame per :meth:`EmacChannel.step`. Physics stays in the model; this class decides only what the
model is given:

* a non-finite command or hinge moment is rejected (the last good value holds) and counted, one
  beyond ±full scale (±10 V) or the hinge-moment limit is clamped and counted: never passed on;
* the brake, engaged when unpowered (section 1.4) or when commands go stale (watchdog), holds the
  surface: the model is re-trimmed at the held position under the present hinge moment, so free play
  and compliance outside the servo loop still show on the surface angle;
* failures (:mod:`ema_sim.emac.failures`) replace the command or add load, or hold the position.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, NamedTuple

from ema_msgs_py.contract import Scaling, scaling_of
from ema_sim.emac.crosstalk import Crosstalk
from ema_sim.emac.failures import Failure, HardOver, Stall, Zero, parse_failure
from ema_sim.errors import ConfigError
from ema_sim.faults import Fault, FaultSchedule, parse_faults
from ema_sim.models.base import ActuatorModel, Flags, Sample
from ema_sim.parameters import param


class InputStatus(enum.Enum):
    """What happened to an input value."""

    OK = "ok"
    CLAMPED = "clamped"
    REJECTED = "rejected"


RUN_TIME: frozenset[str] = frozenset({"watchdog_timeout_s", "motor_power_on", "hinge_moment_limit_inlb", "failure"})
"""Settings a running EMAC node applies from its next frame (the others are read-only once it runs)."""


@dataclass(frozen=True)
class EmacSettings:
    """EMAC node parameters (``config/emac.yaml``, section ``emac``), each declared once with its metadata."""

    frame_hz: float = param("Hz", "FMU frame rate: feedback once per frame (table 5)", default=200.0, min=1.0,
                            max=1e5)
    watchdog_timeout_s: float = param("s", "commands older than this engage the brake (watchdog)", default=0.05,
                                      min=1e-4, max=3600.0)
    initial_position_deg: float = param("deg", "trim position at start-up (brake engaged until the first command)",
                                        default=0.0, min=-90.0, max=90.0)
    motor_power_on: bool = param("-", "150 V motor power; off engages the brake (section 1.4)", default=True)
    hinge_moment_limit_inlb: float = param("in·lb", "hinge moments beyond this are clamped (and counted)",
                                           default=20000.0, min=1.0, max=1e7)
    failure: str = param("-", "failure mode: none, stuck, hard_over:direction=±1, zero, power_loss, "
                         "stall:load_factor=X", default="none")
    faults: str = param("-", "faults injected on a schedule, ';'-separated specs with times from the channel's start: "
                        "coulomb_friction:at_s=5,ramp_s=2,size=0.5 (docs/faults.md); none: no fault",
                        default="none")
    seed: int = param("-", "crosstalk noise seed", default=0, min=0, max=2**62)
    stamp_tolerance_s: float = param("s", "real time: a command stamped further ahead of the last one taken than "
                                     "the wall time since it came plus this is dropped (future_stamp; a burst of "
                                     "commands may run ahead of the wall clock by less)", default=10.0, min=0.0,
                                     max=86400.0)
    resync_commands: int = param("-", "real time: consecutive commands that misfit the last one taken but fit each "
                                 "other, after which the EMAC follows their clock (an FMU restart, a stepped clock)",
                                 default=5, min=2, max=10000)

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], origin: str = "emac") -> EmacSettings:
        """Validate a parameter mapping (unknown keys are left to the caller).

        Parameters
        ----------
        params : mapping of str to Any
            The ``emac.*`` values, by field name.
        origin : str
            Where they come from, for messages.

        Returns
        -------
        EmacSettings
            The checked settings.
        """
        values: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in params:
                continue
            raw = params[f.name]
            try:
                if f.type in ("float", float):
                    values[f.name] = float(raw)
                    if not math.isfinite(values[f.name]):
                        raise ValueError("not finite")
                elif f.type in ("int", int):
                    values[f.name] = int(raw)
                elif f.type in ("bool", bool):
                    if not isinstance(raw, bool):
                        raise ValueError("not true or false")
                    values[f.name] = raw
                else:
                    values[f.name] = str(raw)
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{origin}: parameter {f.name}: {exc} ({raw!r})") from None
        out = cls(**values)
        if out.frame_hz <= 0.0 or out.watchdog_timeout_s <= 0.0 or out.hinge_moment_limit_inlb <= 0.0:
            raise ConfigError(f"{origin}: frame_hz, watchdog_timeout_s and hinge_moment_limit_inlb must be positive")
        parse_failure(out.failure)
        return out

    @property
    def frame_s(self) -> float:
        """The FMU frame."""
        return 1.0 / self.frame_hz


class Feedback(NamedTuple):
    """What one frame of one channel produced (immutable; a named tuple, cheap to make every frame)."""

    position_v: float
    """LVDT position feedback to the FMU, V (crosstalk included)."""
    current_a: float
    """Motor current feedback, A; NaN when the model has no motor."""
    position_deg: float
    surface_deg: float
    rate_dps: float
    hinge_moment_inlb: float
    """Hinge moment applied over the frame (failure loads included)."""
    bus_v: float
    """150 V bus, V; NaN when the model has none."""
    flags: int
    braked: bool
    held: bool
    """Position held (brake or jam)."""


COUNTERS = ("frames", "rejected_commands", "clamped_commands", "rejected_loads", "clamped_loads",
            "watchdog_trips", "braked_frames")


class EmacChannel:
    """A model behind one EMAC channel (see the module docstring).

    Parameters
    ----------
    model : ActuatorModel
        The channel's model (one instance).
    settings : EmacSettings or None
        The channel logic's settings (None: the defaults).
    scaling : Scaling or None
        The channel's degree↔volt scaling (None: the model's channel's).
    crosstalk_noise_pp_v : float
        Peak-to-peak feedback noise while other channels slew, V.
    stream : int
        The noise's random stream (one per channel).
    """

    def __init__(self, model: ActuatorModel, settings: EmacSettings | None = None, *,
                 scaling: Scaling | None = None, crosstalk_noise_pp_v: float = 0.0, stream: int = 0) -> None:
        if model.n != 1:
            raise ValueError("an EMAC channel drives one model instance")
        self.model = model
        self.settings = settings or EmacSettings()
        self.cfg = model.channel
        self.scaling = scaling or scaling_of(self.cfg)
        self.frame_s = self.settings.frame_s
        self.failure: Failure = parse_failure(self.settings.failure)
        self.schedule = FaultSchedule(model, parse_faults(self.settings.faults))
        """The injected faults (their truth: :meth:`fault_truth`)."""
        self.motor_power_on = self.settings.motor_power_on
        self.crosstalk = Crosstalk(crosstalk_noise_pp_v, self.settings.seed, stream)
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.stall_torque_inlb = self.cfg.stall_force_lbf * self.cfg.crank_arm_in
        self._command_v: float | None = None
        self._load_inlb = 0.0
        self._stale = True
        self._hold: tuple[float, float] | None = None
        self.last = self.start(self.settings.initial_position_deg, 0.0)

    # ----------------------------------------------------------------- inputs
    def start(self, position_deg: float = 0.0, hinge_moment_inlb: float = 0.0) -> Feedback:
        """Trim the model at rest at ``position_deg`` under the load; the brake holds until commanded.

        Parameters
        ----------
        position_deg : float
            Surface position, deg.
        hinge_moment_inlb : float
            Hinge moment, in·lb.

        Returns
        -------
        Feedback
            The held state's feedback.
        """
        self._load_inlb = float(hinge_moment_inlb)
        self._hold = None
        sample = self.model.trim(position_deg=position_deg, hinge_moment_inlb=self._load_inlb)
        self.last = self._hold_outputs(float(sample.position_deg[0]), self._load_inlb, braked=True)
        return self.last

    def set_command(self, volts: float) -> InputStatus:
        """The FMU's command for the coming frames, V: checked, never passed on when bad.

        Parameters
        ----------
        volts : float
            The command, V.

        Returns
        -------
        InputStatus
            Taken, clamped or rejected.
        """
        try:
            v = float(volts)
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v):
            self.counters["rejected_commands"] += 1
            return InputStatus.REJECTED
        limit = self.scaling.full_scale_v
        if abs(v) > limit:
            self.counters["clamped_commands"] += 1
            self._command_v = math.copysign(limit, v)
            return InputStatus.CLAMPED
        self._command_v = v
        return InputStatus.OK

    def set_load(self, inlb: float) -> InputStatus:
        """The hinge moment for the coming frames, in·lb: checked like the command.

        Parameters
        ----------
        inlb : float
            The hinge moment, in·lb.

        Returns
        -------
        InputStatus
            Taken, clamped or rejected.
        """
        try:
            h = float(inlb)
        except (TypeError, ValueError):
            h = math.nan
        if not math.isfinite(h):
            self.counters["rejected_loads"] += 1
            return InputStatus.REJECTED
        limit = self.settings.hinge_moment_limit_inlb
        if abs(h) > limit:
            self.counters["clamped_loads"] += 1
            self._load_inlb = math.copysign(limit, h)
            return InputStatus.CLAMPED
        self._load_inlb = h
        return InputStatus.OK

    def set_faults(self, text: str) -> tuple[Fault, ...]:
        """Replace the injected faults (``;``-separated specs, times from the channel's start; ``none``: none).

        Parameters
        ----------
        text : str
            The specs.

        Returns
        -------
        tuple of Fault
            The faults now scheduled.
        """
        self.schedule = FaultSchedule(self.model, parse_faults(text))
        return self.schedule.faults

    def fault_truth(self) -> dict[str, float]:
        """Each injected fault's size in at the last frame (``fault_<kind>``: empty without faults)."""
        frames = self.counters["frames"]
        return self.schedule.truth(frames * self.frame_s) if self.schedule.faults else {}

    def set_failure(self, failure: Failure | str) -> Failure:
        """Switch the failure mode (takes effect at the next frame).

        Parameters
        ----------
        failure : Failure or str
            The mode, or its spec string (``stuck``, ``hard_over:direction=-1``...).

        Returns
        -------
        Failure
            The mode now in effect.
        """
        self.failure = parse_failure(failure) if isinstance(failure, str) else failure
        return self.failure

    @property
    def command_v(self) -> float | None:
        """The last good command, V (None before the first)."""
        return self._command_v

    @property
    def braked(self) -> bool:
        """Brake engaged at the last frame."""
        return self.last.braked

    # ----------------------------------------------------------------- one frame
    def step(self, command_age_s: float | None, activity: float = 0.0) -> Feedback:
        """Advance one frame.

        Parameters
        ----------
        command_age_s : float or None
            How old the last good command is, s (None: never commanded).
        activity : float
            The other channels' activity (crosstalk), 0 to 1.

        Returns
        -------
        Feedback
            The frame's feedback.
        """
        stale = command_age_s is None or command_age_s > self.settings.watchdog_timeout_s
        if stale and not self._stale:
            self.counters["watchdog_trips"] += 1
        self._stale = stale
        powered = self.motor_power_on and self.failure.powered
        braked = stale or not powered
        hm = self._load_inlb
        self.counters["frames"] += 1
        if braked or self.failure.holds_position:
            if self._hold is None:
                self._hold = (self.last.position_deg, math.nan)
            fb = self._hold_outputs(self._hold[0], hm, braked=braked, powered=powered)
        else:
            self._hold = None
            command_deg = self._command_deg()
            if isinstance(self.failure, Stall):
                hm += self._stall_load(command_deg)
            t = (self.counters["frames"] - 1) * self.frame_s
            sched = self.schedule
            if sched.faults:
                sched.frame(t, self.last.position_deg)
                fb = self._frame_feedback(self.model.step_values(command_deg, sched.load(t, hm), self.frame_s), hm)
                pos = sched.reading(t + self.frame_s, fb.position_deg)
                fb = _replace(fb, position_deg=pos, position_v=self.scaling.feedback_deg_to_v(pos))
            else:
                fb = self._frame_feedback(self.model.step_values(command_deg, hm, self.frame_s), hm)
        if braked:
            self.counters["braked_frames"] += 1
        noise = self.crosstalk.step(activity)
        if noise:
            fb = _replace(fb, position_v=fb.position_v + noise)
        self.last = fb
        return fb

    def _command_deg(self) -> float:
        cfg = self.cfg
        if isinstance(self.failure, HardOver):
            return cfg.position_max_deg if self.failure.direction > 0 else cfg.position_min_deg
        volts = 0.0 if isinstance(self.failure, Zero) else (self._command_v or 0.0)
        return self.scaling.command_v_to_deg(volts)

    def _stall_load(self, command_deg: float) -> float:
        """Hinge moment opposing deflection, beyond what the motor can hold (section 1.3)."""
        toward = command_deg if command_deg != 0.0 else self.last.position_deg
        if toward == 0.0:
            return 0.0
        return -math.copysign(self.failure.load_factor * self.stall_torque_inlb, toward)  # type: ignore[attr-defined]

    def _hold_outputs(self, position_deg: float, hm: float, *, braked: bool, powered: bool = True) -> Feedback:
        """Surface held at ``position_deg``: re-trim when the load changed, report the held position exactly."""
        hold = self._hold
        if hold is None or hold[1] != hm or not hasattr(self, "_held_fb"):
            sample = self.model.trim(position_deg=position_deg, hinge_moment_inlb=hm)
            shift = position_deg - float(sample.position_deg[0])
            fb = self._feedback(sample, hm, braked=braked, held=True)
            self._held_fb = _replace(fb, position_deg=position_deg, surface_deg=fb.surface_deg + shift,
                                     position_v=self.scaling.feedback_deg_to_v(position_deg), rate_dps=0.0)
            self._hold = (position_deg, hm)
        fb = self._held_fb
        flags = fb.flags | int(Flags.BRAKE) if braked else fb.flags & ~int(Flags.BRAKE)
        current = 0.0 if (self.model.has_current and not powered) else fb.current_a
        return _replace(fb, braked=braked, flags=flags, current_a=current)

    def _frame_feedback(self, v: list[float], hm: float) -> Feedback:
        """A stepped frame's outputs (``ActuatorModel.step_values``: position, surface, rate, current, bus, flags)."""
        pos = v[0]
        return Feedback(self.scaling.feedback_deg_to_v(pos), v[3], pos, v[1], v[2], hm, v[4], int(v[5]), False, False)

    def _feedback(self, s: Sample, hm: float, *, braked: bool, held: bool) -> Feedback:
        pos = float(s.position_deg[0])
        return Feedback(
            position_v=self.scaling.feedback_deg_to_v(pos),
            current_a=float(s.current_a[0]),
            position_deg=pos,
            surface_deg=float(s.surface_deg[0]),
            rate_dps=float(s.rate_dps[0]),
            hinge_moment_inlb=hm,
            bus_v=float(s.bus_v[0]),
            flags=int(s.flags[0]),
            braked=braked,
            held=held,
        )

    def status(self) -> dict[str, str]:
        """Key values for diagnostics."""
        out = {
            "model": self.model.name,
            "failure": self.failure.spec(),
            "motor_power_on": str(self.motor_power_on).lower(),
            "brake_engaged": str(self.last.braked).lower(),
            "position_deg": f"{self.last.position_deg:.4f}",
            "command_v": "none" if self._command_v is None else f"{self._command_v:.4f}",
        }
        out.update({k: str(v) for k, v in self.counters.items()})
        return out


def _replace(fb: Feedback, **changes: Any) -> Feedback:
    return fb._replace(**changes)

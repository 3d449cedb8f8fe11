"""One frame of the flight computer and the simulated vehicle: the code the ``fmu`` node and ``ema ail`` share.

At frame *k* (time *kT*), :meth:`Fmu.frame` takes what the FMU side has at that instant and returns
what it sends for the frame [*kT*, *(k+1)T*):

1. the deflections the simulated aerodynamics sees at *kT*: the FMU-side LVDT feedback (closed-loop
   AIL: "the EMA LVDT feedback signals were fed into the simulation", 2.10), the true surface angle
   (flight), or, open loop, a model actuator running in the simulation (2.10, 4.3);
2. the sensed vehicle state at *kT* → the autopilot's wing commands; the other channels are held;
3. the aerodynamic hinge moment of every surface at *kT*; what is applied to the real surfaces is that
   (flight) or the bungee (AIL: the surfaces are on the ground);
4. the vehicle advances to *(k+1)T* with the seen deflections held over the frame.

Commands leave in volts through each channel's command curve, feedback comes back through the
feedback curve, as on the wire (:mod:`ema_msgs_py.contract`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from ema_msgs_py.contract import Scaling
from ema_sim.ail.autopilot import Autopilot, SurfaceCommand
from ema_sim.ail.params import WINGS, AilConfig, Setup
from ema_sim.ail.vehicle import Vehicle, VehicleState
from ema_sim.config import CHANNELS, load_channel, scaling
from ema_sim.errors import EmaError
from ema_sim.models import create
from ema_sim.models.base import O_POS, ActuatorModel

FEEDBACK, SURFACE, EMAC_COMMAND = "feedback", "surface", "emac_command"
"""Names of the inputs a frame may need (:attr:`Fmu.needs`)."""


@dataclass(frozen=True)
class FrameInputs:
    """What the FMU side has at the start of a frame."""

    feedback_v: Mapping[str, float]
    """LVDT feedback as the FMU reads it (after the test environment), V, stamped at this frame."""
    surface_deg: Mapping[str, float]
    """True surface angles at this frame, deg (the external sensor's; flight's aerodynamics)."""
    emac_command_v: Mapping[str, float] | None = None
    """The previous frame's command at the EMAC input, V (open loop: the simulation's model actuator)."""


@dataclass(frozen=True)
class FrameOutputs:
    """What one frame produced."""

    command_v: dict[str, float]
    """Commands sent for the frame, V (through each channel's command curve)."""
    command_deg: dict[str, float]
    """The same commands, surface degrees."""
    hinge_moment_inlb: dict[str, float]
    """Applied to the real surfaces over the frame."""
    aero_hinge_moment_inlb: dict[str, float]
    """The simulation's aerodynamic hinge moments at the frame (applied only when the surfaces fly)."""
    seen_deg: dict[str, float]
    """Deflections the simulated aerodynamics used over the frame."""
    vehicle: VehicleState
    """The vehicle at the frame (what the FMU sensed)."""
    autopilot: SurfaceCommand
    """The control law's output at the frame."""


class Fmu:
    """The flight computer, its vehicle simulation and (open loop) its model actuators.

    Parameters
    ----------
    cfg : AilConfig
        The vehicle, autopilot, hinge moments and held commands.
    setup : Setup
        What the aerodynamics sees and what loads the real surfaces.
    open_loop : bool, optional
        The simulation flies its own model actuators (2.10, 4.3) instead of the feedback.
    sim_model : str, optional
        The simulation's model actuator (open loop); default ``cfg.sim_model``.
    channels : tuple[str, ...], optional
        The channels the FMU commands (both wings needed).

    Raises
    ------
    EmaError
        A wing is missing, or the set-up is not valid.
    """

    def __init__(self, cfg: AilConfig, setup: Setup, *, open_loop: bool = False, sim_model: str | None = None,
                 channels: tuple[str, ...] = CHANNELS) -> None:
        setup.validate()
        missing = [w for w in WINGS if w not in channels]
        if missing:
            raise EmaError(f"the vehicle loop needs both wings; missing {', '.join(missing)}")
        self.cfg = cfg
        self.setup = setup
        self.open_loop = bool(open_loop)
        self.channels = tuple(channels)
        self.frame_s = 1.0 / cfg.frame_hz
        self.vehicle = Vehicle(cfg.vehicle, self.frame_s)
        self.autopilot = Autopilot(cfg.autopilot, self.frame_s)
        self.scalings: dict[str, Scaling] = {ch: scaling(ch) for ch in self.channels}
        self.hinge = {ch: cfg.hinge_moment[load_channel(ch).surface] for ch in self.channels}
        self.k = 0
        self.sim_model = sim_model or cfg.sim_model
        self.sim: dict[str, ActuatorModel] = {}
        self._sim_load: dict[str, float] = {}
        self._sim_seen: dict[str, float] = {}
        if self.open_loop:  # the simulation's model actuators start trimmed at the FMU's trim commands
            alpha = self.vehicle.state.alpha_deg
            for ch in self.channels:
                start = cfg.autopilot.trim_elevon_deg if ch in WINGS else cfg.held_deg[ch]
                self._sim_load[ch] = self.hinge[ch].at(alpha, start)
                model = create(self.sim_model, ch)
                sample = model.trim(position_deg=start, hinge_moment_inlb=self._sim_load[ch])
                self.sim[ch] = model
                self._sim_seen[ch] = float(sample.position_deg[0])

    @property
    def needs(self) -> frozenset[str]:
        """The inputs the next frame uses (the node waits for exactly these)."""
        if self.open_loop:
            return frozenset({EMAC_COMMAND}) if self.k > 0 else frozenset()
        return frozenset({FEEDBACK if self.setup.aero_input == "feedback" else SURFACE})

    def _seen(self, inputs: FrameInputs) -> dict[str, float]:
        if self.open_loop:
            if self.k > 0:
                if inputs.emac_command_v is None:
                    raise EmaError("open loop: the frame needs the previous frame's EMAC-side command")
                for ch, model in self.sim.items():
                    deg = self.scalings[ch].command_v_to_deg(float(inputs.emac_command_v[ch]))
                    self._sim_seen[ch] = model.step_values(float(deg), float(self._sim_load[ch]), self.frame_s)[O_POS]
            return dict(self._sim_seen)
        if self.setup.aero_input == "feedback":
            return {ch: self.scalings[ch].feedback_v_to_deg(float(inputs.feedback_v[ch])) for ch in self.channels}
        return {ch: float(inputs.surface_deg[ch]) for ch in self.channels}

    def frame(self, inputs: FrameInputs) -> FrameOutputs:
        """One frame (see the module docstring).

        Parameters
        ----------
        inputs : FrameInputs
            What the FMU side has at the frame's start (:attr:`needs` says which fields it uses).

        Returns
        -------
        FrameOutputs
            The commands for the frame, the hinge moments, the deflections seen and the vehicle.
        """
        seen = self._seen(inputs)
        state = self.vehicle.state
        ap = self.autopilot.command(state)
        command_deg = {ch: (ap.left_deg if ch == "left_wing" else ap.right_deg if ch == "right_wing"
                            else self.cfg.held_deg[ch]) for ch in self.channels}
        command_v = {ch: self.scalings[ch].command_deg_to_v(deg) for ch, deg in command_deg.items()}
        aero = {ch: self.hinge[ch].at(state.alpha_deg, seen[ch]) for ch in self.channels}
        if self.setup.surface_load == "aerodynamic":
            applied = dict(aero)
        else:
            applied = {ch: (self.setup.bungee_inlb if ch in WINGS else 0.0) for ch in self.channels}
        if self.open_loop:
            self._sim_load = dict(aero)
        self.vehicle.advance(seen["left_wing"], seen["right_wing"])
        self.k += 1
        return FrameOutputs(command_v, command_deg, applied, aero, seen, state, ap)

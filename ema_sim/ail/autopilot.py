"""The FMU's attitude hold in pitch and roll with trim, one 200 Hz frame at a time.

Pitch (a trailing-edge-down elevon pitches the nose down)::

    δe = trim + Kθ·(θ − θref) + Kiθ·∫(θ − θref) + Kq·q

Roll (positive aileron rolls right)::

    δa = −[Kφ·(φ − φref) + Kiφ·∫(φ − φref) + Kp·p]

The references are the attitudes at engagement (the first frame); the integrators start at zero, so
the trim is the FMU's trim elevon and the integral takes up whatever the vehicle needs beyond it.
Each axis is limited about its trim, and its integral stops while the axis is limited (no wind-up).
The integrals advance by forward Euler after each frame's command, as a flight computer's would.
"""

from __future__ import annotations

from dataclasses import dataclass

from ema_sim.ail.params import AutopilotParams
from ema_sim.ail.vehicle import VehicleState, wings


@dataclass(frozen=True)
class SurfaceCommand:
    """One frame's wing commands and the axes they came from (degrees)."""

    left_deg: float
    """Left wing command."""
    right_deg: float
    """Right wing command."""
    elevon_deg: float
    """The pitch axis's command (trim included), limited about the trim."""
    aileron_deg: float
    """The roll axis's command, limited about zero."""


def _limit(value: float, centre: float, half_range: float) -> tuple[float, bool]:
    low, high = centre - half_range, centre + half_range
    if value > high:
        return high, True
    if value < low:
        return low, True
    return value, False


class Autopilot:
    """The control law (see the module docstring).

    Parameters
    ----------
    params : AutopilotParams
        Gains, trim and limits (``config/ail_vehicle.yaml``).
    frame_s : float
        The FMU frame, s: the integrals' time step.
    """

    def __init__(self, params: AutopilotParams, frame_s: float) -> None:
        self.params = params
        self.frame_s = float(frame_s)
        self.theta_ref_deg: float | None = None
        self.phi_ref_deg: float | None = None
        self.pitch_integral = 0.0
        """∫(θ − θref) dt, deg·s."""
        self.roll_integral = 0.0
        """∫(φ − φref) dt, deg·s."""

    def reset(self) -> None:
        """Disengaged: the next frame captures the references again."""
        self.theta_ref_deg = self.phi_ref_deg = None
        self.pitch_integral = self.roll_integral = 0.0

    def command(self, s: VehicleState) -> SurfaceCommand:
        """This frame's wing commands from the sensed vehicle state; advances the integrals.

        Parameters
        ----------
        s : VehicleState
            The vehicle as the FMU senses it at the frame (the first call captures the references).

        Returns
        -------
        SurfaceCommand
            Both wings' commands and the limited elevon and aileron they came from.
        """
        p = self.params
        if self.theta_ref_deg is None or self.phi_ref_deg is None:
            self.theta_ref_deg, self.phi_ref_deg = s.theta_deg, s.phi_deg
        e_theta = s.theta_deg - self.theta_ref_deg
        e_phi = s.phi_deg - self.phi_ref_deg
        de_raw = (p.trim_elevon_deg + p.pitch_attitude_gain_deg_per_deg * e_theta
                  + p.pitch_integral_gain_per_s * self.pitch_integral + p.pitch_rate_gain_s * s.q_dps)
        da_raw = -(p.roll_attitude_gain_deg_per_deg * e_phi + p.roll_integral_gain_per_s * self.roll_integral
                   + p.roll_rate_gain_s * s.p_dps)
        de, de_limited = _limit(de_raw, p.trim_elevon_deg, p.elevon_limit_deg)
        da, da_limited = _limit(da_raw, 0.0, p.aileron_limit_deg)
        if not de_limited:
            self.pitch_integral += self.frame_s * e_theta
        if not da_limited:
            self.roll_integral += self.frame_s * e_phi
        left, right = wings(de, da)
        return SurfaceCommand(left, right, de, da)

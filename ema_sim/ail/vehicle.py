"""A minimal rigid-body vehicle: short period in pitch and roll, flown by the two wings as elevons.

States are deviations from the trimmed flight condition of :class:`~ema_sim.ail.params.VehicleParams`,
in degrees and seconds: ``[Δα, q, Δθ, p, φ]``::

    Δα' = Zα·Δα + q + Zδ·Δδe          q' = Mα·Δα + Mq·q + Mδ·Δδe          Δθ' = q
    p'  = Lp·p + Lδa·δa                φ' = p

with the elevon ``δe = (δ_left + δ_right)/2`` (``Δδe = δe − trim``) and the aileron
``δa = (δ_left − δ_right)/2``. The surfaces are zero-order held over each frame and the state is
advanced with the exact discretization of that hold (python-control's ``c2d``, zero-order hold), so the
FMU's 200 Hz frame adds no integration error. The offline harness and the ``fmu`` node run the same
arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.ail.params import VehicleParams

FloatArray = NDArray[np.float64]
STATES: tuple[str, ...] = ("alpha_deg", "q_dps", "theta_deg", "p_dps", "phi_deg")
"""The vehicle's outputs, absolute (trim added back), in this order."""
I_ALPHA, I_Q, I_THETA, I_P, I_PHI = range(5)


def elevon_aileron(left_deg: float, right_deg: float) -> tuple[float, float]:
    """Wing deflections → (elevon, aileron) = ((l + r)/2, (l − r)/2).

    Parameters
    ----------
    left_deg, right_deg : float
        The wings' deflections, deg.

    Returns
    -------
    tuple[float, float]
        Elevon and aileron, deg.
    """
    return 0.5 * (left_deg + right_deg), 0.5 * (left_deg - right_deg)


def wings(elevon_deg: float, aileron_deg: float) -> tuple[float, float]:
    """(elevon, aileron) → (left, right) wing deflections.

    Parameters
    ----------
    elevon_deg, aileron_deg : float
        The two axes, deg.

    Returns
    -------
    tuple[float, float]
        Left and right wing, deg.
    """
    return elevon_deg + aileron_deg, elevon_deg - aileron_deg


def matrices(p: VehicleParams) -> tuple[FloatArray, FloatArray]:
    """Continuous ``A`` (5×5) and ``B`` (5×2, inputs Δδe and δa).

    Parameters
    ----------
    p : VehicleParams
        The vehicle's stability and control derivatives.

    Returns
    -------
    tuple[FloatArray, FloatArray]
        ``A`` and ``B`` on the states ``[Δα, q, Δθ, p, φ]``.
    """
    a = np.zeros((5, 5))
    b = np.zeros((5, 2))
    a[I_ALPHA, I_ALPHA] = p.z_alpha_per_s
    a[I_ALPHA, I_Q] = 1.0
    a[I_Q, I_ALPHA] = p.m_alpha_per_s2
    a[I_Q, I_Q] = p.m_q_per_s
    a[I_THETA, I_Q] = 1.0
    a[I_P, I_P] = p.l_p_per_s
    a[I_PHI, I_P] = 1.0
    b[I_ALPHA, 0] = p.z_elevon_per_s
    b[I_Q, 0] = p.m_elevon_per_s2
    b[I_P, 1] = p.l_aileron_per_s2
    return a, b


def discretize(a: FloatArray, b: FloatArray, frame_s: float) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold discretization: ``x⁺ = Ad·x + Bd·u``.

    Parameters
    ----------
    a, b : FloatArray
        The continuous state and input matrices.
    frame_s : float
        The hold, s.

    Returns
    -------
    tuple[FloatArray, FloatArray]
        ``Ad`` and ``Bd``.
    """
    import control  # noqa: PLC0415 - python-control (1.2 s of import): only when a vehicle is built

    n, m = b.shape
    sysd = control.c2d(control.ss(a, b, np.eye(n), np.zeros((n, m))), frame_s, method="zoh")
    return np.asarray(sysd.A, dtype=float), np.asarray(sysd.B, dtype=float)


@dataclass
class VehicleState:
    """The vehicle at one frame, absolute angles."""

    alpha_deg: float
    """Angle of attack."""
    q_dps: float
    """Pitch rate."""
    theta_deg: float
    """Pitch attitude."""
    p_dps: float
    """Roll rate."""
    phi_deg: float
    """Bank angle."""

    def values(self) -> tuple[float, ...]:
        """In :data:`STATES` order."""
        return (self.alpha_deg, self.q_dps, self.theta_deg, self.p_dps, self.phi_deg)


class Vehicle:
    """The vehicle, advanced one FMU frame at a time (see the module docstring).

    Parameters
    ----------
    params : VehicleParams
        Trim and derivatives (``config/ail_vehicle.yaml``).
    frame_s : float
        The FMU frame, s.
    """

    def __init__(self, params: VehicleParams, frame_s: float) -> None:
        self.params = params
        self.frame_s = float(frame_s)
        self.ad, self.bd = discretize(*matrices(params), self.frame_s)
        self.x = np.zeros(5)

    def reset(self) -> None:
        """Back to trimmed flight."""
        self.x = np.zeros(5)

    @property
    def state(self) -> VehicleState:
        """Absolute angles and rates now."""
        p, x = self.params, self.x
        return VehicleState(p.trim_alpha_deg + x[I_ALPHA], x[I_Q], p.trim_theta_deg + x[I_THETA], x[I_P], x[I_PHI])

    def advance(self, left_deg: float, right_deg: float) -> None:
        """One frame with the wings held at these deflections (as the aerodynamics sees them).

        Parameters
        ----------
        left_deg, right_deg : float
            The wings over the frame, deg.
        """
        de, da = elevon_aileron(left_deg, right_deg)
        self.x = self.ad @ self.x + self.bd @ np.array([de - self.params.trim_elevon_deg, da])

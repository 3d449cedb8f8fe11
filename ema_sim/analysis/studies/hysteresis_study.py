"""Hysteretic damping on the model (sections 3.2.2, 3.3): the rw13 replication and figure 37 on HOAD3.

The measured-data side (loops from a load test) is :mod:`ema_sim.analysis.section2.hysteresis`.

Units, as the report uses them: the test applied a hinge moment and measured the surface angle; the
loop is drawn at the actuator, **force** (hinge moment / crank arm, lbf) against **deflection** (surface
angle in radians × crank arm, in). Its area is lbf·in, which the report writes in·lb, and
``h = A/(π·Pk²)`` with Pk the deflection amplitude in inches is in lb/in, the gear train's own units.
rw13: ±1,780 in·lb → ±1,027.9 lbf at the 1.7317 in arm; A = 4.88 in·lb, Pk = 0.02155 in → 3,344.84 lb/in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ema_sim.analysis.section2.hysteresis import hysteretic_damping_constant
from ema_sim.analysis.section2.sine_dwell import FrequencyResponse, sine_dwell
from ema_sim.config import load_channel
from ema_sim.models.high_order import HighOrderParams, Hoad3

RW13_AREA_INLB = 4.88
RW13_AMPLITUDE_IN = 0.02155
RW13_LOAD_INLB = 1780.0
RW13_OMEGA_RAD_S = (0.0785, 0.785)
"""The low- and high-frequency cases of the test (0.025 Hz and 0.25 Hz, section 2.9)."""


@dataclass(frozen=True)
class HysteresisLoop:
    """One steady cycle of force (lbf) against deflection (in) at the actuator.

    Parameters
    ----------
    omega_rad_s : float
        Load frequency, rad/s.
    force_lbf : np.ndarray
        Force at the screw, lbf.
    deflection_in : np.ndarray
        Deflection at the actuator, in.
    """

    omega_rad_s: float
    force_lbf: np.ndarray
    deflection_in: np.ndarray

    @property
    def area_inlb(self) -> float:
        """The area inside the loop, ∮ x dF (lbf·in, the report's in·lb)."""
        return float(abs(np.trapezoid(self.deflection_in, self.force_lbf)))

    @property
    def amplitude_in(self) -> float:
        """Half the peak-to-peak deflection."""
        return float(0.5 * np.ptp(self.deflection_in))

    @property
    def h_lbf_per_in(self) -> float:
        """The hysteretic damping constant this loop implies."""
        return hysteretic_damping_constant(self.area_inlb, self.amplitude_in)


def rw13_loop(omega_rad_s: float = RW13_OMEGA_RAD_S[0], *, hysteresis: bool = True, channel: str = "right_wing",
              load_inlb: float = RW13_LOAD_INLB, points_per_cycle: int = 4000) -> HysteresisLoop:
    """Test rw13 on HOAD3: a sinusoidal hinge moment with the motor and control logic removed.

    "Removed" is the brake holding the unpowered motor, so only the coupling (figure 36) and the
    load act; the damper's ω is the load's. Two cycles run; the second is the loop.

    Parameters
    ----------
    omega_rad_s : float
        Load frequency, rad/s.
    hysteresis : bool
        Hysteretic damping in the model.
    channel : str
        The channel (``left_wing``...).
    load_inlb : float
        Load amplitude, in·lb.
    points_per_cycle : int
        Samples per load cycle.

    Returns
    -------
    HysteresisLoop
        The loop and its figures.
    """
    model = Hoad3(channel, noise=False, quantization_v=0.0, hysteresis=hysteresis, hysteresis_freq_rad_s=omega_rad_s)
    model.set_power(False)
    model.trim(0.0, 0.0)
    n = points_per_cycle
    t = np.arange(2 * n + 1) * (2.0 * math.pi / omega_rad_s) / n
    hm = load_inlb * np.sin(omega_rad_s * t)
    rec = model.run(t, np.zeros_like(t), hm, end_s=t[-1])
    arm = model.channel.crank_arm_in
    deflection = np.radians(rec.surface_deg[0, n:]) * arm  # motor side held: the surface moves by the deflection
    return HysteresisLoop(omega_rad_s, hm[n:] / arm, deflection)


def frequency_effect(freq_hz: np.ndarray, channel: str = "right_wing", amp_deg: float = 1.0,
                     output: str = "position_deg") -> tuple[FrequencyResponse, FrequencyResponse]:
    """Figure 37: HOAD3's response with and without hysteretic damping, ω of h/ω at each dwell's frequency.

    Parameters
    ----------
    freq_hz : np.ndarray
        Frequency, Hz.
    channel : str
        The channel (``left_wing``...).
    amp_deg : float
        Amplitude, deg.
    output : str
        Name of the output.

    Returns
    -------
    tuple
        Largest change of gain (dB) and phase (deg).
    """
    f = np.asarray(freq_hz, dtype=float)
    base = HighOrderParams.from_channel(load_channel(channel), "hoad3")
    with_h = Hoad3(channel, n=f.size, noise=False, hysteresis=True,
                   params=[base.replace(hysteresis_freq_rad_s=2.0 * math.pi * x) for x in f])
    return (sine_dwell(with_h, f, amp_deg, output=output),
            sine_dwell(Hoad3(channel, n=f.size, noise=False), f, amp_deg, output=output))

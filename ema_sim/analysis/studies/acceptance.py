"""The actuator specifications of table 1 and the acceptance tests of table A2, run on a model.

Each test drives a model the way the acceptance test or section-2 test drives the hardware and
measures the one figure the specification names: slew rate unloaded and against the rated opposing
load at 125 V, stall force, −3 dB bandwidth with the inertial load, backlash and static stiffness and
brake holding with the motor unpowered (brake on), and the bus peak of the regeneration test (2.5).
Forces are at the actuator (lbf), hinge moments through the crank arm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ema_sim.analysis.section2.sine_dwell import sine_dwell
from ema_sim.jsontypes import JsonObject
from ema_sim.models import ActuatorModel, Flags, Record, create
from ema_sim.models.high_order.models import HighOrderModel

FRAME_S = 0.005
RATED_LOAD_LBF = {"wing": 500.0, "rudder": 526.0, "cowl": 2000.0}
"""Table A2, force versus rate at 125 Vdc: the opposing load of each surface..."""
RATED_RATE_IN_S = {"wing": 3.5, "rudder": 3.3, "cowl": 3.1}
"""...and the rate it must still reach."""
LOW_BUS_V = 125.0
"""Table 1: the minimum motor voltage the acceptance figures are stated at."""


@dataclass(frozen=True)
class Figure:
    """One measured figure against its requirement.

    Parameters
    ----------
    name : str
        What is measured.
    value : float
        The value.
    unit : str
        Its unit.
    requirement : str
        The requirement of table 1 or A2, as text.
    passed : bool
        Whether the measured value meets it.
    """

    name: str
    value: float
    unit: str
    requirement: str
    passed: bool

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"name": self.name, "value": self.value, "unit": self.unit, "requirement": self.requirement,
                "passed": self.passed}


def _model(name: str, channel: str, **kwargs: object) -> ActuatorModel:
    """The model as a test stand sees it: the FMU's quantization and noise are not in the test set-up."""
    opts = {"noise": False, "quantization_v": 0.0} if name in ("hoad2", "hoad3") else {}
    return create(name, channel, **opts, **kwargs)


def _frames(duration_s: float) -> np.ndarray:
    return np.arange(round(duration_s / FRAME_S)) * FRAME_S


def slew_rate_in_s(name: str = "hoac1", channel: str = "left_wing", *, opposing_lbf: float = 0.0,
                   supply_v: float | None = None) -> float:
    """Steady rate while rate-limited through a 20° step against an opposing load (in/s at the screw).

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).
    opposing_lbf : float
        Force opposing the motion at the screw, lbf.
    supply_v : float or None
        Bus supply, V.

    Returns
    -------
    float
        Slew rate at the actuator, in/s.
    """
    kwargs = {} if supply_v is None else {"bus_supply_v": supply_v}
    model = _model(name, channel, **kwargs)
    arm = model.channel.crank_arm_in
    t = _frames(0.8)
    hm = np.full_like(t, -opposing_lbf * arm)
    model.trim(0.0, hm[0])
    samples = np.arange(0, 800) / 1000.0
    rec = model.run(t, np.where(t >= 0.1, 20.0, 0.0), hm, sample_times=samples, end_s=0.8)
    limited = (rec.flags[0] & Flags.RATE_LIMIT) != 0
    if limited.sum() < 20:
        return math.nan
    return float(np.median(rec.rate_dps[0, limited]) / model.channel.deg_per_in)


def stall_force_lbf(name: str = "hoac1", channel: str = "left_wing", *, supply_v: float = LOW_BUS_V,
                    lo: float = 2000.0, hi: float = 3500.0, resolution: float = 5.0) -> float:
    """The largest opposing load under which a 5° step still advances (≥ 0.5° in 0.4 s), lbf.

    Eight loads at a time between ``lo`` and ``hi`` (one batch run), narrowed to ``resolution``.

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).
    supply_v : float
        Bus supply, V.
    lo : float
        Lowest force of the search, lbf.
    hi : float
        Highest force of the search, lbf.
    resolution : float
        Bisection stops within this many lbf.

    Returns
    -------
    float
        The stall force, lbf.
    """
    while hi - lo > resolution:
        loads = np.linspace(lo, hi, 8)
        model = _model(name, channel, n=loads.size, bus_supply_v=supply_v)
        arm = model.channel.crank_arm_in
        t = _frames(0.5)
        hm = -loads[:, None] * arm * np.ones_like(t)
        model.trim(0.0, hm[:, 0])
        rec = model.run(t, np.where(t >= 0.1, 5.0, 0.0), hm, end_s=0.5)
        advanced = rec.position_deg[:, -1] > rec.position_deg[:, 0] + 0.5
        if not advanced[0] or advanced.all():
            return math.nan  # the stall force is outside [lo, hi]
        k = int(np.argmin(advanced))
        lo, hi = float(loads[k - 1]), float(loads[k])
    return lo


def bandwidth_hz(name: str = "hoac1", channel: str = "left_wing", amp_deg: float = 1.0) -> float:
    """−3 dB frequency of command to position, unloaded with the inertial load (sine dwells).

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).
    amp_deg : float
        Amplitude, deg.

    Returns
    -------
    float
        The −3 dB frequency of the ±1° response, Hz.
    """
    f = np.array([5.0, 6.0, 7.0, 7.5, 8.0, 9.0, 10.0, 11.0, 12.0, 14.0])
    fr = sine_dwell(_model(name, channel, n=f.size), f, amp_deg, settle_cycles=2, measure_cycles=2,
                    min_settle_s=0.15)
    return fr.bandwidth_hz()


def _unpowered_static(name: str, channel: str, forces_lbf: list[float]) -> tuple[np.ndarray, np.ndarray, Record]:
    """Brake on (unpowered): slowly applied loads; LVDT (output against the housing) and surface, in."""
    model = _model(name, channel, n=len(forces_lbf))
    if not isinstance(model, HighOrderModel):  # the high-order models have a power switch; the base interface not
        raise TypeError(f"{name} has no motor power switch (a high-order model has)")
    model.set_power(False)
    model.trim(0.0, 0.0)
    arm = model.channel.crank_arm_in
    t = _frames(1.2)
    ramp = np.clip((t - 0.1) / 0.6, 0.0, 1.0)
    hm = np.asarray(forces_lbf)[:, None] * arm * ramp[None, :]
    rec = model.run(t, np.zeros_like(t), hm, end_s=1.2)
    dpi = model.channel.deg_per_in
    return rec.position_deg[:, -1] / dpi, rec.surface_deg[:, -1] / dpi, rec


def backlash_and_stiffness(name: str = "hoac1", channel: str = "left_wing") -> dict[str, float]:
    """Backlash (a ±50 lbf reversal less its elastic part) and static stiffness between 1,000 and 2,000 lbf.

    ``actuator`` stiffness is the output against the actuator housing (as the acceptance test holds
    it); ``installed`` includes the backup structure (the surface against the airframe).

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).

    Returns
    -------
    dict
        Backlash (in) and static stiffness (lbf/in), with and without the backup structure.
    """
    lvdt, surface, _ = _unpowered_static(name, channel, [-50.0, 50.0, 1000.0, 2000.0])
    k_act = 1000.0 / (lvdt[3] - lvdt[2])
    return {"backlash_in": float(lvdt[1] - lvdt[0] - 100.0 / k_act), "actuator_lbf_per_in": float(k_act),
            "installed_lbf_per_in": float(1000.0 / (surface[3] - surface[2]))}


def brake_holds(name: str = "hoac1", channel: str = "left_wing", force_lbf: float = 4000.0) -> bool:
    """Unpowered, the brake holds ``force_lbf`` without the motor turning.

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).
    force_lbf : float
        Force at the screw, lbf.

    Returns
    -------
    bool
        Whether the brake holds the force.
    """
    _, _, rec = _unpowered_static(name, channel, [force_lbf])
    return bool(np.max(np.abs(rec.rate_dps[0])) == 0.0 and np.all(rec.flags[0] & Flags.BRAKE))


def regeneration_peak_v(name: str = "hoac1", channel: str = "left_wing") -> tuple[float, float]:
    """Section 2.5: a 5 % full-scale square wave stepped from 0.1 to 5 Hz; (peak, lowest) bus voltage.

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).

    Returns
    -------
    tuple
        Peak and lowest bus voltage, V.
    """
    segments = [np.zeros(40)]
    for f in (0.1, 0.5, 1.0, 2.0, 5.0):
        tt = np.arange(round(1.0 / f / FRAME_S)) * FRAME_S
        segments.append(0.05 * 43.0 * np.sign(np.sin(2 * np.pi * f * tt + 1e-9)))
    cmd = np.concatenate(segments)
    t = np.arange(cmd.size) * FRAME_S
    model = _model(name, channel)
    model.trim(0.0, 0.0)
    rec = model.run(t, cmd, sample_times=np.arange(0, round(t[-1] * 2000)) / 2000.0, end_s=t[-1])
    return float(rec.bus_v.max()), float(rec.bus_v.min())


def acceptance(name: str = "hoac1", channel: str = "left_wing") -> list[Figure]:
    """Every table 1 / table A2 figure of ``channel``'s actuator, measured on model ``name``.

    Parameters
    ----------
    name : str
        The model's name (``ema models``).
    channel : str
        The channel (``left_wing``...).

    Returns
    -------
    list
        The figures in table order.
    """
    surface = create(name, channel).channel.surface
    rated, rate = RATED_LOAD_LBF[surface], RATED_RATE_IN_S[surface]
    slew = slew_rate_in_s(name, channel)
    loaded = slew_rate_in_s(name, channel, opposing_lbf=rated, supply_v=LOW_BUS_V)
    stall = stall_force_lbf(name, channel)
    bw = bandwidth_hz(name, channel)
    mech = backlash_and_stiffness(name, channel)
    holds = brake_holds(name, channel)
    peak, _ = regeneration_peak_v(name, channel)
    return [
        Figure("slew rate, unloaded", slew, "in/s", "3.5 in/s (115.8 deg/s)", slew >= 3.5),
        Figure(f"rate at {rated:g} lbf, 125 V", loaded, "in/s", f">= {rate:g} in/s (table A2)", loaded >= rate),
        Figure("stall force, 125 V", stall, "lbf", ">= 2,500 lbf", stall >= 2500.0),
        Figure("bandwidth (-3 dB, +-1 deg)", bw, "Hz", ">= 7.5 Hz", bw >= 7.5),
        Figure("backlash", mech["backlash_in"], "in", "<= 0.005 in", mech["backlash_in"] <= 0.005),
        Figure("static stiffness (actuator)", mech["actuator_lbf_per_in"], "lbf/in", ">= 400,000 lbf/in",
               mech["actuator_lbf_per_in"] >= 400_000.0),
        Figure("static stiffness (installed)", mech["installed_lbf_per_in"], "lbf/in",
               "information: surface against airframe", True),
        Figure("brake holds 4,000 lbf unpowered", float(holds), "", "> 4,000 lbf", holds),
        Figure("bus peak, regeneration test", peak, "V", "<= 185 V (2.5)", peak <= 185.0),
    ]


def format_acceptance(figures: list[Figure]) -> str:
    """A Markdown table.

    Parameters
    ----------
    figures : list
        The figures (:func:`acceptance`).

    Returns
    -------
    str
        The table as text.
    """
    lines = ["| figure | measured | requirement | |", "| --- | --- | --- | --- |"]
    for f in figures:
        if f.unit == "":
            value = "yes" if f.value else "no"
        elif abs(f.value) >= 1000.0:
            value = f"{f.value:,.0f} {f.unit}"
        else:
            value = f"{f.value:.4g} {f.unit}"
        lines.append(f"| {f.name} | {value} | {f.requirement} | {'pass' if f.passed else 'FAIL'} |")
    return "\n".join(lines)

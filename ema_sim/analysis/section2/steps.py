"""Step responses (section 2.7): rise, settling, overshoot, slew rate, and a second-order fit per step.

Steps of 0.5°, 1° and 20° give the small- and large-amplitude slew rates. For each command edge:

* initial level: mean over the last 0.1 s before the edge; final: mean over the last 30 % of the hold;
* first motion (:func:`ema_sim.analysis.section2.timing.first_motion`), 10-90 % rise time, settling time into
  a band of ±max(2 %, 4σ/|A|) about the final value, counted from the edge, and overshoot;
* peak rate from a Savitzky-Golay derivative (11 ms, quadratic), and the plateau rate, the slope of a
  line through the samples whose rate is within 5 % of the peak (not biased up by noise as a peak is);
* rate limiting: a step is rate-limited when its rate holds within 5 % of its peak for more than
  60 % of its 10-90 % rise (and at least 3 samples: a linear second order stays there for 0.64/ωn,
  at most 53 % of its rise for any ζ ≥ 0.2, while a step on its rate limit rises at that rate almost
  throughout), when its peak reaches 80 % of the channel's rated slew (table 1), or when its peak
  falls 15 % short of what a second order fitted to a smaller step predicts, or when its peak reaches the record's
  speed plateau (:func:`ema_sim.analysis.estimation.slew.plateau`: the ceiling the output's runs flatten against
  wherever the command asks for more, within 10 %). Rate-limited steps give the large-amplitude
  slew rate and no linear fit; the others get :func:`ema_sim.analysis.estimation.second_order_fit.fit_step` and
  the hand calculation from rise and settling time beside it.

Every step is also read against its **commanded level** (:mod:`ema_sim.analysis.estimation.settling`): overshoot
past the command, settling into the band about the command, and, when the output is still outside
that band at the next edge, *unsettled* with the error left to the command (a servo that stops short
of its command settles against its own last value all the same).

The large-amplitude slew rate is the slope of the record's rate-limited moves
(:func:`ema_sim.analysis.estimation.slew.measure`, on the record's own stamps), the measurement ``ema identify``
restarts its rate limit from and compares it with; the rate-limited steps' own plateau rate is kept
beside it, and a disagreement between the two is said.

Each step's quality: ``saturated`` when rate-limited, ``not_determined`` when the step is within ten
times the noise, else its fit's. A step set recognised from the metadata (a suite bag's
``steps:amps_deg=…``) whose steps the command does not show as edges lists each missing step under
``not_computed`` with the reason. The test runs on the ``steps`` and ``square`` segments; ``steps`` is
what :func:`read_steps` calls any run of edges no other test claims.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation import settling, slew
from ema_sim.analysis.estimation.linearity import amplitude_change
from ema_sim.analysis.estimation.quality import Quality
from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit, fit_step, hand_calculation, simulate
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import image, num, quality, table
from ema_sim.analysis.records.series import Edge, derivative, moving_average, settled
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import EdgeRun, Reading
from ema_sim.analysis.section2.timing import first_motion
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

PRE_S = 0.1
PLATEAU_SHARE = 0.6
RATED_FRACTION = 0.8
SHORTFALL = 0.85


@dataclass(frozen=True)
class StepResponse:
    """Metrics (and fit) of one step.

    Parameters
    ----------
    time_s : float
        Time of the command edge, s.
    command_from_deg : float
        Command before the edge, deg.
    command_to_deg : float
        Command after it, deg.
    output : str
        Name of the output.
    initial_deg : float
        Output before the edge, deg.
    final_deg : float
        Settled output after it, deg.
    noise_deg : float
        Noise on the output before the edge, deg.
    delay_s : float or None
        First motion after the edge, s.
    rise_s : float or None
        10-90 % rise time, s.
    settling_s : float or None
        2 % settling time, s.
    settling_band : float
        Settling band, share of the step.
    overshoot_pct : float or None
        Overshoot, %.
    peak_rate_dps : float
        Peak rate, deg/s.
    plateau_s : float
        Time within 5 % of the peak rate, s.
    plateau_rate_dps : float or None
        Slope of a line through the samples whose rate is within 5 % of the peak (the slew rate).
    rate_limited : bool
        Whether the step is rate-limited.
    rate_reason : str
        The evidence.
    fit : SecondOrderFit or None
        Its second-order fit.
    fit_note : str
        Why there is no fit, or ``fitted``.
    start : int
        First sample of the step's window.
    stop : int
        One past its last sample.
    edge : int
        Sample of the command edge.
    against_command : Settling or None
        The step read against its commanded level (overshoot, settling, error left at the next edge).
    """

    time_s: float
    command_from_deg: float
    command_to_deg: float
    output: str
    initial_deg: float
    final_deg: float
    noise_deg: float
    delay_s: float | None
    rise_s: float | None
    settling_s: float | None
    settling_band: float
    overshoot_pct: float | None
    peak_rate_dps: float
    plateau_s: float
    plateau_rate_dps: float | None
    """Slope of a line through the samples whose rate is within 5 % of the peak (the slew rate)."""
    rate_limited: bool
    rate_reason: str
    fit: SecondOrderFit | None
    fit_note: str
    start: int
    stop: int
    edge: int = 0
    """Sample of the command edge."""
    against_command: settling.Settling | None = None
    """The step read against its commanded level (overshoot, settling, error left at the next edge)."""

    @property
    def quality(self) -> Quality:
        """``saturated`` when rate-limited, ``not_determined`` when unfitted in the noise, else the fit's."""
        if self.rate_limited:
            return "saturated"
        if self.fit is None:
            return "not_determined" if "noise" in self.fit_note else "ok"
        return self.fit.quality

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        if self.rate_limited:
            return self.rate_reason
        if self.fit is None:
            return self.fit_note if self.quality != "ok" else ""
        return self.fit.quality_note

    @property
    def command_step_deg(self) -> float:
        """Commanded change."""
        return self.command_to_deg - self.command_from_deg

    @property
    def amplitude_deg(self) -> float:
        """Measured change."""
        return self.final_deg - self.initial_deg

    @property
    def label(self) -> str:
        """``step +1.00° at 2.500 s``."""
        return f"step {self.command_step_deg:+.2f}° at {self.time_s:.3f} s"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The step's metrics, rate-limit evidence, fit and quality.
        """
        return {
            "time_s": self.time_s, "command_from_deg": self.command_from_deg, "command_to_deg": self.command_to_deg,
            "command_step_deg": self.command_step_deg, "output": self.output, "initial_deg": self.initial_deg,
            "final_deg": self.final_deg, "amplitude_deg": self.amplitude_deg, "noise_deg": self.noise_deg,
            "first_motion_s": self.delay_s, "rise_10_90_s": self.rise_s, "settling_s": self.settling_s,
            "settling_band_pct": 100.0 * self.settling_band, "overshoot_pct": self.overshoot_pct,
            "peak_rate_dps": self.peak_rate_dps, "rate_plateau_s": self.plateau_s,
            "plateau_rate_dps": self.plateau_rate_dps, "rate_limited": self.rate_limited,
            "rate_limit_evidence": self.rate_reason, "fit": self.fit.as_dict() if self.fit else None,
            "fit_note": self.fit_note, "quality": self.quality, "quality_note": self.quality_note,
            "against_command": self.against_command.as_dict() if self.against_command else None,
            "settled_to_command": self.against_command.settled if self.against_command else None,
        }


def _crossing(t: FloatArray, z: FloatArray, level: float) -> float | None:
    idx = np.flatnonzero(z >= level)
    if idx.size == 0:
        return None
    i = int(idx[0])
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (t[i] - t[i - 1]) * (level - z[i - 1]) / (z[i] - z[i - 1]))


class _EdgeMetrics(TypedDict):
    """One edge's figures as measured, before the step response is judged (times s, positions deg)."""

    start: int
    stop: int
    y0: float
    y1: float
    noise: float
    delay: float | None
    rise: float | None
    settling: float | None
    band: float
    overshoot: float | None
    peak: float
    plateau: float
    plateau_rate: float | None


def _metrics(t: FloatArray, y: FloatArray, e: Edge, dt: float, noise_floor: float) -> _EdgeMetrics:
    pre = max(e.before.start, e.index - max(5, round(PRE_S / dt)))
    y0 = float(np.mean(y[pre:e.index]))
    noise = float(np.std(y[pre:e.index])) if e.index - pre > 5 else noise_floor
    noise = max(min(noise, 5.0 * noise_floor) if noise_floor > 0 else noise, noise_floor)
    y1, _ = settled(y, e.index, e.after.stop, 0.3)
    amp = y1 - y0
    seg = slice(e.index, e.after.stop)
    tt = t[seg] - t[e.index]
    z = (y[seg] - y0) / amp if amp != 0.0 else np.zeros(tt.size)
    zs = moving_average(z, max(1, round(0.005 / dt)))
    t_motion = first_motion(t, y, e.index, y0, amp, noise, e.after.stop)
    t10, t90 = _crossing(tt, zs, 0.1), _crossing(tt, zs, 0.9)
    rise = None if t10 is None or t90 is None else t90 - t10
    band = max(0.02, 4.0 * noise / abs(amp)) if amp != 0 else 0.02
    outside = np.flatnonzero(np.abs(z - 1.0) > band)
    settling = None
    if outside.size and outside[-1] + 1 < tt.size:
        settling = float(tt[outside[-1] + 1])
    elif outside.size == 0:
        settling = 0.0
    overshoot = float(max(0.0, (zs.max() - 1.0) * 100.0)) if amp != 0 else None
    rate = derivative(y[seg], dt)
    direction = math.copysign(1.0, amp) if amp != 0 else 1.0
    peak = float(np.max(rate * direction)) if rate.size else 0.0
    on_plateau = rate * direction >= 0.95 * peak if peak > 0 else np.zeros(rate.size, dtype=bool)
    plateau = float(np.sum(on_plateau) * dt)
    plateau_rate = None
    if on_plateau.sum() >= 5:
        idx = np.flatnonzero(on_plateau)
        plateau_rate = float(abs(np.polyfit(tt[idx], y[seg][idx], 1)[0]))
    return {
        "start": pre, "stop": e.after.stop, "y0": y0, "y1": y1, "noise": noise,
        "delay": None if t_motion is None else t_motion - float(t[e.index]),
        "rise": rise, "settling": settling, "band": band, "overshoot": overshoot, "peak": peak, "plateau": plateau,
        "plateau_rate": plateau_rate,
    }


def _predicted_peak_rate(amp: float, wn: float, zeta: float) -> float:
    """Peak rate of a linear second-order step of amplitude ``amp``."""
    if zeta >= 1.0:
        # Critically/over-damped: evaluate numerically.
        tt = np.linspace(0.0, 10.0 / wn, 2001)
        s1 = -wn * (zeta - np.sqrt(zeta * zeta - 1.0 + 1e-12))
        s2 = -wn * (zeta + np.sqrt(zeta * zeta - 1.0 + 1e-12))
        v = (np.exp(s1 * tt) - np.exp(s2 * tt)) * wn * wn / (s1 - s2 if s1 != s2 else 1e-12)
        return float(abs(amp) * np.max(np.abs(v)))
    wd = wn * np.sqrt(1.0 - zeta * zeta)
    tp = np.arctan2(np.sqrt(1.0 - zeta * zeta), zeta) / wd
    return float(abs(amp) * wn / np.sqrt(1.0 - zeta * zeta) * np.exp(-zeta * wn * tp) * np.sin(wd * tp))


def analyze_steps(t: FloatArray, u: FloatArray, y: FloatArray, edges: list[Edge], *, output: str,
                  noise_floor: float, rated_slew_dps: float | None = None, fit: bool = True,
                  sampled: bool = False, counts: float | None = None,
                  plateau_dps: float | None = None) -> list[StepResponse]:
    """Metrics of every step, then fits in order of increasing amplitude (see the module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    u : numpy.ndarray
        Command, deg.
    y : numpy.ndarray
        The output the steps are measured on.
    edges : list of Edge
        The command edges.
    output : str
        The output's name.
    noise_floor : float
        Its noise floor.
    rated_slew_dps : float, optional
        The channel's rated slew rate (table 1), when the record is of one of its channels.
    fit : bool
        Fit a second order to every step that is not rate-limited.
    sampled : bool
        The command was sampled from a running demand, not held.
    counts : float, optional
        The output's count (for the settling band about the command).
    plateau_dps : float, optional
        The record's speed plateau (:func:`ema_sim.analysis.estimation.slew.plateau`): a step whose peak rate
        reaches it is rate-limited.

    Returns
    -------
    list of StepResponse
        One per edge, in the edges' order.
    """
    dt = float(np.median(np.diff(t)))
    rows = [(e, _metrics(t, y, e, dt, noise_floor)) for e in edges]
    order = sorted(range(len(rows)), key=lambda i: abs(rows[i][1]["y1"] - rows[i][1]["y0"]))
    reference: SecondOrderFit | None = None
    reference_amp = 0.0
    results: dict[int, StepResponse] = {}
    for i in order:
        e, m = rows[i]
        amp = m["y1"] - m["y0"]
        reasons = []
        if m["rise"] and m["plateau"] >= PLATEAU_SHARE * m["rise"] and m["plateau"] >= 3 * dt - 1e-12:
            reasons.append(f"rate within 5 % of its {m['peak']:.1f} °/s peak for {1e3 * m['plateau']:.0f} ms of its "
                           f"{1e3 * m['rise']:.0f} ms rise")
        if plateau_dps and m["peak"] >= (1.0 - slew.AGREE) * plateau_dps:
            reasons.append(f"peak rate {m['peak']:.1f}/s reaches the record's speed plateau {plateau_dps:.1f}/s")
        if rated_slew_dps and m["peak"] >= RATED_FRACTION * rated_slew_dps:
            reasons.append(f"peak rate {m['peak']:.1f} °/s ≥ {RATED_FRACTION:.0%} of the rated {rated_slew_dps:g} °/s")
        if reference is not None:
            pred = _predicted_peak_rate(amp, reference.wn_rad_s.value, reference.zeta.value)
            if m["peak"] < SHORTFALL * pred:
                reasons.append(f"peak rate {m['peak']:.1f} °/s below the {pred:.1f} °/s a linear second order predicts")
        limited = bool(reasons)
        hand = hand_calculation(m["rise"], m["settling"] - (m["delay"] or 0.0)) \
            if m["rise"] and m["settling"] else None
        step_fit = None
        if limited:
            note = "rate-limited: a linear second-order fit does not apply (slew rate reported)"
        elif not fit:
            note = "fit not requested"
        elif abs(amp) < 10.0 * m["noise"]:
            note = f"step {abs(amp):.3g}° is within 10× the noise ({m['noise']:.2g}°): not fitted"
        else:
            sl = slice(m["start"], m["stop"])
            wn0 = hand.wn_rad_s if hand else 50.0
            z0 = hand.zeta if hand else 0.7
            step_fit = fit_step(t[sl], u[sl], y[sl], test=f"step {e.jump:+.2f}° at {t[e.index]:.3f} s",
                                output_name=output, wn0=min(max(wn0, 5.0), 1000.0), zeta0=min(max(z0, 0.1), 2.0),
                                delay0=m["delay"] or 0.005, hand=hand, sampled=sampled)
            note = "fitted"
            if reference is None:
                reference, reference_amp = step_fit, amp
            elif changed := amplitude_change(reference, reference_amp, step_fit):
                note = f"fitted; {changed}"
        results[i] = StepResponse(
            time_s=float(t[e.index]), command_from_deg=e.before.value, command_to_deg=e.after.value, output=output,
            initial_deg=m["y0"], final_deg=m["y1"], noise_deg=m["noise"], delay_s=m["delay"], rise_s=m["rise"],
            settling_s=m["settling"], settling_band=m["band"], overshoot_pct=m["overshoot"], peak_rate_dps=m["peak"],
            plateau_s=m["plateau"], plateau_rate_dps=m["plateau_rate"], rate_limited=limited,
            rate_reason="; ".join(reasons), fit=step_fit, fit_note=note, start=m["start"], stop=m["stop"],
            edge=e.index, against_command=settling.read(t, y, e.after.start, e.after.stop, commanded=e.after.value,
                                                        change=e.jump, noise=noise_floor, counts=counts),
        )
    return [results[i] for i in range(len(rows))]


@dataclass(frozen=True)
class SlewRates:
    """Small- and large-amplitude slew rates (section 2.7).

    Parameters
    ----------
    small_dps : float or None
        Peak rate of the steps that are not rate-limited, deg/s.
    small_steps_deg : list
        Their sizes, deg.
    large_dps : float or None
        The large-amplitude slew rate: the slope of the record's rate-limited moves when it has any, else the
        plateau rate of the longest rate-limited step, deg/s.
    large_steps_deg : list
        The rate-limited steps' sizes, deg.
    large_sigma_dps : float or None
        The slope's spread over its moves (over √moves).
    large_source : str
        Where ``large_dps`` comes from.
    plateau_dps : float or None
        Plateau rate of the rate-limited step that stays on its limit longest, deg/s.
    agreement : str
        How the slope and the plateau rate compare (the disagreement explained), or "".
    """

    small_dps: float | None
    small_steps_deg: list[float]
    large_dps: float | None
    large_steps_deg: list[float]
    large_sigma_dps: float | None = None
    large_source: str = "plateau rate of the rate-limited step that stays on its limit longest"
    plateau_dps: float | None = None
    agreement: str = ""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Small- and large-amplitude slew rates, the steps they come from, and their definition.
        """
        return {"small_amplitude_dps": self.small_dps, "small_amplitude_steps_deg": [*self.small_steps_deg],
                "large_amplitude_dps": self.large_dps, "large_amplitude_sigma_dps": self.large_sigma_dps,
                "large_amplitude_source": self.large_source, "large_amplitude_steps_deg": [*self.large_steps_deg],
                "plateau_dps": self.plateau_dps, "agreement": self.agreement,
                "definition": "small: peak rate of the steps that are not rate-limited; large: slope of the straight "
                              "middle (20-80 %) of the record's rate-limited moves, median over the moves (the same "
                              "measurement ema identify restarts its rate limit from), else the rate plateau of the "
                              "rate-limited step that stays on its limit longest"}


def _longest_plateau_rate(large: list[StepResponse]) -> float | None:
    """Slew rate of the rate-limited step that stays on its limit longest (closest to the steady limit)."""
    if not large:
        return None
    best = max(large, key=lambda s: s.plateau_s)
    return best.plateau_rate_dps if best.plateau_rate_dps is not None else best.peak_rate_dps


def slew_rates(steps: list[StepResponse], slope: slew.Slew | None = None) -> SlewRates:
    """Peak rates of the linear steps (small amplitude) and the slope of the rate-limited moves (large amplitude).

    Parameters
    ----------
    steps : list of StepResponse
        The steps of a record.
    slope : Slew, optional
        The slope of the record's rate-limited moves (:func:`ema_sim.analysis.estimation.slew.measure`): the
        large-amplitude rate when the steps include a rate-limited one and it found rate-limited moves.

    Returns
    -------
    SlewRates
        Both slew rates, where the large one comes from, and how it compares with the steps' plateau.
    """
    small = [s for s in steps if not s.rate_limited]
    large = [s for s in steps if s.rate_limited]
    plateau = _longest_plateau_rate(large)
    small_dps = max((s.peak_rate_dps for s in small), default=None)
    small_steps = sorted({round(abs(s.command_step_deg), 4) for s in small})
    large_steps = sorted({round(abs(s.command_step_deg), 4) for s in large})
    if not large or slope is None or slope.rate is None:
        return SlewRates(small_dps, small_steps, plateau, large_steps, plateau_dps=plateau)
    rate = slope.rate
    source = (f"slope of the straight middle of the record's {slope.moves} rate-limited move(s), median (the "
              "measurement ema identify restarts its rate limit from)")
    agreement = ""
    if plateau is not None:
        tol = max(slew.AGREE * rate, 2.0 * (slope.sigma or 0.0))
        if abs(plateau - rate) <= tol:
            agreement = f"the longest step's plateau rate {plateau:.4g} agrees (within {100 * tol / rate:.2g} %)"
        else:
            agreement = (f"the longest step's plateau rate, {plateau:.4g}, differs by "
                         f"{100 * (plateau / rate - 1):+.0f} %: it is the line through the samples within 5 % of "
                         "that step's peak rate (a speed loop's overshoot or a short plateau biases it), where the "
                         "slope is the straight middle 20-80 % of every rate-limited move")
    return SlewRates(small_dps, small_steps, rate, large_steps, slope.sigma, source, plateau, agreement)


def read_steps(run: EdgeRun) -> Reading:
    """Any run of command edges no other test claims: a step set.

    Parameters
    ----------
    run : EdgeRun
        Consecutive command edges.

    Returns
    -------
    Reading
        ``steps``.
    """
    jumps = ", ".join(f"{j:+.3g}°" for j in run.jumps[:6])
    return Reading("steps", f"{run.n} step edge(s) of {jumps}{'...' if run.n > 6 else ''}")


def _commanded_edges(ra: RecordAnalysis) -> list[tuple[float, float]]:
    """(time, jump) of every step the metadata's maneuver commands (none without a maneuver)."""
    m = ra.recognition.maneuver
    if m is None or m.kind not in ("step", "steps", "square"):
        return []
    t = ra.data.time_s
    spec = m.command_deg(t - t[0])
    idx = np.flatnonzero(np.diff(spec) != 0.0) + 1
    return [(float(t[i]), float(spec[i] - spec[i - 1])) for i in idx]


def _missing_steps(ra: RecordAnalysis, found: list[StepResponse]) -> None:
    """List under ``not_computed`` every commanded step the command does not show as an edge."""
    rec = ra.recognition
    for when, jump in _commanded_edges(ra):
        seen = any(abs(s.time_s - when) <= 0.2 and np.sign(s.command_step_deg) == np.sign(jump)
                   and abs(abs(s.command_step_deg) - abs(jump)) <= 0.5 * abs(jump) for s in found)
        if not seen:
            ra.not_computed[f"steps: {jump:+g}° at {when:.3f} s"] = (
                "commanded by the metadata's maneuver but not found in the command as an edge between two holds "
                f"(the command counts as held within {rec.command_tolerance_deg:.2g}° and as stepping from "
                f"{rec.edge_threshold_deg:.3g}°)")


def plot_window(ra: RecordAnalysis, r: StepResponse) -> slice:
    """The samples a step's plot shows: up to 1.5 settling times, or the whole hold when the step is unsettled.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.
    r : StepResponse
        The step.

    Returns
    -------
    slice
        From before the edge to where the plot ends (the next edge for an unsettled step: the error left is
        the plot's last samples less the command).
    """
    dt = ra.sample_s()
    if r.against_command is not None and not r.against_command.settled:
        return slice(r.start, r.stop)
    settle = r.settling_s if r.settling_s else 0.4
    return slice(r.start, min(r.stop, r.edge + max(round(1.5 * settle / dt), round(0.3 / dt), 12)))


def _against(s: StepResponse, unit: str) -> str:
    """The step against its commanded level, in a few words."""
    c = s.against_command
    if c is None:
        return "—"
    if c.settled:
        return f"settled in {1e3 * (c.settling_command_s or 0.0):.0f} ms, overshoot {c.overshoot_command_pct:.1f} %"
    state = "still moving" if c.settling_final_s is None else "flat"
    return f"**unsettled** ({state}): {c.error_left:+.3g}{unit} left at the next edge"


class Steps(Section2Test[StepResponse]):
    """Step metrics, fits and slew rates of every edge of the step and square-wave segments."""

    key = "steps"
    title = "Steps"
    kinds = ("steps", "square")
    absent = "no step or square-wave command recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[StepResponse]:
        edges = [e for s in ra.segments(*self.kinds) for e in s.edges]
        out: list[StepResponse] = []
        if edges:
            name, y = ra.primary(("position_deg", "surface_deg"))
            d = ra.data
            rated = ra.channel.slew_rate_dps if d.unit == "deg" and ra.channel.channel == d.metadata.get(
                "channel") else None
            flat = ra.slew.plateau if ra.slew is not None else None
            out = analyze_steps(d.time_s, d.command_deg, y, edges, output=name, noise_floor=ra.noise_deg[name],
                                rated_slew_dps=rated, sampled=ra.command.assumed_sampled,
                                counts=ra.resolution_deg.get(name), plateau_dps=flat.rate if flat else None)
        _missing_steps(ra, out)
        return out

    @override
    def as_json(self, results: list[StepResponse], ra: RecordAnalysis) -> JsonObject:
        return {self.key: [s.as_dict() for s in results],
                "slew_rates": slew_rates(results, ra.slew).as_dict() if results else None}


    @override
    def fits(self, r: StepResponse) -> list[SecondOrderFit]:
        return [r.fit] if r.fit is not None else []

    @override
    def markdown(self, ra: RecordAnalysis, results: list[StepResponse],
                 images: list[str | None]) -> list[str]:
        u = ra.unit
        lines = table(["step", "first motion, ms", "rise 10-90 %, ms", "settling, ms", "overshoot, %",
                       "against the command", f"peak rate, {u.strip()}/s", "rate-limited", "quality"],
                      [[s.label, num(None if s.delay_s is None else 1e3 * s.delay_s, ".2f"),
                        num(None if s.rise_s is None else 1e3 * s.rise_s, ".1f"),
                        num(None if s.settling_s is None else 1e3 * s.settling_s, ".0f"),
                        num(s.overshoot_pct, ".1f"), _against(s, u),
                        f"{s.peak_rate_dps:.1f}", ("yes: " + s.rate_reason) if s.rate_limited else "no",
                        quality(s.quality, "" if s.rate_limited else s.quality_note)] for s in results])
        lines += ["Settling and overshoot are read against the output's own last value (mean of the last 30 % of "
                  "the hold) and, in *against the command*, against the commanded level: a step still outside the "
                  "band about the command at the next edge is unsettled, with the error left.", ""]
        if ra.command.assumed_sampled:
            lines += [f"The command is sampled, not held: first motions are against the sample at which the change "
                      f"was logged; the demand changed up to {1e3 * ra.sample_s():.3g} ms earlier.", ""]
        sr = slew_rates(results, ra.slew)
        sigma = f" ± {sr.large_sigma_dps:.2g}" if sr.large_sigma_dps else ""
        lines += [f"Slew rate: small amplitude {num(sr.small_dps, '.1f', f' {u.strip()}/s')} (steps "
                  f"{', '.join(f'{a:g}{u}' for a in sr.small_steps_deg) or '—'}), large amplitude "
                  f"{num(sr.large_dps, '.1f', f' {u.strip()}/s')}{sigma} (steps "
                  f"{', '.join(f'{a:g}{u}' for a in sr.large_steps_deg) or '—'}; {sr.large_source}"
                  + (f"; {sr.agreement}" if sr.agreement else "")
                  + ("; table 1: 115.8 °/s" if ra.channel_named else "") + ").", ""]
        for s, img in zip(results, images, strict=True):
            lines += image(img, s.label)
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: StepResponse) -> list[str]:
        f = r.fit
        extra = (f"; fit ωn {f.wn_rad_s.value:.2f} ± {f.wn_rad_s.sigma:.2g}, ζ {f.zeta.value:.3f}, delay "
                 f"{1e3 * f.delay_s.value:.2f} ms" if f else f"; {r.fit_note}")
        if f and r.fit_note.startswith("fitted; "):
            extra += f" ({r.fit_note.removeprefix('fitted; ')})"
        flag = "" if r.quality in ("ok", "saturated") else f" [{r.quality}: {r.quality_note}]"
        c = r.against_command
        left = f"; {c.statement}" if c is not None and not c.settled else ""
        return [f"{r.label}: peak rate {r.peak_rate_dps:.1f} °/s{extra}{flag}{left}"]

    @override
    def plot(self, ra: RecordAnalysis, r: StepResponse, path: Path) -> bool:
        d = ra.data
        y = getattr(d, r.output)
        dt = ra.sample_s()
        sl = plot_window(ra, r)
        tt = 1e3 * (d.time_s[sl] - r.time_s)
        fig, ax = figure.pyplot().subplots(2, 1, figsize=(7, 5.2), sharex=True,
                                           gridspec_kw={"height_ratios": [3, 1.3]})
        ax[0].step(tt, d.command_deg[sl], where="post", color=figure.COLORS["command"], lw=0.8, label="command")
        ax[0].plot(tt, y[sl], ".-", ms=2.5, color=figure.COLORS.get(r.output, "tab:blue"), lw=1.0, label=r.output)
        c = r.against_command
        if c is not None:
            ax[0].axhspan(c.commanded - c.band, c.commanded + c.band, color="0.9", zorder=0,
                          label=f"command ± {c.band:.2g} band")
        if r.fit:
            f = r.fit
            model = f.gain.value * simulate(d.command_deg[sl], dt, f.wn_rad_s.value, f.zeta.value, f.delay_s.value) \
                + (f.bias_deg.value if f.bias_deg else 0.0)
            ax[0].plot(tt, model, "k--", lw=0.9, label=f"2nd-order fit ({f.quality})")
            ax[1].plot(tt, y[sl] - model, lw=0.8, color="tab:red")
            ax[1].set_ylabel("residual, deg")
        else:
            ax[1].plot(tt, y[sl] - d.command_deg[sl], lw=0.8, color="tab:red")
            ax[1].set_ylabel("output − command")
        title = r.label + (" (rate-limited)" if r.rate_limited else "")
        if c is not None:
            title += f"\nagainst the command: {c.statement}"
        ax[0].set_title(title, fontsize=8)
        ax[0].set_ylabel("deg")
        ax[1].set_xlabel("ms from the edge")
        ax[0].legend(fontsize=7)
        for a in ax:
            a.grid(lw=0.3)
        figure.save(fig, path)
        return True


TEST = Steps()

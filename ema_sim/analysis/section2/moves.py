"""Profiled moves: a drive's trapezoid demands, held levels joined by constant-speed moves.

Industrial drives and test benches command positions through a profile generator: accelerate,
cruise at a set speed, decelerate, dwell, move again. Such a demand is neither a step (its moves take
time) nor a tone (it dwells). :func:`find_moves` reads it from the command: two consecutive held
levels joined by a monotone transition longer than a step's are a *move* when

* its holds at both ends are deliberate: twice as long as a sine through the same swing in the same
  time would sit still at its turns (while it stays within one count of its peak, ``2·√(2q/A)/ω``,
  and for two samples at least); and
* it cruises: at least 45 % of the move (of 10 samples or more) within 10 % of its top speed (a
  sine's arc between two turning points spends 29 % there, a drive's trapezoid with up to 25 % of
  each move accelerating at least 55 %); or it dwells for at least a quarter of the move at each
  end, the move spanning at least 40 counts.

Per move (:class:`MoveMetrics`): the command's cruise speed and acceleration, the output's
following error while cruising and the lag it means (error / speed), the overshoot past the target,
the settling time after the command arrives, and whether the output kept up with the commanded speed
(``saturated`` when its own rate stays under 95 % of it: the measured slew). Over the whole profile
a second order with delay is fitted to the output (:func:`ema_sim.analysis.estimation.second_order_fit.fit_step`);
slow moves leave ωn and ζ poorly determined, and the fit's quality says so.

:func:`read_ramp` reads a slow monotone moving command (a ramp of section 2.7's kind), which no
figure of this tool applies to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation.quality import Quality
from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit, fit_step, simulate
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, num, quality, table
from ema_sim.analysis.records.series import Hold, settled
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import Move, MoveRun, MovingStretch, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

CRUISE_SHARE = 0.45
MIN_MOVE_SAMPLES = 10
"""Fewer samples in a move tell nothing of a cruise."""
TOP_SPEED = 0.9
DWELL_SHARE = 0.25
MIN_COUNTS = 40
KEEP_UP = 0.95
RAMP_DPS = 1.0
"""A moving command slower than this everywhere is a slow ramp."""


def _speed(t: FloatArray, u: FloatArray, counts: float) -> FloatArray:
    """The command's speed along a move, over a tenth of the move (and at least 20 counts' worth of travel).

    A tenth of the move keeps the scatter of samples taken at jittery instants out of the cruise
    (it blurs a trapezoid's corners by as much, and a sine's arc hardly at all).
    """
    n = u.size
    dt = float(np.median(np.diff(t)))
    mean_step = abs(float(u[-1] - u[0])) / max(n - 1, 1)
    lag = int(np.ceil(0.1 * n))
    if counts > 0 and mean_step > 0:
        lag = max(lag, int(np.ceil(20.0 * counts / mean_step)))
    lag = max(1, min(lag, max(1, n // 4)))
    return np.asarray((u[lag:] - u[:-lag]) / (lag * dt), dtype=float)


def characterise_move(t: FloatArray, u: FloatArray, a: Hold, b: Hold, counts: float, tol: float) -> Move | None:
    """One transition between two holds as a :class:`~ema_sim.analysis.section2.segments.Move`, or None.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    u : numpy.ndarray
        The command.
    a : Hold
        The hold before.
    b : Hold
        The hold after.
    counts : float
        The command's count (0 when continuous).
    tol : float
        How far a held command may wander.

    Returns
    -------
    Move or None
        None when the transition is not a move (see the module docstring).
    """
    lo, hi = a.stop - 1, b.start + 1
    seg = u[lo:hi]
    jump = b.value - a.value
    if seg.size < 4 or jump == 0.0:
        return None
    sign = np.sign(jump)
    if np.any(np.diff(seg) * sign < -2.0 * tol):
        return None  # not monotone
    speed = np.abs(_speed(t[lo:hi], seg, counts))
    top = float(np.max(speed)) if speed.size else 0.0
    if top <= 0.0:
        return None
    cruising = speed >= TOP_SPEED * top
    share = float(np.mean(cruising))
    cruise_speed = float(np.median(speed[cruising]))
    dt = float(np.median(np.diff(t)))
    q = max(counts, tol)
    dwell = min(a.length, b.length) * dt
    move_s = (b.start - a.stop + 1) * dt
    # A sine through the same swing in the same time sits still at its turns while it stays within a count
    # (2·√(2q/A)/ω) and for two samples at least: a dwell is deliberate when it lasts twice that.
    amp, omega = 0.5 * abs(jump), np.pi / move_s
    sine_dwell = 2.0 * np.sqrt(2.0 * q / amp) / omega + 2.0 * dt
    if dwell < 2.0 * sine_dwell:
        return None
    cruises = seg.size >= MIN_MOVE_SAMPLES and share >= CRUISE_SHARE
    long_dwell = dwell >= DWELL_SHARE * move_s and abs(jump) >= MIN_COUNTS * q
    if not (cruises or long_dwell):
        return None
    return Move(a, b, share, cruise_speed)


def find_moves(t: FloatArray, u: FloatArray, holds: list[Hold], *, min_jump: float, max_gap: int, counts: float,
               tol: float) -> list[list[Move]]:
    """Runs of consecutive moves between the command's holds (see the module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    u : numpy.ndarray
        The command.
    holds : list of Hold
        The command's holds, in time order.
    min_jump : float
        The smallest change between two holds that counts.
    max_gap : int
        The longest transition of a step, samples: a move takes longer.
    counts : float
        The command's count (0 when continuous).
    tol : float
        How far a held command may wander.

    Returns
    -------
    list of list of Move
        Each run's moves, consecutive moves sharing their hold.
    """
    runs: list[list[Move]] = []
    for a, b in pairwise(holds):
        if b.start - a.stop <= max_gap or abs(b.value - a.value) < min_jump:
            continue
        m = characterise_move(t, u, a, b, counts, tol)
        if m is None:
            continue
        if runs and runs[-1][-1].after == a:
            runs[-1].append(m)
        else:
            runs.append([m])
    return runs


def read_profile(run: MoveRun) -> Reading:
    """Moves no other test claims (a staircase of them is a calibration): a profiled move sequence.

    Parameters
    ----------
    run : MoveRun
        Consecutive moves of the command.

    Returns
    -------
    Reading
        ``profile`` with the median cruise speed.
    """
    speeds = [m.speed_dps for m in run.moves]
    jumps = ", ".join(f"{m.jump:+.3g}°" for m in run.moves[:6])
    return Reading("profile", f"{run.n} profiled move(s) of {jumps}{'...' if run.n > 6 else ''} at "
                              f"{np.median(speeds):.3g} °/s between held levels (trapezoid demand)",
                   {"speed_dps": float(np.median(speeds))})


def read_ramp(m: MovingStretch) -> Reading | None:
    """A command with at most 3 turning points that never moves faster than 1 °/s: a slow ramp.

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``ramp``, or None.
    """
    if m.turns.size > 3:
        return None
    rate = np.abs(np.diff(m.u)) / m.dt
    fast = float(np.percentile(rate, 99)) if rate.size else 0.0
    if fast >= RAMP_DPS:
        return None
    return Reading("ramp", f"slow monotone command (≤ {fast:.3g} °/s, {m.turns.size} turning point(s))")


@dataclass(frozen=True)
class MoveMetrics:
    """How the output followed one profiled move.

    Parameters
    ----------
    start_s : float
        When the command left its old level, s.
    end_s : float
        When the command left its old level and when it reached the new one, s.
    jump_deg : float
        The move, deg.
    speed_dps : float
        The command's cruise speed, deg/s.
    accel_dps2 : float or None
        The command's acceleration, deg/s².
    following_error_deg : float or None
        Command minus output while cruising (median), in the direction of the move.
    lag_s : float or None
        Following error over speed, s.
    output_rate_dps : float or None
        The output's own speed while the command cruises (slope through the cruise).
    overshoot_pct : float or None
        Overshoot past the target, % of the move.
    settling_s : float or None
        After the command reached its new level.
    saturated : bool
        The output could not keep up with the commanded speed.
    """

    start_s: float
    end_s: float
    """When the command left its old level and when it reached the new one, s."""
    jump_deg: float
    speed_dps: float
    accel_dps2: float | None
    following_error_deg: float | None
    """Command minus output while cruising (median), in the direction of the move."""
    lag_s: float | None
    output_rate_dps: float | None
    """The output's own speed while the command cruises (slope through the cruise)."""
    overshoot_pct: float | None
    settling_s: float | None
    """After the command reached its new level."""
    saturated: bool

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The move's command and response figures.
        """
        return {"start_s": self.start_s, "end_s": self.end_s, "jump_deg": self.jump_deg, "speed_dps": self.speed_dps,
                "accel_dps2": self.accel_dps2, "following_error_deg": self.following_error_deg, "lag_s": self.lag_s,
                "output_rate_dps": self.output_rate_dps, "overshoot_pct": self.overshoot_pct,
                "settling_s": self.settling_s, "saturated": self.saturated}


@dataclass(frozen=True)
class ProfileResult:
    """The profiled moves of one segment, and a second order fitted over them.

    Parameters
    ----------
    output : str
        Name of the output.
    start : int
        First sample of the segment.
    stop : int
        One past the last sample.
    moves : list
        Every move's figures.
    fit : SecondOrderFit or None
        Second order fitted over the profile.
    notes : list
        Notes.
    """

    output: str
    start: int
    stop: int
    moves: list[MoveMetrics]
    fit: SecondOrderFit | None
    notes: list[str] = field(default_factory=list)

    @property
    def quality(self) -> Quality:
        """``saturated`` when a move outran the output, else the fit's."""
        if any(m.saturated for m in self.moves):
            return "saturated"
        return self.fit.quality if self.fit else "not_determined"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        sat = [m for m in self.moves if m.saturated]
        if sat:
            m = sat[0]
            return (f"{len(sat)} move(s) outran the output: {m.output_rate_dps:.3g} °/s against "
                    f"{m.speed_dps:.3g} °/s commanded")
        return self.fit.quality_note if self.fit else "no fit"

    @property
    def lag_s(self) -> float | None:
        """Median lag over the moves that kept up."""
        lags = [m.lag_s for m in self.moves if m.lag_s is not None and not m.saturated]
        return float(np.median(lags)) if lags else None

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Every move, the median lag, the fit, quality and notes.
        """
        return {"output": self.output, "moves": [m.as_dict() for m in self.moves], "lag_s": self.lag_s,
                "second_order_fit": self.fit.as_dict() if self.fit else None, "quality": self.quality,
                "quality_note": self.quality_note, "notes": [*self.notes]}


def move_metrics(t: FloatArray, u: FloatArray, y: FloatArray, move: Move, noise: float,
                 counts: float | None) -> MoveMetrics:
    """The output's response to one move (see :class:`MoveMetrics`).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    u : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.
    move : Move
        The move.
    noise : float
        The output's noise floor.
    counts : float or None
        The output's count.

    Returns
    -------
    MoveMetrics
        The figures.
    """
    dt = float(np.median(np.diff(t)))
    a, b = move.before, move.after
    sign = float(np.sign(move.jump))
    lo, hi = a.stop, b.start
    speed = np.abs(np.gradient(u[lo - 1:hi + 1], dt))[1:-1]
    cruise = np.flatnonzero(speed >= TOP_SPEED * move.speed_dps) + lo
    accel = None
    if cruise.size:
        t_acc = float(t[cruise[0]] - t[lo - 1])
        accel = move.speed_dps / t_acc if t_acc > dt else None
    err = lag = rate = None
    saturated = False
    if cruise.size >= 3:
        err = float(np.median((u[cruise] - y[cruise]) * sign))
        lag = err / move.speed_dps
        rate = float(abs(np.polyfit(t[cruise], y[cruise], 1)[0]))
        saturated = rate < KEEP_UP * move.speed_dps and err > 0.0
    final, _ = settled(y, b.start, b.stop, 0.3)
    after = (y[b.start:b.stop] - final) * sign
    overshoot = float(max(0.0, np.max(after)) / abs(move.jump) * 100.0) if after.size else None
    band = max(0.02 * abs(move.jump), 4.0 * noise, 1.5 * (counts or 0.0))
    outside = np.flatnonzero(np.abs(y[b.start:b.stop] - final) > band)
    settling = None
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] + 1 < b.stop - b.start:
        settling = float(t[b.start + outside[-1] + 1] - t[b.start])
    return MoveMetrics(float(t[lo]), float(t[hi]), move.jump, move.speed_dps, accel, err, lag, rate, overshoot,
                       settling, saturated)


class Profiles(Section2Test[ProfileResult]):
    """How the output follows each sequence of profiled moves."""

    key = "profiled_moves"
    title = "Profiled moves (trapezoid demands)"
    kinds = ("profile",)
    absent = "no profiled moves (held levels joined by constant-speed moves) recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[ProfileResult]:
        data, t = ra.data, ra.data.time_s
        name, y = ra.primary(("position_deg", "surface_deg"))
        noise, counts = ra.noise_deg[name], ra.resolution_deg.get(name)
        out = []
        for seg in ra.segments(*self.kinds):
            moves = [m for m in seg.moves if isinstance(m, Move)]
            rows = [move_metrics(t, data.command_deg, y, m, noise, counts) for m in moves]
            sl = slice(seg.start, seg.stop)
            notes: list[str] = []
            fit = None
            if np.ptp(y[sl]) > 10.0 * noise:
                fit = fit_step(t[sl], data.command_deg[sl], y[sl], test=f"profiled moves at {t[seg.start]:.2f} s",
                               output_name=name, wn0=min(50.0, 0.5 * np.pi / ra.sample_s()),
                               sampled=ra.command.assumed_sampled)
            else:
                notes.append("the output moves less than ten times its noise: no fit")
            if ra.command.assumed_sampled:
                notes.append("the command is sampled, not held: lags and the fitted delay are against the logged "
                              "samples")
            out.append(ProfileResult(name, seg.start, seg.stop, rows, fit, notes))
        return out


    @override
    def fits(self, r: ProfileResult) -> list[SecondOrderFit]:
        return [r.fit] if r.fit is not None else []

    @override
    def markdown(self, ra: RecordAnalysis, results: list[ProfileResult],
                 images: list[str | None]) -> list[str]:
        u = ra.unit
        v = f"{u.strip()}/s"
        lines: list[str] = []
        for p, img in zip(results, images, strict=True):
            t = ra.data.time_s
            lines += [f"**{len(p.moves)} move(s), {t[p.start]:.2f}-{t[p.stop - 1]:.2f} s, on {p.output}**; quality "
                      f"{quality(p.quality, p.quality_note)}.", ""]
            lines += table(["from, s", "move", f"speed, {v}", f"accel, {v}²", "following error", "lag, ms",
                            f"output rate, {v}", "overshoot, %", "settling, ms", "kept up"],
                           [[f"{m.start_s:.3f}", f"{m.jump_deg:+.4g}{u}", f"{m.speed_dps:.4g}",
                             num(m.accel_dps2, ".4g"), num(m.following_error_deg, ".4g", u),
                             num(None if m.lag_s is None else 1e3 * m.lag_s, ".1f"), num(m.output_rate_dps, ".4g"),
                             num(m.overshoot_pct, ".1f"), num(None if m.settling_s is None else 1e3 * m.settling_s,
                                                              ".0f"),
                             "no (saturated)" if m.saturated else "yes"] for m in p.moves])
            if p.fit:
                f = p.fit
                lines += [f"Second order over the profile: ωn {f.wn_rad_s.value:.4g} ± {f.wn_rad_s.sigma:.2g} rad/s, "
                          f"ζ {f.zeta.value:.3f} ± {f.zeta.sigma:.2g}, delay {1e3 * f.delay_s.value:.2f} ± "
                          f"{1e3 * f.delay_s.sigma:.2g} ms, RMS {f.rms:.3g}{u}; quality "
                          f"{quality(f.quality, f.quality_note)}.", ""]
            lines += bullets(p.notes)
            lines += image(img, "profiled moves")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: ProfileResult) -> list[str]:
        lag = "—" if r.lag_s is None else f"{1e3 * r.lag_s:.1f} ms"
        flag = "" if r.quality == "ok" else f" [{r.quality}: {r.quality_note}]"
        return [f"profiled moves: {len(r.moves)} move(s), lag {lag}{flag}"]

    @override
    def plot(self, ra: RecordAnalysis, r: ProfileResult, path: Path) -> bool:
        d = ra.data
        sl = slice(r.start, r.stop)
        t = d.time_s[sl]
        u = d.command_deg[sl]
        y = getattr(d, r.output)[sl]
        model = None
        if r.fit is not None:
            f = r.fit
            model = f.gain.value * simulate(u, ra.sample_s(), f.wn_rad_s.value, f.zeta.value, f.delay_s.value) + (
                f.bias_deg.value if f.bias_deg else 0.0)
        fig, ax = figure.pyplot().subplots(3, 1, figsize=(10, 8), gridspec_kw={"height_ratios": [2.2, 1, 2.2]})
        ax[0].plot(t, u, color=figure.COLORS["command"], lw=0.8, label="command")
        ax[0].plot(t, y, color=figure.COLORS.get(r.output, "tab:blue"), lw=0.8, label=r.output)
        resid = y - (model if model is not None else u)
        if model is not None:
            ax[0].plot(t, model, "k--", lw=0.7, label="2nd-order fit")
        ax[1].plot(t, resid, color="tab:red", lw=0.6)
        ax[1].set_ylabel("residual" if model is not None else "output − command")
        zoom = figure.zoom_window(t, resid, min(max(6 * ra.sample_s() * 10, 0.5), 0.25 * float(t[-1] - t[0])))
        ax[2].step(t[zoom], u[zoom], where="post", color=figure.COLORS["command"], lw=0.9, label="command")
        ax[2].plot(t[zoom], y[zoom], ".-", ms=3, color=figure.COLORS.get(r.output, "tab:blue"), lw=0.8,
                   label=r.output)
        if model is not None:
            ax[2].plot(t[zoom], model[zoom], "k--", lw=0.8, label="fit")
        ax[2].set_title("zoom: where the residual is largest", fontsize=9)
        ax[0].set_title(f"profiled moves on {r.output}: quality {r.quality}", fontsize=9)
        for a in (ax[0], ax[2]):
            a.legend(fontsize=7)
        for a in ax:
            a.grid(lw=0.3)
        ax[2].set_xlabel("time, s")
        figure.save(fig, path)
        return True


TEST = Profiles()

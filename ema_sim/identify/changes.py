"""A record that changed, said so: the final model's parameters fitted on parts of the record, and their trend.

One model fitted to a whole record is an average. When the actuator changed while it was recorded (a
winding that heats and loses gain, a fieldbus whose delay wanders), that average fits no part of the
record well, the error left is far above the floor, and the search takes in whatever effect absorbs
some of the change (a rate limit that slows the fast moves the early, faster part makes). So, once the
model is chosen:

1. **Windows of the record's own excitation.** A command that repeats (the autocorrelation of the
   command has a peak of at least :data:`PERIODIC` at a lag of :data:`MIN_WINDOW_S` or more) is cut at
   its period, each window one or more whole periods (at most :data:`MAX_WINDOWS`), so that every window
   carries the same excitation and differs only in time; any other record in :data:`PLAIN_WINDOWS` equal
   parts. Each cut is moved to the end of the longest rest of the command near it, and each window's fit
   runs its model from up to :data:`LEAD_S` before the cut, on the samples before it, not fitted.
   A window fits only the samples the whole record fits: what the record's mask leaves out (a dropout, a
   spike) is left out of every window too.
2. **The final model's parameters refitted on each window** with identification's own fit
   (:func:`ema_sim.identify.stepwise.fit_model`), from the final values, each with an uncertainty that covers
   the model's misfit as well as the noise (:func:`ema_sim.identify.window_sigma.window_sigmas`: a model that
   lacks structure gives windows of unlike excitation unlike equivalents, not a changed actuator). Whether a
   parameter **changes**, and its **trend** (falls, grows or wanders), is decided by
   :func:`ema_sim.analysis.estimation.trend.trend`, the same test ``ema analyze`` applies to a periodic test's
   cycles; a value on its search's bound does not vote, nor does one found by a grid search (Kb and offset
   behind a quantizer): its ± is the grid's finest spacing, a resolution, not a σ, so it is said to be
   untested. The report gives the value per window, not one equivalent for the whole.
3. **No proxy for the change.** With a parameter changing, each effect the search added is tested as the
   record allows: the windows refitted without it. When the windows, each with its own parameters, do
   not need it (their summed ΔBIC does not reach :data:`~ema_sim.identify.criteria.MAX_DELTA_BIC`), the
   effect only helped the whole-record fit because of the change: it is taken out, and said so. The windows
   are refitted without it largest error first, and no further once those fitted already leave so much that the
   summed ΔBIC cannot get above that bound (:func:`refit_without`; the report says after how many).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.trend import MIN_CHANGE, Trend, trend
from ema_sim.identify.criteria import MAX_DELTA_BIC
from ema_sim.identify.effects import BY_KEY, FREE, KEYS, Effect
from ema_sim.identify.fit import TINY, Fit
from ema_sim.identify.grid_fit import fit_model, no_worse
from ema_sim.identify.outcome import Identification, Removal, Step
from ema_sim.identify.parallel import SERIAL, Pool, one_blas_thread
from ema_sim.identify.parallel import result as value_of
from ema_sim.identify.problem import SETTLE_S, Cancelled, Problem
from ema_sim.identify.stepwise import offs
from ema_sim.identify.trust import bandwidth_hz
from ema_sim.identify.window_sigma import grid_searched, window_sigmas
from ema_sim.io.measured import MeasuredData
from ema_sim.jsontypes import JsonObject
from ema_sim.models.second_order import SecondOrderParams

FloatArray = NDArray[np.float64]
_TESTS = itertools.count()
"""Window fits of the proxy tests, for their cancellation tokens."""
MIN_WINDOW_S = 5.0
"""The shortest window fitted (and the shortest period of a repeating command taken as one)."""
MAX_WINDOWS = 8
PLAIN_WINDOWS = 4
"""Windows of a record whose command does not repeat (halves for one shorter than four of :data:`MIN_WINDOW_S`)."""
PERIODIC = 0.9
"""Normalised autocorrelation of the command at its period for it to count as repeating."""
LEAD_S = 0.5
"""A window's model runs from this much before its first fitted sample (within the rest before it)."""
SNAP_SHARE = 0.25
"""A cut moves to the end of the longest rest of the command within this share of a window around it."""
LABELS = {"wn_rad_s": "ωn (wn_rad_s)", "zeta": "ζ (zeta)", "delay_s": "the command delay (delay_s)",
          "feedback_delay_s": "the feedback delay (feedback_delay_s)"}
"""How a parameter is named in the statements (the vocabulary's report name otherwise)."""
DISPLAY = {"delay_s": (1e3, "ms"), "feedback_delay_s": (1e3, "ms"), "wn_rad_s": (1.0, "rad/s")}
"""Parameters shown in another unit than the model's: factor and unit."""


@dataclass(frozen=True)
class Window:
    """One part of the record: its fitted samples, and where its model starts running."""

    lead: int
    """Index of the first sample the window's model runs from (not fitted before :attr:`start`)."""
    start: int
    end: int
    """One past the last sample."""
    start_s: float
    end_s: float
    alike: bool = False
    """Every window carries the same excitation (a period of a repeating command)."""


@dataclass
class WindowFit:
    """The fits of one model on every window."""

    free: tuple[str, ...]
    fits: list[Fit]
    n: int
    """Residual entries over all windows."""

    @property
    def rss(self) -> float:
        """Summed weighted residual over the windows."""
        return float(sum(f.rss for f in self.fits))

    @property
    def parameters(self) -> int:
        """Parameters fitted over all windows."""
        return len(self.free) * len(self.fits)


@dataclass(frozen=True)
class Track(Trend):
    """One parameter across the windows (its values, one per window), and what they say."""

    name: str

    def statement(self, bandwidths: tuple[float, ...] = ()) -> str:
        """The track in words: per-window values with ±1σ, the fitted slope or the range.

        Parameters
        ----------
        bandwidths : tuple[float, ...]
            The bandwidth per window, Hz (said beside ωn), empty when not measured.
        """
        k, unit = DISPLAY.get(self.name, (1.0, ""))
        u = f" {unit}" if unit else ""
        label = LABELS.get(self.name, KEYS[self.name].name if self.name in KEYS else self.name)
        per = ", ".join(f"{k * v:.4g} ± {k * s:.2g}" for v, s in zip(self.values, self.sigma, strict=True))
        if not self.changed:
            return (f"{label} holds over the record: {per}{u} on {len(self.values)} windows "
                    f"(χ² {self.chi2:.3g} on {self.dof} degrees of freedom)")
        span = self.times_s[-1] - self.times_s[0] if len(self.times_s) > 1 else 0.0
        mean = float(np.mean(self.values))
        if self.kind == "wanders":
            how = (f"wanders between {k * min(self.values):.4g} and {k * max(self.values):.4g}{u} (not a straight "
                   f"trend: the line through the windows leaves most of their spread)")
        else:
            total = self.slope_per_s * span
            how = (f"{self.kind} from {k * self.values[0]:.4g}{u} to {k * self.values[-1]:.4g}{u} (fitted slope "
                   f"{k * self.slope_per_s:+.3g} ± {k * self.slope_sigma:.2g}{u} per s, "
                   f"{100 * total / mean if mean else 0.0:+.0f} % over {span:.3g} s)")
        text = (f"{label} changes over the record beyond its uncertainty: it {how}; per window of the record "
                f"{per}{u} (χ² {self.chi2:.3g} on {self.dof} degrees of freedom, p {self.p_value:.2g})")
        if bandwidths and self.name in ("wn_rad_s", "zeta"):
            text += (f"; the servo's bandwidth per window {', '.join(f'{b:.3g}' for b in bandwidths)} Hz "
                     f"({'falls' if bandwidths[-1] < bandwidths[0] else 'grows'} from {bandwidths[0]:.3g} to "
                     f"{bandwidths[-1]:.3g} Hz)")
        return text

    def as_dict(self) -> JsonObject:
        """Plain values for JSON."""
        return {"parameter": self.name, "trend": self.kind, "values": list(self.values), "sigma": list(self.sigma),
                "window_mid_s": list(self.times_s), "chi2": self.chi2, "dof": self.dof, "p_value": self.p_value,
                "slope_per_s": self.slope_per_s, "slope_sigma_per_s": self.slope_sigma}


@dataclass
class Changes:
    """What the windowed refits found (module docstring)."""

    windows: list[Window] = field(default_factory=list)
    how: str = ""
    """How the windows were cut, in words."""
    tracks: list[Track] = field(default_factory=list)
    bandwidth_hz: tuple[float, ...] = ()
    """The final model's linear bandwidth on each window."""
    rms_over_noise: dict[str, float] = field(default_factory=dict)
    """Each output's rms over its floor with the parameters fitted per window (the whole record's model for
    comparison is the final one)."""
    statements: list[str] = field(default_factory=list)
    proxies: list[str] = field(default_factory=list)
    """Effects taken out because they only stood in for the change, one line each."""
    skipped: str = ""
    tests: list[ProxyTest] = field(default_factory=list)
    """Each added effect tested on the windows with their own parameters (when a parameter changes)."""

    @property
    def changed(self) -> bool:
        """Some parameter changes over the record."""
        return any(t.changed for t in self.tracks)

    @property
    def warnings(self) -> list[str]:
        """The lines a reader must not miss: the trends and the proxies taken out."""
        return [t.statement(self.bandwidth_hz) for t in self.tracks if t.changed] + self.proxies

    def as_dict(self) -> JsonObject:
        """Plain values for JSON."""
        return {"changed": self.changed, "how": self.how, "skipped": self.skipped or None,
                "windows_s": [[w.start_s, w.end_s] for w in self.windows],
                "parameters": [t.as_dict() for t in self.tracks],
                "bandwidth_hz": list(self.bandwidth_hz), "rms_over_noise_windowed": {**self.rms_over_noise},
                "proxies_removed": [*self.proxies], "proxy_tests": [t.as_dict() for t in self.tests],
                "statements": [*self.statements]}


# ------------------------------------------------------------------------------------------ windows
def period_s(time_s: FloatArray, command: FloatArray) -> float | None:
    """The command's period when it repeats (module docstring), else None.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s.
    command : numpy.ndarray
        The command.

    Returns
    -------
    float or None
        The period, s.
    """
    u = command - float(np.mean(command))
    n = u.size
    dt = float(time_s[-1] - time_s[0]) / max(n - 1, 1)
    if n < 8 or not np.any(u) or dt <= 0.0:
        return None
    spec = np.fft.rfft(u, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[:n]
    norm = acf / np.maximum(acf[0] * (n - np.arange(n)) / n, TINY)  # unbiased: each lag over its overlap
    lo, hi = math.ceil(MIN_WINDOW_S / dt), n // 2
    if hi <= lo:
        return None
    above = np.flatnonzero(norm[lo:hi] >= PERIODIC)
    if above.size == 0:
        return None
    # the first run of lags above the threshold holds the period (its multiples come later, as high)
    run = above[: int(np.argmax(np.diff(above) > 1)) + 1] if np.any(np.diff(above) > 1) else above
    k = lo + int(run[np.argmax(norm[lo + run])])
    return float(k * dt)


def _rest_end(command: FloatArray, near: int, reach: int) -> tuple[int, int]:
    """The end of the longest rest of the command within ``reach`` samples of ``near``, and the rest's length."""
    lo, hi = max(1, near - reach), min(command.size - 1, near + reach)
    if hi <= lo:
        return near, 0
    moving = np.flatnonzero(np.diff(command[lo - 1:hi + 1]) != 0.0) + lo  # a sample where a new level starts
    edges = np.concatenate([[lo], moving, [hi]])
    lengths = np.diff(edges)
    k = int(np.argmax(lengths))
    return int(edges[k + 1]), int(lengths[k])


def windows(problem: Problem) -> tuple[list[Window], str]:
    """The windows the final model is refitted on, and how they were cut (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.

    Returns
    -------
    tuple
        The windows (empty: the record is too short for two) and a sentence.
    """
    t = problem.time_s
    u = problem.data.command_deg
    first = int(np.argmax(problem.mask))
    span = float(t[-1] - t[first])
    dt = span / max(t.size - first - 1, 1)
    period = period_s(t[first:], u[first:])
    if period is not None:
        periods = int(span // period)
        per = max(1, math.ceil(periods / MAX_WINDOWS))
        length = per * period
        # every cut at one phase of the period: the end of the command's longest rest in the first period
        rest_end, _ = _rest_end(u, first + round(0.5 * period / dt), round(0.5 * period / dt))
        starts = [float(t[rest_end]) + k * length for k in range(periods)]
        starts = [s for s in starts if s + length <= t[-1] + 0.5 * dt]
        how = (f"the command repeats every {period:.3g} s: windows of {per} period{'s' if per > 1 else ''} "
               f"({length:.3g} s) each, the same excitation in each")
        cuts = [int(np.searchsorted(t, s - 0.5 * dt)) for s in starts]
        if cuts:
            cuts.append(min(int(np.searchsorted(t, starts[-1] + length - 0.5 * dt)), t.size))
    else:
        count = PLAIN_WINDOWS if span >= PLAIN_WINDOWS * MIN_WINDOW_S else 2
        length = span / count
        how = f"the command does not repeat: {count} parts of about {length:.3g} s, cut where it rests"
        reach = round(SNAP_SHARE * length / dt)
        cuts = [first] + [_rest_end(u, int(np.searchsorted(t, t[first] + k * length)), reach)[0]
                          for k in range(1, count)] + [t.size]
    if period is not None and len(cuts) < 3:  # a period too long for two windows: equal parts instead
        count = PLAIN_WINDOWS if span >= PLAIN_WINDOWS * MIN_WINDOW_S else 2
        length = span / count
        how = f"the command repeats every {period:.3g} s, longer than half the record: {count} parts of {length:.3g} s"
        reach = round(SNAP_SHARE * length / dt)
        cuts = [first] + [_rest_end(u, int(np.searchsorted(t, t[first] + k * length)), reach)[0]
                          for k in range(1, count)] + [t.size]
        period = None  # parts, not periods: unlike excitation
    if len(cuts) < 3 or length < MIN_WINDOW_S:
        return [], f"the record ({span:.3g} s fitted) is too short for two windows of {MIN_WINDOW_S:g} s"
    lead = round(LEAD_S / dt)
    out = []
    for a, b in itertools.pairwise(cuts):
        if b - a < 10:
            continue
        start = a if a <= first else max(0, a - lead)
        out.append(Window(0 if a <= first else start, a, b, float(t[a]), float(t[b - 1]), period is not None))
    return (out, f"{how}: {len(out)} windows") if len(out) >= 2 else ([], "the record's windows are too short")


def _sub(data: MeasuredData, a: int, b: int) -> MeasuredData:
    """Samples ``a`` to ``b`` of a record (every per-sample column)."""
    changes: dict[str, Any] = {}
    for f in fields(data):
        value = getattr(data, f.name)
        if isinstance(value, np.ndarray) and value.shape[:1] == data.time_s.shape:
            changes[f.name] = value[a:b]
    changes["extra"] = {k: v[a:b] for k, v in data.extra.items()}
    return replace(data, **changes)


def window_problem(problem: Problem, w: Window) -> Problem:
    """The record's window as a problem of its own: same noise floors, command timing, sensor range and stamps.

    Parameters
    ----------
    problem : Problem
        The whole record.
    w : Window
        The window.

    Returns
    -------
    Problem
        Fitted on the window's samples that the record fits (its mask), its model run from :attr:`Window.lead`.
    """
    t = problem.time_s
    settle = float(t[w.start] - t[w.lead]) if w.lead < w.start else problem.settle_s
    sub = Problem(_sub(problem.data, w.lead, w.end), problem.channel, step_s=problem.step_s,
                  settle_s=settle if settle > 0.0 else SETTLE_S, noise=problem.noise,
                  command_sampled=problem.command_sampled, output_range=dict(problem.output_range))
    sub.mask &= problem.mask[w.lead:w.end]  # what the record leaves out of its fit, every window leaves out
    if problem.timing_s > 0.0:
        sub.set_timing(problem.timing_s, {o: r[w.lead:w.end] for o, r in problem.timing_rates.items()})
    return sub


def fit_window(sub: Problem, params: SecondOrderParams, free: tuple[str, ...], flip: bool, token: str = ""
               ) -> Fit | None:
    """``free`` of ``params`` fitted on one window (never worse than at ``params``), with one BLAS thread.

    Parameters
    ----------
    sub : Problem
        The window (:func:`window_problem`).
    params : SecondOrderParams
        The start.
    free : tuple of str
        The parameters fitted.
    flip : bool
        Run with the hinge moment reversed.
    token : str
        What the fit is stopped by (:meth:`Problem.cancel`): then None.
    """
    try:
        with one_blas_thread(), sub.tally(token):
            return no_worse(sub, params, free, fit_model(sub, params, free, flip=flip))
    except Cancelled:
        return None


def fit_windows(subs: list[Problem], params: SecondOrderParams, free: tuple[str, ...], flip: bool,
                pool: Pool = SERIAL) -> WindowFit:
    """``free`` of ``params`` fitted on every window (never worse than at ``params``), on ``pool``'s workers at once.

    Parameters
    ----------
    subs : list of Problem
        The windows (:func:`window_problem`).
    params : SecondOrderParams
        The start (everything not fitted stays as here).
    free : tuple of str
        The parameters fitted.
    flip : bool
        Run with the hinge moment reversed.
    pool : Pool
        Where the windows' fits run (each independent of the others: the same fits wherever they run).

    Returns
    -------
    WindowFit
        One fit per window.
    """
    pending = [pool.submit(fit_window, sub, params, free, flip) for sub in subs]
    fits = [value_of(f) for f in pending]
    assert all(f is not None for f in fits)  # only a token stops a window's fit, and none was given
    return WindowFit(free, fits, sum(sub.n_fit for sub in subs))


@dataclass(frozen=True)
class ProxyTest:
    """One added effect tested on the windows: what its ΔBIC came to, and how many windows that took."""

    effect: str
    delta_bic: float
    """Over all windows; with :attr:`fitted` short of :attr:`windows`, the bound the fitted ones already set."""
    fitted: int
    windows: int
    elapsed_s: float

    @property
    def needed(self) -> bool:
        """The windows need the effect (it is kept)."""
        return self.delta_bic <= MAX_DELTA_BIC

    def as_dict(self) -> JsonObject:
        """Plain values for JSON."""
        stopped = (f"stopped after {self.fitted} of {self.windows} windows: those alone leave more without the "
                   f"effect than the windows with it leave on all {self.windows}, so its ΔBIC is at most "
                   f"{self.delta_bic:+.1f} whatever the others give" if self.fitted < self.windows else None)
        return {"effect": self.effect, "delta_bic": self.delta_bic, "windows_fitted": self.fitted,
                "windows": self.windows, "elapsed_s": round(self.elapsed_s, 3), "stopped_early": stopped}


def refit_without(subs: list[Problem], params: SecondOrderParams, free: tuple[str, ...], flip: bool, with_: WindowFit,
                  pool: Pool = SERIAL) -> tuple[WindowFit | None, float, int]:
    """The windows refitted with ``free`` only, stopped once the ones fitted show the effect is needed.

    The ΔBIC of the model with the effect against the one without falls as the error without it grows, and the
    windows not yet fitted can add no less than nothing to that error: once the windows fitted leave, without the
    effect, so much that the ΔBIC is at most :data:`~ema_sim.identify.criteria.MAX_DELTA_BIC` even with nothing on
    the rest, the effect is needed whatever they give, and they are not fitted. The windows are fitted in the
    order of the error the effect's absence leaves at the start (one run each), largest first, as many at once as
    ``pool`` has workers; the bound is checked after each in that order, so the answer and the count said are the
    same wherever they ran.

    Parameters
    ----------
    subs : list of Problem
        The windows (:func:`window_problem`).
    params : SecondOrderParams
        The start: the final model with the effect switched off.
    free : tuple of str
        The parameters fitted without the effect.
    flip : bool
        Run with the hinge moment reversed.
    with_ : WindowFit
        The windows' fits with the effect.
    pool : Pool
        Where the windows' fits run.

    Returns
    -------
    tuple
        The windows' fits without it (None when stopped early), the ΔBIC (its bound when stopped early) and
        the windows fitted.
    """
    starts = []
    for sub in subs:
        r = sub.weighted_residual(sub.simulate([params], [flip])[0])
        starts.append(float(np.dot(r, r)))
    order = sorted(range(len(subs)), key=lambda k: -starts[k])
    q = (len(with_.free) - len(free)) * len(subs)
    n = with_.n
    fits: dict[int, Fit] = {}
    batch = max(1, pool.workers) if pool.enabled else 1
    for first in range(0, len(order), batch):
        chunk = order[first:first + batch]
        tokens = {k: f"without/{next(_TESTS)}" for k in chunk}
        pending = {k: pool.submit(fit_window, subs[k], params, free, flip, tokens[k]) for k in chunk}
        for k, future in pending.items():
            fit = value_of(future)
            assert fit is not None  # cancelled only after the loop stopped taking fits
            fits[k] = fit
            if len(fits) == len(subs):
                break
            least = sum(f.rss for f in fits.values())  # the windows left add at least nothing
            bound = n * math.log(max(with_.rss, TINY) / max(least, TINY)) + q * math.log(max(n, 2))
            if bound <= MAX_DELTA_BIC:
                for j in chunk:  # the batch's fits still running stop at their next simulation
                    if j not in fits:
                        subs[j].cancel(tokens[j])
                return None, bound, len(fits)
    without = WindowFit(free, [fits[k] for k in range(len(subs))], n)
    return without, _pays(without, with_), len(subs)


def track(name: str, wf: WindowFit, ws: list[Window], subs: list[Problem]) -> Track:
    """One parameter across the windows, and its trend (:func:`ema_sim.analysis.estimation.trend.trend`).

    Parameters
    ----------
    name : str
        The model parameter.
    wf : WindowFit
        The windows' fits.
    ws : list of Window
        The windows.
    subs : list of Problem
        The windows as fitted (:func:`window_problem`).

    Returns
    -------
    Track
        Its values, uncertainty (:func:`~ema_sim.identify.window_sigma.window_sigmas`) and trend; ``not
        determined`` for a grid-searched one (its ± a resolution: no test of a change can be built on it).
    """
    values = np.array([float(getattr(f.params, name)) for f in wf.fits])
    sigma = np.array(window_sigmas(subs, wf.fits, name, all(w.alike for w in ws)))
    times = np.array([0.5 * (w.start_s + w.end_s) for w in ws])
    free = FREE.get(name)
    bounded = np.array([free is not None and (v <= free.low + 1e-6 * (free.high - free.low)
                                              or v >= free.high - 1e-6 * (free.high - free.low)) for v in values])
    grid = np.array([grid_searched(f.params, name) for f in wf.fits])
    tr = trend(values, sigma, times, usable=~bounded & ~grid)
    return Track(**{f.name: getattr(tr, f.name) for f in fields(tr)}, name=name)


# ------------------------------------------------------------------------------------------ the stage
def _pays(without: WindowFit, with_: WindowFit) -> float:
    """ΔBIC of ``with_`` against ``without`` over all windows (each window its own parameters)."""
    n = with_.n
    q = with_.parameters - without.parameters
    return n * math.log(max(with_.rss, TINY) / max(without.rss, TINY)) + q * math.log(max(n, 2))


def analyse(problem: Problem, result: Identification, declared: SecondOrderParams,
            say: Callable[[str], None] = lambda _m: None, pool: Pool = SERIAL) -> Changes:
    """Refit the final model on windows of the record, report what changes, take out what stood in for it.

    ``result.final``, ``steps`` and ``removed`` change when an effect is taken out (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        The identification so far (its final model is the vocabulary's: the declared model and its effects).
    declared : SecondOrderParams
        The declared model's starting values (an effect's off value where it has none).
    say : callable
        Progress lines.
    pool : Pool
        The identification's workers: the windows' fits and the proxy tests' refits run on them.

    Returns
    -------
    Changes
        The windows, each parameter's track, the proxies taken out.
    """
    out = Changes()
    final = result.final
    if result.final_model or result.physical is not None or not final.free:
        out.skipped = "the final model has no vocabulary parameters to refit on parts of the record"
        return out
    ws, how = windows(problem)
    out.how = how
    if not ws:
        out.skipped = how
        return out
    out.windows = ws
    subs = [window_problem(problem, w) for w in ws]
    cur = fit_windows(subs, final.params, final.free, final.flip, pool)
    out.tracks, ridge = _on_the_ridge([track(f, cur, ws, subs) for f in final.free], cur)
    say(f"changes: {how}; " + ", ".join(f"{t.name} {t.kind}" for t in out.tracks))
    if out.changed:
        cur = _proxies(problem, result, declared, subs, cur, out, say, pool)
        out.tracks, ridge = _on_the_ridge([track(f, cur, ws, subs) for f in result.final.free], cur)
    out.bandwidth_hz = tuple(bandwidth_hz(f.params) for f in cur.fits)
    out.rms_over_noise = {
        o: float(np.sqrt(sum(float(np.sum(sub.errors_deg(f.sim)[o] ** 2)) for sub, f in zip(subs, cur.fits,
                                                                                              strict=True))
                         / sum(int(sub.mask.sum()) for sub in subs))) / problem.sigma_deg[o]
        for o in problem.outputs}
    changed = [t for t in out.tracks if t.changed]
    if changed:
        out.statements = [t.statement(out.bandwidth_hz) for t in changed]
        out.statements.append(
            f"the record changed while it was logged: one set of parameters is an equivalent of the whole that fits "
            f"no part of it; with them fitted per window ({how}) the error is "
            f"{', '.join(f'{o} {v:.3g}×' for o, v in out.rms_over_noise.items())} the noise floor")
    else:
        out.statements = [f"the parameters hold over the record ({how}): "
                          + "; ".join(t.statement() for t in out.tracks if t.kind != "not determined")]
    out.statements += ridge
    if grid := " and ".join(t.name for t in out.tracks if grid_searched(result.final.params, t.name)):
        out.statements.append(f"{grid} not tested for a change over the record: found by a grid search behind the "
                              "quantizer, the ± per window is the grid's finest spacing, a resolution, not a σ")
    early = [t for t in out.tests if t.fitted < t.windows]
    if early:
        out.statements.append("the added effects tested on the windows with their own parameters, the refits without "
                              "each stopped once the windows fitted decided it: " + "; ".join(
                                  f"{t.effect} needed (ΔBIC at most {t.delta_bic:+.1f} after {t.fitted} of "
                                  f"{t.windows} windows, {t.elapsed_s:.1f} s)" for t in early))
    return out


def _on_the_ridge(tracks: list[Track], wf: WindowFit) -> tuple[list[Track], list[str]]:
    """ωn and ζ that move together while the servo's bandwidth holds are one response fitted two ways, not a change.

    An overdamped or poorly excited second order is determined along one combination of ωn and ζ (its
    bandwidth) far better than along the other: windows of an unchanged actuator land at different points
    of that ridge. When the bandwidth per window varies by less than
    :data:`~ema_sim.analysis.estimation.trend.MIN_CHANGE`, ωn's and ζ's differences are not reported as a
    change of the record; the reason is given instead.
    """
    pair = [t for t in tracks if t.name in ("wn_rad_s", "zeta") and t.changed]
    if not pair or len(wf.fits) < 2:
        return tracks, []
    bw = np.array([bandwidth_hz(f.params) for f in wf.fits])
    spread = float(np.ptp(bw)) / max(float(np.mean(bw)), TINY)
    if spread >= MIN_CHANGE:
        return tracks, []
    names = " and ".join(LABELS[t.name] for t in pair)
    text = (f"{names} differ between the windows beyond their uncertainty, but the servo's bandwidth holds "
            f"({', '.join(f'{b:.3g}' for b in bw)} Hz, within {100 * spread:.1f} %): the windows fit one response "
            "along the ridge where ωn and ζ trade against each other, not an actuator that changed")
    return [replace(t, kind="steady") if t in pair else t for t in tracks], [text]


def _proxies(problem: Problem, result: Identification, declared: SecondOrderParams, subs: list[Problem],
             cur: WindowFit, out: Changes, say: Callable[[str], None], pool: Pool) -> WindowFit:
    """Take out each added effect the windows, each with its own parameters, do not need (module docstring)."""
    changed = ", ".join(t.name for t in out.tracks if t.changed)
    for step in reversed(list(result.steps)):
        effect = BY_KEY.get(f"{step.effect}/{step.where}")
        final = result.final
        if effect is None or not effect.fields or not all(f in final.free for f in effect.owned):
            continue
        off = offs(effect.owned, declared)
        free = tuple(f for f in final.free if f not in off)
        if not free:
            continue
        clock = time.perf_counter()
        without, d, fitted = refit_without(subs, final.params.replace(**off), free, final.flip, cur, pool)
        test = ProxyTest(effect.name, d, fitted, len(subs), time.perf_counter() - clock)
        out.tests.append(test)
        bound = f"at most {d:+.1f} after {fitted} of {len(subs)} windows" if fitted < len(subs) else f"{d:+.1f}"
        say(f"  changes: {effect.name} on windows with their own parameters: ΔBIC {bound}")
        if test.needed or without is None:
            continue
        refit = no_worse(problem, final.params.replace(**off), free,
                         fit_model(problem, final.params.replace(**off), free, flip=final.flip))
        why = (f"only stood in for a change over the record ({changed} changes between windows): with the "
               f"parameters fitted per window the record does not need it (ΔBIC {d:+.1f} over the windows)")
        out.proxies.append(f"{_name(effect, step)} taken out: it {why}")
        result.steps.remove(step)
        result.removed.append(Removal(step.effect, step.where, dict(step.params), why))
        result.final = refit
        cur = without
    return cur


def _name(effect: Effect, step: Step) -> str:
    values = ", ".join(f"{k} {v:.4g}" for k, v in step.params.items())
    return f"{effect.name} ({values})" if values else effect.name

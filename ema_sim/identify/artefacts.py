"""The sensors' and the logger's artefacts, found from the record itself and kept out of the fit.

Two kinds of sample no actuator produced, each found without any model:

* a **spike**: one sample that leaves its neighbours and comes back (``y[i]`` far from the mean of
  ``y[i−1]`` and ``y[i+1]``, which agree with each other) while the command does nothing of the kind,
  and its :data:`SIDE` neighbours on each side lie on a smooth line it leaves (a turning point of a
  ringing output sampled slowly leaves its neighbours too, but they do not lie on a line).
  "Far" is :data:`SPIKE_SPREAD` robust spreads of that second difference and :data:`SPIKE_NOISE` noise
  floors; a record where more than :data:`MAX_SHARE` of the samples qualify has no spikes, only motion;
* a **stale reading**: an output that was moving, then repeats one value for at least
  :data:`STALE_SAMPLES` samples and jumps to catch up (a dropout, a logger that re-sent its last value):
  an actuator that sticks breaks away gradually, a stale reading does not.

Least squares gives one 5° spike on a 0.002° sensor the weight of thousands of good samples; such samples
are taken out of the fit (the problem's mask), counted and said, never silently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.identify.problem import Problem

FloatArray = NDArray[np.float64]
SPIKE_SPREAD = 12.0
SPIKE_NOISE = 10.0
RETURN_SHARE = 0.3
"""A spike's neighbours differ from each other by less than this share of its excursion."""
MAX_SHARE = 0.01
SIDE = 3
"""Neighbours on each side that must lie on a quadratic a spike leaves."""
SMOOTH = 0.25
"""The neighbours stay within this share of the spike's excursion of the quadratic through them."""
STALE_SAMPLES = 3
CATCH_UP = 2.0
"""A stale reading's jump after it exceeds this many times the per-sample motion before it."""


@dataclass(frozen=True)
class Artefact:
    """Samples of one output that no actuator produced."""

    output: str
    kind: str
    """``spike`` or ``stale``."""
    indices: tuple[int, ...]
    """The samples taken out of the fit."""
    times_s: tuple[float, ...]
    """Where each spike or stale stretch starts."""
    size: float
    """The largest excursion (spike) or catch-up jump (stale), in the output's unit."""

    @property
    def statement(self) -> str:
        """The artefact in words."""
        n = len(self.times_s)
        when = ", ".join(f"{t:.3f}" for t in self.times_s[:5]) + ("…" if n > 5 else "")
        if self.kind == "spike":
            return (f"{self.output}: {n} isolated spike(s) at {when} s (single samples up to {self.size:.3g} off "
                    "their neighbours, the command quiet): a sensor or logger glitch, taken out of the fit")
        return (f"{self.output}: {n} stale stretch(es) at {when} s ({len(self.indices)} samples repeating the last "
                f"value while moving, then a catch-up jump of up to {self.size:.3g}): a dropout, taken out of the fit")

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Output, kind, samples, times and size.
        """
        return {"output": self.output, "kind": self.kind, "samples": len(self.indices),
                "times_s": list(self.times_s), "size": self.size, "statement": self.statement}


def _spikes(t: FloatArray, u: FloatArray, y: FloatArray, sigma: float) -> tuple[list[int], float]:
    if y.size < 5:
        return [], 0.0
    d = y[1:-1] - 0.5 * (y[:-2] + y[2:])
    du = u[1:-1] - 0.5 * (u[:-2] + u[2:])
    r = d - du
    spread = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    cut = max(SPIKE_SPREAD * spread, SPIKE_NOISE * sigma)
    back = np.abs(y[2:] - y[:-2]) < RETURN_SHARE * np.abs(d)
    idx = np.flatnonzero((np.abs(r) > cut) & back) + 1
    if idx.size > MAX_SHARE * y.size:
        return [], 0.0
    idx = np.array([i for i in idx if _isolated(t, y, int(i), cut)], dtype=int)
    return [int(i) for i in idx], float(np.max(np.abs(d[idx - 1]), initial=0.0))


def _isolated(t: FloatArray, y: FloatArray, i: int, cut: float) -> bool:
    """Whether ``y[i]`` leaves a smooth curve that its neighbours on both sides lie on."""
    lo, hi = i - SIDE, i + SIDE + 1
    if lo < 0 or hi > y.size:
        return False
    k = np.r_[lo:i, i + 1:hi]
    tk = t[k] - t[i]
    coef = np.polyfit(tk, y[k], 2)
    off = abs(float(y[i] - coef[-1]))
    spread = float(np.max(np.abs(y[k] - np.polyval(coef, tk))))
    return off > cut and spread < SMOOTH * off


def _stale(y: FloatArray, sigma: float) -> tuple[list[int], list[int], float]:
    n = y.size
    same = np.concatenate([[False], y[1:] == y[:-1]])
    out: list[int] = []
    starts: list[int] = []
    jump_max = 0.0
    i = 1
    while i < n:
        if not same[i]:
            i += 1
            continue
        a = i - 1  # the first sample of the repeated value
        b = i
        while b < n and same[b]:
            b += 1
        # samples a..b-1 repeat y[a]; b is the first new value
        if b - a >= STALE_SAMPLES and a >= 1 and b < n:
            before = abs(float(y[a] - y[a - 1]))
            jump = abs(float(y[b] - y[b - 1]))
            if before > 5.0 * sigma and jump > CATCH_UP * before:
                out += list(range(a + 1, b))
                starts.append(a + 1)
                jump_max = max(jump_max, jump)
        i = b
    if len(out) > 10 * MAX_SHARE * n:
        return [], [], 0.0
    return out, starts, jump_max


def find(problem: Problem) -> list[Artefact]:
    """Spikes and stale readings on each output (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.

    Returns
    -------
    list of Artefact
        What was found, one entry per output and kind.
    """
    out: list[Artefact] = []
    t = problem.time_s
    u = problem.data.command_deg
    for o in problem.outputs:
        y = problem.observed[o]
        sigma = problem.sigma_deg[o]
        idx, size = _spikes(t, u, y, sigma)
        if idx:
            out.append(Artefact(o, "spike", tuple(idx), tuple(float(t[i]) for i in idx), size))
        stale, starts, jump = _stale(y, sigma)
        if stale:
            out.append(Artefact(o, "stale", tuple(stale), tuple(float(t[i]) for i in starts), jump))
    return out


def exclude(problem: Problem, found: list[Artefact]) -> None:
    """Take the artefacts' samples out of the fit (every output loses them: the residual stacks by sample).

    Parameters
    ----------
    problem : Problem
        The record as fitted (its mask is changed).
    found : list of Artefact
        What :func:`find` found.
    """
    for a in found:
        problem.mask[np.asarray(a.indices, dtype=int)] = False

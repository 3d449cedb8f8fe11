"""Samples no actuator produced, found from the record alone: sensor spikes and stale readings (dropouts).

Both tools read them here (``ema identify`` takes them out of its fit, ``ema analyze`` cuts a record at a
dropout as at a gap in its stamps):

* a **spike**: one sample that leaves its neighbours and comes back (``y[i]`` far from the mean of
  ``y[i−1]`` and ``y[i+1]``, which agree with each other) while the command does nothing of the kind,
  and its :data:`SIDE` neighbours on each side lie on a smooth line it leaves (a turning point of a
  ringing output sampled slowly leaves its neighbours too, but they do not lie on a line).
  "Far" is :data:`SPIKE_SPREAD` robust spreads of that second difference and :data:`SPIKE_NOISE` noise
  floors; a record where more than :data:`MAX_SHARE` of the samples qualify has no spikes, only motion;
* a **stale reading**: an output that was moving, then repeats one value for at least
  :data:`STALE_SAMPLES` samples and jumps to catch up, the jump :data:`CATCH_UP` times the motion of the
  sample before it and of the sample after it (a dropout, a logger that re-sent its last value): an actuator
  that sticks breaks away gradually, one that rests until its command moves again keeps accelerating after
  its first sample, a stale reading does neither.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.records.series import cut
from ema_sim.io.measured import OUTPUTS, MeasuredData

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
"""A stale reading's jump exceeds this many times the per-sample motion before it and after it."""
MOVING_NOISE = 5.0
"""An output moves when a sample's change exceeds this many noise floors."""


@dataclass(frozen=True)
class Artefact:
    """Samples of one output that no actuator produced."""

    output: str
    kind: str
    """``spike`` or ``stale``."""
    indices: tuple[int, ...]
    """The samples that are not the actuator's."""
    times_s: tuple[float, ...]
    """Where each spike or stale stretch starts."""
    size: float
    """The largest excursion (spike) or catch-up jump (stale), in the output's unit."""

    def statement(self, done: str = "taken out of the fit") -> str:
        """The artefact in words, ending with what was done with it.

        Parameters
        ----------
        done : str
            What was done with its samples.

        Returns
        -------
        str
            One sentence.
        """
        n = len(self.times_s)
        when = ", ".join(f"{t:.3f}" for t in self.times_s[:5]) + ("…" if n > 5 else "")
        if self.kind == "spike":
            return (f"{self.output}: {n} isolated spike(s) at {when} s (single samples up to {self.size:.3g} off "
                    f"their neighbours, the command quiet): a sensor or logger glitch, {done}")
        return (f"{self.output}: {n} stale stretch(es) at {when} s ({len(self.indices)} samples repeating the last "
                f"value while moving, then a catch-up jump of up to {self.size:.3g}): a dropout, {done}")

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Output, kind, samples, times and size.
        """
        return {"output": self.output, "kind": self.kind, "samples": len(self.indices),
                "times_s": list(self.times_s), "size": self.size, "statement": self.statement()}


def spikes(t: FloatArray, u: FloatArray, y: FloatArray, sigma: float) -> tuple[list[int], float]:
    """The isolated spikes of ``y`` (module docstring) and the largest excursion.

    Parameters
    ----------
    t, u, y : numpy.ndarray
        Stamps (s), command and output.
    sigma : float
        The output's noise floor.

    Returns
    -------
    tuple
        The spikes' samples and the largest one's excursion.
    """
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


def stale(y: FloatArray, sigma: float) -> tuple[list[int], list[int], float]:
    """The stale readings of ``y`` (module docstring): their samples, where each stretch starts, the largest jump.

    The first sample of a repeated value is the last real reading; the repeats after it are the stale ones.

    Parameters
    ----------
    y : numpy.ndarray
        The output.
    sigma : float
        Its noise floor.

    Returns
    -------
    tuple
        The stale samples, each stretch's first stale sample, and the largest catch-up jump.
    """
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
        if b - a >= STALE_SAMPLES and a >= 1 and b + 1 < n:
            before = abs(float(y[a] - y[a - 1]))
            jump = abs(float(y[b] - y[b - 1]))
            after = abs(float(y[b + 1] - y[b]))
            if before > MOVING_NOISE * sigma and jump > CATCH_UP * max(before, after):
                out += list(range(a + 1, b))
                starts.append(a + 1)
                jump_max = max(jump_max, jump)
        i = b
    if len(out) > 10 * MAX_SHARE * n:
        return [], [], 0.0
    return out, starts, jump_max


def find(time_s: FloatArray, command: FloatArray, outputs: Mapping[str, FloatArray], sigma: Mapping[str, float],
         kinds: tuple[str, ...] = ("spike", "stale")) -> list[Artefact]:
    """Spikes and stale readings on each output (module docstring).

    Parameters
    ----------
    time_s, command : numpy.ndarray
        Stamps (s) and command.
    outputs : mapping
        Output name → its samples.
    sigma : mapping
        Output name → its noise floor.
    kinds : tuple of str
        The kinds looked for.

    Returns
    -------
    list of Artefact
        What was found, one entry per output and kind.
    """
    out: list[Artefact] = []
    for o, y in outputs.items():
        if "spike" in kinds:
            idx, size = spikes(time_s, command, y, sigma[o])
            if idx:
                out.append(Artefact(o, "spike", tuple(idx), tuple(float(time_s[i]) for i in idx), size))
        if "stale" in kinds:
            bad, starts, jump = stale(y, sigma[o])
            if bad:
                out.append(Artefact(o, "stale", tuple(bad), tuple(float(time_s[i]) for i in starts), jump))
    return out


def robust_floor(y: FloatArray) -> float:
    """A noise floor for finding dropouts before any analysis: the robust spread of the second difference.

    Never under half the smallest step the output takes (one count of a quantized reading), so counts
    are never taken for motion.

    Parameters
    ----------
    y : numpy.ndarray
        The output.

    Returns
    -------
    float
        The floor, in the output's unit.
    """
    if y.size < 4:
        return 0.0
    d2 = np.diff(y, 2)
    mad = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    steps = np.abs(np.diff(y))
    steps = steps[steps > 0.0]
    return max(mad, 0.5 * float(steps.min()) if steps.size else 0.0)


def split_at_dropouts(data: MeasuredData) -> list[MeasuredData]:
    """The record's stretches on either side of its outputs' stale readings, each a record of its own.

    What the actuator did while its reading was stale is unknown, so no analysis may read across it: the
    record is cut there as at a gap in its stamps (:func:`ema_sim.analysis.records.series.split_at_gaps`), the
    stale samples left out and the cut said in each stretch's metadata (``dropouts``); stretches under
    :data:`~ema_sim.analysis.records.series.MIN_STRETCH` samples are left out and said.

    Parameters
    ----------
    data : MeasuredData
        A record as read.

    Returns
    -------
    list of MeasuredData
        ``[data]`` unchanged when no output has a dropout.

    Raises
    ------
    DataError
        No stretch between the dropouts is long enough.
    """
    outputs = {name: np.asarray(y, dtype=float) for name in OUTPUTS if (y := getattr(data, name)) is not None}
    t = np.asarray(data.time_s, dtype=float)
    found = find(t, np.asarray(data.command_deg, dtype=float), outputs,
                 {o: robust_floor(y) for o, y in outputs.items()}, kinds=("stale",))
    if not found:
        return [data]
    bad = np.zeros(t.size, dtype=bool)
    for a in found:
        bad[np.asarray(a.indices, dtype=int)] = True
    edges = np.flatnonzero(np.diff(np.concatenate([[1], bad.astype(int), [1]])))
    parts = [(int(lo), int(hi)) for lo, hi in zip(edges[::2], edges[1::2], strict=True) if hi > lo]
    head = "; ".join(f.statement("cut out: the record is analysed on each side of it, never across it")
                     for f in found)
    return cut(data, parts, "dropouts", head)

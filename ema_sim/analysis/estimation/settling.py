"""How the output answered one commanded change, read as a person reads it: against the command.

A step's overshoot and settling time are usually read against the output's own final value (the mean
of the end of the hold). That hides the servo that stops short of the command, or is still creeping
towards it when the next edge comes: its output is flat at the end of the hold, so it "settles"
against itself. :func:`read` reads the same stretch both ways:

* against the **command**: the peak past the commanded level (overshoot, % of the commanded change),
  and the time from the command's arrival after which the output stays within the band about the
  commanded level; when it is still outside the band at the end of the hold (the next edge), the
  change is *unsettled*, and the error left to the command is the output at the end of the hold
  (mean of its last :data:`END_SAMPLES` samples) minus the commanded level;
* against the output's **own last value** (mean of the last :data:`FINAL_SHARE` of the hold): the
  classic overshoot and settling time, and whether the output was still moving at the next edge.

The band is ±max(2 % of the commanded change, 4σ of the output's noise floor, 1.5 counts).

:class:`Transitions` reads several changes in one direction (every cycle of a periodic test) at once:
the mean of each figure with its uncertainty, and "unsettled" when any of them did not settle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.quality import Measurement
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

BAND_SHARE = 0.02
NOISE_SIGMAS = 4.0
COUNTS = 1.5
FINAL_SHARE = 0.3
END_SAMPLES = 3


@dataclass(frozen=True)
class Settling:
    """One commanded change read against the command and against the output's own last value.

    Parameters
    ----------
    commanded : float
        The commanded level after the change.
    change : float
        The commanded change (new level minus old).
    final : float
        The output's own last value: mean of the last 30 % of the hold.
    end : float
        The output at the end of the hold (the next edge): mean of its last 3 samples.
    band : float
        Half width of the settling band.
    hold_s : float
        From the command's arrival to the end of the hold, s.
    overshoot_command_pct : float
        Peak past the commanded level, % of the commanded change (0 when it never passes it).
    overshoot_final_pct : float
        Peak past the output's own last value, % of the commanded change.
    settling_command_s : float or None
        From the command's arrival until the output stays within the band about the commanded level (None: unsettled).
    settling_final_s : float or None
        The same about the output's own last value (None: still moving at the end of the hold).
    sample_s : float
        The sample interval: a time read off the samples is known to within it.
    noise : float
        The output's noise floor: the end of the hold, a mean of 3 samples, is known to within noise/√3.
    """

    commanded: float
    change: float
    final: float
    end: float
    band: float
    hold_s: float
    overshoot_command_pct: float
    overshoot_final_pct: float
    settling_command_s: float | None
    settling_final_s: float | None
    sample_s: float = 0.0
    noise: float = 0.0

    @property
    def settled(self) -> bool:
        """Whether the output settled within the band about the commanded level before the hold ended."""
        return self.settling_command_s is not None

    @property
    def error_left(self) -> float:
        """Output minus command at the end of the hold."""
        return self.end - self.commanded

    @property
    def statement(self) -> str:
        """One line: settled (in how long), or unsettled with the error left."""
        if self.settled:
            return f"settled to the command in {1e3 * (self.settling_command_s or 0.0):.0f} ms (±{self.band:.3g} band)"
        own = ("still moving" if self.settling_final_s is None else
               f"flat after {1e3 * self.settling_final_s:.0f} ms but")
        return (f"unsettled: {own} {self.error_left:+.3g} from the command at the next edge "
                f"({1e3 * self.hold_s:.0f} ms after the command arrived; band ±{self.band:.3g})")

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Both readings, the band, the error left and the statement.
        """
        return {"commanded": self.commanded, "change": self.change, "final": self.final, "end": self.end,
                "band": self.band, "hold_s": self.hold_s, "overshoot_command_pct": self.overshoot_command_pct,
                "overshoot_final_pct": self.overshoot_final_pct, "settling_command_s": self.settling_command_s,
                "settling_final_s": self.settling_final_s, "settled": self.settled, "error_left": self.error_left,
                "statement": self.statement}


def _settling(tt: FloatArray, y: FloatArray, level: float, band: float) -> float | None:
    """From ``tt[0]`` until ``y`` stays within ``band`` of ``level`` (None: outside at the end)."""
    outside = np.flatnonzero(np.abs(y - level) > band)
    if outside.size == 0:
        return 0.0
    if outside[-1] + 1 >= y.size:
        return None
    return float(tt[outside[-1] + 1] - tt[0])


def band_for(change: float, noise: float, counts: float | None) -> float:
    """The settling band's half width (module docstring).

    Parameters
    ----------
    change : float
        The commanded change.
    noise : float
        The output's noise floor.
    counts : float or None
        The output's count.

    Returns
    -------
    float
        ±max(2 % of the change, 4σ, 1.5 counts).
    """
    return max(BAND_SHARE * abs(change), NOISE_SIGMAS * noise, COUNTS * (counts or 0.0))


def read(t: FloatArray, y: FloatArray, arrive: int, end: int, *, commanded: float, change: float, noise: float,
         counts: float | None) -> Settling:
    """One commanded change read both ways (module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    y : numpy.ndarray
        The output.
    arrive : int
        First sample at which the command holds its new level (for a step, the edge).
    end : int
        One past the last sample of the hold (the next edge, or the end of the test).
    commanded : float
        The new commanded level.
    change : float
        The commanded change.
    noise : float
        The output's noise floor.
    counts : float or None
        The output's count.

    Returns
    -------
    Settling
        The reading.
    """
    seg = np.asarray(y[arrive:end], dtype=float)
    tt = np.asarray(t[arrive:end], dtype=float)
    if seg.size == 0:
        raise ValueError("an empty hold has no settling")
    first = seg.size - max(1, int(seg.size * FINAL_SHARE))
    final = float(np.mean(seg[first:]))
    last = float(np.mean(seg[-min(END_SAMPLES, seg.size):]))
    band = band_for(change, noise, counts)
    sign = 1.0 if change >= 0 else -1.0
    size = max(abs(change), 1e-12)
    over_cmd = max(0.0, float(np.max((seg - commanded) * sign))) / size * 100.0
    over_fin = max(0.0, float(np.max((seg - final) * sign))) / size * 100.0
    step = float(np.median(np.diff(tt))) if tt.size > 1 else 0.0
    hold_s = float(tt[-1] - tt[0]) + step
    return Settling(commanded, change, final, last, band, hold_s, over_cmd, over_fin,
                    _settling(tt, seg, commanded, band), _settling(tt, seg, final, band), step, noise)


@dataclass(frozen=True)
class Transitions:
    """The command's changes in one direction, read over every cycle.

    Parameters
    ----------
    direction : str
        ``rising`` or ``falling``.
    readings : list
        Each change's :class:`~ema_sim.analysis.Settling`.
    """

    direction: str
    readings: list[Settling]

    def _ms(self, values: list[float]) -> str:
        mean, se = self._time(values)
        return f"{1e3 * mean:.0f} ± {1e3 * se:.2g} ms"

    def _time(self, values: list[float]) -> tuple[float, float]:
        """Mean of times read off the samples, ± the larger of their standard error and a sample's /√12."""
        v = np.array(values)
        se = float(np.std(v, ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0
        step = max(r.sample_s for r in self.readings)
        return float(np.mean(v)), max(se, step / float(np.sqrt(12.0)))

    @staticmethod
    def _mean_se(values: list[float]) -> tuple[float, float | None]:
        """Mean and standard error (None when not determined: one value, or all identical, a spread of 0)."""
        v = np.array(values)
        se = float(np.std(v, ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0
        return float(np.mean(v)), (se if se > 0.0 else None)

    @property
    def settled(self) -> int:
        """How many changes settled to the command before the next one."""
        return sum(r.settled for r in self.readings)

    @property
    def change(self) -> float:
        """Mean commanded change."""
        return float(np.mean([r.change for r in self.readings]))

    @property
    def error_left(self) -> tuple[float, float | None]:
        """Output minus command at the end of the hold: mean, and its uncertainty.

        The uncertainty is the standard error over the changes with the noise floor's share (a mean of 3
        samples per change) added in quadrature.
        """
        mean, se = self._mean_se([r.error_left for r in self.readings])
        n = len(self.readings)
        floor = max(r.noise for r in self.readings) / float(np.sqrt(END_SAMPLES * n))
        return mean, float(np.hypot(se or 0.0, floor))

    @property
    def overshoot_command(self) -> tuple[float, float | None]:
        """Overshoot past the command, %: mean and standard error."""
        return self._mean_se([r.overshoot_command_pct for r in self.readings])

    @property
    def overshoot_final(self) -> tuple[float, float | None]:
        """Overshoot past the output's own last value, %: mean and standard error."""
        return self._mean_se([r.overshoot_final_pct for r in self.readings])

    @property
    def settling_command(self) -> Measurement:
        """Settling to the command: mean ± standard error when every change settled, else "unsettled"."""
        n = len(self.readings)
        times = [r.settling_command_s for r in self.readings if r.settling_command_s is not None]
        if len(times) == n:
            mean, se_t = self._time(times)
            return Measurement(mean, se_t, "ok", f"settled to the command in {self._ms(times)} (all {n})")
        err, err_se = self.error_left
        flat = [r.settling_final_s for r in self.readings if r.settling_final_s is not None]
        own = (f"flat against its own last value after {self._ms(flat)}, but "
               if len(flat) == n else "still moving at the next change: ")
        band = float(np.mean([r.band for r in self.readings]))
        se = f" ± {err_se:.2g}" if err_se is not None else ""
        return Measurement(None, None, "not_determined",
                       f"not measured: unsettled at {n - len(times)} of {n} changes: {own}{err:+.3g}{se} from the "
                       f"command at the next change (band ±{band:.3g})")

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Count, commanded change, error left, overshoots, settling both ways, and every change's reading.
        """
        err, err_se = self.error_left
        oc, oc_se = self.overshoot_command
        of, of_se = self.overshoot_final
        flat = [r.settling_final_s for r in self.readings if r.settling_final_s is not None]
        own: tuple[float | None, float | None] = self._time(flat) if len(flat) == len(self.readings) else (None, None)
        return {"direction": self.direction, "changes": len(self.readings), "settled_to_command": self.settled,
                "commanded_change": self.change, "error_left": err, "error_left_sigma": err_se,
                "overshoot_command_pct": oc, "overshoot_command_sigma_pct": oc_se, "overshoot_final_pct": of,
                "overshoot_final_sigma_pct": of_se, "settling_command": self.settling_command.as_dict(),
                "settling_final_s": own[0], "settling_final_sigma_s": own[1],
                "each": [r.as_dict() for r in self.readings]}

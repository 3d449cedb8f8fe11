"""How far a result of ``ema analyze`` can be trusted, in one word every result carries.

* ``ok``: the record determines it;
* ``on_bound``: an estimate sits on a bound of its allowed range (the value is a limit of the search,
  not a measurement);
* ``not_determined``: the record cannot determine it (too little excitation, above the Nyquist
  frequency, below the sensor's resolution, a command sampled rather than held);
* ``saturated``: a rate or position limit shaped it (not the small-signal figure);
* ``non_causal``: the output leads its command beyond the figure's uncertainty, which no servo does: the
  figure says more of how the record was logged than of the actuator (:mod:`ema_sim.analysis.estimation.causal`).

A :class:`Measurement` is one figure with its uncertainty and quality, or the sentence saying why it
was not measured.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ema_sim.jsontypes import JsonObject

Quality = Literal["ok", "on_bound", "not_determined", "saturated", "non_causal"]
QUALITY_WORDS: dict[str, str] = {"ok": "ok", "on_bound": "on a bound", "not_determined": "not determined",
                                 "saturated": "saturated", "non_causal": "leads its command (not causal)"}
_RANK = {"ok": 0, "saturated": 1, "on_bound": 2, "non_causal": 3, "not_determined": 4}


def worst(*qualities: Quality) -> Quality:
    """The most severe of several qualities (not determined, not causal, on a bound, saturated, ok).

    Parameters
    ----------
    *qualities : Quality
        The qualities to combine.

    Returns
    -------
    Quality
        The most severe (``ok`` when none is given).
    """
    return max(qualities, key=lambda q: _RANK[q], default="ok")


@dataclass(frozen=True)
class Measurement:
    """A figure: its value and uncertainty, or why it was not measured ("not measured: why").

    Parameters
    ----------
    value : float or None
        The figure (None: not measured).
    sigma : float or None
        Its uncertainty (standard error over the cycles, or the half width of a bracket).
    quality : Quality
        ``ok``, ``saturated`` or ``not_determined``.
    statement : str
        The figure in words, or "not measured: why".
    """

    value: float | None
    sigma: float | None
    quality: Quality
    statement: str

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Value, uncertainty, quality and statement.
        """
        return {"value": self.value, "sigma": self.sigma, "quality": self.quality, "statement": self.statement}

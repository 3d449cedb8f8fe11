"""How far a result of ``ema analyze`` can be trusted, in one word every result carries.

* ``ok``: the record determines it;
* ``on_bound``: an estimate sits on a bound of its allowed range (the value is a limit of the search,
  not a measurement);
* ``not_determined``: the record cannot determine it (too little excitation, above the Nyquist
  frequency, below the sensor's resolution, a command sampled rather than held);
* ``saturated``: a rate or position limit shaped it (not the small-signal figure).
"""

from __future__ import annotations

from typing import Literal

Quality = Literal["ok", "on_bound", "not_determined", "saturated"]
QUALITY_WORDS: dict[str, str] = {"ok": "ok", "on_bound": "on a bound", "not_determined": "not determined",
                                 "saturated": "saturated"}
_RANK = {"ok": 0, "saturated": 1, "on_bound": 2, "not_determined": 3}


def worst(*qualities: Quality) -> Quality:
    """The most severe of several qualities (not determined, on a bound, saturated, ok).

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

"""Small formatting helpers the tests' Markdown sections share: numbers, tables, notes, images, quality."""

from __future__ import annotations

import numpy as np

from ema_sim.analysis.estimation.quality import QUALITY_WORDS


def num(value: float | None, fmt: str = ".4g", unit: str = "") -> str:
    """A number with its unit, or an em dash when it does not exist.

    Parameters
    ----------
    value : float or None
        The number.
    fmt : str
        Its format.
    unit : str
        Appended to it.

    Returns
    -------
    str
        The text.
    """
    if value is None or not np.isfinite(value):
        return "—"
    return f"{value:{fmt}}{unit}"


def ms(value_s: float | None, fmt: str = ".2f") -> str:
    """Seconds shown in milliseconds (— when None).

    Parameters
    ----------
    value_s : float or None
        Seconds.
    fmt : str
        Format of the milliseconds.

    Returns
    -------
    str
        The text.
    """
    return num(None if value_s is None else 1e3 * value_s, fmt)


def pm(value: float, sigma: float, fmt: str = ".4g") -> str:
    """``value ± sigma``.

    Parameters
    ----------
    value : float
        The estimate.
    sigma : float
        Its standard error.
    fmt : str
        Format of the estimate.

    Returns
    -------
    str
        The text.
    """
    return f"{value:{fmt}} ± {sigma:.2g}"


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table and a blank line.

    Parameters
    ----------
    head : list of str
        Column headings.
    rows : list of list of str
        Cells.

    Returns
    -------
    list of str
        Lines.
    """
    out = ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return [*out, ""]


def bullets(notes: list[str]) -> list[str]:
    """Notes as a bullet list and a blank line (nothing when there are none).

    Parameters
    ----------
    notes : list of str
        The notes.

    Returns
    -------
    list of str
        Lines.
    """
    return [*(f"- {n}" for n in notes), ""] if notes else []


def image(path: str | None, alt: str) -> list[str]:
    """An image link and a blank line (nothing without an image).

    Parameters
    ----------
    path : str or None
        The PNG, relative to the report.
    alt : str
        Its alternative text.

    Returns
    -------
    list of str
        Lines.
    """
    return [f"![{alt}]({path})", ""] if path else []


def quality(value: str, note: str = "") -> str:
    """A result's quality in words, with its reason when it is not ``ok``.

    Parameters
    ----------
    value : str
        ``ok``, ``on_bound``, ``not_determined`` or ``saturated``.
    note : str
        Why.

    Returns
    -------
    str
        ``ok``, or ``**on a bound**: ζ at its upper bound 3`` and the like.
    """
    words = QUALITY_WORDS.get(value, value)
    if value == "ok":
        return words
    return f"**{words}**" + (f": {note}" if note else "")

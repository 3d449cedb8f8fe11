"""Texts in the record's unit: what the analyses write in degrees, said in a linear rig's unit.

The analyses compute on positions as logged and word their findings in degrees, the X-43A's unit. A
linear rig's positions are in its own unit (``mm``): every figure is in that unit and that unit per
second, and its texts must say so. :func:`in_unit` rewrites a text for the record's unit at the
report's boundary (JSON, Markdown, console): a number followed by ``°`` (or ``°/s``, ``°/s²``), and
the words ``deg``, ``deg/s``, ``dps``. A phase angle stays in degrees: a ``°`` whose clause speaks of
a phase, a lead, a lag or an angle is left as it is.
"""

from __future__ import annotations

import re
from typing import overload

from ema_sim.jsontypes import JsonObject, JsonValue

ANGLE_WORDS = re.compile(r"phase|lead|\blag\b|\blags\b|angle", re.I)
"""Words whose clause carries a phase angle, in degrees whatever the record's unit."""
CLAUSE = re.compile(r"[;:\[\]|]|\. ")
"""Where a clause ends (the look-back for :data:`ANGLE_WORDS` stops there)."""
AS_GIVEN = ("data", "metadata", "source")
"""Keys whose texts are the user's own (a path, the record's metadata): never rewritten."""
_DEGREE = re.compile(r"(?P<num>\d)\s?°(?P<rate>/s²|/s2|/s)?")
_WORD = re.compile(r"(?<![_A-Za-z*])(?P<word>deg/s²|deg/s|deg|dps)(?![_A-Za-z])")


def _angle(text: str, at: int) -> bool:
    """Whether the ``°`` at ``at`` is a phase angle: its clause names one."""
    start = 0
    for m in CLAUSE.finditer(text, 0, at):
        start = m.end()
    return bool(ANGLE_WORDS.search(text, max(start, at - 80), at))


def in_unit(text: str, unit: str) -> str:
    """``text`` with its degrees said in ``unit`` (unchanged for a record in degrees).

    Parameters
    ----------
    text : str
        A text the analyses wrote in degrees.
    unit : str
        The record's unit (``deg``, ``mm``...).

    Returns
    -------
    str
        The text in the record's unit; phase angles stay in degrees.
    """
    if unit == "deg" or ("°" not in text and not _WORD.search(text)):
        return text

    def degree(m: re.Match[str]) -> str:
        if _angle(text, m.start()):
            return m.group(0)
        return f"{m.group('num')} {unit}{m.group('rate') or ''}"

    def word(m: re.Match[str]) -> str:
        if _angle(text, m.start()):
            return m.group(0)
        w = m.group("word")
        return {"deg": unit, "deg/s": f"{unit}/s", "dps": f"{unit}/s", "deg/s²": f"{unit}/s²"}[w]

    return _WORD.sub(word, _DEGREE.sub(degree, text))


@overload
def texts_in_unit(value: JsonObject, unit: str) -> JsonObject: ...
@overload
def texts_in_unit(value: JsonValue, unit: str) -> JsonValue: ...
def texts_in_unit(value: JsonValue, unit: str) -> JsonValue:
    """Every string in a nested JSON-ready structure :func:`in_unit` (keys, which name fields, untouched).

    Parameters
    ----------
    value : JSON value
        Dicts, lists and scalars.
    unit : str
        The record's unit.
    """
    if unit == "deg":
        return value
    if isinstance(value, dict):
        return {k: v if k in AS_GIVEN else texts_in_unit(v, unit) for k, v in value.items()}
    if isinstance(value, list):
        return [texts_in_unit(v, unit) for v in value]
    return in_unit(value, unit) if isinstance(value, str) else value

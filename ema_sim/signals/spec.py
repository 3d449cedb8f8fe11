"""``kind:field=value,field=value`` specs for maneuvers and loads, parsed into typed dataclasses.

A malformed spec raises :class:`~ema_sim.errors.SpecError` naming the bad field; an unknown kind an
:class:`~ema_sim.errors.UnknownNameError` listing the known ones.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import ClassVar, TypeVar, get_type_hints

from ema_sim.errors import SpecError, UnknownNameError

T = TypeVar("T")
FieldValue = bool | int | float | str
"""What a spec field holds (:func:`_convert` makes it from the spec's text)."""
V = TypeVar("V", bound=FieldValue)


def param(default: V, *, low: float | None = None, high: float | None = None, strict: bool = False,
          doc: str = "") -> V:
    """A spec field with bounds: ``low`` ≤ value (``<`` when ``strict``), value ≤ ``high``.

    Parameters
    ----------
    default : object
        The field's default.
    low : float, optional
        Lower bound.
    high : float, optional
        Upper bound.
    strict : bool
        ``low`` itself excluded.
    doc : str
        What the field is.

    Returns
    -------
    dataclasses.Field
        The field (typed as its value, as :func:`dataclasses.field` is, for the dataclass body).
    """
    return field(default=default, metadata={"low": low, "high": high, "strict": strict, "doc": doc})


@dataclass(frozen=True)
class Spec:
    """Base of every spec dataclass: a ``kind`` name and typed, bounded fields."""

    kind: ClassVar[str] = "?"
    family: ClassVar[str] = "spec"

    def spec(self) -> str:
        """The canonical spec string (round-trips through :func:`parse`)."""
        parts = [f"{f.name}={_fmt(getattr(self, f.name))}" for f in fields(self)]
        return f"{self.kind}:{','.join(parts)}" if parts else self.kind

    def as_dict(self) -> dict[str, FieldValue]:
        """Kind and fields, for bag metadata and JSON reports."""
        return {"kind": self.kind, **{f.name: getattr(self, f.name) for f in fields(self)}}

    def _check(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            low, high, strict = f.metadata.get("low"), f.metadata.get("high"), f.metadata.get("strict")
            if isinstance(value, float) and not math.isfinite(value):
                raise SpecError(f"{self.family} {self.kind!r}: field {f.name!r} must be finite")
            if low is not None and (value < low or (strict and value == low)):
                rel = ">" if strict else "≥"
                raise SpecError(f"{self.family} {self.kind!r}: field {f.name!r} must be {rel} {low}, got {value}")
            if high is not None and value > high:
                raise SpecError(f"{self.family} {self.kind!r}: field {f.name!r} must be ≤ {high}, got {value}")

    def __post_init__(self) -> None:
        self._check()
        self.validate()

    def validate(self) -> None:
        """Cross-field checks of a concrete spec (raise SpecError)."""


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _convert(family: str, kind: str, f: Field[FieldValue], hint: type, raw: str) -> FieldValue:
    try:
        if hint is float:
            return float(raw)
        if hint is int:
            value = float(raw)
            if not value.is_integer():
                raise ValueError(raw)
            return int(value)
        if hint is bool:
            low = raw.lower()
            if low in ("1", "true", "yes", "on"):
                return True
            if low in ("0", "false", "no", "off"):
                return False
            raise ValueError(raw)
    except ValueError:
        what = {float: "a number", int: "an integer", bool: "true or false"}[hint]
        raise SpecError(f"{family} {kind!r}: field {f.name!r} must be {what}, got {raw!r}") from None
    return raw


def split(text: str, family: str) -> tuple[str, dict[str, str]]:
    """``"kind:a=1,b=2"`` → ``("kind", {"a": "1", "b": "2"})``.

    Parameters
    ----------
    text : str
        The spec.
    family : str
        What it is, for messages (``maneuver``, ``load``, ``test``).

    Returns
    -------
    kind : str
        The kind, lower case.
    fields : dict
        Field name → its text.
    """
    text = text.strip()
    if not text:
        raise SpecError(f"empty {family} spec")
    kind, _, rest = text.partition(":")
    kind = kind.strip().lower()
    values: dict[str, str] = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key or not value.strip():
            raise SpecError(f"{family} {kind!r}: expected field=value, got {item!r}")
        if key in values:
            raise SpecError(f"{family} {kind!r}: field {key!r} given twice")
        values[key] = value.strip()
    return kind, values


def parse(text: str, registry: dict[str, type[T]], family: str) -> T:
    """Build the dataclass registered for the spec's kind, converting and checking every field.

    Parameters
    ----------
    text : str
        The spec.
    registry : dict
        Kind → dataclass.
    family : str
        What it is, for messages.

    Returns
    -------
    object
        The dataclass instance.
    """
    kind, raw = split(text, family)
    if kind not in registry:
        raise UnknownNameError(family, kind, registry)
    cls = registry[kind]
    hints = get_type_hints(cls)
    known = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    kwargs: dict[str, FieldValue] = {}
    for key, value in raw.items():
        if key not in known:
            raise SpecError(f"{family} {kind!r}: unknown field {key!r} (fields: {', '.join(known) or 'none'})")
        kwargs[key] = _convert(family, kind, known[key], hints[key], value)
    missing = [n for n, f in known.items() if f.default is MISSING and n not in kwargs]
    if missing:
        raise SpecError(f"{family} {kind!r}: missing field {missing[0]!r}")
    return cls(**kwargs)


def describe(registry: dict[str, type[Spec]]) -> list[str]:
    """One line per kind: its spec with defaults and its docstring's first line.

    Parameters
    ----------
    registry : dict
        Kind → spec dataclass.

    Returns
    -------
    list of str
        Two lines per kind.
    """
    lines = []
    for kind, cls in registry.items():
        defaults = ",".join(f"{f.name}={_fmt(f.default)}" for f in fields(cls))
        doc = (cls.__doc__ or "").strip().splitlines()[0]
        lines.append(f"{kind}:{defaults}\n    {doc}")
    return lines

"""Reports as published contracts: a JSON Schema generated from a report's TypedDicts, and the check against it.

The reports ``ema identify --json`` and ``ema analyze --json`` write are what other tools read, so their shape is
written once, as TypedDicts next to the code that fills them, and the schema users get is generated from those
types (:func:`schema_of`), never written by hand beside them. :func:`check` validates a report with ``jsonschema``
(draft 2020-12). A report that breaks its contract is still written, whole, with a warning: losing a user's
results to a schema slip would be worse. With ``EMA_STRICT_REPORTS=1`` (the test suite sets it) the check
raises instead, so every report a test builds is validated.
"""

from __future__ import annotations

import os
import types
import typing
import warnings
from collections.abc import Mapping
from typing import Literal, NotRequired, Required, Union, get_args, get_origin, get_type_hints, is_typeddict

import jsonschema

__all__ = ["STRICT_ENV", "ReportContractError", "check", "schema_of"]

STRICT_ENV = "EMA_STRICT_REPORTS"
DIALECT = "https://json-schema.org/draft/2020-12/schema"

_SCALARS: dict[type, dict[str, object]] = {
    str: {"type": "string"},
    bool: {"type": "boolean"},
    int: {"type": "integer"},
    float: {"type": "number"},  # JSON has one number type; an int is a valid float
    type(None): {"type": "null"},
}


class ReportContractError(ValueError):
    """A report that does not match its published schema (raised only under ``EMA_STRICT_REPORTS=1``)."""


def _unwrap(tp: object) -> object:
    """A field's type without ``Required``/``NotRequired``."""
    while get_origin(tp) in (Required, NotRequired):
        tp = get_args(tp)[0]
    return tp


def _schema(tp: object, defs: dict[str, object]) -> dict[str, object]:  # noqa: PLR0911 - one return per kind
    """The schema of one type, TypedDicts collected into ``defs`` by name."""
    tp = _unwrap(tp)
    if tp is object:
        return {}
    if isinstance(tp, type) and tp in _SCALARS:
        return dict(_SCALARS[tp])
    if is_typeddict(tp):
        name = typing.cast(type, tp).__name__
        if name not in defs:
            defs[name] = {}  # placeholder: a TypedDict that refers to itself
            defs[name] = _typeddict(typing.cast(type, tp), defs)
        return {"$ref": f"#/$defs/{name}"}
    origin, args = get_origin(tp), get_args(tp)
    if origin is Literal:
        return {"enum": list(args)}
    if origin in (Union, types.UnionType):
        return {"anyOf": [_schema(a, defs) for a in args]}
    if origin is list:
        return {"type": "array", "items": _schema(args[0], defs)} if args else {"type": "array"}
    if origin in (dict, Mapping) or tp is dict:
        if args and args[0] is not str:
            raise TypeError(f"JSON object keys are strings, not {args[0]!r}")
        return {"type": "object", "additionalProperties": _schema(args[1], defs)} if args else {"type": "object"}
    raise TypeError(f"no JSON Schema for {tp!r}")


def _typeddict(td: type, defs: dict[str, object]) -> dict[str, object]:
    """A TypedDict as a closed object: its keys, the required ones, and no other."""
    hints = get_type_hints(td, include_extras=True)
    total = bool(getattr(td, "__total__", True))
    # read from the hints, not __required_keys__: under postponed annotations Python 3.11 sees strings there
    required = sorted(k for k, v in hints.items()
                      if get_origin(v) is Required or (total and get_origin(v) is not NotRequired))
    out: dict[str, object] = {
        "type": "object",
        "properties": {k: _schema(v, defs) for k, v in hints.items()},
        "required": required,
        "additionalProperties": False,
    }
    if td.__doc__:
        out["description"] = " ".join(td.__doc__.split())
    return out


def schema_of(td: type, title: str) -> dict[str, object]:
    """The JSON Schema (draft 2020-12) of a report whose top level is the TypedDict ``td``.

    Parameters
    ----------
    td : type
        The report's TypedDict.
    title : str
        The schema's title.

    Returns
    -------
    dict
        The schema, its TypedDicts under ``$defs``.
    """
    if not is_typeddict(td):
        raise TypeError(f"{td!r} is not a TypedDict")
    defs: dict[str, object] = {}
    top = _typeddict(td, defs)
    return {"$schema": DIALECT, "title": title, **top, "$defs": {k: defs[k] for k in sorted(defs)}}


def violations(report: Mapping[str, object], schema: Mapping[str, object]) -> list[str]:
    """Every place ``report`` breaks ``schema``, as ``path: message`` lines (empty when it holds).

    Parameters
    ----------
    report : Mapping[str, object]
        The report, as it will be written.
    schema : Mapping[str, object]
        Its schema (:func:`schema_of`).
    """
    validator = jsonschema.Draft202012Validator(schema)
    out = []
    for err in sorted(validator.iter_errors(report), key=lambda e: list(map(str, e.absolute_path))):
        path = "/".join(str(p) for p in err.absolute_path) or "(top)"
        out.append(f"{path}: {err.message[:300]}")
    return out


def check(report: Mapping[str, object], schema: Mapping[str, object], what: str) -> None:
    """Validate a report against its schema: a warning when it breaks it, an error under ``EMA_STRICT_REPORTS=1``.

    Parameters
    ----------
    report : mapping
        The report, as it will be written.
    schema : mapping
        Its schema (:func:`schema_of`).
    what : str
        The report's name in the message (``ema identify``).
    """
    found = violations(report, schema)
    if not found:
        return
    text = f"the {what} report does not match its published schema: " + "; ".join(found[:8])
    if len(found) > 8:
        text += f"; and {len(found) - 8} more"
    if os.environ.get(STRICT_ENV, "") not in ("", "0"):
        raise ReportContractError(text)
    warnings.warn(text, stacklevel=2)

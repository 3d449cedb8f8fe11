"""Parameter metadata: every parameter declared once, everything else read from that declaration.

A parameter set is a frozen dataclass whose fields are declared with :func:`param`: unit, range,
description, where its default comes from (a channel's YAML section or its physical data, whose
declaration a linked field shares: :func:`linked`), its
conversion into the numba kernel's units and the kernel slot it fills, the value that switches its
stage off and the element name that does so by name (``--disable``), and the report's uncertainty
bounds where the report gives them. From that one declaration come

* the loader, :func:`load` (channel data, YAML section and subsections, then overrides),
* the validator, :func:`validate` (range, finiteness, switch-off value, a text's choices, declared relations,
  and the relations of the set linked fields come from),
* the kernel layout, :func:`kernel_layout` and :func:`kernel_vector` (slots generated from the
  declared kernel names, never numbered by hand), and :func:`slots` for any other index layout,
* the listing, :func:`describe` (:class:`ParameterInfo`), which identification bounds, Monte Carlo
  dispersions and ROS parameter descriptors (units, ranges) read.

A set may carry data that are not parameters (a channel's model-family sections): such a field is
declared with :func:`carried`, loaded as given and listed nowhere.

Numba's on-disk cache does not follow changes in other modules: after changing a layout, remove the
``__pycache__`` directories so every kernel recompiles against it. One concept, the declaration and what is read
from it, in one module of about 720 lines: the readers above must agree with each other, so they sit together.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import itertools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import Any, Protocol, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import ConfigError, UnknownNameError

META_KEY = "ema_sim"
"""The key of a field's ``metadata`` that holds its :class:`Meta`."""
CARRIED_KEY = "ema_sim.carried"
"""The key of a field's ``metadata`` that marks it carried, not a parameter (:func:`carried`)."""

P = TypeVar("P")
Value = float | tuple[float, ...] | str
"""A parameter's value: a number, a fixed number of them (a curve's breakpoints), or a text (a name)."""
Relation = tuple[str, str, str]
"""``(a, "<" or "<=", b)``: a declared relation between two parameters of a set."""


@dataclass(frozen=True)
class Meta:
    """What one parameter is: the single source of its unit, range, slot and switch.

    Parameters
    ----------
    unit : str
        Unit of the value as the YAML file and the dataclass hold it (``"rad/s"``, ``"-"``...).
    description : str
        What it is, with the report's section or figure.
    min, max : float
        Valid range (inclusive; see ``min_exclusive``). Identification fits inside it.
    min_exclusive : bool
        True when ``min`` itself is not allowed (a positive quantity).
    size : int
        Number of values: 1 for a number, more for a tuple (a curve).
    increasing : bool
        A tuple's values must be strictly increasing (breakpoints).
    off : float or None
        The value that switches the parameter's stage off (allowed outside the range); None when
        the stage cannot be switched off.
    element : str or None
        The element name that switches it off by name (``--disable``); None for none.
    kernel : str or None
        Name of the kernel slot it fills, with the kernel's unit in the name; None when it has no
        slot of its own (it enters through other slots' conversions).
    to_kernel : float or callable
        Kernel value: the value times this factor, or this function of the whole parameter set.
    uncertainty : tuple of float or None
        (low, high) the report gives for it, in ``unit``; None where the report gives none.
    uncertainty_source : str
        Where the report gives ``uncertainty``.
    choices : tuple of str or None
        A text parameter (a name), one of these; None for a number.
    channel : str or None
        Attribute of :class:`~ema_sim.config.ChannelConfig` the default comes from (see :func:`linked`).
    source : type or None
        The parameter set that declares the ``channel`` attribute; its relations apply to the linked fields.
    section : str or None
        YAML subsection of the family's section it lives in (``"hoad3"``); None: the top level.
    variants : tuple of str
        Variants whose own subsection holds it (``("hoad2", "hoad3")``); absent: the field default.
    """

    unit: str
    description: str
    min: float = -math.inf
    max: float = math.inf
    min_exclusive: bool = False
    size: int = 1
    increasing: bool = False
    off: float | None = None
    element: str | None = None
    kernel: str | None = None
    to_kernel: float | Callable[[Any], float] = 1.0
    uncertainty: tuple[float, float] | None = None
    uncertainty_source: str = ""
    choices: tuple[str, ...] | None = None
    channel: str | None = None
    source: type | None = None
    section: str | None = None
    variants: tuple[str, ...] = ()

    def range_text(self) -> str:
        """The range in words, for messages and listings."""
        if self.choices is not None:
            return "one of " + ", ".join(self.choices)
        low = "(" if self.min_exclusive else "["
        return f"{low}{self.min:g}, {self.max:g}] {self.unit}"


def param(unit: str, description: str, *, default: Any = MISSING, **meta: Any) -> Any:
    """A dataclass field declared with its :class:`Meta` (the keyword arguments).

    Parameters
    ----------
    unit : str
        Unit of the value (see :class:`Meta`).
    description : str
        What it is (see :class:`Meta`).
    default : float, optional
        Field default; without one the value must come from the channel or its section.
    **meta
        The other :class:`Meta` fields (``min``, ``max``, ``kernel``, ``off``...).

    Returns
    -------
    dataclasses.Field
        The field, for a dataclass body.
    """
    info = Meta(unit, description, **meta)
    return dataclasses.field(default=default, metadata={META_KEY: info})


def linked(source: type, name: str, *, description: str | None = None, **meta: Any) -> Any:
    """A field whose default is attribute ``name`` of a ``source`` set, sharing that declaration.

    Unit, range, size, uncertainty and description come from the source's field (declared once there);
    ``meta`` adds what the linking set does with the value (its kernel slot, conversion, switch-off value).
    The source's declared relations between linked attributes hold for the linked fields too.

    Parameters
    ----------
    source : type
        The parameter set that declares the value (:class:`~ema_sim.config.ChannelConfig`).
    name : str
        Its field in ``source``.
    description : str, optional
        The value's role in the linking set (default: the source's description).
    **meta
        Further :class:`Meta` fields (``kernel``, ``to_kernel``, ``off``, ``element``...).

    Returns
    -------
    dataclasses.Field
        The field, for a dataclass body.
    """
    shared = metas(source)[name]
    info = dataclasses.replace(shared, channel=name, source=source,
                               description=shared.description if description is None else description, **meta)
    return dataclasses.field(default=MISSING, metadata={META_KEY: info})


def carried(description: str, *, default_factory: Callable[[], object]) -> Any:
    """A field a parameter set carries that is no parameter (not loaded by name, checked or listed).

    Parameters
    ----------
    description : str
        What it holds.
    default_factory : callable
        Its default (an empty mapping...).

    Returns
    -------
    dataclasses.Field
        The field, for a dataclass body.
    """
    return dataclasses.field(default_factory=default_factory, metadata={CARRIED_KEY: description})


def meta_of(field: dataclasses.Field[object]) -> Meta:
    """The :class:`Meta` of a field declared with :func:`param`.

    Parameters
    ----------
    field : dataclasses.Field
        A field of a parameter dataclass.

    Returns
    -------
    Meta
        Its metadata (a ``TypeError`` names a field declared without :func:`param`).
    """
    info = field.metadata.get(META_KEY)
    if not isinstance(info, Meta):
        raise TypeError(f"parameter field {field.name!r} is not declared with ema_sim.parameters.param")
    return info


def metas(cls: object) -> dict[str, Meta]:
    """Field name → :class:`Meta` of a parameter dataclass, in declaration order.

    Parameters
    ----------
    cls : type or instance
        A parameter dataclass (or an instance).

    Returns
    -------
    dict
        One entry per field (the same dict every call: do not change it).
    """
    return _metas(cls if isinstance(cls, type) else type(cls))


@functools.cache
def _metas(cls: type) -> dict[str, Meta]:
    return {f.name: meta_of(f) for f in fields(cls) if CARRIED_KEY not in f.metadata}


def relations(cls: object) -> tuple[Relation, ...]:
    """The declared relations of a set: its own ``RELATIONS``, then its linked sources' between linked fields.

    Parameters
    ----------
    cls : type or instance
        A parameter dataclass (or an instance).

    Returns
    -------
    tuple of Relation
        Each ``(a, "<" or "<=", b)`` in the set's own field names.
    """
    return _relations(cls if isinstance(cls, type) else type(cls))


@functools.cache
def _relations(cls: type) -> tuple[Relation, ...]:
    own: tuple[Relation, ...] = tuple(getattr(cls, "RELATIONS", ()))
    out = list(own)
    sources = dict.fromkeys(m.source for m in metas(cls).values() if m.source is not None)
    for source in sources:
        local = {m.channel: n for n, m in metas(cls).items() if m.source is source}
        out += [(local[a], rel, local[b]) for a, rel, b in relations(source) if a in local and b in local]
    return tuple(dict.fromkeys(out))


# ---------------------------------------------------------------------------------------- layouts
class Slots(Protocol):
    """An index layout: one integer attribute per name, frozen into numba kernels as constants."""

    def __getattr__(self, name: str) -> int: ...

    def __len__(self) -> int: ...


def slots(name: str, names: Iterable[str]) -> Slots:
    """An index layout with one slot per name, numbered in order (a namedtuple numba reads as constants).

    Parameters
    ----------
    name : str
        Type name of the layout (for reprs).
    names : iterable of str
        The slot names, units in the names.

    Returns
    -------
    Slots
        ``layout.<name>`` is the slot's index; ``len(layout)`` the number of slots.
    """
    names = tuple(names)
    if len(set(names)) != len(names):
        raise ValueError(f"{name}: slot names repeat")
    return cast("Slots", collections.namedtuple(name, names)(*range(len(names))))


def kernel_names(cls: type, extra: Sequence[str] = ()) -> tuple[str, ...]:
    """The kernel slot names of a parameter set: declared ``kernel`` names in field order, then ``extra``.

    Parameters
    ----------
    cls : type
        A parameter dataclass.
    extra : sequence of str
        Slots no single parameter fills (derived from several, options, calibration).

    Returns
    -------
    tuple of str
        The slot names in slot order.
    """
    return tuple(m.kernel for m in metas(cls).values() if m.kernel is not None) + tuple(extra)


def kernel_layout(cls: type, extra: Sequence[str] = ()) -> Slots:
    """The kernel layout of a parameter set (see :func:`kernel_names`).

    Parameters
    ----------
    cls : type
        A parameter dataclass.
    extra : sequence of str
        Slots no single parameter fills.

    Returns
    -------
    Slots
        Slot name → index.
    """
    return slots(f"{cls.__name__}Kernel", kernel_names(cls, extra))


def kernel_vector(params: object, layout: Slots, extra: Mapping[str, float] | None = None) -> NDArray[np.float64]:
    """The parameters in kernel order and kernel units.

    Parameters
    ----------
    params : dataclass instance
        A parameter set declared with :func:`param`.
    layout : Slots
        Its :func:`kernel_layout`.
    extra : mapping, optional
        The value of every extra slot of the layout.

    Returns
    -------
    numpy.ndarray
        One float per slot.
    """
    values = np.zeros(len(layout))
    filled = set()
    for name, m in metas(params).items():
        if m.kernel is None:
            continue
        conv = m.to_kernel
        values[getattr(layout, m.kernel)] = conv(params) if callable(conv) else getattr(params, name) * conv
        filled.add(m.kernel)
    for key, value in (extra or {}).items():
        values[getattr(layout, key)] = value
        filled.add(key)
    missing = [n for n in cast("tuple[str, ...]", layout._fields) if n not in filled]
    if missing:
        raise ValueError(f"kernel slots without a value: {', '.join(missing)}")
    return values


# ------------------------------------------------------------------------------ loading and checking
def coerce(name: str, m: Meta, value: Any, origin: str, family: str) -> Value:
    """A parameter's value as a float (or ``m.size`` floats) from YAML or an override; one error naming it.

    A string is refused even when it reads as a number: YAML 1.1 reads ``5.0e6`` (no exponent sign) as a
    string, and a ROS node would too.

    Parameters
    ----------
    name : str
        The parameter.
    m : Meta
        Its metadata.
    value : object
        The value given.
    origin : str
        Where it comes from, for messages.
    family : str
        The family's name in messages.

    Returns
    -------
    float, tuple of float or str
        The value.
    """
    if m.choices is not None:
        if not isinstance(value, str) or (m.choices and value not in m.choices):
            raise ConfigError(f"{origin}: {family} parameter {name} must be {m.range_text()}, got {value!r}")
        return value
    bad = ConfigError(f"{origin}: {family} parameter {name} must be a number, got {value!r}")
    try:
        if m.size == 1:
            if isinstance(value, str | bytes):
                raise bad
            return float(value)
        items = tuple(float(x) for x in np.asarray(value, dtype=float).ravel())
    except (TypeError, ValueError):
        raise bad from None
    if len(items) != m.size:
        raise ConfigError(f"{origin}: {family} parameter {name} needs {m.size} values, got {len(items)}")
    return items


def load(
    cls: type[P],
    values: Mapping[str, object],
    *,
    origin: str,
    family: str,
    section: str = "",
    overrides: Mapping[str, object] | None = None,
    options: Iterable[str] = (),
    variant: str | None = None,
    source: object = None,
    carry: Mapping[str, object] | None = None,
) -> P:
    """The one loader: a parameter set from a YAML mapping (with subsections) and overrides, validated.

    Parameters
    ----------
    cls : type
        The parameter dataclass.
    values : mapping
        The YAML mapping (a channel's family section, a profile's path); nested mappings are the
        subsections fields declare with ``section`` or ``variants``.
    origin : str
        Where the values come from, for messages (a file or channel name).
    family : str
        The family's name in messages (``"second-order"``).
    section : str
        The section's name in messages (``"second_order"``).
    overrides : mapping, optional
        Values that replace the file's (unknown names are an :class:`~ema_sim.errors.UnknownNameError`).
    options : iterable of str
        Names the caller accepts besides the parameters (listed with them when a name is unknown).
    variant : str, optional
        Which variant subsection the ``variants`` fields come from.
    source : parameter set, optional
        The set the :func:`linked` fields take their values from before the file's (a channel's
        :class:`~ema_sim.config.ChannelConfig`).
    carry : mapping, optional
        The values of the :func:`carried` fields, as they are.

    Returns
    -------
    object
        The validated parameter set.
    """
    info = metas(cls)
    where = section or family
    chosen: dict[str, object] = {n: getattr(source, m.channel) for n, m in info.items()
                              if source is not None and m.channel is not None}
    for key, value in values.items():
        if isinstance(value, Mapping):
            fixed = [n for n, m in info.items() if m.section == key]
            varied = [n for n, m in info.items() if key in m.variants]
            if not fixed and not varied:
                raise ConfigError(f"{origin}: unknown parameter {key!r} in {where}")
            for sub, sub_value in value.items():
                if sub not in fixed and sub not in varied:
                    raise ConfigError(f"{origin}: unknown parameter {sub!r} in {where}.{key}")
                if sub in fixed or key == variant:
                    chosen[sub] = sub_value
            continue
        m = info.get(key)
        if m is None or m.section is not None or m.variants:
            raise ConfigError(f"{origin}: unknown parameter {key!r} in {where}")
        chosen[key] = value
    for key, value in (overrides or {}).items():
        if key not in info:
            raise UnknownNameError(f"{family} parameter", key, [*info, *options])
        chosen[key] = value
    required = {f.name for f in fields(cls) if f.default is MISSING and f.name in info}  # type: ignore[arg-type]
    missing = sorted(required - chosen.keys())
    if missing:
        raise ConfigError(f"{origin}: {where} is missing {', '.join(missing)}")
    out = cls(**{k: coerce(k, info[k], v, origin, family) for k, v in chosen.items()}, **(carry or {}))
    validate(out, family, origin)
    return out


def _bad(value: float, m: Meta) -> str | None:
    """Why ``value`` is outside ``m``'s range (None when it is inside or switches the stage off)."""
    why = None
    low = value < m.min or (m.min_exclusive and value == m.min)
    if math.isnan(value) or (math.isinf(value) and value != m.off):
        why = "must be finite"
    elif m.off is not None and value == m.off:
        why = None
    elif low and m.min >= 0.0 and value <= 0.0 and (m.min > 0.0 or m.min_exclusive):
        why = f"must be positive, got {value:g} (range {m.range_text()})"
    elif low and m.min == 0.0:
        why = f"must be a finite number ≥ 0, got {value:g}"
    elif low:
        why = f"must be {'>' if m.min_exclusive else '≥'} {m.min:g}, got {value:g} (range {m.range_text()})"
    elif value > m.max:
        why = f"must not exceed {m.max:g}, got {value:g} (range {m.range_text()})"
    return why



_VALID = "_validated"
"""The attribute a frozen parameter set carries once it has passed :func:`validate` (not a field)."""


def validate(params: Any, family: str, origin: str = "") -> None:
    """The one validator: every value in its declared range, then the set's declared relations.

    Parameters
    ----------
    params : dataclass instance
        A parameter set declared with :func:`param`; its class may declare ``RELATIONS``
        (a tuple of :data:`Relation`), and the sets its :func:`linked` fields come from theirs
        (:func:`relations`).
    family : str
        The family's name in messages.
    origin : str
        Where the values come from, prefixed to messages when given.

    Raises
    ------
    ConfigError
        One message naming the parameter and what is wrong with it.
    """
    frozen = type(params).__dataclass_params__.frozen
    if frozen and params.__dict__.get(_VALID):
        return  # a frozen set cannot have changed since it passed
    where = f"{origin}: " if origin else ""
    for name, m in metas(params).items():
        value = getattr(params, name)
        if m.choices is not None:
            if not isinstance(value, str) or (m.choices and value not in m.choices):
                raise ConfigError(f"{where}{family} parameter {name} must be {m.range_text()}, got {value!r}")
            continue
        items = value if isinstance(value, tuple) else (value,)
        for item in items:
            why = _bad(item, m)
            if why is not None:
                raise ConfigError(f"{where}{family} parameter {name} {why}")
        if m.increasing and not all(a < b for a, b in itertools.pairwise(items)):
            raise ConfigError(f"{where}{family} parameter {name} must be {m.size} increasing values, got {items}")
    for a, rel, b in relations(params):
        va, vb = getattr(params, a), getattr(params, b)
        if rel == "<" and not va < vb:
            raise ConfigError(f"{where}{family} parameter {a} must be below {b}")
        if rel == "<=" and not va <= vb:
            raise ConfigError(f"{where}{family} parameter {b} must be at least {a}")
    if frozen:
        object.__setattr__(params, _VALID, True)


def switched_off(cls: type, elements: Iterable[str] | None = None) -> dict[str, float]:
    """Parameter → switch-off value, for every switchable parameter (or those of the named elements).

    Parameters
    ----------
    cls : type
        A parameter dataclass.
    elements : iterable of str, optional
        Element names (``Meta.element``); all switchable parameters when omitted.

    Returns
    -------
    dict
        The overrides that switch those stages off.
    """
    chosen = None if elements is None else set(elements)
    return {n: m.off for n, m in metas(cls).items()
            if m.off is not None and (chosen is None or m.element in chosen)}


def elements(cls: type) -> tuple[str, ...]:
    """The element names a parameter set switches off by name, in declaration order.

    Parameters
    ----------
    cls : type
        A parameter dataclass.

    Returns
    -------
    tuple of str
        Each name once.
    """
    return tuple(dict.fromkeys(m.element for m in metas(cls).values() if m.element is not None))


# ----------------------------------------------------------------------------------------- listing
@dataclass(frozen=True)
class ParameterInfo:
    """One parameter as other tools read it (identification bounds, dispersions, ROS descriptors).

    Parameters
    ----------
    name : str
        Field and YAML key, unit in the name.
    path : str
        Dotted YAML path under the node's ``ros__parameters`` (``high_order.hoad3.quantization_v``);
        the channel attribute's name for values from the channel's physical data.
    unit : str
        Unit of the value.
    description : str
        What it is.
    min, max : float
        Valid range.
    min_exclusive : bool
        True when ``min`` is excluded.
    size : int
        Number of values (1, or a tuple's length).
    default : float, tuple of float or None
        The value for the channel asked for (None when no channel was given).
    switchable : bool
        True when the stage can be switched off.
    off : float or None
        Its switch-off value.
    element : str or None
        The element name that switches it off by name.
    slot : int or None
        Its kernel slot; None when it has none of its own.
    kernel : str or None
        The slot's name, kernel unit in the name.
    uncertainty : tuple of float or None
        The report's (low, high) for it.
    uncertainty_source : str
        Where the report gives it.
    """

    name: str
    path: str
    unit: str
    description: str
    min: float
    max: float
    min_exclusive: bool
    size: int
    default: Value | None
    switchable: bool
    off: float | None
    element: str | None
    slot: int | None
    kernel: str | None
    uncertainty: tuple[float, float] | None
    uncertainty_source: str


def describe(cls: type, *, defaults: object = None, layout: Slots | None = None, section: str = "",
             variant: str | None = None) -> list[ParameterInfo]:
    """Every parameter of a set with its metadata, the defaults of one channel and its kernel slot.

    Parameters
    ----------
    cls : type
        A parameter dataclass.
    defaults : dataclass instance, optional
        A loaded set whose values are listed as defaults.
    layout : Slots, optional
        The kernel layout whose slot numbers are listed.
    section : str
        The YAML section the set is loaded from (for the paths).
    variant : str, optional
        The variant whose subsection the ``variants`` fields come from.

    Returns
    -------
    list of ParameterInfo
        In declaration order.
    """
    out = []
    for name, m in metas(cls).items():
        if m.channel is not None:
            path = m.channel
        else:
            sub = m.section or (variant if variant in m.variants else None)
            path = ".".join(p for p in (section, sub, name) if p)
        out.append(ParameterInfo(
            name=name, path=path, unit=m.unit, description=m.description, min=m.min, max=m.max,
            min_exclusive=m.min_exclusive, size=m.size,
            default=None if defaults is None else getattr(defaults, name), switchable=m.off is not None,
            off=m.off, element=m.element,
            slot=None if layout is None or m.kernel is None else getattr(layout, m.kernel),
            kernel=m.kernel, uncertainty=m.uncertainty, uncertainty_source=m.uncertainty_source,
        ))
    return out


def parameters_doc(cls: type) -> str:
    """A numpydoc ``Parameters`` section generated from the metadata (appended to the class docstring).

    Parameters
    ----------
    cls : type
        A parameter dataclass.

    Returns
    -------
    str
        The section text.
    """
    lines = ["", "Parameters", "----------"]
    for name, m in metas(cls).items():
        kind = "str" if m.choices is not None else "float" if m.size == 1 else f"tuple of {m.size} float"
        extra = f"; off: {m.off:g}" if m.off is not None else ""
        lines += [f"{name} : {kind}", f"    {m.description} ({m.range_text()}{extra})."]
    return "\n".join(lines)


def documented(cls: type[P]) -> type[P]:
    """Class decorator: append :func:`parameters_doc` to a parameter dataclass's docstring.

    Parameters
    ----------
    cls : type
        A parameter dataclass.

    Returns
    -------
    type
        The same class.
    """
    cls.__doc__ = (cls.__doc__ or "").rstrip() + "\n" + parameters_doc(cls) + "\n"
    return cls

"""A node's ROS parameters: declared at start-up with descriptors, changed at run time only where it takes effect.

Every suite node declares all of its parameters when it starts (``ros2 param list`` shows them before any
file is given), each with a descriptor: what it is, its unit, its range and whether it is read-only. A
parameter file (``--params-file``) or a command-line flag overrides the declared default, which comes from
the package's ``config/`` files. A run-time change (``ros2 param set``) of a parameter the node can apply
mid-run (the EMAC's watchdog, failure and motor power; the test environment's noise, delay, lag and
quantization) takes effect at the next frame and is logged; every other parameter is read-only, its description
says why (:attr:`Spec.why`), and ROS refuses the change with the reason (``Trying to set a read-only
parameter``); a value outside the declared range is refused the same way.
"""

from __future__ import annotations

import copy
import math
import re
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ema_sim.errors import ConfigError, EmaError
from ema_sim.jsontypes import JsonObject
from ema_sim.parameters import ParameterInfo

if TYPE_CHECKING:
    from rclpy.parameter import AllowableParameterValue as ParameterValue

ARRAYS = frozenset({ParameterType.PARAMETER_BOOL_ARRAY, ParameterType.PARAMETER_INTEGER_ARRAY,
                    ParameterType.PARAMETER_DOUBLE_ARRAY, ParameterType.PARAMETER_STRING_ARRAY,
                    ParameterType.PARAMETER_BYTE_ARRAY})
"""The list parameter types."""
HUGE = sys.float_info.max
"""Open end of a range (a ROS range needs both ends)."""
READ_AT_START = "read when the node starts (what it sets up is built once): restart the node to change it"
"""Why a parameter is read-only, unless its :class:`Spec` says more."""

@dataclass(frozen=True)
class Spec:
    """One parameter: its default and its descriptor's content."""

    name: str
    default: object
    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    read_only: bool = True
    kind: int | None = None
    """A :class:`ParameterType` where the default cannot tell (an empty list)."""
    why: str = ""
    """Why it is read-only, in its description (empty: :data:`READ_AT_START`)."""

    def type(self) -> int:
        """The ROS parameter type."""
        if self.kind is not None:
            return self.kind
        return int(Parameter.Type.from_parameter_value(_plain(self.default)).value)

    def descriptor(self) -> ParameterDescriptor:
        """The ROS descriptor: description (with the unit, and why it is read-only), range, read-only flag, type."""
        text = self.description + (f" [{self.unit}]" if self.unit else "")
        if self.read_only and "read-only" not in text:  # a description may say it already, with its reason
            text += f" (read-only: {self.why or READ_AT_START})"
        d = ParameterDescriptor(name=self.name, type=self.type(), description=text, read_only=self.read_only)
        if self.unit:
            d.additional_constraints = f"unit: {self.unit}"
        if self.low is not None or self.high is not None:
            low = -HUGE if self.low is None else self.low
            high = HUGE if self.high is None else self.high
            if d.type == ParameterType.PARAMETER_INTEGER:
                d.integer_range = [IntegerRange(from_value=int(max(low, -2**62)), to_value=int(min(high, 2**62)),
                                                step=0)]
            elif d.type == ParameterType.PARAMETER_DOUBLE:
                d.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
        return d


def _plain(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value


def flatten(mapping: Mapping[str, object], prefix: str = "") -> Iterator[tuple[str, object]]:
    """``{"a": {"b": 1}}`` → ``("a.b", 1)``: a nested parameter mapping as ROS parameter names.

    Parameters
    ----------
    mapping : mapping
        Nested parameters (a section of a parameter file).
    prefix : str
        Put before every name (a section's, dot included: ``"a."``).

    Yields
    ------
    tuple of (str, object)
        Each leaf's dotted name and value.
    """
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from flatten(value, f"{name}.")
        else:
            yield name, value


def nested(flat: Mapping[str, object]) -> dict[str, Any]:
    """``{"a.b": 1}`` → ``{"a": {"b": 1}}``.

    Parameters
    ----------
    flat : mapping
        Parameters by dotted name.

    Returns
    -------
    dict
        The same, nested at each dot.
    """
    out: dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split(".")
        here = out
        for part in parts[:-1]:
            here = here.setdefault(part, {})
        here[parts[-1]] = value
    return out


def merged(base: Mapping[str, object], override: Mapping[str, object]) -> dict[str, object]:
    """Deep merge, ``override`` winning.

    Parameters
    ----------
    base : mapping
        Nested parameters.
    override : mapping
        Nested parameters that replace ``base``'s, key by key (a mapping merged into a mapping).

    Returns
    -------
    dict
        A new mapping (neither argument is changed).
    """
    out = copy.deepcopy(dict(base))
    for key, value in override.items():
        current = out.get(key)
        if isinstance(value, Mapping) and isinstance(current, Mapping):
            out[key] = merged(current, value)
        else:
            out[key] = value
    return out


def declared_spec(name: str, default: object, info: ParameterInfo, where: str, *, read_only: bool = True) -> Spec:
    """The spec of a declared parameter: description, unit and range from its one declaration.

    Parameters
    ----------
    name : str
        The ROS parameter's name.
    default : object
        Its default value.
    info : ParameterInfo
        The parameter's metadata (:func:`ema_sim.parameters.describe`).
    where : str
        Where the default comes from, appended to the description.
    read_only : bool
        Whether a run-time change is refused.

    Returns
    -------
    Spec
        The spec; the range is widened to take the parameter's switch-off value.
    """
    low: float | None = None
    high: float | None = None
    if info.size == 1:
        lo, hi = info.min, info.max
        if info.off is not None:
            lo, hi = min(lo, info.off), max(hi, info.off)
        low, high = (lo if math.isfinite(lo) else None), (hi if math.isfinite(hi) else None)
    unit = "" if info.unit in ("", "-") else info.unit
    return Spec(name, default, f"{info.description} ({where})", unit, low, high, read_only=read_only)


def config_specs(values: Mapping[str, object], origin: str, prefix: str = "",
                 known: Mapping[str, ParameterInfo] | None = None) -> list[Spec]:
    """Read-only specs of a parameter file's mapping: defaults its values, the rest from the declarations.

    Parameters
    ----------
    values : mapping
        The file's ``ros__parameters`` (nested).
    origin : str
        Where the values come from, for the descriptions.
    prefix : str
        Names go under ``prefix.`` (none when empty).
    known : mapping, optional
        YAML path → the declared parameter's metadata: its description, unit and range
        (:func:`declared_spec`). A value not declared there is described by its origin alone.

    Returns
    -------
    list of Spec
        One per value, in file order.
    """
    out = []
    for path, value in flatten(values):
        name = f"{prefix}.{path}" if prefix else path
        info = (known or {}).get(path)
        out.append(Spec(name, value, f"from {origin}") if info is None else declared_spec(name, value, info, origin))
    return out


def names_list(text: str) -> list[str]:
    """A comma-separated list flag's items (repeated flags are joined by :func:`ema_sim.nodes.common.run_nodes`).

    Parameters
    ----------
    text : str
        The flag's value, e.g. ``left_wing,rudder``.

    Returns
    -------
    list of str
        Its non-empty items, stripped.
    """
    return [item.strip() for item in text.split(",") if item.strip()]


def cli_overrides(args: object, exclude: Iterable[str] = ()) -> list[Parameter]:
    """The flags given on a node's command line as parameter overrides (they win over parameter files).

    A parser whose options default to ``argparse.SUPPRESS`` and whose ``dest`` is the parameter's name
    gives exactly the flags that were given.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed flags.
    exclude : iterable of str
        Flags that are not parameters (the node resolves them itself).

    Returns
    -------
    list of rclpy.parameter.Parameter
        One per flag given.
    """
    skip = set(exclude)
    return [Parameter(k, value=_plain(v)) for k, v in vars(args).items() if k not in skip and v is not None]


class Declared:
    """The parameters a node declared, their values, and who applies a run-time change.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (its set-parameters callback is registered here).
    """

    def __init__(self, node: Node) -> None:
        self.node = node
        self.specs: dict[str, Spec] = {}
        self.appliers: dict[str, Callable[[ParameterValue], str]] = {}
        node.add_on_set_parameters_callback(self._on_set)

    def declare(self, specs: Sequence[Spec], origin: str) -> dict[str, Any]:
        """Declare ``specs`` (overrides applied); their values by name. A bad override is one :class:`ConfigError`.

        Parameters
        ----------
        specs : sequence of Spec
            The parameters.
        origin : str
            What declares them, for the error message.

        Returns
        -------
        dict
            Each parameter's value by name.
        """
        node = self.node
        overrides = node._parameter_overrides  # a file's 25 for a double parameter becomes 25.0
        batch: list[tuple[str] | tuple[str, Parameter.Type] | tuple[str, object, ParameterDescriptor]] = []
        empty: list[Parameter] = []  # lists declared empty (by default, or by a file's [], which rcl gives untyped)
        for spec in specs:
            d = spec.descriptor()
            given = overrides.get(spec.name)
            if given is not None and given.type_ == Parameter.Type.NOT_SET and d.type in ARRAYS:
                del overrides[spec.name]  # a file's [] (rcl gives it no type): the list is empty
                given, is_empty = None, True
            else:
                is_empty = given is None and isinstance(spec.default, list | tuple) and not spec.default
            if given is not None:
                overrides[spec.name] = _coerced(given, d.type)
            value: object = _plain(spec.default)
            if is_empty:  # an empty list tells no type: declare the type, then set the empty value
                value = Parameter.Type(d.type)
                empty.append(Parameter(spec.name, Parameter.Type(d.type), []))
            elif isinstance(value, list) and not value:
                value = overrides[spec.name].value
            batch.append((spec.name, value, d))
            self.specs[spec.name] = spec
        try:
            node.declare_parameters("", batch)
            # A list declared empty has a value, not only a type, so GetParameters, a dump and rqt show it:
            # rclpy types a bare [] as a byte array, so it is set with its declared type (as the declaration's
            # own value: without the read-only check).
            if empty:
                done = node._set_parameters_atomically_common(
                    empty, {p.name: node.describe_parameter(p.name) for p in empty})
                if not done.successful:
                    raise InvalidParameterValueException(", ".join(p.name for p in empty), [], done.reason)
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            raise ConfigError(f"{node.get_name()} parameters ({origin}): {exc}") from None
        return {spec.name: self.value(spec.name) for spec in specs}

    def value(self, name: str) -> object:
        """A declared parameter's value (an empty list when a list parameter was never set).

        Parameters
        ----------
        name : str
            The parameter.

        Returns
        -------
        object
            Its value.
        """
        p = self.node.get_parameter_or(name, Parameter(name, value=None))
        if p.type_ == Parameter.Type.NOT_SET:
            return []
        value = p.value
        return list(value) if isinstance(value, list | tuple) or hasattr(value, "tolist") else value

    def prefixed(self, prefix: str) -> JsonObject:
        """The declared values under ``prefix.``, nested, prefix stripped.

        Parameters
        ----------
        prefix : str
            A section, e.g. ``model``.

        Returns
        -------
        dict
            Its values, nested.
        """
        n = len(prefix) + 1
        return nested({name[n:]: self.value(name) for name in self.specs if name.startswith(prefix + ".")})

    def on_change(self, name: str, apply: Callable[[ParameterValue], str]) -> None:
        """``apply(value)`` makes a run-time change take effect and says what changed (for the log).

        Parameters
        ----------
        name : str
            A parameter declared writable.
        apply : callable
            Called with the new value; returns a line for the log, or raises ``EmaError`` or ``ValueError`` to
        refuse the change (with that reason).
        """
        self.appliers[name] = apply

    def _on_set(self, params: Sequence[Parameter]) -> SetParametersResult:
        applied = []
        for p in params:
            if p.name == "use_sim_time" and self.node.has_parameter(p.name) \
                    and p.value != self.node.get_parameter(p.name).value:
                return SetParametersResult(successful=False, reason=(
                    "use_sim_time is read when the node starts (true: lockstep on /clock, frame by frame); restart "
                    "the node with -p use_sim_time:=true or false"))
            apply = self.appliers.get(p.name)
            if apply is None:
                continue
            try:
                applied.append(apply(p.value))
            except (EmaError, ValueError) as exc:  # refused with the reason; the node goes on
                return SetParametersResult(successful=False, reason=f"{p.name}: {exc}")
        for line in applied:
            self.node.get_logger().info(line)
        return SetParametersResult(successful=True)


def as_float(value: ParameterValue) -> float:
    """A double parameter's new value as a float (rclpy checked it against the declared type).

    Parameters
    ----------
    value : bool, int, float, str or list
        The value a set-parameters request carries.

    Returns
    -------
    float
        The value.

    Raises
    ------
    ValueError
        It is no number (the change is refused with this reason).
    """
    if isinstance(value, int | float):
        return float(value)
    raise ValueError(f"{value!r} is no number")


def _coerced(param: Parameter, kind: int) -> Parameter:
    """An integer override of a double parameter as a double (rcl types ``25`` as an integer)."""
    value = param.value
    if kind == ParameterType.PARAMETER_DOUBLE and param.type_ == Parameter.Type.INTEGER:
        return Parameter(param.name, value=float(value))
    if kind == ParameterType.PARAMETER_DOUBLE_ARRAY and param.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(param.name, value=[float(v) for v in value])
    return param



# --------------------------------------------------------------------------- parameter files as rcl reads them
def ros_arguments(argv: Sequence[str]) -> list[str]:
    """The ROS arguments of a command line: what follows each ``--ros-args`` (up to its ``--``).

    Parameters
    ----------
    argv : sequence of str
        A command line (a process's, or a node's ``cli_args``).

    Returns
    -------
    list of str
        The ROS arguments, in order.
    """
    out: list[str] = []
    inside = False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
        elif arg == "--":
            inside = False
        elif inside:
            out.append(arg)
    return out


def params_files(argv: Sequence[str]) -> list[Path]:
    """The ``--params-file`` paths among a command line's ROS arguments, in order.

    Parameters
    ----------
    argv : sequence of str
        A command line (a process's, or a node's ``cli_args``).

    Returns
    -------
    list of Path
        The parameter files, in the order given.
    """
    args = ros_arguments(argv)
    return [Path(args[i + 1]) for i, a in enumerate(args[:-1]) if a == "--params-file"]


def remapped(argv: Sequence[str], key: str) -> str | None:
    """The last process-wide remapping of ``key`` (``__node``, ``__ns``) among a command line's ROS arguments.

    Parameters
    ----------
    argv : sequence of str
        A command line.
    key : str
        ``__node`` or ``__ns``.

    Returns
    -------
    str or None
        The value remapped to, or None when there is none.
    """
    args = ros_arguments(argv)
    found = None
    for i, a in enumerate(args[:-1]):
        if a in ("-r", "--remap") and args[i + 1].startswith(f"{key}:="):
            found = args[i + 1].split(":=", 1)[1]
    return found


def key_matches(key: str, fqn: str) -> bool:
    """Whether a parameter file's node key applies to the node named ``fqn``, as rcl matches it.

    A key without a leading ``/`` is in the root namespace; ``/*`` stands for one name and ``/**`` for any
    number of them (``/**`` applies to every node, ``/**/emac_left_wing`` to that name in any namespace).

    Parameters
    ----------
    key : str
        The node key of a parameter file (the path down to its ``ros__parameters``).
    fqn : str
        The node's fully qualified name (``/aircraft2/emac_left_wing``).

    Returns
    -------
    bool
        True when the file's parameters under ``key`` are the node's.
    """
    pattern = key if key.startswith("/") else f"/{key}"
    pattern = re.escape(pattern).replace(r"/\*\*", r"(/\w+)*").replace(r"/\*", r"(/\w+)")
    return re.fullmatch(pattern, fqn) is not None


def file_entries(path: Path) -> list[tuple[str, dict[str, Any]]]:
    """(node key, ``ros__parameters`` flattened to ROS names) of every node section of a parameter file.

    Parameters
    ----------
    path : Path
        A ROS 2 parameter file.

    Returns
    -------
    list of (str, dict)
        The sections in file order; nested namespace keys are joined with ``/``.

    Raises
    ------
    ConfigError
        The file cannot be read or is no parameter file.
    """
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"parameter file {path}: cannot read ({exc})") from None
    out: list[tuple[str, dict[str, Any]]] = []

    def walk(mapping: Mapping[str, object], prefix: str) -> None:
        for key, value in mapping.items():
            if not isinstance(value, Mapping):
                continue
            name = f"{prefix}/{key}" if prefix else str(key)
            if isinstance(value.get("ros__parameters"), Mapping):
                out.append((name, dict(flatten(value["ros__parameters"]))))
            else:
                walk(value, name)

    if isinstance(doc, Mapping):
        walk(doc, "")
    return out

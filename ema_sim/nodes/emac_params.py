"""The EMAC node's parameters: which file sections apply to it, its name and channels, what it declares.

An EMAC node (:mod:`ema_sim.nodes.emac`) declares three groups of parameters at start-up, each with a
descriptor (:mod:`ema_sim.nodes.params`): its own (:func:`node_specs`: model, channels, rate, elements
switched off, ``frame_id``), the channel logic's ``emac.*`` settings (:func:`emac_specs`, the
:class:`~ema_sim.emac.EmacSettings` metadata with ``config/emac.yaml``'s defaults) and each hosted channel's
physical and model parameters (:func:`channel_specs`, ``config/<channel>.yaml``). Before it exists, its name
and channels come from the command line and the parameter files that apply to it (:func:`default_name`); once
it exists, every place that names its channels must agree (:func:`resolve_channels`) and a file keyed only for
another EMAC node is an error (:func:`check_files`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from rcl_interfaces.msg import ParameterType
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.parameter import Parameter

from ema_sim.config import CHANNELS, ChannelConfig, config_dir, ros_parameters
from ema_sim.emac import EmacSettings
from ema_sim.emac.channel import RUN_TIME
from ema_sim.errors import ConfigError
from ema_sim.models import model_names
from ema_sim.models.registry import model_parameters
from ema_sim.nodes.params import Spec, config_specs, file_entries, key_matches, params_files, remapped
from ema_sim.nodes.ports import frames_spec
from ema_sim.parameters import ParameterInfo, describe, metas
from ema_sim.signals.plans import channel_list

KNOWN = frozenset(CHANNELS)
"""The channel names."""
STRINGS = ParameterType.PARAMETER_STRING_ARRAY


@dataclass(frozen=True)
class Section:
    """A parameter file section that applies to an EMAC node of a namespace (:func:`emac_sections`)."""

    node: str | None
    """The one EMAC node name it is keyed for (``emac_<channel>``, ``emac``); None: a wildcard key."""
    channels: list[str] | None
    """The channels its ``channels`` or ``channel`` parameter names (None: neither)."""
    where: str
    """``<file>: <key>``, for messages."""


def emac_sections(argv: Sequence[str], namespace: str) -> list[Section]:
    """The sections of a command line's parameter files that apply to an EMAC node named as the suite names them.

    Parameters
    ----------
    argv : sequence of str
        The node's command line (ROS arguments included).
    namespace : str
        The node's namespace (``/`` or ``/aircraft2``).

    Returns
    -------
    list of Section
        In file order: those keyed for one of ``emac_<channel>`` and ``emac`` there, and wildcard ones.
    """
    ns = namespace.rstrip("/")
    ns = ns if not ns or ns.startswith("/") else f"/{ns}"
    out = []
    for path in params_files(argv):
        for key, params in file_entries(path):
            nodes = [n for n in (*(f"emac_{ch}" for ch in CHANNELS), "emac") if key_matches(key, f"{ns}/{n}")]
            if not nodes:
                continue
            value = params.get("channels", params.get("channel"))
            channels = None if value is None else channel_list([value] if isinstance(value, str) else value)
            out.append(Section(nodes[0] if len(nodes) == 1 else None, channels, f"{path}: {key}"))
    return out


def default_name(flag: list[str] | None, argv: Sequence[str], namespace: str | None = None) -> str:
    """The EMAC node's name before any remapping: ``emac_<channel>``, or ``emac`` for a box of several.

    Its channels are ``--channel``'s; else the one channel the command line's parameter files give the node:
    a section keyed for ``emac_<channel>`` in its namespace (a channel file, ``config/<channel>.yaml``), or a
    ``channel`` or ``channels`` parameter in a section that applies to any EMAC node (``/**``). Without either,
    the left wing. A ``-r __node:=`` remapping names the node anyway (its name then gives its channel).

    Parameters
    ----------
    flag : list of str or None
        ``--channel``'s channels.
    argv : sequence of str
        The node's command line (ROS arguments included).
    namespace : str or None
        The node's namespace when not remapped (None: the root).

    Returns
    -------
    str
        The node name.

    Raises
    ------
    ConfigError
        The parameter files give the node different channels and nothing says which.
    """
    def named(channels: list[str]) -> str:
        return f"emac_{channels[0]}" if len(channels) == 1 else "emac"

    if flag:
        return named(flag)
    if remapped(argv, "__node") is not None:
        return "emac"
    found: dict[tuple[str, ...], str] = {}
    for sec in emac_sections(argv, remapped(argv, "__ns") or namespace or "/"):
        if sec.channels is not None:
            found.setdefault(tuple(sec.channels), sec.where)
        elif sec.node is not None and sec.node != "emac":
            found.setdefault((sec.node[len("emac_"):],), sec.where)
    if len(found) > 1:
        said = "; ".join(f"{', '.join(chs)} ({where})" for chs, where in found.items())
        raise ConfigError(f"emac: the parameter files give different channels ({said}): say which with --channel or "
                          "-r __node:=emac_<channel>")
    return named(list(next(iter(found)))) if found else "emac_left_wing"


def node_specs(channels: list[str]) -> list[Spec]:
    """The EMAC node's own parameters.

    Parameters
    ----------
    channels : list of str
        The hosted channels, as resolved before declaring (the ``channels`` default).

    Returns
    -------
    list of Spec
        Model, channels, rate, elements switched off, ``frame_id``, ``frames_per_message``.
    """
    return [
        Spec("model", "loada", "actuator model of every hosted channel (ema models)"),
        Spec("channels", channels, "hosted channels: one, or several for an EMAC box", kind=STRINGS),
        Spec("rate_hz", 0.0, "integration rate of a discrete model (0: the model's default)", "Hz", 0.0, 1e7),
        Spec("disable", [], "model elements switched off: dead_band, quantization, noise (others are the test "
             "environment's and ignored here)", kind=STRINGS),
        Spec("frame_id", channels[0] if len(channels) == 1 else "emac", "header frame_id of the feedback, surface and "
             "bus messages (default: the channel's name; an EMAC box's: emac)"),
        frames_spec(),
    ]


def emac_specs(base: dict[str, Any]) -> list[Spec]:
    """``emac.*``: the channel logic's settings (:class:`EmacSettings` metadata; defaults from ``config/emac.yaml``).

    Parameters
    ----------
    base : dict of str to Any
        ``config/emac.yaml``'s ``emac`` section.

    Returns
    -------
    list of Spec
        The settings, the lockstep wait and each channel's crosstalk noise.
    """
    defaults = EmacSettings.from_parameters({k: v for k, v in base.items() if not isinstance(v, dict)}, "emac.yaml")
    out = []
    for name, m in metas(EmacSettings).items():
        low, high = (m.min if math.isfinite(m.min) else None), (m.max if math.isfinite(m.max) else None)
        out.append(Spec(f"emac.{name}", getattr(defaults, name), m.description, "" if m.unit == "-" else m.unit,
                        low, high, read_only=name not in RUN_TIME))
    out.append(Spec("emac.lockstep_wait_s", float(base.get("lockstep_wait_s", 5.0)),
                    "lockstep: wall time to wait for a frame's inputs while their publishers live", "s", 0.0, 3600.0,
                    read_only=False))
    out.append(Spec("emac.lockstep_source_wait_s", float(base.get("lockstep_source_wait_s", 2.5)),
                    "lockstep: wall time to wait for a frame's peer feedback (the crosstalk sources) while their "
                    "publishers live; below the clock's stall_timeout_s, so a live channel waiting on a dead peer is "
                    "not left out with it", "s", 0.0, 3600.0, read_only=False))
    out += [Spec(f"emac.crosstalk.{ch}_pp_v", float(base.get("crosstalk", {}).get(f"{ch}_pp_v", 0.0)),
                 f"peak-to-peak feedback noise on {ch} while the other channels slew (section 2.2)", "V", 0.0, 20.0)
            for ch in CHANNELS]
    return out


def channel_specs(channel: str, prefix: str = "") -> list[Spec]:
    """A channel's physical and model parameters (``config/<channel>.yaml``), read-only: the model is built once.

    Each value's description, unit and range come from its one declaration (the channel's
    :class:`~ema_sim.config.ChannelConfig` and the model parameter sets' metadata,
    :func:`ema_sim.models.registry.model_parameters`).

    Parameters
    ----------
    channel : str
        The channel.
    prefix : str
        Prepended to every name (``<channel>.``, an EMAC box's), or empty.

    Returns
    -------
    list of Spec
        The channel file's values, read-only.
    """
    path = config_dir() / f"{channel}.yaml"
    where = f"config/{channel}.yaml; the model is built once: read-only"
    return config_specs(ros_parameters(path), where, prefix, known=_declared_parameters())


@cache
def _declared_parameters() -> dict[str, ParameterInfo]:
    """YAML path → the metadata of the channel's data and of every model parameter of every registered model."""
    out: dict[str, ParameterInfo] = {info.path: info for info in describe(ChannelConfig)}
    for name in model_names():
        for info in model_parameters(name):
            out.setdefault(info.path, info)
    return out


def resolve_channels(flag: list[str] | None, name: str, overrides: Mapping[str, Parameter], fqn: str) -> list[str]:
    """The hosted channels, from every place that names them; one :class:`ConfigError` when two disagree.

    ``--channel`` (a shorthand), the node's name after remapping (``emac_<channel>``), and the ``channels``
    and ``channel`` parameters of the parameter files and ``-p`` arguments that apply to the node
    (``channel``: a channel file's, ``config/<channel>.yaml``). None of them: the left wing.

    Parameters
    ----------
    flag : list of str or None
        ``--channel``'s channels.
    name : str
        The node's name (after remapping).
    overrides : mapping of str to Parameter
        The parameter overrides rcl gave the node (its files and ``-p`` arguments).
    fqn : str
        The node's full name, for the message.

    Returns
    -------
    list of str
        The channels.

    Raises
    ------
    ConfigError
        Two places name different channels.
    """
    sources: list[tuple[str, list[str]]] = []
    if flag:
        sources.append(("--channel", flag))
    if name.startswith("emac_") and name[len("emac_"):] in KNOWN:
        sources.append((f"the node's name {name}", [name[len("emac_"):]]))
    for key in ("channels", "channel"):
        p = overrides.get(key)
        if p is not None and p.value is not None:
            value = [p.value] if isinstance(p.value, str) else [str(v) for v in p.value]
            sources.append((f"parameter {key} (a parameter file or -p)", channel_list(value)))
    if not sources:
        return ["left_wing"]
    first = sources[0][1]
    if any(channels != first for _, channels in sources[1:]):
        said = "; ".join(f"{where}: {', '.join(channels)}" for where, channels in sources)
        raise ConfigError(f"{fqn}: the channel is given differently ({said}); give it one way (a parameter file's "
                          "channel, the node name emac_<channel>, or --channel)")
    return first


def check_files(argv: Sequence[str], namespace: str, name: str, fqn: str, logger: RcutilsLogger) -> None:
    """Parameter files keyed for other EMAC nodes and not for this one: one error, or a warning.

    A file keyed for ``emac_right_wing`` given to a node that runs as ``emac_left_wing`` (``--channel``,
    ``-r __node:=``) would leave every value of it unapplied: an error, as is any disagreement on the
    channel (:func:`resolve_channels`). A section keyed with the node's name alone (no leading ``/``)
    applies in the root namespace only (rcl's rule): in another namespace it is not applied, with a warning.

    Parameters
    ----------
    argv : sequence of str
        The node's command line (ROS arguments included).
    namespace : str
        The node's namespace.
    name : str
        The node's name (after remapping).
    fqn : str
        The node's full name, for the messages.
    logger : RcutilsLogger
        The node's logger, for the warning.

    Raises
    ------
    ConfigError
        The files are keyed for other EMAC nodes only.
    """
    sections = emac_sections(argv, namespace)
    others = sorted({sec.node for sec in sections if sec.node is not None} - {name})
    if others and not any(sec.node in (name, None) for sec in sections):
        where = "; ".join(sorted({sec.where for sec in sections}))
        raise ConfigError(f"{fqn}: the parameter files are keyed for {', '.join(others)} ({where}), not for this "
                          "node: none of their values would apply; run it as that node (drop --channel, or -r "
                          "__node:= to that name) or key the file for this node")
    if namespace == "/":
        return
    for path in params_files(argv):
        for key, _ in file_entries(path):
            if key == name:
                logger.warning(
                    f"{path}: section {key!r} applies to /{key} only (a key without a namespace is in the root "
                    f"namespace), not to this node, {fqn}: its parameters are not applied; key it '/**/{key}' "
                    f"(any namespace) or '{namespace}/{key}'")

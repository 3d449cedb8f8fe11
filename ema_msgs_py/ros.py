"""The contract in rclpy terms: QoS profiles, stamps, message classes (imports rclpy)."""

from __future__ import annotations

from importlib import import_module
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ema_msgs_py.contract import TOPICS, QosSpec


def qos(spec: QosSpec | str) -> QoSProfile:
    """The rclpy profile of a QoS spec or of a contract topic's name.

    Parameters
    ----------
    spec : QosSpec or str
        A QoS spec, or the name of a contract topic (its spec).

    Returns
    -------
    QoSProfile
        Keep last ``depth``, with the spec's reliability and durability.
    """
    if isinstance(spec, str):
        spec = TOPICS[spec].qos
    return QoSProfile(  # type: ignore[no-untyped-call]  # rclpy's QoSProfile(**kwargs) carries no annotations
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE),
    )


def message_class(msgtype: str) -> type:
    """The rclpy message class of a message type.

    Parameters
    ----------
    msgtype : str
        ``pkg/msg/Type``, e.g. ``sensor_msgs/msg/JointState``.

    Returns
    -------
    type
        The generated Python class.
    """
    pkg, kind, name = msgtype.split("/")
    cls: type = getattr(import_module(f"{pkg}.{kind}"), name)
    return cls


# Any below: rclpy's message classes (std_msgs, sensor_msgs ...) are generated without type information.
def set_stamp(msg: Any, ns: int) -> None:
    """Set ``msg.header.stamp`` from nanoseconds.

    Parameters
    ----------
    msg : Any
        An rclpy message with a ``header``.
    ns : int
        The stamp, ns.
    """
    msg.header.stamp.sec = int(ns // 1_000_000_000)
    msg.header.stamp.nanosec = int(ns % 1_000_000_000)


def stamp_ns(msg: Any) -> int:
    """``msg.header.stamp`` in nanoseconds.

    Parameters
    ----------
    msg : Any
        An rclpy message with a ``header``.

    Returns
    -------
    int
        The stamp, ns.
    """
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)

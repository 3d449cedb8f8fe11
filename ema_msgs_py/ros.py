"""The contract in rclpy terms: QoS profiles, stamps, message classes (imports rclpy)."""

from __future__ import annotations

from importlib import import_module
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ema_msgs_py.contract import TOPICS, QosSpec


def qos(spec: QosSpec | str) -> QoSProfile:
    """The rclpy profile of a QoS spec or of a contract topic's name."""
    if isinstance(spec, str):
        spec = TOPICS[spec].qos
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE),
    )


def message_class(msgtype: str) -> type:
    """The rclpy message class of ``pkg/msg/Type``."""
    pkg, kind, name = msgtype.split("/")
    return getattr(import_module(f"{pkg}.{kind}"), name)


def set_stamp(msg: Any, ns: int) -> None:
    """Set ``msg.header.stamp`` from nanoseconds."""
    msg.header.stamp.sec = int(ns // 1_000_000_000)
    msg.header.stamp.nanosec = int(ns % 1_000_000_000)


def stamp_ns(msg: Any) -> int:
    """``msg.header.stamp`` in nanoseconds."""
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)

"""The contract's messages without a ROS install: a rosbags typestore (ROS 2 Jazzy definitions).

Bags are written and read with these helpers; the definitions, and so the type hashes, are the
Jazzy ``common_interfaces`` ones that rclpy publishes.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import Any, ClassVar, Literal, Protocol, overload

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore
from rosbags.typesys.stores.ros2_jazzy import (
    builtin_interfaces__msg__Time,
    rosgraph_msgs__msg__Clock,
    sensor_msgs__msg__JointState,
    std_msgs__msg__Header,
    std_msgs__msg__String,
)

from ema_msgs_py.contract import QosSpec


class Message(Protocol):
    """A typestore message: rosbags' dataclass of its type, which names the type."""

    __msgtype__: ClassVar[str]


class Stamped(Message, Protocol):
    """A typestore message with a header."""

    header: std_msgs__msg__Header


@cache
def typestore() -> Typestore:
    """The ROS 2 Jazzy typestore (cached)."""
    return get_typestore(Stores.ROS2_JAZZY)


def _time(ns: int) -> builtin_interfaces__msg__Time:
    return builtin_interfaces__msg__Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def header(stamp_ns: int, frame_id: str = "") -> std_msgs__msg__Header:
    """A ``std_msgs/Header``.

    Parameters
    ----------
    stamp_ns : int
        The stamp, ns.
    frame_id : str, optional
        The frame id (empty on the contract's messages).

    Returns
    -------
    std_msgs__msg__Header
        The typestore message.
    """
    return std_msgs__msg__Header(stamp=_time(stamp_ns), frame_id=frame_id)


def joint_state(stamp_ns: int, names: Sequence[str], position: Sequence[float] = (),
                velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> sensor_msgs__msg__JointState:
    """A ``sensor_msgs/JointState`` (empty arrays: not measured).

    Parameters
    ----------
    stamp_ns : int
        The FMU frame the values belong to, ns.
    names : Sequence[str]
        The channels (or states) the arrays list.
    position, velocity, effort : Sequence[float], optional
        One value per name, or empty when not measured.

    Returns
    -------
    sensor_msgs__msg__JointState
        The typestore message.
    """
    return sensor_msgs__msg__JointState(header=header(stamp_ns), name=list(names),
                                        position=np.asarray(position, dtype=np.float64),
                                        velocity=np.asarray(velocity, dtype=np.float64),
                                        effort=np.asarray(effort, dtype=np.float64))


def clock(stamp_ns: int) -> rosgraph_msgs__msg__Clock:
    """A ``rosgraph_msgs/Clock``.

    Parameters
    ----------
    stamp_ns : int
        The clock's time, ns.

    Returns
    -------
    rosgraph_msgs__msg__Clock
        The typestore message.
    """
    return rosgraph_msgs__msg__Clock(clock=_time(stamp_ns))


def string(text: str) -> std_msgs__msg__String:
    """A ``std_msgs/String``.

    Parameters
    ----------
    text : str
        Its ``data``.

    Returns
    -------
    std_msgs__msg__String
        The typestore message.
    """
    return std_msgs__msg__String(data=text)


def serialize(msg: Message) -> bytes:
    """CDR bytes of a typestore message, as rclpy would publish them.

    Parameters
    ----------
    msg : Message
        A message built by this module (or read from a bag).

    Returns
    -------
    bytes
        Little-endian CDR with its encapsulation header.
    """
    return bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


@overload
def deserialize(raw: bytes | memoryview, msgtype: Literal["sensor_msgs/msg/JointState"]
                ) -> sensor_msgs__msg__JointState: ...
@overload
def deserialize(raw: bytes | memoryview, msgtype: Literal["std_msgs/msg/String"]) -> std_msgs__msg__String: ...
@overload
def deserialize(raw: bytes | memoryview, msgtype: Literal["rosgraph_msgs/msg/Clock"]) -> rosgraph_msgs__msg__Clock: ...
@overload
def deserialize(raw: bytes | memoryview, msgtype: str) -> Any: ...  # Any: another type, named at run time


def deserialize(raw: bytes | memoryview, msgtype: str) -> Any:
    """A typestore message from CDR bytes.

    Parameters
    ----------
    raw : bytes or memoryview
        The serialized message.
    msgtype : str
        Its type, ``pkg/msg/Type``.

    Returns
    -------
    object
        The typestore message: the contract's types (:data:`~ema_msgs_py.contract.JOINT_STATE`, ``STRING``,
        ``CLOCK``) typed as their classes.
    """
    return typestore().deserialize_cdr(raw, msgtype)


def stamp_ns(msg: Stamped) -> int:
    """Header stamp of a message in nanoseconds.

    Parameters
    ----------
    msg : Stamped
        A typestore message with a ``header``.

    Returns
    -------
    int
        The stamp, ns.
    """
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def qos_profiles(spec: QosSpec) -> list[Qos]:
    """The offered QoS of a contract topic, for a bag's metadata.

    Parameters
    ----------
    spec : QosSpec
        The topic's QoS.

    Returns
    -------
    list[Qos]
        One profile, as ``ros2 bag`` records a topic's offered QoS.
    """
    zero = QosTime(sec=0, nsec=0)
    return [Qos(
        history=QosHistory.KEEP_LAST,
        depth=spec.depth,
        reliability=QosReliability.RELIABLE if spec.reliability == "reliable" else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if spec.durability == "transient_local" else QosDurability.VOLATILE,
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )]

"""The ema_sim topic contract, as code: channels, topics, message types, QoS, units, ±10 V scaling.

Standard ``common_interfaces`` types only (no custom rosidl build). :mod:`.contract` is pure Python;
:mod:`.typestore` writes and reads the messages without ROS (rosbags); :mod:`.ros` adapts the same
contract to rclpy. See ``README.md`` beside this file.
"""

from ema_msgs_py.contract import (
    CHANNELS,
    CLOCK_QOS,
    FRAME_HZ,
    FRAME_QOS,
    FULL_SCALE_V,
    LATCHED_QOS,
    TOPICS,
    QosSpec,
    Scaling,
    TopicSpec,
    canonical,
    endpoint,
    failure_topic,
    scaling_of,
    topic,
)

__all__ = [
    "CHANNELS",
    "CLOCK_QOS",
    "FRAME_HZ",
    "FRAME_QOS",
    "FULL_SCALE_V",
    "LATCHED_QOS",
    "TOPICS",
    "QosSpec",
    "Scaling",
    "TopicSpec",
    "canonical",
    "endpoint",
    "failure_topic",
    "scaling_of",
    "topic",
]

"""ROS parameters ↔ the nested mappings of ``config/*.yaml`` (files give defaults, ROS overrides)."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from rclpy.node import Node


def nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1}`` → ``{"a": {"b": 1}}``."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split(".")
        here = out
        for part in parts[:-1]:
            here = here.setdefault(part, {})
        here[parts[-1]] = value
    return out


def merged(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """Deep merge, ``override`` winning."""
    out = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merged(out[key], value)
        else:
            out[key] = value
    return out


def overrides(node: Node, prefix: str = "", exclude: tuple[str, ...] = ("use_sim_time",)) -> dict[str, Any]:
    """The node's declared parameters under ``prefix`` (nested, prefix stripped)."""
    flat = {name: p.value for name, p in node.get_parameters_by_prefix(prefix).items() if name not in exclude}
    return nested(flat)

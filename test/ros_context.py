"""Test-only: an rclpy context on a ROS domain of its own, for the tests that run nodes in their own process.

Shared by the in-process node tests (`test_emac_node_params.py`, `test_emac_node_streams.py`,
`test_emac_node_time.py`, `test_joint_states.py`, `test_ports.py`).
"""

import os
from collections.abc import Iterator
from contextlib import contextmanager

import rclpy

from ema_sim.suite import free_domain_id


@contextmanager
def ros_context(offset: int) -> Iterator[rclpy.Context]:
    """A context on the domain ``free_domain_id(pid + offset)`` (each module its own offset), shut down after."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=free_domain_id(os.getpid() + offset))
    try:
        yield ctx
    finally:
        rclpy.shutdown(context=ctx)

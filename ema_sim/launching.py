"""The suite as ``ros2 launch`` actions: the launch files under ``launch/`` call :func:`generate`.

The launch files and ``ema launch`` start the same processes from the same
:class:`~ema_sim.run.RunDescription`: its :meth:`~ema_sim.run.RunDescription.processes` become
``launch_ros`` ``Node`` actions, each given the run's one parameter file (written next to the bag, as
``<bag>.logs/run.yaml``), its node name, the namespace and the ``/clock`` remapping (``clock_topic``); the
processes named by ``respawn`` are restarted when they end; the driver's end shuts the launch down (its bag is
then closed). Before any node starts, live nodes with the run's names on its domain make the launch fail with
one error naming each (as ``ema launch`` refuses them). Imports ``launch`` and ``launch_ros``, which a
ROS 2 install has.
"""

from __future__ import annotations

import os
from pathlib import Path

from ema_sim.nodes.names import refuse_taken
from ema_sim.run import LAUNCH_ARGUMENTS, from_launch_arguments

PACKAGE = "ema_sim"


def generate(layout: str) -> object:
    """The launch description of one layout.

    Parameters
    ----------
    layout : str
        ``single``, ``container`` or ``processes`` (:data:`~ema_sim.run.LAYOUTS`).

    Returns
    -------
    object
        A ``launch.LaunchDescription``: the arguments declared, the nodes made once their values are known.
    """
    from launch import LaunchDescription  # noqa: PLC0415 - a ROS 2 install's, not in the pip requirements
    from launch.actions import DeclareLaunchArgument, OpaqueFunction  # noqa: PLC0415 - the same

    declared = [DeclareLaunchArgument(name, default_value=default, description=text)
                for name, (default, text) in LAUNCH_ARGUMENTS.items()]
    return LaunchDescription([*declared, OpaqueFunction(function=_nodes, kwargs={"layout": layout})])


NAMES_LOOK_S = 1.5
"""How long the launch looks for live nodes with its names before it starts any, s (wall time)."""


def check_names(full_names: list[str], look_s: float = NAMES_LOOK_S) -> None:
    """Refuse a launch whose names live nodes on its domain (``ROS_DOMAIN_ID``) already claim.

    Parameters
    ----------
    full_names : list of str
        The run's nodes by full name (``/emac_left_wing``, ``/aircraft2/testenv``).
    look_s : float
        How long to look at most, s (the look ends soon after a claim comes).

    Raises
    ------
    EmaError
        One line naming each node that claims one of the names (they would merge with the launch's own).
    """
    refuse_taken(full_names, int(os.environ.get("ROS_DOMAIN_ID") or 0), look_s,
                 os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "SUBNET")  # as the nodes will look


def _nodes(context: object, layout: str) -> list[object]:
    """The run's processes as ``Node`` actions, once the launch arguments are known."""
    from launch.actions import Shutdown  # noqa: PLC0415 - a ROS 2 install's, not in the pip requirements
    from launch.substitutions import LaunchConfiguration  # noqa: PLC0415 - the same
    from launch_ros.actions import Node  # noqa: PLC0415 - the same

    values = {name: LaunchConfiguration(name).perform(context) for name in LAUNCH_ARGUMENTS}
    run = from_launch_arguments(values, layout)
    check_names([f"{run.namespace}/{name}" for name in run.node_names()])
    params = run.write(Path(f"{run.bag}.logs") / "run.yaml")
    clock = values.get("clock_topic") or "/clock"
    remap = [("/clock", clock)] if clock != "/clock" else []
    procs = run.processes()
    return [Node(package=PACKAGE, executable=proc.executable, name=proc.node_name, namespace=run.namespace or None,
                 parameters=[str(params)], remappings=remap, arguments=list(proc.arguments), output="screen",
                 respawn=proc.name in run.respawn, respawn_delay=0.0,
                 on_exit=[Shutdown(reason=f"{run.driver} finished")] if proc is procs[-1] else None)
            for proc in procs]

"""ROS 2 nodes of the suite: thin adapters between the topic contract and the pure parts of ema_sim.

The contract is :mod:`ema_msgs_py`; the pure parts are the models, :mod:`ema_sim.emac`,
:mod:`ema_sim.environment` and :mod:`ema_sim.io.bag`.

``emac`` (one channel, or an EMAC box of several), ``testenv``, ``maneuver`` (FMU, load rig and
recorder), ``simclock`` (lockstep), ``fmu_bridge`` (the JointState pair of topic_based_ros2_control).
Each is a console script of the same name and runs :func:`ema_sim.nodes.common.run`.
"""

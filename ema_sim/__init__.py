"""ema_sim: the X-43A electromechanical actuator subsystem, at every model fidelity of NASA/TM-2008-214637.

Pure models live in :mod:`ema_sim.models`; ROS 2 adapters in :mod:`ema_sim.nodes`.
"""

__version__ = "0.1.0"

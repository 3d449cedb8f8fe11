"""Watching an actuator against its model: residuals, sequential detection, isolation and re-estimation.

Pure logic (no ROS): the offline command and the lifecycle node are thin adapters over these objects.
"""

from ema_sim.monitor.detect import Cusum, threshold
from ema_sim.monitor.learning import learn
from ema_sim.monitor.reference import Reference, from_name, from_report
from ema_sim.monitor.watch import Detection, Options, Verdict, check_inputs, watch

__all__ = ["Cusum", "Detection", "Options", "Reference", "Verdict", "check_inputs", "from_name", "from_report",
           "learn", "threshold", "watch"]

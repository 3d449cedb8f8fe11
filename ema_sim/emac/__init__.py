"""One EMAC channel around a model, as the FMU sees it: volts in, volts out (pure Python, no ROS).

:mod:`.channel` validates inputs, runs the watchdog and the brake, applies failures and publishes
feedback in volts; :mod:`.failures` are the run-time failure modes; :mod:`.crosstalk` the
multichannel coupling of section 2.2. The ``emac`` node is a thin adapter around these.
"""

from ema_sim.emac.channel import EmacChannel, EmacSettings, Feedback, InputStatus
from ema_sim.emac.crosstalk import ActivityMeter, Crosstalk
from ema_sim.emac.failures import FAILURES, Failure, parse_failure

__all__ = [
    "FAILURES",
    "ActivityMeter",
    "Crosstalk",
    "EmacChannel",
    "EmacSettings",
    "Failure",
    "Feedback",
    "InputStatus",
    "parse_failure",
]

"""The test environment between flight computer and EMAC (section 4.3), pure Python, no ROS.

Small elements stepping once per FMU frame (:mod:`.elements`) chained into the command and the
feedback paths of a profile (:mod:`.profile`): ``config/flight.yaml`` (≈ 11 ms FMU command to
first motion) and ``config/ail.yaml`` (≈ 30 ms), each element switchable off. The ``testenv`` node
and the offline aircraft-in-the-loop harness share these classes.
"""

from ema_sim.environment.elements import Element, FirstOrderLag, Noise, Quantizer, SignalPath, TransportDelay
from ema_sim.environment.profile import ELEMENTS, PATHS, PathSpec, Profile, load_profile, profile_names

__all__ = [
    "ELEMENTS",
    "PATHS",
    "Element",
    "FirstOrderLag",
    "Noise",
    "PathSpec",
    "Profile",
    "Quantizer",
    "SignalPath",
    "TransportDelay",
    "load_profile",
    "profile_names",
]

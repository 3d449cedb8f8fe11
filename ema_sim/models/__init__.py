"""Pure actuator models (no ROS): every fidelity of table 4 behind one stepping interface."""

from ema_sim.models.base import ActuatorModel, Flags, Record, Sample
from ema_sim.models.registry import create, model_class, model_names, model_parameters

__all__ = ["ActuatorModel", "Flags", "Record", "Sample", "create", "model_class", "model_names", "model_parameters"]

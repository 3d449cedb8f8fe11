"""Faults injected on a schedule into the models (pure: no ROS), and the runs that carry them."""

from ema_sim.faults.kinds import FAULTS, Fault, fault_help, parse_fault, parse_faults
from ema_sim.faults.schedule import FaultSchedule, check_faults, model_family, run_faulted, truth_columns

__all__ = ["FAULTS", "Fault", "FaultSchedule", "check_faults", "fault_help", "model_family", "parse_fault",
           "parse_faults", "run_faulted", "truth_columns"]

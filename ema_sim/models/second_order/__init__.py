"""The second-order family of section 3.1: LOAC, LOADF, LOADA and the identification simulator (tables 4, 5).

One file per figure of the report, then one per integrator:

* :mod:`.params`   every parameter, declared once (unit, range, slot, switch)
* :mod:`.figure21` the basic second order with the rate limit on its velocity command
* :mod:`.figure26` the modified model's chain of stages (command path, servo, LVDT, compliance)
* :mod:`.figure29` the free-play subsystem
* :mod:`.loada`    LOADA and LOADF (Euler), :mod:`.loac` LOAC (Dormand–Prince), :mod:`.rk4` the RK4 simulator
* :mod:`.models`   the model classes
"""

from ema_sim.models.second_order.models import Loac, Loada, Loadf, SecondOrder, SecondOrderModel
from ema_sim.models.second_order.params import N_STATE, P, SecondOrderParams, X

__all__ = ["N_STATE", "Loac", "Loada", "Loadf", "P", "SecondOrder", "SecondOrderModel", "SecondOrderParams", "X"]

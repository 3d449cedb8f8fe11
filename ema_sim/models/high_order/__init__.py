"""The high-order family of section 3.2: HOAC1, HOAD2 and HOAD3 (tables 4 and 5).

One file per figure of the report, then one per implementation:

* :mod:`.params`     every parameter, declared once (unit, range, kernel slot, switch)
* :mod:`.figure30`   the EMAC channel, motor, bus and mechanics: every element and the chain of stages 4–8
* :mod:`.gear_train` stage 12: figures 32, 33 and 36
* :mod:`.hoad`       HOAD2/HOAD3: stages 1–3 and 16–17 around figure 30, fixed step at 10 kHz
* :mod:`.hoac1`      HOAC1: figure 30 in continuous time with every regime change located
* :mod:`.trim`       the equilibrium every implementation starts from
* :mod:`.linear`     HOAD3 linearized for HOALM (section 4.2.7)
* :mod:`.models`     the model classes
"""

from ema_sim.models.high_order.linear import LinearizedActuator, linearize
from ema_sim.models.high_order.models import HighOrderModel, Hoac1, Hoad2, Hoad3
from ema_sim.models.high_order.params import BOUNDS, OPTIONS, VARIANTS, HighOrderParams, P, X
from ema_sim.models.high_order.trim import equilibrium

__all__ = [
    "BOUNDS", "OPTIONS", "VARIANTS", "HighOrderModel", "HighOrderParams", "Hoac1", "Hoad2", "Hoad3",
    "LinearizedActuator", "P", "X", "equilibrium", "linearize",
]

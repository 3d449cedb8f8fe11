"""The declared starting model: which second-order stages it has and which of its parameters are fitted."""

from __future__ import annotations

from ema_sim.config import ChannelConfig
from ema_sim.errors import UnknownNameError
from ema_sim.identify.effects import FREE
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

DECLARED = ("second_order", "loac", "loada", "loadf", "sloac")
"""Models identification can start from: the second-order family (fitted with its accurate simulator)."""


COMPANION = {
    "velocity_loop_hz": "accel_limit_dps2",
    "linkage_zeta": "linkage_freq_hz",
    "compliance_stiff_deg_per_kinlb": "compliance_knee_inlb",
    "lvdt_compliance_stiff_deg_per_kinlb": "lvdt_compliance_knee_inlb",
}
"""A parameter that means something only with another stage on: the stage that switches it."""


def declared(model: str, channel: ChannelConfig, overrides: dict[str, float]) -> tuple[SecondOrderParams, list[str]]:
    """Starting parameters and the names of the model's own fitted parameters.

    ``second_order`` is the basic model of figure 21 (ωn, ζ); overrides switch more stages on and
    make them the model's own. ``loac``/``loada``/``loadf`` start from the channel's configuration
    and fit ωn, ζ and every continuous element it has on; quantization and the load terms stay as
    configured. ``sloac`` is the second order with its delay. The discrete models' integrators are
    not part of the physics: they are simulated accurately (their own discretization error is
    reported separately).
    """
    key = model.strip().lower()
    if key not in DECLARED:
        raise UnknownNameError("declared model for identification", model, DECLARED)
    if key == "second_order":
        params = SecondOrderParams.basic(channel, **overrides)
    elif key == "sloac":
        cfg = SecondOrderParams.from_channel(channel)
        params = SecondOrderParams.basic(channel, delay_s=cfg.delay_s, **overrides)
    else:
        params = SecondOrderParams.from_channel(channel, **overrides)
    free = ["wn_rad_s", "zeta"]
    info = metas(SecondOrderParams)
    for name in FREE:
        switch = COMPANION.get(name, name)
        if name not in free and getattr(params, switch) != info[switch].off:
            free.append(name)
    return params, free

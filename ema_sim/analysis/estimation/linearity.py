"""Whether a servo is linear over the amplitudes of its steps: the larger steps' linear fits against the smallest's.

A servo linear over two amplitudes gives both steps the same ωn and delay. An acceleration or current limit
acting before the rate plateau slows the larger step without flattening its rate, so no rate test sees it: its
linear fit is then that amplitude's equivalent, not the servo's, and the step says so.
"""

from __future__ import annotations

import math

from ema_sim.analysis.estimation.second_order_fit import Estimate, SecondOrderFit

__all__ = ["LINEAR_DELAY_S", "LINEAR_SIGMAS", "LINEAR_WN_SHARE", "amplitude_change"]

LINEAR_SIGMAS = 3.0
"""A step's ωn or delay differs from the smallest step's beyond this many combined standard errors..."""
LINEAR_WN_SHARE = 0.05
"""...and ωn by more than this share of the smallest step's, or the delay by more than :data:`LINEAR_DELAY_S`:
the servo is not linear over the two amplitudes."""
LINEAR_DELAY_S = 0.001


def amplitude_change(reference: SecondOrderFit, reference_amp: float, fit: SecondOrderFit) -> str:
    """How a larger step's linear fit differs from the smallest step's, in words (empty: it does not).

    Parameters
    ----------
    reference : SecondOrderFit
        The smallest fitted step's fit.
    reference_amp : float
        Its measured change, deg.
    fit : SecondOrderFit
        A larger step's fit.

    Returns
    -------
    str
        The difference, or an empty string.
    """
    def beyond(a: Estimate, b: Estimate, material: float) -> bool:
        se = math.hypot(a.sigma or 0.0, b.sigma or 0.0)
        return abs(a.value - b.value) > max(LINEAR_SIGMAS * se, material)

    wn = beyond(fit.wn_rad_s, reference.wn_rad_s, LINEAR_WN_SHARE * reference.wn_rad_s.value)
    delay = beyond(fit.delay_s, reference.delay_s, LINEAR_DELAY_S)
    if not (wn or delay):
        return ""
    return (f"not linear over the amplitudes: ωn {fit.wn_rad_s.value:.3g} and delay {1e3 * fit.delay_s.value:.3g} ms "
            f"here, {reference.wn_rad_s.value:.3g} and {1e3 * reference.delay_s.value:.3g} ms at the "
            f"{abs(reference_amp):.3g}° step (a limit on acceleration or current acting before the rate plateau): "
            "this fit is this amplitude's equivalent")

"""Multichannel crosstalk (section 2.2): noise on a channel's feedback while the other channels move.

Section 2.2.1 saw about 0.02 V (≈ 0.086°) of noise on the right wing's position feedback while three
other channels ran square waves just below saturation, where the PWM limits the current; the other
channels showed none. The coupling here is that observation as a configurable element: each
source channel's activity is its slew demand, |Δfeedback| per frame over its full slew (0 at rest, 1
when slewing at 115.8 °/s), and the observed channel's feedback carries uniform noise of
``noise_pp_v`` peak to peak scaled by the largest activity. The noise rides on the reported
feedback only: it stayed below the threshold and did not move the surface.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.errors import ConfigError


class ActivityMeter:
    """Activity of the other channels, from their successive feedback voltages.

    Parameters
    ----------
    frame_s : float
        The frame period, s.
    """

    def __init__(self, frame_s: float) -> None:
        self.frame_s = float(frame_s)
        self._last: dict[str, float] = {}
        self._activity: dict[str, float] = {}

    def observe(self, source: str, position_v: float, slew_v_per_s: float) -> None:
        """The feedback of ``source`` at the next frame (its full slew in V/s scales the activity).

        Parameters
        ----------
        source : str
            The channel that sent it.
        position_v : float
            Its position feedback, V.
        slew_v_per_s : float
            Its full slew rate, V/s.
        """
        if not math.isfinite(position_v):
            return
        last = self._last.get(source)
        self._last[source] = position_v
        if last is not None and slew_v_per_s > 0.0:
            self._activity[source] = min(1.0, abs(position_v - last) / (self.frame_s * slew_v_per_s))

    @property
    def activity(self) -> float:
        """Largest activity of any source, 0 to 1."""
        return max(self._activity.values(), default=0.0)

    def activity_except(self, channel: str) -> float:
        """Largest activity of the sources other than ``channel`` (an EMAC box observes its own channels).

        Parameters
        ----------
        channel : str
            The observed channel.

        Returns
        -------
        float
            The activity, 0 to 1.
        """
        return max((a for name, a in self._activity.items() if name != channel), default=0.0)


class Crosstalk:
    """Noise volts on the observed channel's feedback for a given source activity.

    Parameters
    ----------
    noise_pp_v : float
        Peak-to-peak noise at full activity, V.
    seed : int
        The random seed.
    stream : int
        The random stream (one per channel).
    """

    def __init__(self, noise_pp_v: float, seed: int = 0, stream: int = 0) -> None:
        if not (math.isfinite(noise_pp_v) and noise_pp_v >= 0.0):
            raise ConfigError(f"crosstalk noise must be a non-negative number of volts, got {noise_pp_v!r}")
        self.noise_pp_v = float(noise_pp_v)
        self._rng = np.random.default_rng([int(seed), int(stream), 2])

    @property
    def active(self) -> bool:
        """False when the coupling is off."""
        return self.noise_pp_v > 0.0

    def step(self, activity: float) -> float:
        """Noise of this frame, volts.

        Parameters
        ----------
        activity : float
            The sources' activity, 0 to 1.

        Returns
        -------
        float
            The noise, V.
        """
        if self.noise_pp_v == 0.0 or activity <= 0.0:
            return 0.0
        return self.noise_pp_v * min(activity, 1.0) * (float(self._rng.random()) - 0.5)

"""Records of a servo that changes while it is logged, and of a logger whose stamps jitter (numpy only).

A plant of its own, not the simulator identification fits with: a position servo whose closed loop is
a second order (ωn, ζ) integrated on a 0.1 ms grid, driven by a host command held between the logger's
instants, behind a transport delay; ωn and the delay may change over the record. The logger samples at
its own instants, prints the position in counts with white noise on it, and stamps each sample (integer
milliseconds, with a software clock's error when asked). The command repeats a block of four steps and a
0.5-5 Hz chirp, so that every part of the record carries the same excitation.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ema_sim.io.measured import MeasuredData

TICK_S = 1e-4
BLOCK_S = 6.0


def block(t: np.ndarray, amp: float) -> np.ndarray:
    """The repeating excitation: four held steps, then a faded 0.5-5 Hz chirp, then rest."""
    tb = np.mod(t, BLOCK_S)
    steps = np.select([tb < 0.6, tb < 1.2, tb < 1.8, tb < 2.4], [amp, -amp, 0.5 * amp, -0.5 * amp], 0.0)
    tau = np.clip(tb - 2.6, 0.0, 3.0)
    k = math.log(10.0) / 3.0
    phase = 2.0 * math.pi * 0.5 * (np.exp(k * tau) - 1.0) / k
    fade = np.clip(np.minimum(tau, 3.0 - tau) / 0.4, 0.0, 1.0)
    chirp = np.where((tb >= 2.6) & (tb <= 5.6), 0.6 * amp * np.sin(phase) * 0.5 * (1 - np.cos(np.pi * fade)), 0.0)
    return steps + chirp


def record(duration_s: float = 24.0, *, seed: int = 0, rate_hz: float = 100.0, wn: Callable[[np.ndarray], np.ndarray]
           | None = None, zeta: float = 0.75, delay_s: Callable[[np.ndarray], np.ndarray] | None = None,
           stamp_error_s: float = 0.0, noise_deg: float = 0.002, count_deg: float = 0.001, amp_deg: float = 3.0
           ) -> MeasuredData:
    """A logged record of the servo (module docstring).

    ``wn`` and ``delay_s`` are functions of time (default: 40 rad/s and no delay, steady); ``stamp_error_s`` is the
    peak of the stamps' uniform error about the true (uniform) instants.
    """
    rng = np.random.default_rng(seed)
    n_log = int(duration_s * rate_hz)
    t_log = np.arange(n_log) / rate_hz
    cmd = np.round(block(t_log, amp_deg), 4)
    grid = np.arange(0.0, t_log[-1] + 1e-9, TICK_S)
    held = cmd[np.clip(np.searchsorted(t_log, grid, side="right") - 1, 0, n_log - 1)]
    if delay_s is not None:
        idx = np.clip(np.round((grid - delay_s(grid)) / TICK_S).astype(int), 0, grid.size - 1)
        held = held[idx]
    w = wn(grid) if wn is not None else np.full(grid.size, 40.0)
    x = np.empty(grid.size)
    pos, vel = 0.0, 0.0
    for k in range(grid.size):  # semi-implicit Euler on the 0.1 ms grid
        vel += TICK_S * (w[k] * w[k] * (held[k] - pos) - 2.0 * zeta * w[k] * vel)
        pos += TICK_S * vel
        x[k] = pos
    y = np.interp(t_log, grid, x) + rng.normal(0.0, noise_deg, n_log)
    y = np.round(y / count_deg) * count_deg
    stamps = t_log + (rng.uniform(-stamp_error_s, stamp_error_s, n_log) if stamp_error_s > 0 else 0.0)
    stamps = np.round(stamps * 1e3) / 1e3
    keep = np.concatenate([[True], np.diff(stamps) > 0])
    return MeasuredData(time_s=stamps[keep], command_deg=cmd[keep], position_deg=y[keep], source="changing")

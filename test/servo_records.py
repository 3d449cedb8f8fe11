"""A damped servo following a held staircase, made with numpy alone: the records of the stamp and dropout tests."""

from __future__ import annotations

import numpy as np

FINE_S = 1e-4
"""The servo's integration step (s)."""


def servo(t: np.ndarray, levels: list[tuple[float, float]], seed: int = 0, noise: float = 0.003,
          rate_dps: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """The held command (``(from_s, level)`` pairs) and a 60 rad/s, ζ 0.7 response at ``t``.

    Its rate is clipped at ``rate_dps``, and ``noise`` (rms, °) is added to the response as read.
    """
    fine = np.arange(0.0, t[-1] + 2 * FINE_S, FINE_S)
    starts = np.array([a for a, _ in levels])
    values = np.array([v for _, v in levels])

    def held(x: np.ndarray) -> np.ndarray:
        return values[np.clip(np.searchsorted(starts, x, side="right") - 1, 0, values.size - 1)]

    u = held(fine)
    wn, zeta = 60.0, 0.7
    y, v = np.zeros_like(fine), 0.0
    for i in range(1, fine.size):
        v += FINE_S * (wn * wn * (u[i - 1] - y[i - 1]) - 2.0 * zeta * wn * v)
        v = min(max(v, -rate_dps), rate_dps)
        y[i] = y[i - 1] + FINE_S * v
    rng = np.random.default_rng(seed)
    return held(t), np.interp(t, fine, y) + rng.normal(0.0, noise, t.size)

"""Reproducible measurement noise drawn inside numba kernels (HOAD2 and HOAD3, section 4.3).

Each model instance owns its generator state (xorshift64*, seeded by splitmix64), so a run gives the
same noise whether it is stepped frame by frame or run whole, and instances in a batch or in other
models never share a stream. Noise is band-limited: a first-order (Ornstein–Uhlenbeck) process of a
given rms and bandwidth, so its effect does not change with the model's step size.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.models.stages import jit

RNG_WORDS = 1
"""uint64 words of generator state per instance."""
NORMAL_WORDS = 2
"""float64 words per instance for the Box–Muller spare: (have one, value)."""

_U53 = 1.0 / 9007199254740992.0  # 2**-53


@jit
def splitmix64(seed: int) -> np.uint64:
    """A well-mixed 64-bit word from an integer seed (never zero)."""
    z = np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    if z == np.uint64(0):
        z = np.uint64(0x2545F4914F6CDD1D)
    return z


@jit
def uniform(state: np.ndarray) -> float:
    """A uniform draw in (0, 1] from xorshift64*; advances ``state[0]``."""
    x = state[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    state[0] = x
    r = x * np.uint64(0x2545F4914F6CDD1D)
    return (float(r >> np.uint64(11)) + 1.0) * _U53


@jit
def normal(state: np.ndarray, spare: np.ndarray) -> float:
    """A standard normal draw (Box–Muller, the second value of each pair kept in ``spare``)."""
    if spare[0] != 0.0:
        spare[0] = 0.0
        return spare[1]
    u1 = uniform(state)
    u2 = uniform(state)
    rad = math.sqrt(-2.0 * math.log(u1))
    ang = 2.0 * math.pi * u2
    spare[0] = 1.0
    spare[1] = rad * math.sin(ang)
    return rad * math.cos(ang)


@jit
def band_limited_step(value: float, rms: float, decay: float, state: np.ndarray, spare: np.ndarray) -> float:
    """One step of first-order noise of rms ``rms``: ``n ← a·n + rms·√(1 − a²)·w`` with ``a = decay``."""
    if rms <= 0.0:
        return 0.0
    return decay * value + rms * math.sqrt(1.0 - decay * decay) * normal(state, spare)


def noise_decay(bandwidth_hz: float, dt_s: float) -> float:
    """``a = exp(−2π·f·dt)`` of the first-order noise over ``dt_s`` (0: white at that step)."""
    if bandwidth_hz <= 0.0:
        return 0.0
    return math.exp(-2.0 * math.pi * bandwidth_hz * dt_s)

"""Reproducible measurement noise drawn inside numba kernels (HOAD2 and HOAD3, section 4.3).

Each model instance owns its generator state (xorshift64*, seeded by splitmix64), so a run gives the
same noise whether it is stepped frame by frame or run whole, and instances in a batch or in other
models never share a stream. Noise is band-limited: a first-order (Ornstein–Uhlenbeck) process of a
given rms and bandwidth, so its effect does not change with the model's step size. Normal draws
use the ziggurat method, a few nanoseconds each, so a 10 kHz kernel can draw every step.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.models.stages import jit

_U53 = 1.0 / 9007199254740992.0  # 2**-53


@jit
def splitmix64(seed: int) -> np.uint64:
    """A well-mixed 64-bit word from an integer seed (never zero).

    Parameters
    ----------
    seed : int
        Any integer.

    Returns
    -------
    numpy.uint64
        A generator state.
    """
    z = np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    if z == np.uint64(0):
        z = np.uint64(0x2545F4914F6CDD1D)
    return z


@jit
def xorshift(x: np.uint64) -> tuple[np.uint64, np.uint64]:
    """xorshift64*'s step on a state held in a register: the next state and its output word.

    The kernels hold their generator's state in a local through a run (a state in an array is written
    back and read again at every draw) and store it once at the end; the array forms below wrap these.

    Parameters
    ----------
    x : numpy.uint64
        The state.

    Returns
    -------
    state : numpy.uint64
        The next state.
    word : numpy.uint64
        The output word.
    """
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    out: np.uint64 = x * np.uint64(0x2545F4914F6CDD1D)
    return x, out


@jit
def next_u64(state: np.ndarray) -> np.uint64:
    """The next 64-bit output of xorshift64*; advances ``state[0]``.

    Parameters
    ----------
    state : numpy.ndarray
        The generator's state (one uint64), advanced.

    Returns
    -------
    numpy.uint64
        The output word.
    """
    x, out = xorshift(state[0])
    state[0] = x
    return out


@jit
def _unit(word: np.uint64) -> float:
    """A word's top 53 bits as a uniform draw in (0, 1]."""
    return (float(word >> np.uint64(11)) + 1.0) * _U53


@jit
def uniform(state: np.ndarray) -> float:
    """A uniform draw in (0, 1] from xorshift64*; advances ``state[0]``.

    Parameters
    ----------
    state : numpy.ndarray
        The generator's state (one uint64), advanced.

    Returns
    -------
    float
        The draw.
    """
    return _unit(next_u64(state))


def _ziggurat_tables(levels: int = 128) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Marsaglia and Tsang's (2000) ziggurat for the standard normal: (k, w, f) for 128 layers."""
    m1 = 2147483648.0
    dn = 3.442619855899
    tn = dn
    vn = 9.91256303526217e-3
    k = np.zeros(levels)
    w = np.zeros(levels)
    f = np.zeros(levels)
    q = vn / math.exp(-0.5 * dn * dn)
    k[0] = dn / q * m1
    k[1] = 0.0
    w[0] = q / m1
    w[levels - 1] = dn / m1
    f[0] = 1.0
    f[levels - 1] = math.exp(-0.5 * dn * dn)
    for i in range(levels - 2, 0, -1):
        dn = math.sqrt(-2.0 * math.log(vn / dn + math.exp(-0.5 * dn * dn)))
        k[i + 1] = dn / tn * m1
        tn = dn
        f[i] = math.exp(-0.5 * dn * dn)
        w[i] = dn / m1
    return k, w, f


_ZIG_K, _ZIG_W, _ZIG_F = _ziggurat_tables()
_ZIG_R = 3.442619855899
"""Where the ziggurat's base strip hands over to the exact tail."""


@jit
def _signed_draw(word: np.uint64) -> tuple[np.int64, np.int64]:
    """A signed 32-bit integer and an independent 7-bit layer from one 64-bit word."""
    hz = np.int64(word >> np.uint64(32))
    if hz >= 2147483648:
        hz -= 4294967296
    return hz, np.int64(word & np.uint64(127))


@jit
def normal_held(x: np.uint64) -> tuple[float, np.uint64]:
    """A standard normal draw by the ziggurat from a state held in a register: the draw and the next state.

    One multiply on 98.8 % of draws, exact in the tails (Marsaglia and Tsang).

    Parameters
    ----------
    x : numpy.uint64
        The generator's state.

    Returns
    -------
    draw : float
        The draw.
    state : numpy.uint64
        The advanced state.
    """
    x, word = xorshift(x)
    hz, iz = _signed_draw(word)
    while True:
        if abs(hz) < _ZIG_K[iz]:
            return float(hz * _ZIG_W[iz]), x
        z = float(hz * _ZIG_W[iz])
        if iz == 0:  # the tail beyond r, by Marsaglia's exponential method
            while True:
                x, word = xorshift(x)
                z = -math.log(_unit(word)) / _ZIG_R
                x, word = xorshift(x)
                y = -math.log(_unit(word))
                if y + y >= z * z:
                    break
            return (_ZIG_R + z if hz > 0 else -_ZIG_R - z), x
        x, word = xorshift(x)
        if _ZIG_F[iz] + _unit(word) * (_ZIG_F[iz - 1] - _ZIG_F[iz]) < math.exp(-0.5 * z * z):
            return z, x
        x, word = xorshift(x)
        hz, iz = _signed_draw(word)


@jit
def normal(state: np.ndarray) -> float:
    """A standard normal draw by the ziggurat (:func:`normal_held`); advances ``state[0]``.

    Parameters
    ----------
    state : numpy.ndarray
        The generator's state (one uint64), advanced.

    Returns
    -------
    float
        The draw.
    """
    draw, state[0] = normal_held(state[0])
    return draw


@jit
def band_limited_held(value: float, decay: float, innovation: float, x: np.uint64) -> tuple[float, np.uint64]:
    """One step of first-order noise (:func:`band_limited_step`) from a state held in a register.

    Parameters
    ----------
    value : float
        The noise so far.
    decay : float
        ``a = exp(−2π·bandwidth·dt)``.
    innovation : float
        ``σ·√(1 − a²)`` (0: the noise is off and nothing is drawn).
    x : numpy.uint64
        The generator's state.

    Returns
    -------
    noise : float
        The noise after the step.
    state : numpy.uint64
        The advanced state.
    """
    if innovation == 0.0:
        return 0.0, x
    draw, x = normal_held(x)
    return decay * value + innovation * draw, x


@jit
def band_limited_step(value: float, decay: float, innovation: float, state: np.ndarray) -> float:
    """One step of first-order noise: ``n ← a·n + σ·√(1 − a²)·w`` with ``a = decay``.

    ``innovation = σ·√(1 − a²)`` (0 when the noise is off); the rms stays σ whatever the step.

    Parameters
    ----------
    value : float
        The noise so far.
    decay : float
        ``a = exp(−2π·bandwidth·dt)``.
    innovation : float
        ``σ·√(1 − a²)``.
    state : numpy.ndarray
        The generator's state, advanced.

    Returns
    -------
    float
        The noise after the step.
    """
    noise, state[0] = band_limited_held(value, decay, innovation, state[0])
    return noise

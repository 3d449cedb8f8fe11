"""Signal elements of the test environment, each stepping once per frame.

Every element takes the frame's input and returns its output for the same frame; ``reset(x)``
puts it in steady state at ``x``. Inputs may be floats or numpy arrays (one value per channel), so
one element can serve a single channel or a whole vehicle. A zero parameter makes an element the
identity, as in the models' stages.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import ConfigError
from ema_sim.models.stages import lag_gain, quantize, quantize_array

Signal = float | NDArray[np.float64]
"""A float, or a numpy array with one value per channel."""


class Element(ABC):
    """One stage of a signal path."""

    name: str = "element"

    @abstractmethod
    def step(self, x: Signal) -> Signal:
        """Output of this frame for input ``x``.

        Parameters
        ----------
        x : float or numpy.ndarray
            The input, one value per channel for an array.

        Returns
        -------
        float or numpy.ndarray
            The output, shaped as the input.
        """

    @abstractmethod
    def reset(self, x: Signal) -> None:
        """Steady state at ``x`` (no transient when the input stays there).

        Parameters
        ----------
        x : float or numpy.ndarray
            The input, one value per channel for an array.
        """

    @property
    def active(self) -> bool:
        """False when the element is the identity."""
        return True

    def describe(self) -> str:
        """One line for logs and bag metadata."""
        return self.name


class TransportDelay(Element):
    """A pure delay of ``delay_s`` on a signal sampled every ``frame_s``.

    Whole frames come from a ring of past inputs; a fractional remainder is linear interpolation
    between the two neighbouring frames (first-order Lagrange), so the phase lag at low frequency is
    exactly ω·delay whatever the frame rate.

    Parameters
    ----------
    delay_s : float
        The delay (s, ≥ 0).
    frame_s : float
        The frame (s).
    initial : float or numpy.ndarray
        The steady input it starts at.
    """

    name = "delay"

    def __init__(self, delay_s: float, frame_s: float, initial: Signal = 0.0) -> None:
        if not (math.isfinite(delay_s) and delay_s >= 0.0):
            raise ConfigError(f"delay_s must be a non-negative number, got {delay_s!r}")
        if not (math.isfinite(frame_s) and frame_s > 0.0):
            raise ConfigError(f"frame_s must be positive, got {frame_s!r}")
        self.delay_s = float(delay_s)
        frames = self.delay_s / frame_s
        self.whole = math.floor(frames + 1e-9)
        frac = frames - self.whole
        self.frac = 0.0 if frac < 1e-9 else frac
        self._buf: deque[Signal] = deque(maxlen=self.whole + 2)
        self.reset(initial)

    @property
    def active(self) -> bool:  # noqa: D102
        return self.delay_s > 0.0

    def reset(self, x: Signal) -> None:  # noqa: D102
        self._buf.clear()
        for _ in range(self._buf.maxlen or 1):
            self._buf.append(_copy(x))

    def step(self, x: Signal) -> Signal:  # noqa: D102
        self._buf.append(_copy(x))
        newest = len(self._buf) - 1
        a = self._buf[newest - self.whole]
        if self.frac == 0.0:
            return a
        b = self._buf[newest - self.whole - 1]
        return (1.0 - self.frac) * a + self.frac * b

    def describe(self) -> str:  # noqa: D102
        return f"delay {self.delay_s * 1e3:g} ms"


class FirstOrderLag(Element):
    """The FMU's first-order lag filter, corner ``corner_hz``, discretised exactly for a held input.

    ``y_k = y_{k-1} + (1 − e^{−2π·f·T})·(x_k − y_{k-1})``: the standard digital first-order filter of a
    flight computer running at frame ``T``; unity gain at DC.

    Parameters
    ----------
    corner_hz : float
        Corner frequency (0: off).
    frame_s : float
        The frame (s).
    initial : float or numpy.ndarray
        The steady input it starts at.
    """

    name = "lag"

    def __init__(self, corner_hz: float, frame_s: float, initial: Signal = 0.0) -> None:
        if not (math.isfinite(corner_hz) and corner_hz >= 0.0):
            raise ConfigError(f"corner_hz must be a non-negative number, got {corner_hz!r}")
        self.corner_hz = float(corner_hz)
        self.gain = lag_gain(self.corner_hz, frame_s)
        self._y: Signal = _copy(initial)

    @property
    def active(self) -> bool:  # noqa: D102
        return self.corner_hz > 0.0

    def reset(self, x: Signal) -> None:  # noqa: D102
        self._y = _copy(x)

    def step(self, x: Signal) -> Signal:  # noqa: D102
        self._y = self._y + self.gain * (x - self._y)
        return self._y

    def describe(self) -> str:  # noqa: D102
        return f"lag {self.corner_hz:g} Hz"


class Quantizer(Element):
    """A converter: mid-tread quantization to ``step_v`` and saturation at ±``full_scale_v``.

    The quantizer is :func:`ema_sim.models.stages.quantize`, the one the models use.

    Parameters
    ----------
    step_v : float
        Resolution (V; 0: off).
    full_scale_v : float
        Saturation (V).
    """

    name = "quantization"

    def __init__(self, step_v: float, full_scale_v: float = 10.0) -> None:
        if not (math.isfinite(step_v) and step_v >= 0.0):
            raise ConfigError(f"step_v must be a non-negative number, got {step_v!r}")
        self.step_v = float(step_v)
        self.full_scale_v = float(full_scale_v)

    @property
    def active(self) -> bool:  # noqa: D102
        return self.step_v > 0.0

    def reset(self, x: Signal) -> None:  # noqa: D102
        del x

    def step(self, x: Signal) -> Signal:  # noqa: D102
        if self.step_v == 0.0:
            return x
        if type(x) is float:  # one channel
            return min(max(quantize(x, self.step_v), -self.full_scale_v), self.full_scale_v)
        arr = np.asarray(x, dtype=float)
        flat = quantize_array(np.ascontiguousarray(arr.reshape(-1)), self.step_v)
        q = np.clip(flat.reshape(arr.shape), -self.full_scale_v, self.full_scale_v)
        return float(q) if np.ndim(q) == 0 else q

    def describe(self) -> str:  # noqa: D102
        return f"quantization {self.step_v * 1e3:g} mV"


NOISE_BLOCK = 1024
"""Normals a :class:`Noise` element draws at a time (one generator call per block, not per frame)."""


class Noise(Element):
    """Additive white Gaussian noise of ``rms_v``, reproducible from ``seed`` and ``stream``.

    Parameters
    ----------
    rms_v : float
        Noise rms (V; 0: off).
    seed : int
        The profile's seed.
    stream : sequence of int
        Which stream (channel, direction), so every path's noise is independent.
    """

    name = "noise"

    def __init__(self, rms_v: float, seed: int = 0, stream: Sequence[int] = ()) -> None:
        if not (math.isfinite(rms_v) and rms_v >= 0.0):
            raise ConfigError(f"rms_v must be a non-negative number, got {rms_v!r}")
        self.rms_v = float(rms_v)
        self._rng = np.random.default_rng([int(seed), *map(int, stream)])
        self._drawn: list[float] = []
        """Normals drawn ahead, in stream order (the generator gives the same sequence in any block size)."""
        self._next = 0

    @property
    def active(self) -> bool:  # noqa: D102
        return self.rms_v > 0.0

    def reset(self, x: Signal) -> None:  # noqa: D102
        del x

    def _normals(self, k: int) -> list[float]:
        """The next ``k`` standard normals of this element's stream."""
        if self._next + k > len(self._drawn):
            rest = self._drawn[self._next:]
            self._drawn = rest + self._rng.standard_normal(max(NOISE_BLOCK, k)).tolist()
            self._next = 0
        out = self._drawn[self._next:self._next + k]
        self._next += k
        return out

    def step(self, x: Signal) -> Signal:  # noqa: D102
        if self.rms_v == 0.0:
            return x
        if isinstance(x, float) or np.ndim(x) == 0:
            if self._next < len(self._drawn):
                z = self._drawn[self._next]
                self._next += 1
            else:
                z = self._normals(1)[0]
            return float(x) + self.rms_v * z
        return x + self.rms_v * np.reshape(self._normals(int(np.size(x))), np.shape(x))

    def describe(self) -> str:  # noqa: D102
        return f"noise {self.rms_v * 1e3:g} mV rms"


class SignalPath(Element):
    """Elements in order; the identity when empty.

    Parameters
    ----------
    elements : sequence of Element
        The elements in the order the signal meets them (inactive ones are dropped).
    """

    name = "path"

    def __init__(self, elements: Sequence[Element]) -> None:
        self.elements = [e for e in elements if e.active]

    @property
    def active(self) -> bool:  # noqa: D102
        return bool(self.elements)

    def reset(self, x: Signal) -> None:
        """Steady state at ``x``: each element is reset at the output of the ones before it.

        Parameters
        ----------
        x : float or numpy.ndarray
            The input, one value per channel for an array.
        """
        for element in self.elements:
            element.reset(x)
            if isinstance(element, Quantizer):
                x = element.step(x)

    def step(self, x: Signal) -> Signal:  # noqa: D102
        for element in self.elements:
            x = element.step(x)
        return x

    def describe(self) -> str:  # noqa: D102
        return " → ".join(e.describe() for e in self.elements) or "pass-through"


def _copy(x: Signal) -> Signal:
    return x.copy() if isinstance(x, np.ndarray) else float(x)

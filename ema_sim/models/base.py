"""The one stepping interface every model fidelity shares.

A model holds ``n`` independent instances (one channel, or a Monte Carlo batch). It is driven by
zero-order-held inputs, command in surface degrees and hinge moment in in·lb, and integrates
internally at its own rate:

* :meth:`ActuatorModel.step` advances by one frame (the FMU's 200 Hz frame, say) and returns the
  outputs at the end of the frame; non-finite inputs are held at their last good value and counted.
* :meth:`ActuatorModel.run` advances through a whole record of input breakpoints in one compiled call
  and samples the outputs where asked (a DAU at 1 kHz, say); non-finite inputs are rejected.

Both share the same state, so a node may ``run`` a warm-up and then ``step`` frame by frame.
Sign convention: a positive hinge moment aids positive deflection.

One concept, the interface every fidelity shares, in one module of about 730 lines: most of it is
:class:`ActuatorModel`'s checked entry points (trim, step, run, batches), which a reader wants side by side.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.config import ChannelConfig, load_channel
from ema_sim.errors import ConfigError, EmaError
from ema_sim.jsontypes import JsonObject
from ema_sim.models import stages
from ema_sim.models.inputs import as_batch, as_record, check_finite, held_inputs
from ema_sim.parameters import ParameterInfo, Slots, describe, elements, switched_off

FloatArray = NDArray[np.float64]
_Params = TypeVar("_Params")
log = logging.getLogger(__name__)

OUTPUT_FIELDS: tuple[str, ...] = ("position_deg", "surface_deg", "rate_dps", "current_a", "bus_v", "flags")
"""Columns of every kernel's output block, in order."""
N_OUT = len(OUTPUT_FIELDS)
O_POS, O_SURF, O_RATE, O_CUR, O_BUS, O_FLAGS = range(N_OUT)

HISTORY_START_S = -1e9
"""Time stamp of the trim breakpoint: the held input the model has seen 'forever'."""
HISTORY_CAPACITY = 256
"""Breakpoints the input-history buffers hold before :meth:`ActuatorModel.step` compacts them."""


class Flags(enum.IntFlag):
    """Which limits were active at a sample; every model reports the ones it has."""

    RATE_LIMIT = stages.FLAG_RATE
    POSITION_LIMIT = stages.FLAG_POSITION
    FREE_PLAY_STOP = stages.FLAG_FREE_PLAY
    THRESHOLD = stages.FLAG_THRESHOLD
    CURRENT_LIMIT = stages.FLAG_CURRENT
    PWM_DEAD_BAND = stages.FLAG_PWM_DEAD_BAND
    BRAKE = stages.FLAG_BRAKE
    STALL = stages.FLAG_STALL


@dataclass(frozen=True)
class Sample:
    """Outputs of all instances at one instant; every array has shape ``(n,)``."""

    time_s: float
    position_deg: FloatArray
    """LVDT position feedback, surface degrees (inside the servo loop)."""
    surface_deg: FloatArray
    """True surface angle, what an external sensor reads (free play and compliance included)."""
    rate_dps: FloatArray
    current_a: FloatArray
    """Motor current; NaN for models without a motor."""
    bus_v: FloatArray
    """150 V bus voltage; NaN for models without one."""
    flags: NDArray[np.int64]

    def active(self, i: int = 0) -> Flags:
        """The limit flags of instance ``i``.

        Parameters
        ----------
        i : int
            The instance.

        Returns
        -------
        Flags
            The limits active at the sample.
        """
        return Flags(int(self.flags[i]))


@dataclass(frozen=True)
class Record:
    """Outputs sampled over time: ``time_s`` has shape ``(k,)``, every other array ``(n, k)``."""

    model: str
    channel: str
    time_s: FloatArray
    command_deg: FloatArray
    """The command in effect at each sample (before any delay)."""
    hinge_moment_inlb: FloatArray
    position_deg: FloatArray
    surface_deg: FloatArray
    rate_dps: FloatArray
    current_a: FloatArray
    bus_v: FloatArray
    flags: NDArray[np.int64]

    def columns(self, i: int = 0) -> dict[str, FloatArray]:
        """Instance ``i`` as named 1-D columns (data-contract names).

        Parameters
        ----------
        i : int
            The instance.

        Returns
        -------
        dict
            Column name → values, one per sample.
        """
        return {
            "time_s": self.time_s,
            "command_deg": self.command_deg[i],
            "position_deg": self.position_deg[i],
            "surface_deg": self.surface_deg[i],
            "hinge_moment_inlb": self.hinge_moment_inlb[i],
            "rate_dps": self.rate_dps[i],
            "current_a": self.current_a[i],
            "bus_v": self.bus_v[i],
            "flags": self.flags[i].astype(float),
        }


class ActuatorModel(ABC):
    """Base of every fidelity: inputs, time, history, validation; families supply the physics.

    Subclasses set the class attributes and implement :meth:`default_params`, :meth:`_trim_states`
    and :meth:`_integrate`.

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel (name, or a loaded configuration).
    n : int
        Number of independent instances stepped together.
    rate_hz : float, optional
        Internal integration rate of a discrete model (its default otherwise).
    """

    name: ClassVar[str]
    """Registry name (``loada``...)."""
    title: ClassVar[str]
    """The report's name for it (table 4)."""
    continuous: ClassVar[bool] = False
    default_rate_hz: ClassVar[float] = 0.0
    """Internal integration rate of a discrete model; 0 for the continuous ones."""
    has_current: ClassVar[bool] = False
    """True when the model knows motor current and bus voltage."""
    one_system: ClassVar[bool] = False
    """True for a linear model: one LTI system for every instance, no per-instance parameters to disperse."""
    _buf_t: FloatArray
    _buf_u: FloatArray
    _buf_h: FloatArray
    _h_lo: int
    _h_hi: int
    """The input history: breakpoint buffers and the live range ``[_h_lo, _h_hi)``."""
    params_class: ClassVar[type]
    """Its parameter set: a dataclass declared with :func:`ema_sim.parameters.param`."""
    params_section: ClassVar[str]
    """The channel file's section the parameters come from."""
    params_layout: ClassVar[Slots | None] = None
    """Its kernel layout (None for the linear models, which have no parameter kernel)."""
    variant: ClassVar[str | None] = None
    """Which subsection variant of the section it reads (the high-order family's ``hoad2``, ``hoad3``)."""
    switchable: ClassVar[bool] = True
    """False when the model has none of its parameters' switchable elements (the linear models)."""
    shared_inputs: ClassVar[bool] = False
    """True when ``_integrate`` takes one row of inputs for every instance (a batch whose instances share a record
    runs it without a copy per instance)."""

    def __init__(self, channel: str | ChannelConfig = "left_wing", *, n: int = 1, rate_hz: float | None = None) -> None:
        if n < 1:
            raise ConfigError("n must be at least 1")
        self.channel = load_channel(channel) if isinstance(channel, str) else channel
        self.n = int(n)
        rate = self.default_rate_hz if rate_hz is None else float(rate_hz)
        if not self.continuous and not (math.isfinite(rate) and rate > 0.0):
            raise EmaError(f"{self.name}: rate must be a positive number of Hz, got {rate_hz!r}")
        self.rate_hz = rate
        self.rejected_inputs = 0
        """How many non-finite command or hinge-moment values :meth:`step` has held instead of using."""
        self._last_reject_log = -math.inf
        self._t = 0.0
        self._sample_t = np.zeros(1)
        """The one sample instant of a frame (reused: the kernels only read it)."""
        self._set_history(np.array([HISTORY_START_S]), np.zeros((self.n, 1)), np.zeros((self.n, 1)))

    # ----------------------------------------------------------------- family interface
    @property
    @abstractmethod
    def max_delay_s(self) -> float:
        """The longest input delay any instance applies (how much input history to keep)."""

    @abstractmethod
    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        """Set every state to the equilibrium of the held command and load."""

    @abstractmethod
    def _integrate(
        self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float, sample_t: FloatArray
    ) -> FloatArray:
        """Advance from ``self._t`` to ``t_end`` through the ZOH inputs; outputs at ``sample_t``.

        Returns an array ``(n, len(sample_t), N_OUT)``; the caller updates ``self._t``.
        """

    @classmethod
    @abstractmethod
    def default_params(cls, channel: ChannelConfig, **overrides: float) -> Any:
        """The parameters a model of this class takes from ``channel``, then ``overrides`` (validated).

        Parameters
        ----------
        channel : ChannelConfig
            The channel.
        **overrides : float
            Values that replace the channel's.

        Returns
        -------
        object
            An instance of :attr:`params_class`.
        """

    def retune(self, **values: float) -> None:  # noqa: ARG002 - the families' signature
        """Change parameters of every instance from the present model time, states kept (a fault's schedule).

        The families with a parameter kernel override this; a linear model has one LTI system and no
        parameter to change while it runs.

        Parameters
        ----------
        **values : float
            Parameter name → new value (validated like an override).
        """
        raise EmaError(f"{self.name} has no parameters to change while it runs")

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """The held command whose equilibrium is ``position_deg`` (families with command maps refine).

        Parameters
        ----------
        position_deg : numpy.ndarray
            The wanted position of each instance (deg).
        hinge_moment_inlb : numpy.ndarray
            The load of each instance (in·lb).

        Returns
        -------
        numpy.ndarray
            The command of each instance (deg).
        """
        del hinge_moment_inlb
        return position_deg

    # ----------------------------------------------------------------- parameters
    @classmethod
    def parameters(cls, channel: str | ChannelConfig | None = None) -> list[ParameterInfo]:
        """Every parameter of this model with its metadata, and a channel's defaults when one is given.

        Parameters
        ----------
        channel : str or ChannelConfig, optional
            The channel whose values are listed as defaults.

        Returns
        -------
        list of ParameterInfo
            In declaration order (see :func:`ema_sim.parameters.describe`).
        """
        defaults = None
        if channel is not None:
            defaults = cls.default_params(load_channel(channel) if isinstance(channel, str) else channel)
        return describe(cls.params_class, defaults=defaults, layout=cls.params_layout, section=cls.params_section,
                        variant=cls.variant)

    @classmethod
    def elements(cls) -> tuple[str, ...]:
        """The element names this model switches off by name: its parameters' declared elements.

        Returns
        -------
        tuple of str
            Empty for a model without them (the linear models removed them).
        """
        return elements(cls.params_class) if cls.switchable else ()

    @classmethod
    def element_overrides(cls, names: Iterable[str]) -> dict[str, float]:
        """The parameter overrides that switch the named elements off (those this model has).

        Parameters
        ----------
        names : iterable of str
            Element names.

        Returns
        -------
        dict
            Parameter name → its switch-off value.
        """
        return switched_off(cls.params_class, set(names) & set(cls.elements()))

    # ----------------------------------------------------------------- public interface
    @property
    def time_s(self) -> float:
        """Model time: seconds since the last :meth:`trim`."""
        return self._t

    def trim(
        self,
        command_deg: ArrayLike | None = 0.0,
        hinge_moment_inlb: ArrayLike = 0.0,
        *,
        position_deg: ArrayLike | None = None,
    ) -> Sample:
        """Restart at time 0 in equilibrium, with no transient.

        Give either the held ``command_deg`` or the ``position_deg`` to trim at (the command is then
        solved for; a quantized command lands within half a quantization step of it).

        Parameters
        ----------
        command_deg : array_like, optional
            The held command, for every instance or each (deg).
        hinge_moment_inlb : array_like
            The held load (in·lb, positive aids positive deflection).
        position_deg : array_like, optional
            The LVDT position to trim at instead (deg).

        Returns
        -------
        Sample
            The outputs at time 0.
        """
        hm = as_batch(hinge_moment_inlb, self.n, "hinge_moment_inlb")
        if position_deg is not None:
            u = self.trim_command(as_batch(position_deg, self.n, "position_deg"), hm)
        else:
            u = as_batch(0.0 if command_deg is None else command_deg, self.n, "command_deg")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(hm))):
            raise EmaError("trim needs finite command, position and hinge moment")
        self._t = 0.0
        self._set_history(np.array([HISTORY_START_S]), u[:, None], hm[:, None])
        self._trim_states(u, hm)
        bp_u, bp_h = np.ascontiguousarray(self._hist_u), np.ascontiguousarray(self._hist_h)
        return self._sample(self._integrate(self._hist_t, bp_u, bp_h, 0.0, np.zeros(1))[:, 0])

    def step(self, command_deg: ArrayLike, hinge_moment_inlb: ArrayLike = 0.0, frame_s: float = 0.005) -> Sample:
        """Advance one frame with the command and load held over it; outputs at the frame's end.

        The frame's breakpoint is written in place after the kept history (no copy of it), and the
        history is then trimmed by moving its start: the kernel sees exactly the breakpoints
        :meth:`run` would give it, so stepping frame by frame equals one run bit for bit.

        Parameters
        ----------
        command_deg : array_like
            The frame's command, for every instance or each (deg); a non-finite value is held at the
            last good one and counted in :attr:`rejected_inputs`.
        hinge_moment_inlb : array_like
            The frame's load (in·lb).
        frame_s : float
            The frame (s).

        Returns
        -------
        Sample
            The outputs at the frame's end.
        """
        return self._sample(self._advance(command_deg, hinge_moment_inlb, frame_s))

    def step_values(self, command_deg: float, hinge_moment_inlb: float = 0.0, frame_s: float = 0.005) -> list[float]:
        """:meth:`step` of instance 0, its outputs as Python floats in :data:`OUTPUT_FIELDS` order.

        The same frame as :meth:`step`, without building arrays for one instance: the per-frame path of
        the node layer (flags come back as a float; ``int()`` them).

        Parameters
        ----------
        command_deg : float
            The frame's command (deg).
        hinge_moment_inlb : float
            The frame's load (in·lb).
        frame_s : float
            The frame (s).

        Returns
        -------
        list of float
            Position, surface, rate, current, bus and flags.
        """
        values: list[float] = self._advance(command_deg, hinge_moment_inlb, frame_s)[0].tolist()
        return values

    def _advance(self, command_deg: float | ArrayLike, hinge_moment_inlb: float | ArrayLike,
                 frame_s: float) -> FloatArray:
        if not (math.isfinite(frame_s) and frame_s > 0.0):
            raise ConfigError(f"frame_s must be positive, got {frame_s!r}")
        hi = self._h_hi
        if hi == self._buf_t.shape[0]:
            self._set_history(self._hist_t, self._hist_u, self._hist_h)  # compacts (and grows when needed)
            hi = self._h_hi
        buf_u, buf_h = self._buf_u, self._buf_h
        if self.n == 1 and type(command_deg) is float and type(hinge_moment_inlb) is float:
            if math.isfinite(command_deg) and math.isfinite(hinge_moment_inlb):
                buf_u[0, hi] = command_deg
                buf_h[0, hi] = hinge_moment_inlb
            else:
                self._hold_bad(np.array([command_deg]), np.array([hinge_moment_inlb]), hi)
        else:
            self._hold_bad(as_batch(command_deg, self.n, "command_deg"),
                           as_batch(hinge_moment_inlb, self.n, "hinge_moment_inlb"), hi)
        t0 = self._t
        self._buf_t[hi] = t0
        self._h_hi = hi + 1
        t_end = t0 + frame_s
        lo = self._h_lo
        # column slices are strided; the kernels take C-contiguous arrays only (one compiled layout)
        bp_u, bp_h = np.ascontiguousarray(buf_u[:, lo:hi + 1]), np.ascontiguousarray(buf_h[:, lo:hi + 1])
        sample_t = self._sample_t
        sample_t[0] = t_end
        out = self._integrate(self._buf_t[lo:hi + 1], bp_u, bp_h, t_end, sample_t)
        self._t = t_end
        self._trim_history()
        return out[:, 0]

    def run(
        self,
        time_s: ArrayLike,
        command_deg: ArrayLike,
        hinge_moment_inlb: ArrayLike | None = None,
        *,
        sample_times: ArrayLike | None = None,
        end_s: float | None = None,
        progress: Callable[[float], None] | None = None,
    ) -> Record:
        """Run through a record of zero-order-held inputs starting at ``time_s[0]``.

        ``time_s`` are the instants the held inputs change (the FMU frames); ``sample_times``
        (default: ``time_s``) where the outputs are read, each from the state at or before it.
        ``end_s`` (default: the last sample) is where the model stops. ``progress`` gets the
        fraction done after each chunk of about a second of simulated time.

        Parameters
        ----------
        time_s : array_like
            Input breakpoints (s), increasing.
        command_deg : array_like
            Command at each breakpoint, one row for all instances or one per instance (deg).
        hinge_moment_inlb : array_like, optional
            Load at each breakpoint (in·lb; 0 when omitted).
        sample_times : array_like, optional
            Where the outputs are read (s).
        end_s : float, optional
            Where the model stops (s).
        progress : callable, optional
            Called with the fraction done.

        Returns
        -------
        Record
            The outputs at the sample times.
        """
        bp_t, u, hm, samples = self._validate_record(time_s, command_deg, hinge_moment_inlb, sample_times)
        out = self._run_block(bp_t, u, hm, samples, end_s, progress)
        held = stages.held_indices(bp_t, samples)
        return Record(
            model=self.name,
            channel=self.channel.channel,
            time_s=samples,
            command_deg=held_inputs(u, held),
            hinge_moment_inlb=held_inputs(hm, held),
            position_deg=out[:, :, O_POS],
            surface_deg=out[:, :, O_SURF],
            rate_dps=out[:, :, O_RATE],
            current_a=out[:, :, O_CUR],
            bus_v=out[:, :, O_BUS],
            flags=out[:, :, O_FLAGS].astype(np.int64),
        )

    def run_outputs(
        self,
        time_s: ArrayLike,
        command_deg: ArrayLike,
        hinge_moment_inlb: ArrayLike | None = None,
        *,
        sample_times: ArrayLike | None = None,
        end_s: float | None = None,
    ) -> FloatArray:
        """:meth:`run` without building a :class:`Record`: the raw ``(n, samples, N_OUT)`` block.

        For callers that simulate many times and need only the outputs (identification).

        Parameters
        ----------
        time_s : array_like
            Input breakpoints (s).
        command_deg : array_like
            Command at each breakpoint (deg).
        hinge_moment_inlb : array_like, optional
            Load at each breakpoint (in·lb).
        sample_times : array_like, optional
            Where the outputs are read (s).
        end_s : float, optional
            Where the model stops (s).

        Returns
        -------
        numpy.ndarray
            ``(n, samples, N_OUT)`` in :data:`OUTPUT_FIELDS` order.
        """
        bp_t, u, hm, samples = self._validate_record(time_s, command_deg, hinge_moment_inlb, sample_times)
        return self._run_block(bp_t, u, hm, samples, end_s, None)

    def _validate_record(
        self, time_s: ArrayLike, command_deg: ArrayLike, hinge_moment_inlb: ArrayLike | None,
        sample_times: ArrayLike | None,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        bp_t = np.asarray(time_s, dtype=float).ravel()
        m = bp_t.shape[0]
        if m == 0:
            raise EmaError("run needs at least one input breakpoint")
        u = as_record(command_deg, self.n, m, "command_deg")
        if hinge_moment_inlb is None:
            hm = np.broadcast_to(np.zeros(m), (self.n, m))
        else:
            hm = as_record(hinge_moment_inlb, self.n, m, "hinge_moment_inlb")
        check_finite(bp_t, "time_s")
        check_finite(u, "command_deg")
        check_finite(hm, "hinge_moment_inlb")
        if np.any(np.diff(bp_t) <= 0.0):
            raise EmaError("time_s must be strictly increasing")
        if bp_t[0] < self._t - stages.TIME_EPS_S:
            raise EmaError(f"time_s starts at {bp_t[0]:.6g} s, before the model time {self._t:.6g} s")
        samples = bp_t.copy() if sample_times is None else np.asarray(sample_times, dtype=float).ravel()
        check_finite(samples, "sample_times")
        if samples.size and (np.any(np.diff(samples) < 0.0) or samples[0] < self._t - stages.TIME_EPS_S):
            raise EmaError("sample_times must be ascending and not before the model time")
        return bp_t, u, hm, samples

    def _run_block(
        self, bp_t: FloatArray, u: FloatArray, hm: FloatArray, samples: FloatArray, end_s: float | None,
        progress: Callable[[float], None] | None,
    ) -> FloatArray:
        t_end = float(samples[-1]) if end_s is None else float(end_s)
        if samples.size and samples[-1] > t_end + stages.TIME_EPS_S:
            raise EmaError("sample_times go past end_s")
        all_t = np.concatenate([self._hist_t, bp_t])
        all_u = self._joined(self._hist_u, u)
        all_h = self._joined(self._hist_h, hm)
        blocks: list[FloatArray] = []  # each fresh from ``_integrate``: one chunk is the output as it is, uncopied
        t_start = self._t
        span = max(t_end - t_start, 1e-12)
        chunk_s = 1.0 if progress is not None else math.inf
        done = 0
        while True:
            t_stop = min(t_end, self._t + chunk_s)
            last = t_stop >= t_end
            upto = samples.size if last else int(np.searchsorted(samples, self._written_before(t_stop), side="left"))
            blocks.append(self._integrate(all_t, all_u, all_h, t_stop, samples[done:upto]))
            self._t = t_stop
            done = upto
            if progress is not None:
                progress((t_stop - t_start) / span)
            if last:
                break
        self._keep_history(all_t, all_u, all_h)
        return blocks[0] if len(blocks) == 1 else np.concatenate(blocks, axis=1)

    def _joined(self, history: FloatArray, values: FloatArray) -> FloatArray:
        """The kept history and a record's inputs as one C-contiguous block for ``_integrate``.

        One row when the family takes :attr:`shared_inputs` and every instance has the same history and record (a
        record given once for all is a broadcast view): a batch then runs without a copy of it per instance.
        """
        shared = self.shared_inputs and values.shape[0] > 1 and values.strides[0] == 0
        if shared and bool(np.all(history == history[:1])):
            return np.concatenate([history[:1], values[:1]], axis=1)
        return np.ascontiguousarray(np.concatenate([history, values], axis=1))

    def _written_before(self, t_stop: float) -> float:
        """Samples before this instant belong to an integration that ends at ``t_stop``.

        A run in chunks hands each chunk exactly the samples one run would write from its states, so no
        chunk boundary shows in the outputs.
        """
        return t_stop

    def describe(self) -> JsonObject:
        """Name, title, rate and channel, for logs and bag metadata."""
        return {
            "model": self.name,
            "title": self.title,
            "channel": self.channel.channel,
            "rate_hz": self.rate_hz if not self.continuous else "continuous",
            "instances": self.n,
        }

    # ----------------------------------------------------------------- helpers
    def _hold_bad(self, u: FloatArray, hm: FloatArray, hi: int) -> None:
        """Write the frame's inputs at ``hi``, non-finite ones replaced by the last good; count and log them."""
        last_u, last_h = self._buf_u[:, hi - 1], self._buf_h[:, hi - 1]
        bad_u = ~np.isfinite(u)
        bad_h = ~np.isfinite(hm)
        if bad_u.any() or bad_h.any():
            self.rejected_inputs += int(bad_u.sum() + bad_h.sum())
            u = np.where(bad_u, last_u, u)
            hm = np.where(bad_h, last_h, hm)
            now = time.monotonic()
            if now - self._last_reject_log >= 1.0:
                self._last_reject_log = now
                log.error(
                    "%s/%s: non-finite input held at its last value (%d rejected so far)",
                    self.name, self.channel.channel, self.rejected_inputs,
                )
        self._buf_u[:, hi] = u
        self._buf_h[:, hi] = hm

    # The input history: breakpoints still inside the longest delay, as views into preallocated
    # buffers (``step`` appends in place, trimming moves the start; compaction is rare).
    @property
    def _hist_t(self) -> FloatArray:
        return self._buf_t[self._h_lo:self._h_hi]

    @property
    def _hist_u(self) -> FloatArray:
        return self._buf_u[:, self._h_lo:self._h_hi]

    @property
    def _hist_h(self) -> FloatArray:
        return self._buf_h[:, self._h_lo:self._h_hi]

    def _set_history(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray) -> None:
        """Copy breakpoints into fresh buffers with room for many frames after them."""
        m = bp_t.shape[0]
        cap = max(HISTORY_CAPACITY, 2 * m)
        buf_t = np.empty(cap)
        buf_u = np.empty((self.n, cap))
        buf_h = np.empty((self.n, cap))
        buf_t[:m] = bp_t
        buf_u[:, :m] = bp_u
        buf_h[:, :m] = bp_h
        self._buf_t, self._buf_u, self._buf_h = buf_t, buf_u, buf_h
        self._h_lo, self._h_hi = 0, m

    def _trim_history(self) -> None:
        """Drop the breakpoints no delay can reach any more (the latest one before the horizon stays)."""
        horizon = self._t - self.max_delay_s - 1e-6
        item, lo, hi = self._buf_t.item, self._h_lo, self._h_hi
        while lo + 1 < hi and item(lo + 1) <= horizon:  # a few breakpoints: faster than searchsorted
            lo += 1
        self._h_lo = lo

    def _keep_history(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray) -> None:
        """Keep the breakpoints of a whole record that delays can still reach (after :meth:`run`)."""
        horizon = self._t - self.max_delay_s - 1e-6
        first = max(int(np.searchsorted(bp_t, horizon, side="right")) - 1, 0)
        self._set_history(bp_t[first:], bp_u[:, first:], bp_h[:, first:])

    def _sample(self, block: FloatArray) -> Sample:
        """Outputs of one instant; ``block`` is fresh from ``_integrate``, so its columns are not copied."""
        return Sample(
            time_s=self._t,
            position_deg=block[:, O_POS],
            surface_deg=block[:, O_SURF],
            rate_dps=block[:, O_RATE],
            current_a=block[:, O_CUR],
            bus_v=block[:, O_BUS],
            flags=block[:, O_FLAGS].astype(np.int64),
        )


class Tolerances:
    """The adaptive integrator's tolerances of a continuous model (LOAC, HOAC1), mixed in before its family.

    Parameters
    ----------
    *args : object
        The family's arguments.
    rtol : float, optional
        Relative tolerance (:attr:`default_rtol`).
    atol : float, optional
        Absolute tolerance (:attr:`default_atol`).
    **kwargs : object
        The family's keyword arguments.
    """

    default_rtol: ClassVar[float] = 1e-9
    default_atol: ClassVar[float] = 1e-11

    def __init__(self, *args: object, rtol: float | None = None, atol: float | None = None, **kwargs: object) -> None:
        self.rtol = self.default_rtol if rtol is None else float(rtol)
        self.atol = self.default_atol if atol is None else float(atol)
        super().__init__(*args, **kwargs)


def batch_params(params: _Params | Sequence[_Params] | None, n: int, default: Callable[[], _Params]) -> list[_Params]:
    """Normalise a family's ``params`` argument: None, one set for all, or one per instance.

    Parameters
    ----------
    params : object, sequence or None
        The argument as given.
    n : int
        Number of instances.
    default : callable
        Makes the default set (called once, when ``params`` is None).

    Returns
    -------
    list
        One parameter set per instance.
    """
    if params is None:
        return [default()] * n
    if isinstance(params, Sequence) and not isinstance(params, str | bytes):
        if len(params) != n:
            raise ConfigError(f"got {len(params)} parameter sets for {n} instances")
        return list(params)
    return [params] * n

"""The high-order models of table 5 behind the one stepping interface: HOAC1, HOAD2, HOAD3.

* ``hoac1`` continuous: adaptive Dormand–Prince with every regime change located (:mod:`.hoac1`).
* ``hoad2`` the 10,000 Hz discrete implementation with the flight/test elements of stages 1–3, 16, 17
  (:mod:`.hoad`).
* ``hoad3`` HOAD2 adjusted to the installed data: the figure-33 gear train, 4 ms + 2 ms delays.

Outputs: position = the (delayed, quantized, noisy) filtered LVDT; surface = the true surface angle,
compliance outside the loop included; rate = the motor-side screw rate; current = motor current;
bus = bus voltage. Power is an input the node layer can drive: :meth:`HighOrderModel.set_power`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ema_sim.config import ChannelConfig
from ema_sim.errors import ConfigError, EmaError, UnknownNameError
from ema_sim.jsontypes import JsonObject
from ema_sim.models import noise as nz
from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import N_OUT, ActuatorModel, Tolerances, batch_params
from ema_sim.models.high_order.figure30 import MOTOR_STUCK
from ema_sim.models.high_order.hoac1 import N_U, U, run_continuous
from ema_sim.models.high_order.hoad import DELAY_STEP_EPS, command_in, run_discrete
from ema_sim.models.high_order.params import BOUNDS, N_CONTINUOUS, N_STATE, SECTION, HighOrderParams, P, X
from ema_sim.models.high_order.trim import Equilibrium, TrimKey, equilibrium
from ema_sim.parameters import Slots, Value, metas

ENVIRONMENT_FIELDS = tuple(n for n, m in metas(HighOrderParams).items() if m.variants and n != "noise_bandwidth_hz")
"""The flight/test elements HOAC1 does not have (a noise bandwidth alone adds nothing)."""


def bound_value(bound: str | float) -> float:
    """A compliance bound by name (``lower``, ``mean``, ``upper``) or number in [−1, 1].

    Parameters
    ----------
    bound : str or float
        The bound.

    Returns
    -------
    float
        −1 … +1.
    """
    if isinstance(bound, str):
        if bound not in BOUNDS:
            raise UnknownNameError("compliance bound", bound, BOUNDS)
        return BOUNDS[bound]
    value = float(bound)
    if not -1.0 <= value <= 1.0:
        raise EmaError(f"compliance bound must be in [-1, 1] (lower, mean, upper), got {bound}")
    return value


class HighOrderModel(ActuatorModel):
    """Common part of HOAC1, HOAD2 and HOAD3: parameters, power, command path and trim.

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel whose configuration gives the defaults.
    n : int
        Number of instances.
    rate_hz : float, optional
        Integration rate (the discrete models; 10,000 Hz).
    params : HighOrderParams or list of HighOrderParams, optional
        The parameters (one set, or one per instance); the channel's otherwise.
    bound : str, float or sequence
        Figure 35's compliance bound, one for all or one per instance (HOAD3).
    hysteresis : bool
        Figure 36's hysteretic damping on (HOAD3).
    noise : bool
        The measured noise on.
    seed : int or sequence of int
        The noise seed, or one per instance.
    **overrides : float
        Parameter values that replace the channel's (not with ``params``).
    """

    has_current = True
    variant: ClassVar[str] = "hoac1"
    figure33: ClassVar[bool] = False
    params_class: ClassVar[type] = HighOrderParams
    params_section: ClassVar[str] = SECTION
    params_layout: ClassVar[Slots | None] = P

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        params: HighOrderParams | list[HighOrderParams] | None = None,
        bound: str | float | Sequence[str | float] = "mean",
        hysteresis: bool | float = False,
        noise: bool | float = True,
        seed: int | float | Sequence[int] = 0,
        **overrides: Value,
    ) -> None:
        super().__init__(channel, n=n, rate_hz=rate_hz)
        if params is not None and overrides:
            raise ConfigError("give either params or keyword overrides, not both")
        bounds = list(bound) if isinstance(bound, Sequence) and not isinstance(bound, str) else [bound] * self.n
        if len(bounds) != self.n:
            raise EmaError(f"got {len(bounds)} compliance bounds for {self.n} instances")
        self.bounds = [bound_value(b) for b in bounds]
        self.hysteresis = bool(hysteresis)
        if not self.figure33 and (any(self.bounds) or self.hysteresis):
            raise EmaError(f"{self.name}: compliance bounds and hysteretic damping belong to HOAD3's figure-33 "
                           "gear train")
        self.noise = bool(noise)
        self.seed: int | Sequence[int] = seed if isinstance(seed, Sequence) else int(seed)
        self.params: list[HighOrderParams] = batch_params(
            params, self.n, lambda: self.default_params(self.channel, **overrides)
        )
        if self.continuous and any(getattr(prm, f) > 0.0 for prm in self.params for f in ENVIRONMENT_FIELDS):
            raise EmaError(f"{self.name} has no flight/test environment (delay, quantization, noise): use hoad2/hoad3")
        self._P = self._kernel_vectors()
        # a delay between two steps blends the inputs of both (:func:`~ema_sim.models.high_order.hoad.split_delay`)
        step = 1.0 / self.rate_hz if not self.continuous and self.rate_hz else 0.0
        self._max_delay_s = float(self._P[:, P.command_delay_s].max()) + step
        self._power = np.ones(self.n)
        self.trim()

    def _kernel_vectors(self) -> FloatArray:
        fb = self.channel.feedback_cal
        return np.stack([
            prm.kernel_vector(figure33=self.figure33, bound=b, hysteresis=self.hysteresis, noise=self.noise,
                              feedback_cal=(fb.c0, fb.c1, fb.c2, fb.c3))
            for prm, b in zip(self.params, self.bounds, strict=True)
        ])

    def retune(self, **values: float) -> None:
        """Change parameters from the present model time; states, delay buffers and noise streams are kept.

        Parameters
        ----------
        **values : float
            Parameter name → new value.
        """
        if "feedback_delay_s" in values:
            raise EmaError(f"{self.name}: the feedback delay's buffer is sized at construction; it cannot change "
                           "while the model runs")
        if self.continuous and any(v > 0.0 for k, v in values.items() if k in ENVIRONMENT_FIELDS):
            raise EmaError(f"{self.name} has no flight/test environment (delay, quantization, noise): use hoad2/hoad3")
        self.params = [prm.replace(**values) for prm in self.params]
        self._P = self._kernel_vectors()
        step = 1.0 / self.rate_hz if not self.continuous and self.rate_hz else 0.0
        self._max_delay_s = max(self._max_delay_s, float(self._P[:, P.command_delay_s].max()) + step)

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: Value) -> HighOrderParams:  # noqa: D102
        return HighOrderParams.from_channel(channel, cls.variant or "hoad3", **overrides)

    # ------------------------------------------------------------------ power and brake
    @property
    def power(self) -> FloatArray:
        """Motor power of each instance (1 on, 0 off: brake engaged, no drive)."""
        return self._power.copy()

    def set_power(self, on: bool | ArrayLike) -> None:
        """Switch the 150 V motor power of every (or each) instance from the current model time.

        Off: the bridge is open (no current), the brake holds the motor (> 4,000 lbf, table 1) and
        the bus reads 0 V. On: the brake releases and the servo loop resumes from where it is.

        Parameters
        ----------
        on : bool or array_like
            On (1, true) or off (0, false), for every instance or each.
        """
        value = np.broadcast_to(np.asarray(on, dtype=float), (self.n,)).copy()
        if not np.all((value == 0.0) | (value == 1.0)):
            raise EmaError("power must be on or off (true/false or 1/0)")
        self._power = value

    # ------------------------------------------------------------------ command path
    def _command_in(self, bp_u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Stage 2 on every breakpoint: command degrees → (quantized command in inches, inches per volt)."""
        bp_u = np.ascontiguousarray(bp_u, dtype=float)
        x_in = np.empty_like(bp_u)
        slope = np.empty_like(bp_u)
        cal = self.channel.command_cal
        command_in(self._P, cal.c0, cal.c1, cal.c2, cal.c3, bp_u, x_in, slope)
        return x_in, slope

    # ------------------------------------------------------------------ base interface
    @property
    def max_delay_s(self) -> float:  # noqa: D102
        return self._max_delay_s

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """The command whose equilibrium LVDT reading is ``position_deg`` under the load.

        Parameters
        ----------
        position_deg : numpy.ndarray
            The wanted LVDT reading of each instance (deg).
        hinge_moment_inlb : numpy.ndarray
            The load of each instance (in·lb).

        Returns
        -------
        numpy.ndarray
            The command of each instance (deg).
        """
        out = np.empty(self.n)
        for i in range(self.n):
            p = self._P[i]
            target = position_deg[i] / p[P.deg_per_in]
            eq = equilibrium(p, target, float(hinge_moment_inlb[i]), self._power[i] > 0.5)
            out[i] = (2.0 * target - eq["lf"]) * p[P.deg_per_in] if eq["motor"] == MOTOR_STUCK else position_deg[i]
        return out

    def stream_seeds(self) -> list[int]:
        """The noise stream of each instance: ``seed`` and the instance number, or one seed per instance.

        A batch given the seeds ``[a, b, …]`` reproduces single models seeded ``a``, ``b``, ….

        Returns
        -------
        list of int
            One 63-bit stream number per instance.
        """
        if isinstance(self.seed, Sequence):
            if len(self.seed) != self.n:
                raise EmaError(f"got {len(self.seed)} seeds for {self.n} instances")
            return [(int(s) * 1_000_003) % 2**63 for s in self.seed]
        return [(self.seed * 1_000_003 + i) % 2**63 for i in range(self.n)]

    def _equilibria(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> list[Equilibrium]:
        x_in, _ = self._command_in(command_deg[:, None])
        return [equilibrium(self._P[i], float(x_in[i, 0]), float(hinge_moment_inlb[i]), self._power[i] > 0.5)
                for i in range(self.n)]

    def describe(self) -> JsonObject:  # noqa: D102
        info = super().describe()
        info.update(bounds=[*self.bounds], hysteresis=self.hysteresis, noise=self.noise,
                    seed=self.seed if isinstance(self.seed, int) else [*self.seed])
        return info


TRIMMED = (X.x_motor_in, X.x_surface_in, X.current_a, X.lvdt_filtered_in, X.bus_v, X.integral_in_s)
"""The state columns trim sets (the rest start at zero)."""
TRIM_KEYS: tuple[TrimKey, ...] = ("xm", "xs", "cur", "lf", "vbus", "xi")


class Hoac1(Tolerances, HighOrderModel):
    """HOAC1: the continuous physics model of figure 30, the reference the discrete ones are judged by.

    Takes :class:`HighOrderModel`'s arguments and the tolerances ``rtol``, ``atol`` (:class:`Tolerances`).
    """

    name = "hoac1"
    title = "High-order actuator continuous model version 1.0 (HOAC1)"
    continuous = True
    variant = "hoac1"
    events: int
    """Regime changes located since the last trim (a measure of how hard the record was)."""

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        self._Y = np.zeros((self.n, N_CONTINUOUS))
        self._U = np.zeros((self.n, N_U))
        for i, eq in enumerate(self._equilibria(command_deg, hinge_moment_inlb)):
            self._Y[i, list(TRIMMED)] = [eq[k] for k in TRIM_KEYS]
            self._U[i, U.motor_regime] = eq["motor"]
        self._h = np.full(self.n, 1e-5)
        self.events = 0

    def set_power(self, on: bool | ArrayLike) -> None:  # noqa: D102
        super().set_power(on)
        self._Y[self._power < 0.5, X.current_a] = 0.0  # the open bridge: no winding current

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        out = np.empty((self.n, sample_t.size, N_OUT))
        x_in, _ = self._command_in(bp_u)
        self.events += run_continuous(
            self._P, self._Y, self._U, self._h, self._power, bp_t, np.ascontiguousarray(x_in),
            np.ascontiguousarray(bp_h), self._t, t_end, sample_t, self.rtol, self.atol, out,
        )
        return out


class Hoad2(HighOrderModel):
    """HOAD2: HOAC1 discretized at 10,000 Hz with time delay, 5 mV quantization and noise (4.2.5)."""

    name = "hoad2"
    title = "High-order actuator discrete model version 2.0 (HOAD2)"
    default_rate_hz = 10_000.0
    variant = "hoad2"

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        dt = 1.0 / self.rate_hz
        nbuf = math.floor(float(self._P[:, P.feedback_delay_s].max()) / dt + DELAY_STEP_EPS) + 2
        self._X = np.zeros((self.n, N_STATE))
        self._buf = np.zeros((self.n, nbuf))
        for i, eq in enumerate(self._equilibria(command_deg, hinge_moment_inlb)):
            self._X[i, list(TRIMMED)] = [eq[k] for k in TRIM_KEYS]
            self._X[i, X.flags] = eq["flags"]
            self._buf[i] = eq["lf"]
        self._rng = np.array([[nz.splitmix64(s)] for s in self.stream_seeds()], dtype=np.uint64)
        self._steps = 0

    def set_power(self, on: bool | ArrayLike) -> None:  # noqa: D102
        super().set_power(on)
        self._X[self._power < 0.5, X.current_a] = 0.0

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        dt = 1.0 / self.rate_hz
        t0 = self._steps * dt
        n_steps = max(math.floor((t_end - t0) / dt + 1e-6), 0)
        x_in, slope = self._command_in(bp_u)
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_discrete(
            self._P, self._X, self._rng, self._buf, self._power, bp_t, np.ascontiguousarray(x_in),
            np.ascontiguousarray(slope), np.ascontiguousarray(bp_h), t0, dt, n_steps, sample_t, out,
        )
        self._steps += n_steps
        return out


class Hoad3(Hoad2):
    """HOAD3: HOAD2 adjusted to the installed data: figure-33 gear train, 4 ms + 2 ms delays (2.3)."""

    name = "hoad3"
    title = "High-order actuator discrete model version 3.0 (HOAD3)"
    variant = "hoad3"
    figure33 = True

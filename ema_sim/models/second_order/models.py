"""The second-order models of table 5 behind the one stepping interface: LOAC, LOADF, LOADA, and ours.

The implementations differ only in how they integrate figure 26 (:mod:`.figure26`):

* ``loac``  continuous: adaptive Dormand–Prince at a tight tolerance, stops located exactly (:mod:`.loac`).
* ``loada`` the auto-coded discrete model: forward-Euler integrators at ``rate_hz`` (800 Hz; :mod:`.loada`).
* ``loadf`` flight 1's FORTRAN: backward Euler, feedback one frame ahead, 200 Hz (:mod:`.loada`).
* ``second_order`` the same equations by event-splitting RK4 (:mod:`.rk4`): identification's simulator,
  defaulting to the basic second order of figure 21 (ωn, ζ) with every other element off.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ema_sim.config import ChannelConfig, load_channel
from ema_sim.errors import ConfigError, EmaError
from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import N_OUT, ActuatorModel, Tolerances, batch_params
from ema_sim.models.second_order import stage_set
from ema_sim.models.second_order.figure26 import HISTORY_SIZE, stages_on_any, trim
from ema_sim.models.second_order.loac import run_continuous
from ema_sim.models.second_order.loada import METHOD_FORWARD_EULER, METHOD_LOADF, run_discrete
from ema_sim.models.second_order.params import N_STATE, SECTION, P, SecondOrderParams, X
from ema_sim.models.second_order.rk4 import run_rk4
from ema_sim.models.stages import TIME_EPS_S
from ema_sim.parameters import Slots


class SecondOrderModel(ActuatorModel):
    """Common part of LOAC, LOADF and LOADA: parameters, trim and the command map.

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel whose configuration gives the defaults.
    n : int
        Number of instances.
    rate_hz : float, optional
        Integration rate (the discrete models).
    params : SecondOrderParams or list of SecondOrderParams, optional
        The parameters (one set, or one per instance); the channel's otherwise.
    **overrides : float
        Parameter values that replace the channel's (not with ``params``).
    """

    params_class: ClassVar[type] = SecondOrderParams
    params_section: ClassVar[str] = SECTION
    params_layout: ClassVar[Slots | None] = P

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        params: SecondOrderParams | list[SecondOrderParams] | None = None,
        **overrides: float,
    ) -> None:
        if isinstance(params, list | tuple) and n == 1:
            n = len(params)
        super().__init__(channel, n=n, rate_hz=rate_hz)
        if params is not None and overrides:
            raise ConfigError("give either params or keyword overrides, not both")
        self.params: list[SecondOrderParams] = batch_params(
            params, self.n, lambda: self.default_params(self.channel, **overrides)
        )
        for prm in self.params:
            prm.validate()
        self._P = np.stack([prm.kernel_vector() for prm in self.params])
        self._on = stage_set.kernel_set(int(stages_on_any(self._P)))
        """The stage set the fixed-step kernel is compiled for."""
        self._max_delay_s = float(self._P[:, P.delay_s].max())
        self._X = np.zeros((self.n, N_STATE))
        delayed = bool(np.any(self._P[:, P.feedback_delay_s] > 0.0))
        self._H = np.zeros((self.n, HISTORY_SIZE if delayed else 1, 3))
        """Each instance's stage-14 ring (time, reading, rate) for the feedback delay."""
        self.trim()

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:  # noqa: D102
        return SecondOrderParams.from_channel(channel, **overrides)

    @property
    def max_delay_s(self) -> float:  # noqa: D102
        return self._max_delay_s

    def retune(self, **values: float) -> None:
        """Change parameters from the present model time; states, delay history and clock are kept.

        Parameters
        ----------
        **values : float
            Parameter name → new value.
        """
        if "feedback_delay_s" in values:
            raise EmaError(f"{self.name}: the feedback delay's ring is sized at construction; it cannot change "
                           "while the model runs")
        self.params = [prm.replace(**values) for prm in self.params]
        self._P = np.stack([prm.kernel_vector() for prm in self.params])
        self._on = stage_set.kernel_set(int(stages_on_any(self._P)))
        self._max_delay_s = max(self._max_delay_s, float(self._P[:, P.delay_s].max()))

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """Invert stages 2 and 5 (quantization is left to land within half a step).

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
        p = self._P
        aiding = np.where(position_deg >= 0.0, hinge_moment_inlb, -hinge_moment_inlb)
        kcp = 1.0 + p[:, P.kcp_per_kinlb] * aiding * 1e-3
        return (position_deg / kcp - p[:, P.offset_deg]) / (1.0 + p[:, P.kb])

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        trim(self._P, np.ascontiguousarray(command_deg, dtype=float),
             np.ascontiguousarray(hinge_moment_inlb, dtype=float), self._X, self._H)


class Loada(SecondOrderModel):
    """LOADA: the discrete auto-coded second-order model, forward Euler at ``rate_hz`` (800 Hz)."""

    name = "loada"
    title = "Low-order actuator discrete auto-code model (LOADA)"
    default_rate_hz = 800.0
    method: ClassVar[int] = METHOD_FORWARD_EULER
    shared_inputs = True

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        super()._trim_states(command_deg, hinge_moment_inlb)
        self._steps = 0  # the model's own clock, in steps: a frame's remainder carries over

    def _last_step(self, t_end: float) -> tuple[float, float, int]:
        """The step, the time of the next step of the model's own clock, and the steps a call to ``t_end`` takes."""
        dt = 1.0 / self.rate_hz
        t0 = self._steps * dt
        return dt, t0, max(math.floor((t_end - t0) / dt + 1e-6), 0)

    def _written_before(self, t_stop: float) -> float:
        # a sample reads the last step at or before it: the call ending on step n writes every sample before
        # step n + 1, as the kernel computes that instant
        dt, t0, n_steps = self._last_step(t_stop)
        return t0 + n_steps * dt + dt - TIME_EPS_S

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        dt, t0, n_steps = self._last_step(t_end)
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_discrete(self._P, self._X, self._H, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, self.method, out, self._on)
        self._steps += n_steps
        return out


class Loadf(Loada):
    """LOADF: flight 1's hand-coded FORTRAN at 200 Hz, with the faults of section 4.2.4."""

    name = "loadf"
    title = "Low-order actuator discrete FORTRAN model (LOADF)"
    default_rate_hz = 200.0
    method = METHOD_LOADF


class Loac(Tolerances, SecondOrderModel):
    """LOAC: the continuous second-order model, the reference the discrete ones are judged against.

    Takes :class:`SecondOrderModel`'s arguments and the tolerances ``rtol``, ``atol`` (:class:`Tolerances`).
    """

    name = "loac"
    title = "Low-order actuator continuous model (LOAC)"
    continuous = True

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        super()._trim_states(command_deg, hinge_moment_inlb)
        self._mode = np.zeros((self.n, 2), dtype=np.int64)
        x = self._X[:, X.position_deg]
        p = self._P
        self._mode[:, 0] = np.where(x >= p[:, P.position_max_deg], 1, np.where(x <= p[:, P.position_min_deg], -1, 0))
        self._mode[:, 1] = np.sign(self._X[:, X.free_play_deg]).astype(np.int64)  # 0 when no subsystem runs
        self._h = np.full(self.n, 1e-4)

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_continuous(self._P, self._X, self._H, self._mode, self._h, bp_t, bp_u, bp_h, self._t, t_end, sample_t,
                       self.rtol, self.atol, out)
        return out


class SecondOrder(SecondOrderModel):
    """The second-order equations by RK4 with exact input breakpoints (identification's simulator).

    Defaults to the basic second order of figure 21 (the channel's ωn and ζ, every other element off);
    keyword overrides switch elements on.

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel whose ωn, ζ and physical data are used.
    n : int
        Number of instances.
    rate_hz : float, optional
        Unused (the model is continuous); accepted for the common interface.
    params : SecondOrderParams or list of SecondOrderParams, optional
        The parameters; :meth:`SecondOrderParams.basic` otherwise.
    step_s : float, optional
        Longest RK4 sub-step (0.25 ms).
    **overrides : float
        Stages to switch on (or values to change) from the basic model.
    """

    name = "second_order"
    title = "Second-order model, RK4 with exact input breakpoints (identification simulator)"
    continuous = True
    default_step_s: ClassVar[float] = 2.5e-4

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        params: SecondOrderParams | list[SecondOrderParams] | None = None,
        step_s: float | None = None,
        **overrides: float,
    ) -> None:
        self.step_s = self.default_step_s if step_s is None else float(step_s)
        if not self.step_s > 0.0:
            raise EmaError(f"step_s must be positive, got {step_s!r}")
        if params is None:
            ch = load_channel(channel) if isinstance(channel, str) else channel
            params = self.default_params(ch, **overrides)
            overrides = {}
        super().__init__(channel, n=n, rate_hz=rate_hz, params=params, **overrides)

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:  # noqa: D102
        return SecondOrderParams.basic(channel, **overrides)

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_rk4(self._P, self._X, self._H, bp_t, bp_u, bp_h, self._t, t_end, self.step_s, sample_t, out)
        return out

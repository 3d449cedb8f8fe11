"""Linear models (section 3.4, 4.2.7): transfer functions built with python-control.

A :class:`LinearModel` wraps a continuous state-space system with inputs (command deg, hinge moment
in·lb) and outputs (LVDT position deg, surface deg), plus a pure delay on the command and optionally
one more on the position output (the motion-to-feedback delay). In the time domain it steps the exact
zero-order-hold discretization at ``rate_hz`` (10 kHz by default), exact whenever the inputs change on
that grid; in the frequency domain :meth:`LinearModel.frequency_response` evaluates the continuous
system and the delays exactly.

* ``sloac``: LOAC's second order and delay (flight 1's linear model).
* ``hoalm``: HOAD3 linearized with its nonlinear elements removed (4.2.7).
* ``loes``: a second order plus delay fitted to HOAD3's sine-dwell frequency response (3.4); the
  coefficients come from the channel's ``loes`` section, refitted by :mod:`ema_sim.analysis.studies.loes`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numba as nb
import numpy as np
from numpy.typing import ArrayLike

from ema_sim import parameters as pm
from ema_sim.config import ChannelConfig, load_channel
from ema_sim.errors import ConfigError
from ema_sim.jsontypes import JsonObject
from ema_sim.models import stages as st
from ema_sim.models.arrays import FloatArray, IntArray
from ema_sim.models.base import N_OUT, O_BUS, O_CUR, O_FLAGS, O_POS, O_RATE, O_SURF, ActuatorModel
from ema_sim.models.high_order.linear import linearize
from ema_sim.models.high_order.models import bound_value
from ema_sim.models.high_order.params import HighOrderParams
from ema_sim.models.second_order.params import SecondOrderParams
from ema_sim.parameters import Value

if TYPE_CHECKING:  # the annotations' type; python-control itself is imported where a system is built
    import control as ct


@nb.njit(cache=True)
def run_lti(Ad: FloatArray, Bd: FloatArray, Cd: FloatArray, Dd: FloatArray, Crate: FloatArray,
            Drate: FloatArray, X: FloatArray, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray,
            source: IntArray, delay: FloatArray, t0: float, dt: float, n_steps: int, sample_t: FloatArray,
            out: FloatArray) -> None:
    """Step ``x ← Ad·x + Bd·u`` for every instance; samples as the discrete models.

    Input ``j`` is the command (``source[j] = 0``) or the hinge moment (1) delayed by ``delay[j]``: the
    command with its delay and the load (two inputs), or, for a model with an output delay, both again
    delayed that much more (four).

    Parameters
    ----------
    Ad, Bd, Cd, Dd : numpy.ndarray
        The zero-order-hold discretization at ``dt``.
    Crate, Drate : numpy.ndarray
        The position output's rate: ``Crate·x + Drate·u``.
    X : numpy.ndarray
        States, one row per instance, advanced in place.
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    bp_u : numpy.ndarray
        Command at each breakpoint, one row per instance (deg).
    bp_h : numpy.ndarray
        Hinge moment at each breakpoint, one row per instance (in·lb).
    source : numpy.ndarray
        Which input each system input is (0 command, 1 hinge moment).
    delay : numpy.ndarray
        Each system input's delay (s).
    t0 : float
        Time of the first step (s).
    dt : float
        The step (s).
    n_steps : int
        Steps to take.
    sample_t : numpy.ndarray
        Sample instants (s).
    out : numpy.ndarray
        Output block ``(instances, samples, outputs)``, filled.
    """
    k_samples = sample_t.shape[0]
    nx = Ad.shape[0]
    nu = source.shape[0]
    xn = np.empty(nx)
    uin = np.empty(nu)
    idx = np.zeros(nu, dtype=np.int64)
    for i in range(X.shape[0]):
        x = X[i]
        for j in range(nu):
            idx[j] = st.zoh_index(bp_t, t0 - delay[j], 0)
        js = 0
        for k in range(n_steps + 1):
            t = t0 + k * dt
            for j in range(nu):
                idx[j] = st.zoh_index(bp_t, t - delay[j], idx[j])
                uin[j] = bp_u[i, idx[j]] if source[j] == 0 else bp_h[i, idx[j]]
            while js < k_samples and (k == n_steps or sample_t[js] < t + dt - st.TIME_EPS_S):
                row = out[i, js]
                row[O_POS] = 0.0
                row[O_SURF] = 0.0
                row[O_RATE] = 0.0
                for j in range(nu):
                    row[O_POS] += Dd[0, j] * uin[j]
                    row[O_SURF] += Dd[1, j] * uin[j]
                    row[O_RATE] += Drate[j] * uin[j]
                for a in range(nx):
                    row[O_POS] += Cd[0, a] * x[a]
                    row[O_SURF] += Cd[1, a] * x[a]
                    row[O_RATE] += Crate[a] * x[a]
                row[O_CUR] = np.nan
                row[O_BUS] = np.nan
                row[O_FLAGS] = 0.0
                js += 1
            if k == n_steps:
                break
            for a in range(nx):
                acc = 0.0
                for j in range(nu):
                    acc += Bd[a, j] * uin[j]
                for b in range(nx):
                    acc += Ad[a, b] * x[b]
                xn[a] = acc
            for a in range(nx):
                x[a] = xn[a]


class LinearModel(ActuatorModel):
    """A continuous LTI system (2 inputs, 2 outputs) with a command delay, stepped exactly.

    ``position_delay_s`` delays the position output further (feedback transport); it is stepped as a
    second copy of the system driven by inputs delayed that much more, so it stays exact.

    Parameters
    ----------
    system : control.StateSpace
        Continuous, inputs (command deg, hinge moment in·lb), outputs (position deg, surface deg).
    delay_s : float
        Command delay (s).
    channel : str or ChannelConfig
        The channel.
    n : int
        Number of instances.
    rate_hz : float, optional
        Stepping rate (10,000 Hz).
    position_delay_s : float
        Further delay of the position output (s).
    """

    default_rate_hz = 10_000.0
    one_system: ClassVar[bool] = True
    switchable: ClassVar[bool] = False

    def __init__(
        self,
        system: ct.StateSpace,
        delay_s: float,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        position_delay_s: float = 0.0,
    ) -> None:
        super().__init__(channel, n=n, rate_hz=rate_hz)
        if system.ninputs != 2 or system.noutputs != 2 or not system.isctime():
            raise ConfigError("a linear actuator model is a continuous system with 2 inputs and 2 outputs")
        if not (delay_s >= 0.0 and position_delay_s >= 0.0):
            raise ConfigError("delays must not be negative")
        self.system = system
        self.delay_s = float(delay_s)
        self.position_delay_s = float(position_delay_s)
        A, B, C, D = (np.asarray(m, dtype=float) for m in (system.A, system.B, system.C, system.D))
        if self.position_delay_s > 0.0:
            # Surface from copy 1 (inputs u(t − τ), hm(t)); position from copy 2, everything τ_p later.
            nx = A.shape[0]
            z = np.zeros((nx, nx))
            zb = np.zeros((nx, 2))
            A = np.block([[A, z], [z, A]])
            B = np.block([[B, zb], [zb, B]])
            C = np.block([[np.zeros((1, nx)), C[0:1]], [C[1:2], np.zeros((1, nx))]])
            D = np.hstack([np.array([[0.0, 0.0], [D[1, 0], D[1, 1]]]), np.array([[D[0, 0], D[0, 1]], [0.0, 0.0]])])
            self._source = np.array([0, 1, 0, 1], dtype=np.int64)
            tau = self.delay_s + self.position_delay_s
            self._delays = np.array([self.delay_s, 0.0, tau, self.position_delay_s])
        else:
            self._source = np.array([0, 1], dtype=np.int64)
            self._delays = np.array([self.delay_s, 0.0])
        self._A, self._B = A, B
        dt = 1.0 / self.rate_hz
        import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
        disc = ct.c2d(ct.ss(A, B, C, D), dt, method="zoh")
        self._Ad = np.ascontiguousarray(disc.A, dtype=float)
        self._Bd = np.ascontiguousarray(disc.B, dtype=float)
        self._Cd = np.ascontiguousarray(disc.C, dtype=float)
        self._Dd = np.ascontiguousarray(disc.D, dtype=float)
        # Position rate: d/dt (C0·x + D0·u) = C0·A·x + C0·B·u for held inputs.
        self._Crate = np.ascontiguousarray(C[0] @ A)
        self._Drate = np.ascontiguousarray(C[0] @ B)
        self._X = np.zeros((self.n, A.shape[0]))
        self.trim()

    @property
    def max_delay_s(self) -> float:  # noqa: D102
        return self.delay_s + self.position_delay_s

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        u = np.stack([command_deg if s == 0 else hinge_moment_inlb for s in self._source])  # (inputs, n)
        self._X[:] = np.linalg.solve(self._A, -self._B @ u).T  # steady state: A·x + B·u = 0
        self._steps = 0

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """The command whose steady state (DC gain) is ``position_deg`` under the given load.

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
        import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
        dc = np.asarray(ct.dcgain(self.system), dtype=float)
        command: FloatArray = (position_deg - dc[0, 1] * hinge_moment_inlb) / dc[0, 0]
        return command

    def _integrate(self, bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t_end: float,
                   sample_t: FloatArray) -> FloatArray:
        dt = 1.0 / self.rate_hz
        t0 = self._steps * dt
        n_steps = max(int(np.floor((t_end - t0) / dt + 1e-6)), 0)
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_lti(self._Ad, self._Bd, self._Cd, self._Dd, self._Crate, self._Drate, self._X, bp_t, bp_u, bp_h,
                self._source, self._delays, t0, dt, n_steps, sample_t, out)
        self._steps += n_steps
        return out

    def frequency_response(self, freq_hz: ArrayLike, output: int = 0) -> tuple[FloatArray, FloatArray]:
        """Gain (dB) and phase (deg) from command to ``output``, delays included.

        Parameters
        ----------
        freq_hz : array_like
            Frequencies (Hz).
        output : int
            0 position, 1 surface.

        Returns
        -------
        gain_db, phase_deg : numpy.ndarray
            The response.
        """
        gain, phase = _db_deg(self.complex_response(freq_hz, output))
        return gain, phase

    def complex_response(self, freq_hz: ArrayLike, output: int = 0) -> np.ndarray:
        """The complex response from the command to ``output``, delays included.

        Parameters
        ----------
        freq_hz : array_like
            Frequencies (Hz).
        output : int
            0 position, 1 surface.

        Returns
        -------
        numpy.ndarray
            One complex value per frequency.
        """
        f = np.atleast_1d(np.asarray(freq_hz, dtype=float))
        w = 2.0 * np.pi * f
        import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
        resp = ct.frequency_response(self.system[output, 0], w)
        delay = self.delay_s + (self.position_delay_s if output == 0 else 0.0)
        response: np.ndarray = np.asarray(resp.complex).reshape(-1) * np.exp(-1j * w * delay)
        return response

    def describe(self) -> JsonObject:  # noqa: D102
        info = super().describe()
        info["delay_s"] = self.delay_s
        if self.position_delay_s:
            info["position_delay_s"] = self.position_delay_s
        info["states"] = int(self.system.nstates)
        return info


def _db_deg(h: np.ndarray) -> tuple[FloatArray, FloatArray]:
    return 20.0 * np.log10(np.abs(h)), np.degrees(np.unwrap(np.angle(h)))


def second_order_system(wn_rad_s: float, zeta: float) -> ct.StateSpace:
    """ωn²/(s² + 2ζωn·s + ωn²) from the command; the hinge moment does not enter; surface = position.

    Parameters
    ----------
    wn_rad_s : float
        Natural frequency.
    zeta : float
        Damping ratio.

    Returns
    -------
    control.StateSpace
        Two inputs, two outputs.
    """
    import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
    g = ct.ss(ct.tf([wn_rad_s**2], [1.0, 2.0 * zeta * wn_rad_s, wn_rad_s**2]))
    A = np.asarray(g.A, dtype=float)
    B = np.hstack([np.asarray(g.B, dtype=float), np.zeros((A.shape[0], 1))])
    C = np.vstack([np.asarray(g.C, dtype=float)] * 2)
    return ct.ss(A, B, C, np.zeros((2, 2)), inputs=["command_deg", "hinge_moment_inlb"],
                 outputs=["position_deg", "surface_deg"])


class Sloac(LinearModel):
    """SLOAC: LOAC reduced to its second-order transfer function and delay (section 4.2.7).

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel.
    n : int
        Number of instances.
    rate_hz : float, optional
        Stepping rate (10,000 Hz).
    **overrides : float
        Second-order parameters that replace the channel's.
    """

    name = "sloac"
    title = "Simplified low-order actuator continuous model (SLOAC)"
    params_class: ClassVar[type] = SecondOrderParams
    params_section: ClassVar[str] = "second_order"

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        **overrides: float,
    ) -> None:
        ch = load_channel(channel) if isinstance(channel, str) else channel
        self.params = self.default_params(ch, **overrides)
        super().__init__(
            second_order_system(self.params.wn_rad_s, self.params.zeta), self.params.delay_s, ch,
            n=n, rate_hz=rate_hz,
        )

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:  # noqa: D102
        # LOAC's parameters (SLOAC keeps ωn, ζ and the delay).
        return SecondOrderParams.from_channel(channel, **overrides)


class Hoalm(LinearModel):
    """HOALM: HOAD3 linearized about a load with its nonlinear elements removed (section 4.2.7).

    ``load_inlb`` is the hinge moment it is linearized at (the report found it under-predicted the
    wing gain at low load and the phase loss at every load); ``bound`` picks the compliance bound.
    Steps at 10,000 Hz like the discrete model it comes from (table 5).

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel.
    n : int
        Number of instances.
    rate_hz : float, optional
        Stepping rate (10,000 Hz).
    load_inlb : float
        The hinge moment it is linearized at (in·lb).
    bound : str or float
        Figure 35's compliance bound.
    **overrides : float
        High-order parameters that replace the channel's.
    """

    name = "hoalm"
    title = "High-order actuator linear model (HOALM)"
    params_class: ClassVar[type] = HighOrderParams
    params_section: ClassVar[str] = "high_order"
    variant: ClassVar[str | None] = "hoad3"

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        load_inlb: float = 0.0,
        bound: str | float = "mean",
        **overrides: float,
    ) -> None:
        ch = load_channel(channel) if isinstance(channel, str) else channel
        self.params = self.default_params(ch, **overrides)
        self.load_inlb = float(load_inlb)
        self.bound = bound_value(bound)
        self.linearized = linearize(self.params, self.load_inlb, bound=self.bound)
        lin = self.linearized
        import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
        system = ct.ss(lin.a, lin.b, lin.c, np.zeros((2, 2)), inputs=["command_deg", "hinge_moment_inlb"],
                       outputs=["position_deg", "surface_deg"])
        super().__init__(system, lin.command_delay_s, ch, n=n, rate_hz=rate_hz, position_delay_s=lin.feedback_delay_s)

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: Value) -> HighOrderParams:  # noqa: D102
        # HOAD3's parameters, the model it linearizes.
        return HighOrderParams.from_channel(channel, "hoad3", **overrides)

    def describe(self) -> JsonObject:  # noqa: D102
        info = super().describe()
        info.update(load_inlb=self.load_inlb, bound=self.bound)
        return info


@pm.documented
@dataclass(frozen=True)
class LoesParams:
    """The LOES coefficients and the settings of the fit that wrote them (config ``loes``)."""

    wn_rad_s: float = pm.param("rad/s", "natural frequency of the equivalent second order (3.4)", min=0.0,
                               min_exclusive=True)
    zeta: float = pm.param("-", "damping ratio of the equivalent second order", min=0.0, min_exclusive=True)
    delay_s: float = pm.param("s", "equivalent delay", min=0.0)
    dc_gain_ratio: float = pm.param("-", "steady-state gain K", min=0.0, min_exclusive=True)
    fit_min_hz: float = pm.param("Hz", "lowest sine dwell of the fit that wrote the coefficients (ema loes)",
                                 min=0.0, min_exclusive=True, default=0.5)
    fit_max_hz: float = pm.param("Hz", "highest sine dwell of the fit", min=0.0, min_exclusive=True, default=20.0)
    dwell_amp_deg: float = pm.param("deg", "amplitude of the fit's sine dwells", min=0.0, min_exclusive=True,
                                    default=1.0)

    RELATIONS: ClassVar[tuple[pm.Relation, ...]] = (("fit_min_hz", "<", "fit_max_hz"),)


LOES_FIELDS = ("wn_rad_s", "zeta", "delay_s", "dc_gain_ratio")
"""The coefficients the model uses (the rest of :class:`LoesParams` are the fit's settings)."""


def loes_system(wn_rad_s: float, zeta: float, dc_gain_ratio: float) -> ct.StateSpace:
    """``K·ωn²/(s² + 2ζωn·s + ωn²)`` from the command to both outputs; the hinge moment does not enter.

    Parameters
    ----------
    wn_rad_s : float
        Natural frequency.
    zeta : float
        Damping ratio.
    dc_gain_ratio : float
        Steady-state gain K.

    Returns
    -------
    control.StateSpace
        Two inputs, two outputs.
    """
    import control as ct  # noqa: PLC0415 - python-control: a 1 s import, only where a system is built
    g = ct.ss(ct.tf([dc_gain_ratio * wn_rad_s**2], [1.0, 2.0 * zeta * wn_rad_s, wn_rad_s**2]))
    A = np.asarray(g.A, dtype=float)
    B = np.hstack([np.asarray(g.B, dtype=float), np.zeros((A.shape[0], 1))])
    C = np.vstack([np.asarray(g.C, dtype=float)] * 2)
    return ct.ss(A, B, C, np.zeros((2, 2)), inputs=["command_deg", "hinge_moment_inlb"],
                 outputs=["position_deg", "surface_deg"])


class Loes(LinearModel):
    """LOES: the low-order equivalent system of HOAD3, a second order plus delay (sections 3.4, 4.2.8).

    The coefficients are the channel's ``loes`` section, written by the fit in
    :mod:`ema_sim.analysis.studies.loes` (``ema loes --write``), so building the model costs nothing. It is the
    command-to-position equivalent: the surface output equals the position and the load does not enter.

    Parameters
    ----------
    channel : str or ChannelConfig
        The channel.
    n : int
        Number of instances.
    rate_hz : float, optional
        Stepping rate (10,000 Hz).
    **overrides : float
        LOES coefficients that replace the channel's.
    """

    name = "loes"
    title = "Low-order equivalent system actuator model (LOES)"
    params_class: ClassVar[type] = LoesParams
    params_section: ClassVar[str] = "loes"

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        **overrides: float,
    ) -> None:
        ch = load_channel(channel) if isinstance(channel, str) else channel
        self.params = self.default_params(ch, **overrides)
        self.coefficients = {k: getattr(self.params, k) for k in LOES_FIELDS}
        super().__init__(loes_system(self.params.wn_rad_s, self.params.zeta, self.params.dc_gain_ratio),
                         self.params.delay_s, ch, n=n, rate_hz=rate_hz)

    @classmethod
    def default_params(cls, channel: ChannelConfig, **overrides: Value) -> LoesParams:  # noqa: D102
        return pm.load(LoesParams, channel.section("loes"), origin=channel.channel, family="LOES", section="loes",
                       overrides=overrides)

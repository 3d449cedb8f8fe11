"""The second-order family of section 3.1: LOAC, LOADF and LOADA (tables 4 and 5).

One pipeline of named stages in the order of figure 26, shared by the three implementations:

command path (FMU side, held between frames)
    1. time delay            command to first motion (section 2.3)
    2. command error         (1 + Kb)·u + offset (3.1.2.2)
    3. quantization          D/A resolution, 0.020° (3.1.2.2)
actuator (integrated at the model's own rate)
    4. command lag           optional first-order lag on the command
    5. compliance correction K_CP, a gain that varies with load (3.1.2.4)
    6. threshold             optional dead zone on the servo error
    7. rate limit            on the velocity command, rl + K2·hm/marm (3.1.2.1)
    8. second order          ωn, ζ (figure 21)
    9. position limits       on the states, so nothing winds up
   10. LVDT compliance       optional deflection with load that the servo loop does not remove
   11. feedback lag          optional first-order lag on the LVDT feedback
surface (outside the servo loop)
   12. free play             hm / Is double-integrated in a limited integrator, ±width/2 (figure 29)
   13. compliance            optional deflection linear in hinge moment, with optional hysteretic
                             damping (figure 36): viscous equivalent h/ω on the linkage

The implementations differ only in how they integrate, as table 5 describes (plus one of ours):

* ``loac``  continuous: adaptive Dormand–Prince at a tight tolerance, stops located exactly.
* ``loada`` the auto-coded discrete model: forward-Euler integrators at ``rate_hz`` (800 Hz).
* ``loadf`` the hand-coded FORTRAN of flight 1, with the faults section 4.2.4 names: backward-Euler
  integrators, the position feedback taken one frame ahead of where it belongs, and 200 Hz. It
  responds to a step sooner than LOAC does, the lead that over-predicted flight 1's margins.
* ``second_order`` the same equations by fixed-step RK4 that splits its steps at every input
  breakpoint, delayed ones included, and solves the free play exactly: fast, accurate (far below
  sensor noise) and smooth in its parameters, so identification can fit it. Its defaults are the
  basic second order of figure 21 (ωn, ζ) with every other element off.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, fields, replace
from typing import Any, ClassVar

import numba as nb
import numpy as np

from ema_sim.config import ChannelConfig, load_channel
from ema_sim.errors import ConfigError, EmaError, UnknownNameError
from ema_sim.models import stages as st
from ema_sim.models.base import (
    N_OUT,
    O_BUS,
    O_CUR,
    O_FLAGS,
    O_POS,
    O_RATE,
    O_SURF,
    ActuatorModel,
    FloatArray,
    batch_params,
)
from ema_sim.models.integrate import make_dopri5


@dataclass(frozen=True)
class SecondOrderParams:
    """Every parameter of the figure-26 pipeline, in the units its name carries."""

    wn_rad_s: float
    zeta: float
    rate_limit_dps: float
    k2_dps_per_lb: float
    moment_arm_in: float
    position_min_deg: float
    position_max_deg: float
    kb: float
    offset_deg: float
    quantization_deg: float
    free_play_deg: float
    surface_inertia_inlbs2: float
    kcp_per_kinlb: float
    delay_s: float
    command_lag_hz: float
    feedback_lag_hz: float
    threshold_deg: float
    compliance_deg_per_kinlb: float
    lvdt_compliance_deg_per_kinlb: float = 0.0
    hysteresis_h_lb_per_in: float = 0.0
    hysteresis_freq_hz: float = 0.0125

    @classmethod
    def basic(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:
        """The basic second order of figure 21: the channel's ωn and ζ, every other element off."""
        base = cls.from_channel(channel)
        off = {
            "rate_limit_dps": math.inf, "k2_dps_per_lb": 0.0, "kb": 0.0, "offset_deg": 0.0,
            "quantization_deg": 0.0, "free_play_deg": 0.0, "kcp_per_kinlb": 0.0, "delay_s": 0.0,
            "command_lag_hz": 0.0, "feedback_lag_hz": 0.0, "threshold_deg": 0.0,
            "compliance_deg_per_kinlb": 0.0, "lvdt_compliance_deg_per_kinlb": 0.0, "hysteresis_h_lb_per_in": 0.0,
        }
        names = {f.name for f in fields(cls)}
        for key in overrides:
            if key not in names:
                raise UnknownNameError("second-order parameter", key, names)
        return base.replace(**{**off, **{k: float(v) for k, v in overrides.items()}})

    @classmethod
    def from_channel(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:
        """Defaults of a channel's ``second_order`` section and its physical data, then overrides."""
        sec = channel.section("second_order")
        names = {f.name for f in fields(cls)}
        values: dict[str, Any] = {
            "moment_arm_in": channel.crank_arm_in,
            "position_min_deg": channel.position_min_deg,
            "position_max_deg": channel.position_max_deg,
            "free_play_deg": channel.free_play_deg,
            "surface_inertia_inlbs2": channel.surface_inertia_inlbs2,
        }
        for key, value in sec.items():
            if key not in names:
                raise ConfigError(f"{channel.channel}: unknown second_order parameter {key!r}")
            values[key] = value
        for key, value in overrides.items():
            if key not in names:
                raise UnknownNameError("second-order parameter", key, names)
            values[key] = value
        missing = {f.name for f in fields(cls) if f.default is MISSING} - values.keys()
        if missing:
            raise ConfigError(f"{channel.channel}: second_order is missing {', '.join(sorted(missing))}")
        params = cls(**{k: float(v) for k, v in values.items()})
        params.validate()
        return params

    def validate(self) -> None:
        """Reject values no actuator can have (one message naming the parameter)."""
        for f in fields(self):
            value = getattr(self, f.name)
            if math.isnan(value) or (math.isinf(value) and f.name != "rate_limit_dps"):
                raise ConfigError(f"second-order parameter {f.name} must be finite")
        positive = ("wn_rad_s", "zeta", "rate_limit_dps", "moment_arm_in", "surface_inertia_inlbs2")
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ConfigError(f"second-order parameter {name} must be positive")
        non_negative = (
            "k2_dps_per_lb", "quantization_deg", "free_play_deg", "delay_s", "command_lag_hz",
            "feedback_lag_hz", "threshold_deg", "hysteresis_h_lb_per_in",
        )
        for name in non_negative:
            if getattr(self, name) < 0.0:
                raise ConfigError(f"second-order parameter {name} must not be negative")
        if self.position_min_deg >= self.position_max_deg:
            raise ConfigError("position_min_deg must be below position_max_deg")
        if self.hysteresis_freq_hz <= 0.0:
            raise ConfigError("second-order parameter hysteresis_freq_hz must be positive")

    def replace(self, **changes: float) -> SecondOrderParams:
        """A copy with some parameters changed (validated)."""
        out = replace(self, **changes)
        out.validate()
        return out

    def as_dict(self) -> dict[str, float]:
        """Name → value."""
        return asdict(self)

    def vector(self) -> FloatArray:
        """The parameters in kernel order (the ``P_*`` indices)."""
        return np.array([getattr(self, f.name) for f in fields(self)], dtype=float)


(
    P_WN, P_ZETA, P_RL, P_K2, P_MARM, P_PMIN, P_PMAX, P_KB, P_OFFSET, P_QUANT, P_FP, P_INERTIA,
    P_KCP, P_DELAY, P_CMD_LAG, P_FB_LAG, P_THRESH, P_COMPL, P_LVDT_COMPL, P_HYST_H, P_HYST_HZ,
) = range(21)
assert len(fields(SecondOrderParams)) == 21  # kernel indices follow the dataclass

# State columns (shared by every implementation).
X_POS, X_RATE, X_FP, X_FP_RATE, X_CMD_LAG, X_FB_LAG, X_COMPL = range(7)
N_STATE = 7

METHOD_FORWARD_EULER = 0
METHOD_LOADF = 1


@nb.njit(cache=True)
def _command_path(p, u):  # noqa: ANN001, ANN202
    """Stages 2–3 on the (already delayed) command."""
    return st.quantize(st.command_error(u, p[P_KB], p[P_OFFSET]), p[P_QUANT])


@nb.njit(cache=True)
def _servo_accel(p, u_in, x, v, hm):  # noqa: ANN001, ANN202
    """Stages 5–8: the acceleration of the actuator and the rate/threshold flags."""
    u_eff = st.compliance_correction(u_in, hm, p[P_KCP])
    e = u_eff - x
    e_dz = st.dead_zone(e, p[P_THRESH])
    up, down = st.load_rate_limits(p[P_RL], p[P_K2], hm, p[P_MARM])
    a, limited = st.rate_limited_second_order(x + e_dz, x, v, p[P_WN], p[P_ZETA], up, down)
    flags = st.FLAG_RATE if limited else 0
    if p[P_THRESH] > 0.0 and e_dz == 0.0:
        flags |= st.FLAG_THRESHOLD
    return a, flags


@nb.njit(cache=True)
def _next_event(t_end, bp_t, m, jd, delay_s, jh, sample_t, js, k_samples):  # noqa: ANN001, ANN202
    """Where an integration step must stop: the next delayed command, hinge moment or sample instant."""
    t_next = t_end
    if jd + 1 < m:
        t_next = min(t_next, bp_t[jd + 1] + delay_s)
    if jh + 1 < m:
        t_next = min(t_next, bp_t[jh + 1])
    if js < k_samples:
        t_next = min(t_next, sample_t[js])
    return t_next


@nb.njit(cache=True)
def _lvdt(p, x_pos, hm):  # noqa: ANN001, ANN202
    """Stage 10: what the LVDT reads, the servo position plus the compliance it does not remove."""
    return x_pos + st.compliance_deflection(hm, p[P_LVDT_COMPL])


@nb.njit(cache=True)
def _compliance_time_constant_s(p):  # noqa: ANN001, ANN202
    """Stage 13: linkage stiffness k and hysteretic damping h/ω make the compliance a first-order lag.

    The linkage deflects x = δ·marm (in) under F = hm/marm (lb), so k = F/x = 1000/(C·marm²) lb/in
    with C in rad per 1000 in·lb; the damper c = h/ω gives τ = c/k. Zero when either is off.
    """
    c = p[P_COMPL]
    if c <= 0.0 or p[P_HYST_H] <= 0.0:
        return 0.0
    k_lb_per_in = 1000.0 / (c * st.DEG2RAD * p[P_MARM] * p[P_MARM])
    return p[P_HYST_H] / (st.TWO_PI * p[P_HYST_HZ]) / k_lb_per_in


@nb.njit(cache=True)
def _write_outputs(p, x, position_fb, hm, flags, row):  # noqa: ANN001, ANN202
    """Stages 10–13 seen from outside: LVDT position, surface angle, rate, flags."""
    row[O_POS] = position_fb
    damped = _compliance_time_constant_s(p) > 0.0
    compliance = x[X_COMPL] if damped else st.compliance_deflection(hm, p[P_COMPL])
    row[O_SURF] = _lvdt(p, x[X_POS], hm) + x[X_FP] + compliance
    row[O_RATE] = x[X_RATE]
    row[O_CUR] = np.nan
    row[O_BUS] = np.nan
    half = 0.5 * p[P_FP]
    if x[X_POS] >= p[P_PMAX] or x[X_POS] <= p[P_PMIN]:
        flags |= st.FLAG_POSITION
    if half > 0.0 and abs(x[X_FP]) >= half:
        flags |= st.FLAG_FREE_PLAY
    row[O_FLAGS] = flags


@nb.njit(cache=True)
def run_discrete(P, X, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, method, out):  # noqa: ANN001, ANN201
    """Fixed-step LOADA/LOADF kernel: all instances through ``n_steps`` steps from ``t0``.

    A sample at time s reads the state of the last step at or before s (a DAU sampling a
    zero-order-held discrete output).
    """
    k_samples = sample_t.shape[0]
    for i in range(P.shape[0]):
        p = P[i]
        x = X[i]
        jd = 0
        jh = 0
        js = 0
        g_cmd = st.lag_gain(p[P_CMD_LAG], dt)
        g_fb = st.lag_gain(p[P_FB_LAG], dt)
        tau_c = _compliance_time_constant_s(p)
        g_c = 1.0 - math.exp(-dt / tau_c) if tau_c > 0.0 else 1.0
        half = 0.5 * p[P_FP]
        fp_acc_per_inlb = st.free_play_accel(1.0, p[P_INERTIA])
        hm = bp_h[i, st.zoh_index(bp_t, t0, 0)]
        _, flags = _servo_accel(p, x[X_CMD_LAG], x[X_POS], x[X_RATE], hm)
        for k in range(n_steps + 1):
            t = t0 + k * dt
            while js < k_samples and (k == n_steps or sample_t[js] < t + dt - st.TIME_EPS_S):
                _write_outputs(p, x, x[X_FB_LAG], hm, flags, out[i, js])
                js += 1
            if k == n_steps:
                break
            u_del, jd = st.transport_delay(bp_t, bp_u[i], t, p[P_DELAY], jd)
            jh = st.zoh_index(bp_t, t, jh)
            hm = bp_h[i, jh]
            uq = _command_path(p, u_del)
            x[X_CMD_LAG] = st.first_order_lag(x[X_CMD_LAG], uq, g_cmd)
            u_in = x[X_CMD_LAG]
            fp_acc = hm * fp_acc_per_inlb
            if method == METHOD_FORWARD_EULER:
                a, flags = _servo_accel(p, u_in, x[X_POS], x[X_RATE], hm)
                x[X_POS] += dt * x[X_RATE]
                x[X_RATE] += dt * a
                x[X_FP] += dt * x[X_FP_RATE]
                x[X_FP_RATE] += dt * fp_acc
            else:
                # LOADF: the loop closes on (and reports) the position one frame ahead, x + T·v,
                # and both integrators are backward Euler (each takes its input of this step).
                a, flags = _servo_accel(p, u_in, x[X_POS] + dt * x[X_RATE], x[X_RATE], hm)
                x[X_RATE] += dt * a
                x[X_POS] += dt * x[X_RATE]
                x[X_FP_RATE] += dt * fp_acc
                x[X_FP] += dt * x[X_FP_RATE]
            x[X_POS], x[X_RATE], _ = st.limited_integrator(x[X_POS], x[X_RATE], p[P_PMIN], p[P_PMAX])
            x[X_FP], x[X_FP_RATE], _ = st.limited_integrator(x[X_FP], x[X_FP_RATE], -half, half)
            fb_pos = x[X_POS] + dt * x[X_RATE] if method == METHOD_LOADF else x[X_POS]
            x[X_FB_LAG] = st.first_order_lag(x[X_FB_LAG], _lvdt(p, fb_pos, hm), g_fb)  # gain 1 when off
            x[X_COMPL] = st.first_order_lag(x[X_COMPL], st.compliance_deflection(hm, p[P_COMPL]), g_c)


@nb.njit(cache=True)
def _loac_rhs(t, y, p, u, dydt):  # noqa: ANN001, ANN202, ARG001 - the integrator's signature
    """LOAC right-hand side; ``u = [command after stages 1–3, hinge moment]``."""
    hm = u[1]
    if p[P_CMD_LAG] > 0.0:
        dydt[X_CMD_LAG] = st.TWO_PI * p[P_CMD_LAG] * (u[0] - y[X_CMD_LAG])
        u_in = y[X_CMD_LAG]
    else:
        dydt[X_CMD_LAG] = 0.0
        u_in = u[0]
    a, _ = _servo_accel(p, u_in, y[X_POS], y[X_RATE], hm)
    dydt[X_POS] = y[X_RATE]
    dydt[X_RATE] = a
    dydt[X_FP] = y[X_FP_RATE]
    dydt[X_FP_RATE] = st.free_play_accel(hm, p[P_INERTIA])
    if p[P_FB_LAG] > 0.0:
        dydt[X_FB_LAG] = st.TWO_PI * p[P_FB_LAG] * (_lvdt(p, y[X_POS], hm) - y[X_FB_LAG])
    else:
        dydt[X_FB_LAG] = 0.0
    tau_c = _compliance_time_constant_s(p)
    if tau_c > 0.0:
        dydt[X_COMPL] = (st.compliance_deflection(hm, p[P_COMPL]) - y[X_COMPL]) / tau_c
    else:
        dydt[X_COMPL] = 0.0


_loac_dopri5 = make_dopri5(_loac_rhs)


@nb.njit(cache=True)
def run_continuous(P, X, MODE, H, bp_t, bp_u, bp_h, t0, t_end, sample_t, rtol, atol, out):  # noqa: ANN001, ANN201
    """LOAC kernel: integrate every instance from ``t0`` to ``t_end``, breaking at each input change.

    ``MODE`` holds each instance's stop modes (position, free play); ``H`` its step size.
    """
    k_samples = sample_t.shape[0]
    m = bp_t.shape[0]
    limits = np.empty((2, 4))
    u = np.empty(2)
    for i in range(P.shape[0]):
        p = P[i]
        y = X[i]
        mode = MODE[i]
        half = 0.5 * p[P_FP]
        limits[0, 0] = X_POS
        limits[0, 1] = X_RATE
        limits[0, 2] = p[P_PMIN]
        limits[0, 3] = p[P_PMAX]
        limits[1, 0] = X_FP
        limits[1, 1] = X_FP_RATE
        limits[1, 2] = -half
        limits[1, 3] = half
        if half <= 0.0:
            mode[1] = 2
            y[X_FP] = 0.0
            y[X_FP_RATE] = 0.0
        h_max = 1.0 / (4.0 * p[P_WN])
        t = t0
        jd = st.zoh_index(bp_t, t - p[P_DELAY], 0)
        jh = st.zoh_index(bp_t, t, 0)
        js = 0
        while True:
            while js < k_samples and sample_t[js] <= t + st.TIME_EPS_S:
                u_now = _command_path(p, bp_u[i, jd])
                u_in = y[X_CMD_LAG] if p[P_CMD_LAG] > 0.0 else u_now
                _, flags = _servo_accel(p, u_in, y[X_POS], y[X_RATE], bp_h[i, jh])
                pos_fb = y[X_FB_LAG] if p[P_FB_LAG] > 0.0 else _lvdt(p, y[X_POS], bp_h[i, jh])
                _write_outputs(p, y, pos_fb, bp_h[i, jh], flags, out[i, js])
                js += 1
            if t >= t_end - st.TIME_EPS_S:
                break
            t_next = _next_event(t_end, bp_t, m, jd, p[P_DELAY], jh, sample_t, js, k_samples)
            u[0] = _command_path(p, bp_u[i, jd])
            u[1] = bp_h[i, jh]
            if t_next > t + st.TIME_EPS_S:
                H[i], _ = _loac_dopri5(p, u, y, t, t_next, H[i], rtol, atol, h_max, limits, mode)
            t = t_next
            jd = st.zoh_index(bp_t, t - p[P_DELAY], jd)
            jh = st.zoh_index(bp_t, t, jh)


@nb.njit(cache=True)
def _free_play_exact(p, y, hm, h):  # noqa: ANN001, ANN202
    """Stage 12 solved exactly over ``h`` with the hinge moment held: a limited double integrator.

    Exact except for an impact and rebound inside one step, which a held load cannot produce.
    """
    half = 0.5 * p[P_FP]
    if half <= 0.0:
        y[X_FP] = 0.0
        y[X_FP_RATE] = 0.0
        return
    a = st.free_play_accel(hm, p[P_INERTIA])
    fp = y[X_FP]
    v = y[X_FP_RATE]
    if (fp >= half and a >= 0.0 and v >= 0.0) or (fp <= -half and a <= 0.0 and v <= 0.0):
        y[X_FP] = half if fp > 0.0 else -half
        y[X_FP_RATE] = 0.0
        return
    fp += h * (v + 0.5 * a * h)
    v += a * h
    if fp >= half:
        fp = half
        v = 0.0
    elif fp <= -half:
        fp = -half
        v = 0.0
    y[X_FP] = fp
    y[X_FP_RATE] = v


@nb.njit(cache=True)
def _switch_state(p, y, u):  # noqa: ANN001, ANN202
    """Which smooth piece of the right-hand side ``y`` is on: rate limit side × dead-zone side."""
    hm = u[1]
    u_in = y[X_CMD_LAG] if p[P_CMD_LAG] > 0.0 else u[0]
    e = st.compliance_correction(u_in, hm, p[P_KCP]) - y[X_POS]
    dz = 0
    if p[P_THRESH] > 0.0:
        dz = 1 if e > p[P_THRESH] else (-1 if e < -p[P_THRESH] else 0)
    e_dz = st.dead_zone(e, p[P_THRESH])
    up, down = st.load_rate_limits(p[P_RL], p[P_K2], hm, p[P_MARM])
    vc = p[P_WN] / (2.0 * p[P_ZETA]) * e_dz
    rate = 1 if vc > up else (-1 if vc < -down else 0)
    return 3 * rate + dz


@nb.njit(cache=True)
def _rk4_step(p, y, u, h, k1, k2, k3, k4, yt, out):  # noqa: ANN001, ANN202
    """One RK4 step of the actuator states from ``y`` into ``out``; free play solved exactly."""
    n = y.shape[0]
    _loac_rhs(0.0, y, p, u, k1)
    for a in range(n):
        yt[a] = y[a] + 0.5 * h * k1[a]
    _loac_rhs(0.0, yt, p, u, k2)
    for a in range(n):
        yt[a] = y[a] + 0.5 * h * k2[a]
    _loac_rhs(0.0, yt, p, u, k3)
    for a in range(n):
        yt[a] = y[a] + h * k3[a]
    _loac_rhs(0.0, yt, p, u, k4)
    for a in range(n):
        out[a] = y[a] + h / 6.0 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a])
    out[X_FP] = y[X_FP]
    out[X_FP_RATE] = y[X_FP_RATE]
    _free_play_exact(p, out, u[1], h)
    out[X_POS], out[X_RATE], _ = st.limited_integrator(out[X_POS], out[X_RATE], p[P_PMIN], p[P_PMAX])


SWITCH_TOL_S = 1e-10
"""How closely a switch of the rate limit or dead zone is located inside an RK4 step."""


@nb.njit(cache=True, parallel=True)
def run_rk4(P, X, bp_t, bp_u, bp_h, t0, t_end, h_max, sample_t, out):  # noqa: ANN001, ANN201, PLR0915
    """Second-order kernel for identification: RK4 that never steps across an event.

    Steps are at most ``h_max`` and never straddle an input breakpoint (delayed or not), a sample, or
    a switch of the rate limit or dead zone (located by bisection); the free play is solved exactly.
    Instances run in parallel threads.
    """
    k_samples = sample_t.shape[0]
    m = bp_t.shape[0]
    for i in nb.prange(P.shape[0]):
        p = P[i]
        y = X[i]
        n = y.shape[0]
        u = np.empty(2)
        k1 = np.empty(n)
        k2 = np.empty(n)
        k3 = np.empty(n)
        k4 = np.empty(n)
        yt = np.empty(n)
        y1 = np.empty(n)
        t = t0
        jd = st.zoh_index(bp_t, t - p[P_DELAY], 0)
        jh = st.zoh_index(bp_t, t, 0)
        js = 0
        while True:
            while js < k_samples and sample_t[js] <= t + st.TIME_EPS_S:
                hm = bp_h[i, jh]
                u_in = y[X_CMD_LAG] if p[P_CMD_LAG] > 0.0 else _command_path(p, bp_u[i, jd])
                _, flags = _servo_accel(p, u_in, y[X_POS], y[X_RATE], hm)
                pos_fb = y[X_FB_LAG] if p[P_FB_LAG] > 0.0 else _lvdt(p, y[X_POS], hm)
                _write_outputs(p, y, pos_fb, hm, flags, out[i, js])
                js += 1
            if t >= t_end - st.TIME_EPS_S:
                break
            t_next = _next_event(t_end, bp_t, m, jd, p[P_DELAY], jh, sample_t, js, k_samples)
            u[0] = _command_path(p, bp_u[i, jd])
            u[1] = bp_h[i, jh]
            while t_next - t > st.TIME_EPS_S:
                h = min(h_max, t_next - t)
                s0 = _switch_state(p, y, u)
                _rk4_step(p, y, u, h, k1, k2, k3, k4, yt, y1)
                if _switch_state(p, y1, u) != s0 and h > SWITCH_TOL_S:
                    lo = 0.0  # the step to the switch: last length still on s0's piece
                    hi = h
                    while hi - lo > SWITCH_TOL_S:
                        mid = 0.5 * (lo + hi)
                        _rk4_step(p, y, u, mid, k1, k2, k3, k4, yt, y1)
                        if _switch_state(p, y1, u) == s0:
                            lo = mid
                        else:
                            hi = mid
                    h = hi
                    _rk4_step(p, y, u, h, k1, k2, k3, k4, yt, y1)
                for a in range(n):
                    y[a] = y1[a]
                t += h
            t = t_next
            jd = st.zoh_index(bp_t, t - p[P_DELAY], jd)
            jh = st.zoh_index(bp_t, t, jh)

class SecondOrderModel(ActuatorModel):
    """Common part of LOAC, LOADF and LOADA: parameters, trim and the command map."""

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
            raise ValueError("give either params or keyword overrides, not both")
        self.params: list[SecondOrderParams] = batch_params(
            params, self.n, lambda: SecondOrderParams.from_channel(self.channel, **overrides)
        )
        for prm in self.params:
            prm.validate()
        self._P = np.stack([prm.vector() for prm in self.params])
        self._max_delay_s = float(self._P[:, P_DELAY].max())
        self._X = np.zeros((self.n, N_STATE))
        self.trim()

    @property
    def max_delay_s(self) -> float:  # noqa: D102
        return self._max_delay_s

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """Invert stages 2 and 5 (quantization is left to land within half a step)."""
        P = self._P
        aiding = np.where(position_deg >= 0.0, hinge_moment_inlb, -hinge_moment_inlb)
        kcp = 1.0 + P[:, P_KCP] * aiding * 1e-3
        return (position_deg / kcp - P[:, P_OFFSET]) / (1.0 + P[:, P_KB])

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        P = self._P
        uq = np.array([_command_path(P[i], command_deg[i]) for i in range(self.n)])
        aiding = np.where(uq > 0.0, hinge_moment_inlb, -hinge_moment_inlb)
        u_eff = np.where(uq == 0.0, 0.0, uq * (1.0 + P[:, P_KCP] * aiding * 1e-3))
        x = np.clip(u_eff, P[:, P_PMIN], P[:, P_PMAX])
        half = 0.5 * P[:, P_FP]
        self._X[:] = 0.0
        self._X[:, X_POS] = x
        self._X[:, X_FP] = half * np.sign(hinge_moment_inlb)
        self._X[:, X_CMD_LAG] = uq
        self._X[:, X_FB_LAG] = x + P[:, P_LVDT_COMPL] * hinge_moment_inlb * 1e-3
        self._X[:, X_COMPL] = P[:, P_COMPL] * hinge_moment_inlb * 1e-3


class Loada(SecondOrderModel):
    """LOADA: the discrete auto-coded second-order model, forward Euler at ``rate_hz`` (800 Hz)."""

    name = "loada"
    title = "Low-order actuator discrete auto-code model (LOADA)"
    default_rate_hz = 800.0
    method: ClassVar[int] = METHOD_FORWARD_EULER

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        super()._trim_states(command_deg, hinge_moment_inlb)
        self._steps = 0  # the model's own clock, in steps: a frame's remainder carries over

    def _integrate(self, bp_t, bp_u, bp_h, t_end, sample_t):  # noqa: ANN001, ANN202
        dt = 1.0 / self.rate_hz
        t0 = self._steps * dt
        n_steps = max(math.floor((t_end - t0) / dt + 1e-6), 0)
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_discrete(self._P, self._X, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, self.method, out)
        self._steps += n_steps
        return out


class Loadf(Loada):
    """LOADF: flight 1's hand-coded FORTRAN at 200 Hz, with the faults of section 4.2.4."""

    name = "loadf"
    title = "Low-order actuator discrete FORTRAN model (LOADF)"
    default_rate_hz = 200.0
    method = METHOD_LOADF


class Loac(SecondOrderModel):
    """LOAC: the continuous second-order model, the reference the discrete ones are judged against."""

    name = "loac"
    title = "Low-order actuator continuous model (LOAC)"
    continuous = True
    default_rtol: ClassVar[float] = 1e-9
    default_atol: ClassVar[float] = 1e-11

    def __init__(self, *args: Any, rtol: float | None = None, atol: float | None = None, **kwargs: Any) -> None:
        self.rtol = self.default_rtol if rtol is None else float(rtol)
        self.atol = self.default_atol if atol is None else float(atol)
        super().__init__(*args, **kwargs)

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        super()._trim_states(command_deg, hinge_moment_inlb)
        self._mode = np.zeros((self.n, 2), dtype=np.int64)
        x = self._X[:, X_POS]
        self._mode[:, 0] = np.where(x >= self._P[:, P_PMAX], 1, np.where(x <= self._P[:, P_PMIN], -1, 0))
        self._mode[:, 1] = np.sign(self._X[:, X_FP]).astype(np.int64)
        self._h = np.full(self.n, 1e-4)

    def _integrate(self, bp_t, bp_u, bp_h, t_end, sample_t):  # noqa: ANN001, ANN202
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_continuous(
            self._P, self._X, self._mode, self._h, bp_t, bp_u, bp_h, self._t, t_end, sample_t,
            self.rtol, self.atol, out,
        )
        return out


class SecondOrder(SecondOrderModel):
    """The second-order equations by RK4 with exact input breakpoints (identification's simulator).

    Defaults to the basic second order of figure 21 (the channel's ωn and ζ, every other element off);
    keyword overrides switch elements on. ``step_s`` bounds the RK4 sub-step (0.25 ms).
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
            params = SecondOrderParams.basic(ch, **overrides)
            overrides = {}
        super().__init__(channel, n=n, rate_hz=rate_hz, params=params, **overrides)

    def _integrate(self, bp_t, bp_u, bp_h, t_end, sample_t):  # noqa: ANN001, ANN202
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_rk4(self._P, self._X, bp_t, bp_u, bp_h, self._t, t_end, self.step_s, sample_t, out)
        return out

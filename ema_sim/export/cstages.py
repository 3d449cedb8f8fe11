"""Figure 26's stages in C, each written once beside the numba function it mirrors.

Every :class:`CStage` is one C function and names its twin, the numba function of
:mod:`ema_sim.models.stages`, :mod:`~ema_sim.models.second_order.figure21`,
:mod:`~ema_sim.models.second_order.figure29` or :mod:`~ema_sim.models.second_order.figure26` it
transcribes: the same IEEE operations in the same order (Python's left-to-right ``a + b + c``,
``max(a, b)`` as numba compiles it, ``np.sign`` returning its argument at zero), so compiled with
``-O2 -fno-fast-math -ffp-contract=off`` it returns the same bits on the same inputs. The tests
(``test/test_export.py``) call every stage here and its twin on randomised inputs and parameters and
compare them bit for bit; a stage added here without a differential test fails them.

The C takes every optional stage as numba's :data:`~ema_sim.models.second_order.stage_set.ALL`
does: each stage decided by its own parameter (the compiled stage sets are the same outputs bit for
bit, :mod:`ema_sim.models.second_order.stage_set`). Parameters are read as ``PP(name)``, the kernel
slot of :data:`~ema_sim.models.second_order.params.P` (``p[P.name]``), and states as ``XX(name)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ema_sim.models import stages as st
from ema_sim.models.second_order import figure21 as f21
from ema_sim.models.second_order import figure26 as f26
from ema_sim.models.second_order import figure29 as f29


@dataclass(frozen=True)
class CStage:
    """One C function and the numba function it transcribes.

    Parameters
    ----------
    name : str
        The C function's name (``ema_`` and the twin's name).
    twin : callable
        The numba function it mirrors.
    code : str
        Its C definition.
    """

    name: str
    twin: Callable[..., object]
    code: str


HELPERS = r"""
/* numba's builtins: max(a, b) keeps b only when b > a, min(a, b) only when b < a; np.sign(0) is its argument */
static double ema_max(double a, double b) { return b > a ? b : a; }
static double ema_min(double a, double b) { return b < a ? b : a; }
static double ema_sign(double x) { return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : x); }
"""
"""Python's and numpy's builtins as numba compiles them (used by the stages, not stages themselves)."""

STAGES: tuple[CStage, ...] = (
    # ------------------------------------------------------------------ ema_sim.models.stages
    CStage("ema_quantize", st.quantize, r"""
double ema_quantize(double u, double step) {
    if (step <= 0.0) return u;
    return step * floor(u / step + 0.5);
}"""),
    CStage("ema_lag_gain", st.lag_gain, r"""
double ema_lag_gain(double corner_hz, double dt) {
    if (corner_hz <= 0.0) return 1.0;
    return 1.0 - exp(-EMA_TWO_PI * corner_hz * dt);
}"""),
    CStage("ema_first_order_lag", st.first_order_lag, r"""
double ema_first_order_lag(double y, double u, double gain) {
    return y + gain * (u - y);
}"""),
    CStage("ema_band_side", st.band_side, r"""
int ema_band_side(double x, double half_width) {
    if (x > half_width) return 1;
    if (x < -half_width) return -1;
    return 0;
}"""),
    CStage("ema_dead_zone", st.dead_zone, r"""
double ema_dead_zone(double e, double half_width, int *side) {
    int s = ema_band_side(e, half_width);
    *side = s;
    if (s > 0) return e - half_width;
    if (s < 0) return e + half_width;
    return 0.0;
}"""),
    CStage("ema_limited_integrator", st.limited_integrator, r"""
int ema_limited_integrator(double *x, double *v, double lo, double hi) {
    if (*x >= hi) { *x = hi; *v = ema_min(*v, 0.0); return 1; }
    if (*x <= lo) { *x = lo; *v = ema_max(*v, 0.0); return 1; }
    return 0;
}"""),
    CStage("ema_euler_pair", st.euler_pair, r"""
void ema_euler_pair(double *x, double *v, double a, double dt, int backward) {
    if (backward) {
        *v = *v + dt * a;
        *x = *x + dt * *v;
        return;
    }
    *x = *x + dt * *v;
    *v = *v + dt * a;
}"""),
    CStage("ema_oscillator_step", st.oscillator_step, r"""
void ema_oscillator_step(double stiffness, double damping, double dt, double *out) {
    double mu = -0.5 * damping;
    double d2 = mu * mu - stiffness;
    double x2 = fabs(d2) * dt * dt;
    double c_t, s_t;
    if (x2 < 1e-6) {
        double sign = d2 >= 0.0 ? 1.0 : -1.0;
        double em = exp(mu * dt);
        c_t = em * (1.0 + sign * x2 / 2.0 + x2 * x2 / 24.0);
        s_t = em * dt * (1.0 + sign * x2 / 6.0 + x2 * x2 / 120.0);
    } else if (d2 > 0.0) {
        double d = sqrt(d2);
        double e1 = exp((mu + d) * dt);
        double e2 = exp((mu - d) * dt);
        c_t = 0.5 * (e1 + e2);
        s_t = 0.5 * (e1 - e2) / d;
    } else {
        double d = sqrt(-d2);
        double em = exp(mu * dt);
        c_t = em * cos(d * dt);
        s_t = em * sin(d * dt) / d;
    }
    double phi11 = c_t + mu * s_t;
    double gamma0;
    if (stiffness > 0.0) gamma0 = (1.0 - phi11 - damping * s_t) / stiffness;
    else if (damping > 0.0) gamma0 = (dt - s_t) / damping;
    else gamma0 = 0.5 * dt * dt;
    out[0] = c_t - mu * s_t;
    out[1] = s_t;
    out[2] = -stiffness * s_t;
    out[3] = phi11;
    out[4] = gamma0;
}"""),
    # ------------------------------------------------------------------ figure 21
    CStage("ema_load_rate_limits", f21.load_rate_limits, r"""
void ema_load_rate_limits(double rl_dps, double k2_dps_per_lb, double hinge_moment_inlb, double marm_in,
                          double *up, double *down) {
    double f_lb = hinge_moment_inlb / marm_in;
    double u = rl_dps + k2_dps_per_lb * f_lb;
    double d = rl_dps - k2_dps_per_lb * f_lb;
    *up = ema_max(u, 0.0);
    *down = ema_max(d, 0.0);
}"""),
    CStage("ema_velocity_command", f21.velocity_command, r"""
double ema_velocity_command(double u, double x, double wn, double zeta, double up, double down, int *side) {
    double vc = wn / (2.0 * zeta) * (u - x);
    if (vc > up) { *side = 1; return up; }
    if (vc < -down) { *side = -1; return -down; }
    *side = 0;
    return vc;
}"""),
    CStage("ema_rate_loop", f21.rate_loop, r"""
double ema_rate_loop(double v_drive, double v, double wn, double zeta) {
    return 2.0 * zeta * wn * (v_drive - v);
}"""),
    # ------------------------------------------------------------------ figure 29
    CStage("ema_free_play_accel", f29.free_play_accel, r"""
double ema_free_play_accel(double hinge_moment_inlb, double inertia_inlbs2) {
    return hinge_moment_inlb / inertia_inlbs2 * EMA_RAD2DEG;
}"""),
    CStage("ema_free_play_euler", f29.free_play_euler, r"""
void ema_free_play_euler(double *fp, double *v, double accel, double dt, double half, int backward) {
    ema_euler_pair(fp, v, accel, dt, backward);
    ema_limited_integrator(fp, v, -half, half);
}"""),
    # ------------------------------------------------------------------ figure 26
    CStage("ema_command_error", f26.command_error, r"""
double ema_command_error(double u, double kb, double offset_deg) {
    return (1.0 + kb) * u + offset_deg;
}"""),
    CStage("ema_command_path", f26.command_path, r"""
double ema_command_path(const double *p, double u) {
    return ema_quantize(ema_command_error(u, PP(kb), PP(offset_deg)), PP(quantization_deg));
}"""),
    CStage("ema_compliance_correction", f26.compliance_correction, r"""
double ema_compliance_correction(double u, double hinge_moment_inlb, double kcp_per_kinlb) {
    if (kcp_per_kinlb == 0.0 || u == 0.0) return u;
    double aiding = u > 0.0 ? hinge_moment_inlb : -hinge_moment_inlb;
    return u * (1.0 + kcp_per_kinlb * aiding * 1e-3);
}"""),
    CStage("ema_compliance_deflection", f26.compliance_deflection, r"""
double ema_compliance_deflection(double hinge_moment_inlb, double deg_per_kinlb, double knee_inlb,
                                 double stiff_deg_per_kinlb) {
    double a = fabs(hinge_moment_inlb);
    double d = a <= knee_inlb ? deg_per_kinlb * a
                              : deg_per_kinlb * knee_inlb + stiff_deg_per_kinlb * (a - knee_inlb);
    return d != 0.0 ? copysign(d * 1e-3, hinge_moment_inlb) : 0.0;
}"""),
    CStage("ema_surface_compliance", f26.surface_compliance, r"""
double ema_surface_compliance(const double *p, double hinge_moment_inlb) {
    return ema_compliance_deflection(hinge_moment_inlb, PP(compliance_deg_per_kinlb), PP(compliance_knee_inlb),
                                     PP(compliance_stiff_deg_per_kinlb));
}"""),
    CStage("ema_drive_on", f26.drive_on, r"""
int ema_drive_on(const double *p) {
    return PP(accel_limit_dps2) < INFINITY || (PP(feedback_filter_in_loop) > 0.5 && PP(linkage_freq_hz) > 0.0);
}"""),
    CStage("ema_velocity_demand", f26.velocity_demand, r"""
double ema_velocity_demand(const double *p, double u_in, double x, double integral_deg_s, double hinge_moment_inlb,
                           double *droop, int *flags, int *piece, double *integrand) {
    double wn = PP(wn_rad_s), zeta = PP(zeta);
    double u_eff = ema_compliance_correction(u_in, hinge_moment_inlb, PP(kcp_per_kinlb));
    double e = u_eff - x;
    int thresholded = PP(threshold_deg) > 0.0;
    double e_dz;
    int dz;
    if (thresholded) {
        e_dz = ema_dead_zone(e, PP(threshold_deg), &dz);
    } else {
        e_dz = e;
        dz = 0;
    }
    double up, down;
    ema_load_rate_limits(PP(rate_limit_dps), PP(k2_dps_per_lb), hinge_moment_inlb, PP(moment_arm_in), &up, &down);
    double wi = EMA_TWO_PI * PP(integral_hz);
    double target = wi > 0.0 ? x + e_dz + wi * integral_deg_s : x + e_dz;
    int side;
    double vc = ema_velocity_command(target, x, wn, zeta, up, down, &side);
    *droop = wn / (2.0 * zeta) * PP(servo_compliance_deg_per_kinlb) * hinge_moment_inlb * 1e-3;
    int f = side != 0 ? EMA_FLAG_RATE : 0;
    if (thresholded && e_dz == 0.0) f |= EMA_FLAG_THRESHOLD;
    *flags = f;
    *integrand = (wi > 0.0 && side == 0 && (!thresholded || dz != 0)) ? e : 0.0;
    *piece = 3 * side + dz;
    return vc;
}"""),
    CStage("ema_drive_step", f26.drive_step, r"""
double ema_drive_step(const double *p, double dt, double *lead) {
    double wv = EMA_TWO_PI * PP(velocity_loop_hz);
    if (dt <= 0.0) { *lead = 0.0; return wv; }
    double g = -expm1(-wv * dt);
    *lead = dt / g - 1.0 / wv;
    return g / dt;
}"""),
    CStage("ema_current_limited_drive", f26.current_limited_drive, r"""
double ema_current_limited_drive(const double *p, double command_dps, double droop_dps, double v_drive, double wv,
                                 int *side) {
    double acc = wv * (command_dps - v_drive);
    double limit = PP(accel_limit_dps2);
    int s = 0;
    if (acc > limit) {
        acc = limit;
        s = 1;
    } else if (acc < -limit) {
        acc = -limit;
        s = -1;
    }
    *side = s;
    return acc + wv * droop_dps;
}"""),
    CStage("ema_servo", f26.servo, r"""
double ema_servo(const double *p, double u_in, double x, double v, const double *y, double hinge_moment_inlb,
                 double dt, int *flags, int *piece, double *integral_rate, double *drive_accel) {
    double droop, integrand;
    int f, pc;
    double vc = ema_velocity_demand(p, u_in, x, y[EMA_X_integral_deg_s], hinge_moment_inlb, &droop, &f, &pc,
                                    &integrand);
    double accel, v_drive;
    if (ema_drive_on(p)) {
        double lead;
        int cside;
        double wv = ema_drive_step(p, dt, &lead);
        accel = ema_current_limited_drive(p, vc, droop, y[EMA_X_drive_rate_dps], wv, &cside);
        v_drive = y[EMA_X_drive_rate_dps];
        if (lead > 0.0) v_drive = v_drive + lead * accel;
        if (cside != 0) {
            f |= EMA_FLAG_CURRENT;
            integrand = 0.0;
        }
        pc += 9 * cside;
    } else {
        accel = 0.0;
        v_drive = vc + droop;
    }
    *flags = f;
    *piece = pc;
    *integral_rate = integrand;
    *drive_accel = accel;
    return ema_rate_loop(v_drive, v, PP(wn_rad_s), PP(zeta));
}"""),
    CStage("ema_lvdt", f26.lvdt, r"""
double ema_lvdt(const double *p, double x_pos, double hinge_moment_inlb) {
    return x_pos + ema_compliance_deflection(hinge_moment_inlb, PP(lvdt_compliance_deg_per_kinlb),
                                             PP(lvdt_compliance_knee_inlb), PP(lvdt_compliance_stiff_deg_per_kinlb));
}"""),
    CStage("ema_actuator_position", f26.actuator_position, r"""
double ema_actuator_position(const double *p, double x, double v) {
    if (PP(feedback_filter_in_loop) > 0.5) return x + v / (2.0 * PP(zeta) * PP(wn_rad_s));
    return x;
}"""),
    CStage("ema_compliance_time_constant_s", f26.compliance_time_constant_s, r"""
double ema_compliance_time_constant_s(const double *p) {
    double c = PP(compliance_deg_per_kinlb);
    if (c <= 0.0 || PP(hysteresis_h_lb_per_in) <= 0.0) return 0.0;
    double k_lb_per_in = 1000.0 / (c * EMA_DEG2RAD * PP(moment_arm_in) * PP(moment_arm_in));
    return PP(hysteresis_h_lb_per_in) / (EMA_TWO_PI * PP(hysteresis_freq_hz)) / k_lb_per_in;
}"""),
    CStage("ema_free_play_subsystem", f26.free_play_subsystem, r"""
int ema_free_play_subsystem(const double *p) {
    return PP(free_play_deg) > 0.0 && PP(linkage_freq_hz) <= 0.0;
}"""),
    CStage("ema_linkage_spring", f26.linkage_spring, r"""
double ema_linkage_spring(const double *p, double e, int *piece) {
    int side;
    double e_dz = ema_dead_zone(e, 0.5 * PP(free_play_deg), &side);
    if (side == 0 && PP(free_play_deg) > 0.0) { *piece = 0; return e_dz; }
    double c = PP(compliance_deg_per_kinlb);
    double knee = PP(compliance_knee_inlb);
    if (c <= 0.0 || knee == INFINITY) { *piece = 1; return e_dz; }
    double a = fabs(e_dz);
    double ck = c * knee * 1e-3;
    if (a <= ck) { *piece = 1; return e_dz; }
    *piece = 2;
    return copysign(ck + c * (a - ck) / ema_max(PP(compliance_stiff_deg_per_kinlb), 1e-6), e_dz);
}"""),
    CStage("ema_linkage_slope", f26.linkage_slope, r"""
double ema_linkage_slope(const double *p, int piece) {
    if (piece == 0) return 0.0;
    if (piece == 1) return 1.0;
    return PP(compliance_deg_per_kinlb) / ema_max(PP(compliance_stiff_deg_per_kinlb), 1e-6);
}"""),
    CStage("ema_linkage_damping", f26.linkage_damping, r"""
double ema_linkage_damping(const double *p) {
    double w0 = EMA_TWO_PI * PP(linkage_freq_hz);
    return 2.0 * PP(linkage_zeta) * w0 + w0 * w0 * ema_compliance_time_constant_s(p);
}"""),
    CStage("ema_linkage_accel", f26.linkage_accel, r"""
double ema_linkage_accel(const double *p, const double *y, double hinge_moment_inlb, double actuator_accel) {
    double w0 = EMA_TWO_PI * PP(linkage_freq_hz);
    double target = ema_surface_compliance(p, hinge_moment_inlb);
    int piece;
    double spring = ema_linkage_spring(p, y[EMA_X_linkage_deg], &piece);
    return w0 * w0 * (target - spring) - ema_linkage_damping(p) * y[EMA_X_linkage_rate_dps] - actuator_accel;
}"""),
    CStage("ema_linkage_steps", f26.linkage_steps, r"""
void ema_linkage_steps(const double *p, double dt, double *steps) {
    double w0 = EMA_TWO_PI * PP(linkage_freq_hz);
    double damping = ema_linkage_damping(p);
    for (int piece = 0; piece < 3; piece++) {
        double k = w0 * w0 * ema_linkage_slope(p, piece);
        ema_oscillator_step(k, damping, dt, steps + 6 * piece);
        steps[6 * piece + 5] = k;
    }
}"""),
    CStage("ema_linkage_step", f26.linkage_step, r"""
void ema_linkage_step(const double *p, const double *y, double hinge_moment_inlb, double actuator_accel,
                      const double *steps, double *deflection, double *rate) {
    double e = y[EMA_X_linkage_deg], v = y[EMA_X_linkage_rate_dps];
    int piece;
    ema_linkage_spring(p, e, &piece);
    const double *s = steps + 6 * piece;
    double f = ema_linkage_accel(p, y, hinge_moment_inlb, actuator_accel) + s[5] * e + ema_linkage_damping(p) * v;
    *deflection = s[0] * e + s[1] * v + s[4] * f;
    *rate = s[2] * e + s[3] * v + s[1] * f;
}"""),
    CStage("ema_feedback_value", f26.feedback_value, r"""
double ema_feedback_value(const double *p, const double *y, double hinge_moment_inlb, double *rate) {
    double reading = ema_lvdt(p, y[EMA_X_position_deg], hinge_moment_inlb);
    if (PP(feedback_lag_hz) > 0.0) {
        *rate = EMA_TWO_PI * PP(feedback_lag_hz) * (reading - y[EMA_X_feedback_lag_deg]);
        return y[EMA_X_feedback_lag_deg];
    }
    *rate = y[EMA_X_rate_dps];
    return reading;
}"""),
    CStage("ema_history_spacing_s", f26.history_spacing_s, r"""
double ema_history_spacing_s(const double *p) {
    return 2.0 * PP(feedback_delay_s) / (double)EMA_HISTORY_SIZE;
}"""),
    CStage("ema_history_write", f26.history_write, r"""
void ema_history_write(const double *p, double *y, double *hist, double t, double value, double rate, int force) {
    long j;
    if (PP(feedback_delay_s) <= 0.0) return;
    if (t <= y[EMA_X_history_last_s] + EMA_TIME_EPS_S) {
        j = (long)y[EMA_X_history_head];
    } else if (force || t >= y[EMA_X_history_last_s] + ema_history_spacing_s(p)) {
        j = (long)y[EMA_X_history_head] + 1;
        if (j >= EMA_HISTORY_SIZE) j = 0;
    } else {
        return;
    }
    hist[3 * j] = t;
    hist[3 * j + 1] = value;
    hist[3 * j + 2] = rate;
    y[EMA_X_history_head] = (double)j;
    y[EMA_X_history_last_s] = t;
}"""),
    CStage("ema_history_read", f26.history_read, r"""
double ema_history_read(const double *y, const double *hist, double t) {
    long size = EMA_HISTORY_SIZE;
    long j = (long)y[EMA_X_history_head];
    long newer = -1;
    int found = 0;
    for (long n = 0; n < size; n++) {
        if (hist[3 * j] <= t + EMA_TIME_EPS_S) { found = 1; break; }
        newer = j;
        j = j > 0 ? j - 1 : size - 1;
    }
    if (!found) return hist[3 * newer + 1];
    double t0 = hist[3 * j];
    double t1 = newer >= 0 ? hist[3 * newer] : hist[3 * j];
    if (newer < 0 || fabs(t - t0) <= EMA_TIME_EPS_S || t1 - t0 <= EMA_TIME_EPS_S) return hist[3 * j + 1];
    double h = t1 - t0;
    double s = (t - t0) / h;
    double s2 = s * s;
    double s3 = s2 * s;
    return (2.0 * s3 - 3.0 * s2 + 1.0) * hist[3 * j + 1] + (s3 - 2.0 * s2 + s) * h * hist[3 * j + 2]
           + (-2.0 * s3 + 3.0 * s2) * hist[3 * newer + 1] + (s3 - s2) * h * hist[3 * newer + 2];
}"""),
    CStage("ema_write_outputs", f26.write_outputs, r"""
void ema_write_outputs(const double *p, const double *x, double position_fb, double hinge_moment_inlb, int flags,
                       double *row) {
    row[EMA_O_POSITION_DEG] = position_fb;
    double actuator = ema_lvdt(p, ema_actuator_position(p, x[EMA_X_position_deg], x[EMA_X_rate_dps]),
                               hinge_moment_inlb);
    double half = 0.5 * PP(free_play_deg);
    int in_free_play;
    if (PP(linkage_freq_hz) > 0.0) {
        row[EMA_O_SURFACE_DEG] = actuator + x[EMA_X_linkage_deg];
        in_free_play = half > 0.0 && fabs(x[EMA_X_linkage_deg]) <= half;
    } else {
        int damped = ema_compliance_time_constant_s(p) > 0.0;
        double compliance = damped ? x[EMA_X_compliance_deg] : ema_surface_compliance(p, hinge_moment_inlb);
        row[EMA_O_SURFACE_DEG] = actuator + x[EMA_X_free_play_deg] + compliance;
        in_free_play = half > 0.0 && fabs(x[EMA_X_free_play_deg]) < half;
    }
    row[EMA_O_RATE_DPS] = x[EMA_X_rate_dps];
    row[EMA_O_CURRENT_A] = NAN;
    row[EMA_O_BUS_V] = NAN;
    if (x[EMA_X_position_deg] >= PP(position_max_deg) || x[EMA_X_position_deg] <= PP(position_min_deg)) {
        flags |= EMA_FLAG_POSITION;
    }
    if (half > 0.0 && !in_free_play) flags |= EMA_FLAG_FREE_PLAY;
    row[EMA_O_FLAGS] = (double)flags;
}"""),
    CStage("ema_compliance_gain", f26.compliance_gain, r"""
double ema_compliance_gain(const double *p, double dt) {
    double tau_c = ema_compliance_time_constant_s(p);
    return tau_c > 0.0 ? 1.0 - exp(-dt / tau_c) : 1.0;
}"""),
    CStage("ema_linkage_rest", f26.linkage_rest, r"""
double ema_linkage_rest(const double *p, double hinge_moment_inlb) {
    return ema_surface_compliance(p, hinge_moment_inlb) + 0.5 * PP(free_play_deg) * ema_sign(hinge_moment_inlb);
}"""),
    CStage("ema_trim", f26.trim, r"""
void ema_trim(const double *p, double command_deg, double hinge_moment_inlb, double *x, double *hist, long entries) {
    double hm = hinge_moment_inlb;
    double uq = ema_command_path(p, command_deg);
    double droop = PP(servo_compliance_deg_per_kinlb) * hm * 1e-3;
    double target = ema_compliance_correction(uq, hm, PP(kcp_per_kinlb));
    for (int i = 0; i < EMA_N_STATE; i++) x[i] = 0.0;
    if (PP(integral_hz) > 0.0) {
        x[EMA_X_integral_deg_s] = -droop / (EMA_TWO_PI * PP(integral_hz));
    } else {
        target = target + droop;
    }
    double pos = ema_min(ema_max(target, PP(position_min_deg)), PP(position_max_deg));
    x[EMA_X_position_deg] = pos;
    x[EMA_X_free_play_deg] = ema_free_play_subsystem(p) ? 0.5 * PP(free_play_deg) * ema_sign(hm) : 0.0;
    x[EMA_X_command_lag_deg] = uq;
    x[EMA_X_feedback_lag_deg] = ema_lvdt(p, pos, hm);
    x[EMA_X_compliance_deg] = ema_surface_compliance(p, hm);
    if (PP(linkage_freq_hz) > 0.0) x[EMA_X_linkage_deg] = ema_linkage_rest(p, hm);
    x[EMA_X_history_last_s] = EMA_NEVER_S;
    double rate;
    double reading = ema_feedback_value(p, x, hm, &rate);
    for (long j = 0; j < entries; j++) {
        hist[3 * j] = EMA_NEVER_S;
        hist[3 * j + 1] = reading;
        hist[3 * j + 2] = 0.0;
    }
}"""),
)
"""Every stage, in the order the C file defines them (a stage only calls stages above it)."""


def stage(name: str) -> CStage:
    """The stage of a C function name.

    Parameters
    ----------
    name : str
        ``ema_quantize``...

    Returns
    -------
    CStage
        The stage.
    """
    for s in STAGES:
        if s.name == name:
            return s
    raise KeyError(name)


def stages_c() -> str:
    """The C definitions of every stage, helpers first.

    Returns
    -------
    str
        C source text (needs the layout and constants of :mod:`ema_sim.export.csource`).
    """
    return HELPERS + "\n".join(s.code for s in STAGES) + "\n"

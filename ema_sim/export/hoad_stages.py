"""Figures 30, 32 and 33's stages in C (HOAD2, HOAD3), each written once beside the numba function it mirrors.

Every :class:`~ema_sim.export.cstages.CStage` here is one C function naming its twin: the numba
function of :mod:`ema_sim.models.high_order.figure30`, :mod:`~ema_sim.models.high_order.gear_train`,
:mod:`~ema_sim.models.high_order.hoad`, :mod:`ema_sim.calibration` or :mod:`ema_sim.models.noise`, or
the Python function of :mod:`~ema_sim.models.high_order.trim` (the trim runs in Python, in IEEE
doubles too). The same operations in the same order, so compiled with
:data:`~ema_sim.export.csource.CFLAGS` (no fast-math, no fused multiply-adds; the HOAD kernel is
compiled without fast-math as well) it returns the same bits. The tests
(``test/test_export_hoad.py``) call each stage and its twin on random inputs and compare every bit.

The noise generator is the models' own (xorshift64* seeded by splitmix64, normal draws by the
ziggurat with its tables written as exact hexadecimal literals), so an export with the noise on is
still the model bit for bit. Parameters are read as ``PP(name)``, the slot of
:data:`~ema_sim.models.high_order.params.P`.
"""

from __future__ import annotations

from ema_sim import calibration as cal
from ema_sim.export.cstages import CStage, stage
from ema_sim.models import noise as nz
from ema_sim.models.high_order import figure30 as f30
from ema_sim.models.high_order import gear_train as gt
from ema_sim.models.high_order import hoad, trim

HELPERS = r"""
/* numba's builtins: max(a, b) keeps b only when b > a, min(a, b) only when b < a */
static double ema_max(double a, double b) { return b > a ? b : a; }
static double ema_min(double a, double b) { return b < a ? b : a; }
"""
"""Python's builtins as numba compiles them."""

STAGES: tuple[CStage, ...] = (
    # ------------------------------------------------------------------ shared elements (ema_sim.models.stages)
    stage("ema_quantize"),
    stage("ema_band_side"),
    # ------------------------------------------------------------------ calibration curves
    CStage("ema_cubic", cal.cubic, r"""
double ema_cubic(double c0, double c1, double c2, double c3, double x) {
    return c0 + x * (c1 + x * (c2 + x * c3));
}"""),
    CStage("ema_cubic_slope", cal.cubic_slope, r"""
double ema_cubic_slope(double c0, double c1, double c2, double c3, double x) {
    (void)c0;
    return c1 + x * (2.0 * c2 + 3.0 * c3 * x);
}"""),
    CStage("ema_cubic_inverse", cal.cubic_inverse, r"""
double ema_cubic_inverse(double c0, double c1, double c2, double c3, double y, double tol) {
    double x = (y - c0) / c1;
    for (int k = 0; k < EMA_NEWTON_STEPS; k++) {
        double dx = (ema_cubic(c0, c1, c2, c3, x) - y) / ema_cubic_slope(c0, c1, c2, c3, x);
        x = x - dx;
        if (fabs(dx) <= tol * (1.0 + fabs(x))) break;
    }
    return x;
}"""),
    # ------------------------------------------------------------------ noise (ema_sim.models.noise)
    CStage("ema_splitmix64", nz.splitmix64, r"""
uint64_t ema_splitmix64(uint64_t seed) {
    uint64_t z = seed + 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    z = z ^ (z >> 31);
    if (z == 0) z = 0x2545F4914F6CDD1DULL;
    return z;
}"""),
    CStage("ema_next_u64", nz.next_u64, r"""
uint64_t ema_next_u64(uint64_t *state) {
    uint64_t x = state[0];
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    state[0] = x;
    return x * 0x2545F4914F6CDD1DULL;
}"""),
    CStage("ema_uniform", nz.uniform, r"""
double ema_uniform(uint64_t *state) {
    uint64_t r = ema_next_u64(state);
    return ((double)(r >> 11) + 1.0) * EMA_U53;
}"""),
    CStage("ema_normal", nz.normal, r"""
static int64_t ema_signed_draw(uint64_t *state, int64_t *iz) {
    uint64_t r = ema_next_u64(state);
    int64_t hz = (int64_t)(r >> 32);
    if (hz >= 2147483648LL) hz -= 4294967296LL;
    *iz = (int64_t)(r & 127ULL);
    return hz;
}

double ema_normal(uint64_t *state) {
    int64_t iz;
    int64_t hz = ema_signed_draw(state, &iz);
    for (;;) {
        if ((double)(hz < 0 ? -hz : hz) < ema_zig_k[iz]) return (double)hz * ema_zig_w[iz];
        double x = (double)hz * ema_zig_w[iz];
        if (iz == 0) {
            for (;;) {
                x = -log(ema_uniform(state)) / EMA_ZIG_R;
                double y = -log(ema_uniform(state));
                if (y + y >= x * x) break;
            }
            return hz > 0 ? EMA_ZIG_R + x : -EMA_ZIG_R - x;
        }
        if (ema_zig_f[iz] + ema_uniform(state) * (ema_zig_f[iz - 1] - ema_zig_f[iz]) < exp(-0.5 * x * x)) return x;
        hz = ema_signed_draw(state, &iz);
    }
}"""),
    CStage("ema_band_limited_step", nz.band_limited_step, r"""
double ema_band_limited_step(double value, double decay, double innovation, uint64_t *state) {
    if (innovation == 0.0) return 0.0;
    return decay * value + innovation * ema_normal(state);
}"""),
    # ------------------------------------------------------------------ figure 30, stages 4-9
    CStage("ema_saturate", f30.saturate, r"""
double ema_saturate(double x, double limit, int segment) {
    if (segment > 0) return limit;
    if (segment < 0) return -limit;
    return x;
}"""),
    CStage("ema_pwm_segment", f30.pwm_segment, r"""
int ema_pwm_segment(double v_demand, double dead_band_v, double v_max) {
    if (v_demand > dead_band_v) return v_demand - dead_band_v > v_max ? 2 : 1;
    if (v_demand < -dead_band_v) return v_demand + dead_band_v < -v_max ? -2 : -1;
    return 0;
}"""),
    CStage("ema_pwm", f30.pwm, r"""
double ema_pwm(double v_demand, double dead_band_v, double v_max, int segment) {
    if (segment == 0) return 0.0;
    if (segment == 1) return v_demand - dead_band_v;
    if (segment == -1) return v_demand + dead_band_v;
    if (segment == 2) return v_max;
    return -v_max;
}"""),
    CStage("ema_position_loop", f30.position_loop, r"""
double ema_position_loop(double x_command_in, double x_feedback_in, double kp_per_s, double integral_in_s) {
    return kp_per_s * (x_command_in - x_feedback_in) + integral_in_s;
}"""),
    CStage("ema_integrating", f30.integrating, r"""
int ema_integrating(int rate_segment, int current_segment, int pwm_region) {
    return rate_segment == 0 && current_segment == 0 && (pwm_region == 1 || pwm_region == -1);
}"""),
    CStage("ema_velocity_loop", f30.velocity_loop, r"""
double ema_velocity_loop(double v_command_in_s, double v_tach_in_s, double kv_a_per_in_s) {
    return kv_a_per_in_s * (v_command_in_s - v_tach_in_s);
}"""),
    CStage("ema_current_loop", f30.current_loop, r"""
double ema_current_loop(double i_command_a, double i_a, double v_tach_in_s, double kc_v_per_a, double r_ohm,
                        double ke_v_per_in_s) {
    return kc_v_per_a * (i_command_a - i_a) + r_ohm * i_command_a + ke_v_per_in_s * v_tach_in_s;
}"""),
    CStage("ema_servo_drive", f30.servo_drive, r"""
void ema_servo_drive(double kp, double vmax, double kv, double imax, double kc, double r, double ke, double vdb,
                     double duty, double x_command_in, double lvdt_in, double integral_in_s, double v_motor_in_s,
                     double current_a, double bus_v, int rate_segment, int current_segment, int pwm_region,
                     int classify, double *values, int *segments) {
    double vc_raw = ema_position_loop(x_command_in, lvdt_in, kp, integral_in_s);
    if (classify) rate_segment = ema_band_side(vc_raw, vmax);
    double ic_raw = ema_velocity_loop(ema_saturate(vc_raw, vmax, rate_segment), v_motor_in_s, kv);
    if (classify) current_segment = ema_band_side(ic_raw, imax);
    double vd = ema_current_loop(ema_saturate(ic_raw, imax, current_segment), current_a, v_motor_in_s, kc, r, ke);
    double vlim = duty * bus_v;
    if (classify) pwm_region = ema_pwm_segment(vd, vdb, vlim);
    values[0] = vc_raw;
    values[1] = ic_raw;
    values[2] = vd;
    values[3] = ema_pwm(vd, vdb, vlim, pwm_region);
    segments[0] = rate_segment;
    segments[1] = current_segment;
    segments[2] = pwm_region;
}"""),
    CStage("ema_drive_flags", f30.drive_flags, r"""
int ema_drive_flags(int rate_segment, int current_segment, int pwm_region, double v_motor_in_s) {
    int flags = 0;
    if (rate_segment != 0) flags |= EMA_FLAG_RATE;
    if (current_segment != 0) {
        flags |= EMA_FLAG_CURRENT;
        if (v_motor_in_s == 0.0) flags |= EMA_FLAG_STALL;
    }
    if (pwm_region == 0) flags |= EMA_FLAG_PWM_DEAD_BAND;
    return flags;
}"""),
    CStage("ema_motor_current_step", f30.motor_current_step, r"""
double ema_motor_current_step(double v_applied, double i_a, double v_motor_in_s, double conductance,
                              double ke_v_per_in_s, double decay) {
    double i_inf = (v_applied - ke_v_per_in_s * v_motor_in_s) * conductance;
    return i_inf + (i_a - i_inf) * decay;
}"""),
    CStage("ema_bus_current", f30.bus_current, r"""
double ema_bus_current(double v_applied, double i_a, double v_bus) {
    return v_applied * i_a / v_bus;
}"""),
    CStage("ema_bus_voltage_step", f30.bus_voltage_step, r"""
double ema_bus_voltage_step(double v_bus, double i_bus_a, double v_supply, double r_source_ohm, double decay) {
    double v_inf = v_supply - r_source_ohm * i_bus_a;
    return v_inf + (v_bus - v_inf) * decay;
}"""),
    CStage("ema_steady_bus_voltage", f30.steady_bus_voltage, r"""
double ema_steady_bus_voltage(double v_supply, double r_source_ohm, double power_w) {
    double disc = v_supply * v_supply - 4.0 * r_source_ohm * power_w;
    return 0.5 * (v_supply + sqrt(ema_max(disc, 0.0)));
}"""),
    # ------------------------------------------------------------------ stages 10-11, 14
    CStage("ema_friction_step", f30.friction_step, r"""
double ema_friction_step(double v, double f_applied, double coulomb_lbf, double stiction_lbf, double dt_per_mass,
                         double damping_dt_per_mass) {
    double implicit = 1.0 / (1.0 + damping_dt_per_mass);
    if (v == 0.0) {
        if (fabs(f_applied) <= stiction_lbf) return 0.0;
        return dt_per_mass * (f_applied - copysign(coulomb_lbf, f_applied)) * implicit;
    }
    double v_new = (v + dt_per_mass * (f_applied - copysign(coulomb_lbf, v))) * implicit;
    if (v_new * v <= 0.0 && fabs(f_applied) <= stiction_lbf) return 0.0;
    return v_new;
}"""),
    # ------------------------------------------------------------------ stage 12: figures 32, 33, 36
    CStage("ema_gear_train_fig32", gt.gear_train_fig32, r"""
double ema_gear_train_fig32(double d, double v_rel, double half_backlash_in, double k_series_lbf_per_in,
                            double damping_lbf_s_per_in, int segment, double *total) {
    double spring;
    if (segment > 0) {
        spring = k_series_lbf_per_in * (d - half_backlash_in);
    } else if (segment < 0) {
        spring = k_series_lbf_per_in * (d + half_backlash_in);
    } else {
        *total = 0.0;
        return 0.0;
    }
    *total = spring + damping_lbf_s_per_in * v_rel;
    return spring;
}"""),
    CStage("ema_lvdt_fig32", gt.lvdt_fig32, r"""
double ema_lvdt_fig32(double x_surface_in, double spring_force_lbf, double k_backup_lbf_per_in) {
    return x_surface_in + spring_force_lbf / k_backup_lbf_per_in;
}"""),
    CStage("ema_three_segment_force", gt.three_segment_force, r"""
double ema_three_segment_force(double d, double f1, double f2, double d1, double d2, double k1, double k2, double k3,
                               double *stiffness, int *segment) {
    double a = fabs(d);
    if (a <= d1) {
        *stiffness = k1;
        *segment = 1;
        return copysign(k1 * a, d);
    }
    if (a <= d2) {
        *stiffness = k2;
        *segment = 2;
        return copysign(f1 + k2 * (a - d1), d);
    }
    *stiffness = k3;
    *segment = 3;
    return copysign(f2 + k3 * (a - d2), d);
}"""),
    CStage("ema_three_segment_deflection", gt.three_segment_deflection, r"""
double ema_three_segment_deflection(double force, double f1, double f2, double d1, double d2, double c1, double c2,
                                    double c3) {
    double a = fabs(force);
    if (a <= f1) return copysign(a * c1, force);
    if (a <= f2) return copysign(d1 + (a - f1) * c2, force);
    return copysign(d2 + (a - f2) * c3, force);
}"""),
    CStage("ema_lvdt_fig33", gt.lvdt_fig33, r"""
double ema_lvdt_fig33(double x_motor_in, double spring_force_lbf, double f1, double f2, double g1, double g2,
                      double c1, double c2, double c3) {
    return x_motor_in - ema_three_segment_deflection(spring_force_lbf, f1, f2, g1, g2, c1, c2, c3);
}"""),
    CStage("ema_hysteretic_damping", gt.hysteretic_damping, r"""
double ema_hysteretic_damping(double coefficient, double k_tangent) {
    return coefficient * k_tangent;
}"""),
    CStage("ema_total_force", f30.total_force, r"""
double ema_total_force(const double *p, double d, double *stiffness, int *segment) {
    return ema_three_segment_force(d, PP(total_f1_lbf), PP(total_f2_lbf), PP(total_d1_in), PP(total_d2_in),
                                   PP(total_k1_lbf_per_in), PP(total_k2_lbf_per_in), PP(total_k3_lbf_per_in),
                                   stiffness, segment);
}"""),
    CStage("ema_total_deflection", f30.total_deflection, r"""
double ema_total_deflection(const double *p, double force) {
    return ema_three_segment_deflection(force, PP(total_f1_lbf), PP(total_f2_lbf), PP(total_d1_in), PP(total_d2_in),
                                        1.0 / PP(total_k1_lbf_per_in), 1.0 / PP(total_k2_lbf_per_in),
                                        1.0 / PP(total_k3_lbf_per_in));
}"""),
    CStage("ema_actuator_deflection", f30.actuator_deflection, r"""
double ema_actuator_deflection(const double *p, double force) {
    return ema_three_segment_deflection(force, PP(actuator_f1_lbf), PP(actuator_f2_lbf), PP(actuator_d1_in),
                                        PP(actuator_d2_in), PP(actuator_c1_in_per_lbf), PP(actuator_c2_in_per_lbf),
                                        PP(actuator_c3_in_per_lbf));
}"""),
    CStage("ema_gear_train", f30.gear_train, r"""
double ema_gear_train(const double *p, double xm, double xs, double *damping, double *lvdt, int *free) {
    double d = xm - xs;
    if (PP(figure33) > 0.5) {
        double ktan;
        int seg;
        double fk = ema_total_force(p, d, &ktan, &seg);
        *damping = PP(linkage_damping_lbf_s_per_in) + ema_hysteretic_damping(PP(hysteresis_coefficient_s), ktan);
        *lvdt = ema_lvdt_fig33(xm, fk, PP(actuator_f1_lbf), PP(actuator_f2_lbf), PP(actuator_d1_in),
                               PP(actuator_d2_in), PP(actuator_c1_in_per_lbf), PP(actuator_c2_in_per_lbf),
                               PP(actuator_c3_in_per_lbf));
        *free = seg == 1;
        return fk;
    }
    int seg = ema_band_side(d, PP(half_backlash_in));
    double total;
    double fk = ema_gear_train_fig32(d, 0.0, PP(half_backlash_in), PP(series_stiffness_lbf_per_in),
                                     PP(gear_damping_lbf_s_per_in), seg, &total);
    *damping = seg != 0 ? PP(gear_damping_lbf_s_per_in) : 0.0;
    *lvdt = ema_lvdt_fig32(xs, fk, PP(backup_stiffness_lbf_per_in));
    *free = seg == 0;
    return fk;
}"""),
    # ------------------------------------------------------------------ stages 1-3, 16-17 (hoad)
    CStage("ema_command_in", hoad.command_in, r"""
double ema_command_in(const double *p, double c0, double c1, double c2, double c3, double u, double *slope) {
    double dpi = PP(deg_per_in);
    double quant = PP(quantization_v);
    if (!(quant > 0.0) && !(PP(command_noise_v) > 0.0)) {
        *slope = 0.0;
        return u / dpi;
    }
    double deg = u;
    if (quant > 0.0) deg = ema_cubic_inverse(c0, c1, c2, c3, ema_quantize(ema_cubic(c0, c1, c2, c3, u), quant), 0.0);
    *slope = 1.0 / (ema_cubic_slope(c0, c1, c2, c3, deg) * dpi);
    return deg / dpi;
}"""),
    CStage("ema_feedback_deg", hoad.feedback_deg, r"""
double ema_feedback_deg(const double *p, double lvdt_in, double noise_v) {
    double deg = lvdt_in * PP(deg_per_in);
    if (PP(quantization_v) <= 0.0 && PP(feedback_noise_v) <= 0.0) return deg;
    double c0 = PP(feedback_cal_c0_deg), c1 = PP(feedback_cal_c1_deg_per_v);
    double c2 = PP(feedback_cal_c2_deg_per_v2), c3 = PP(feedback_cal_c3_deg_per_v3);
    double volts = ema_cubic_inverse(c0, c1, c2, c3, deg, EMA_FEEDBACK_TOL);
    if (PP(feedback_noise_v) > 0.0) volts += noise_v;
    return ema_cubic(c0, c1, c2, c3, ema_quantize(volts, PP(quantization_v)));
}"""),
    CStage("ema_split_delay", hoad.split_delay, r"""
long ema_split_delay(double delay_s, double dt, double *share) {
    double steps = delay_s / dt;
    long m = (long)floor(steps + EMA_DELAY_STEP_EPS);
    double w = steps - (double)m;
    *share = w > EMA_DELAY_STEP_EPS ? w : 0.0;
    return m;
}"""),
    # ------------------------------------------------------------------ trim (Python, ema_sim.models.high_order.trim)
    CStage("ema_positions_from_lvdt", trim.positions_from_lvdt, r"""
void ema_positions_from_lvdt(const double *p, double lvdt, double force, double *xm, double *xs) {
    if (PP(figure33) > 0.5) {
        *xm = lvdt + ema_actuator_deflection(p, force);
        double d = ema_total_deflection(p, force);
        *xs = *xm - d;
        return;
    }
    double s = lvdt - force / PP(backup_stiffness_lbf_per_in);
    double d = force == 0.0 ? 0.0 : force / PP(series_stiffness_lbf_per_in) + copysign(PP(half_backlash_in), force);
    *xm = s + d;
    *xs = s;
}"""),
    CStage("ema_at_stop", trim.at_stop, r"""
void ema_at_stop(const double *p, double xm, double xc, double force, double *lvdt, double *xs, double *cur) {
    if (PP(figure33) > 0.5) {
        *lvdt = xm - ema_actuator_deflection(p, force);
        *xs = xm - ema_total_deflection(p, force);
    } else {
        double d = force == 0.0 ? 0.0 : force / PP(series_stiffness_lbf_per_in)
                                        + copysign(PP(half_backlash_in), force);
        *xs = xm - d;
        *lvdt = *xs + force / PP(backup_stiffness_lbf_per_in);
    }
    double toward = xc != *lvdt ? copysign(1.0, xc - *lvdt) : 0.0;
    double i_db = PP(pwm_dead_band_v) / (PP(current_gain_v_per_a) + PP(stator_resistance_ohm));
    *cur = toward * (PP(current_limit_a) - i_db);
}"""),
    CStage("ema_equilibrium", trim.equilibrium, r"""
void ema_equilibrium(const double *p, double x_command_in, double hinge_moment_inlb, int powered, double *values,
                     int *motor_out, int *flags_out) {
    double xc = ema_min(ema_max(x_command_in, PP(position_min_in)), PP(position_max_in));
    double force = -hinge_moment_inlb / PP(crank_arm_in);
    double kf = PP(force_per_amp_lbf_per_a), kp = PP(position_gain_per_s), kv = PP(velocity_gain_a_per_in_s);
    double kc = PP(current_gain_v_per_a), r = PP(stator_resistance_ohm), vdb = PP(pwm_dead_band_v);
    double i_db = vdb / (kc + r);
    int motor = EMA_MOTOR_STUCK;
    double cur = 0.0, lf = xc, xi = 0.0, xm, xs;
    if (powered) {
        cur = force / kf;
        if (fabs(cur) > PP(current_limit_a) - i_db + PP(stiction_lbf) / kf) {
            motor = hinge_moment_inlb > 0.0 ? EMA_MOTOR_STOP_HIGH : EMA_MOTOR_STOP_LOW;
            cur = 0.0;
        } else if (cur != 0.0) {
            double ic = cur + copysign(i_db, cur);
            if (PP(position_integral_per_s2) > 0.0) xi = ic / kv;
            else lf = xc - ic / (kv * kp);
        }
    }
    if (motor == EMA_MOTOR_STUCK) {
        ema_positions_from_lvdt(p, lf, force, &xm, &xs);
    } else {
        xm = motor == EMA_MOTOR_STOP_HIGH ? PP(position_max_in) : PP(position_min_in);
        ema_at_stop(p, xm, xc, force, &lf, &xs, &cur);
    }
    double volts = r * cur;
    double power = volts * cur;
    double vbus = powered ? ema_steady_bus_voltage(PP(bus_supply_v), PP(bus_source_resistance_ohm), power)
                          : PP(bus_supply_v);
    int flags = powered ? 0 : EMA_FLAG_BRAKE;
    if (powered && cur == 0.0) flags |= EMA_FLAG_PWM_DEAD_BAND;
    if (motor != EMA_MOTOR_STUCK || x_command_in != xc) flags |= EMA_FLAG_POSITION;
    int free;
    if (PP(figure33) > 0.5) free = fabs(force) <= PP(total_f1_lbf);
    else free = ema_band_side(xm - xs, PP(half_backlash_in)) == 0;
    if (free) flags |= EMA_FLAG_FREE_PLAY;
    values[0] = xm;
    values[1] = xs;
    values[2] = cur;
    values[3] = lf;
    values[4] = vbus;
    values[5] = xi;
    *motor_out = motor;
    *flags_out = flags;
}"""),
)
"""Every stage, in the order the C file defines them (a stage only calls stages above it)."""


def stages_c() -> str:
    """The C definitions of every stage, helpers first.

    Returns
    -------
    str
        C source text (needs the layout and constants of :mod:`ema_sim.export.hoad_c`).
    """
    return HELPERS + "\n".join(s.code for s in STAGES) + "\n"

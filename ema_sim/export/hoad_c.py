"""HOAD2 and HOAD3 as C: the stages of :mod:`ema_sim.export.hoad_stages` and the 10 kHz kernel around them.

``ema_actuator.c`` here is :func:`ema_sim.models.high_order.hoad.run_discrete` for one instance, cut at
its step: :c:func:`ema_new` trims (:func:`~ema_sim.models.high_order.trim.equilibrium`) and samples
time 0, :c:func:`ema_advance` holds the command and hinge moment over a whole number of the model's
10 kHz steps and samples their end, :c:func:`ema_step` is one step. A host that calls
:c:func:`ema_advance` once per frame of ``n`` steps runs the model with an input breakpoint at every
frame, which is ``ema simulate`` at that frame rate: the same bits. The header carries the shared
API (:data:`ema_sim.export.csource.API`) and the high-order model's own calls (power, noise seed).

Parameters are the kernel slots of :data:`~ema_sim.models.high_order.params.P`, in kernel units (in,
lbf, SI electrical); each declares its unit, range and description (:func:`slot_rows`), from the
parameter's metadata where one parameter fills it, stated here where a slot is derived (figure 33's
curves, the feedback calibration, force per amp...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ema_sim import calibration as cal
from ema_sim import parameters as pm
from ema_sim.export.csource import API, HEADER, PARAM_INDEX, c_double, c_string, write_texts
from ema_sim.export.hoad_stages import stages_c
from ema_sim.export.target import ExportError, ExportTarget
from ema_sim.models import noise as nz
from ema_sim.models import stages as st
from ema_sim.models.base import HISTORY_START_S, OUTPUT_FIELDS
from ema_sim.models.high_order import figure30 as f30
from ema_sim.models.high_order.hoad import DELAY_STEP_EPS, FEEDBACK_TOL
from ema_sim.models.high_order.params import HighOrderParams, P

STAGES_FILE = "ema_hoad_stages.c"
KERNEL_FILE = "ema_hoad.c"
CONFIG_FILE = "ema_hoad_config.c"
SOURCES: tuple[str, ...] = (STAGES_FILE, KERNEL_FILE, CONFIG_FILE)
SLOTS: tuple[str, ...] = getattr(P, "_fields")  # noqa: B009 - a namedtuple's, not in the Slots protocol
"""The kernel slots of :data:`P` in slot order."""
"""The high-order model's C files (with :data:`~ema_sim.export.csource.HEADER`)."""
RATE_HZ = 10_000.0
"""The model's fixed step (section 4.2.5): a host's frame must be a whole number of them."""
SEED_FACTOR = 1_000_003
"""A model seeded ``s`` draws from the stream ``s·SEED_FACTOR mod 2^63`` (:meth:`HighOrderModel.stream_seeds`)."""

DERIVED: dict[str, tuple[str, str]] = {
    "lvdt_filter_rad_s": ("rad/s", "LVDT filter corner (stage 15): 2π × lvdt_filter_hz"),
    "inductance_h": ("H", "motor inductance (stage 8)"),
    "back_emf_v_per_in_s": ("V/(in/s)", "back-EMF per screw rate (stage 8): Ke / screw travel per motor radian"),
    "motor_mass_lbs2_per_in": ("lbf·s²/in", "rotor, gear and screw inertia at the screw (stage 10): J / G²"),
    "bus_capacitance_f": ("F", "bus capacitance (stage 9)"),
    "hinge_friction_lbf": ("lbf", "surface spindle friction at the screw (stage 14): hinge friction / crank arm"),
    "half_backlash_in": ("in", "half the gear backlash, the figure-32 dead zone's half width (stage 12)"),
    "series_stiffness_lbf_per_in": ("lbf/in", "gear-train and backup stiffness in series (figure 32)"),
    "surface_mass_lbs2_per_in": ("lbf·s²/in", "surface inertia at the screw (stage 14): I / crank arm²"),
    "position_min_in": ("in", "lower mechanical stop at the screw"),
    "position_max_in": ("in", "upper mechanical stop at the screw"),
    "force_per_amp_lbf_per_a": ("lbf/A", "screw force per motor amp (stage 8): Kt / G"),
    "deg_per_in": ("deg/in", "surface degrees per inch of screw travel (stage 13): 180/π / crank arm"),
    "figure33": ("-", "gear train: 1 figure 33's three-segment curves (HOAD3), 0 figure 32's backlash (HOAD2)"),
    "total_f1_lbf": ("lbf", "figure 33 total curve: first breakpoint force"),
    "total_f2_lbf": ("lbf", "figure 33 total curve: second breakpoint force"),
    "total_d1_in": ("in", "figure 33 total curve: deflection at the first breakpoint"),
    "total_d2_in": ("in", "figure 33 total curve: deflection at the second breakpoint"),
    "total_k1_lbf_per_in": ("lbf/in", "figure 33 total curve: first segment stiffness (at the export's bound)"),
    "total_k2_lbf_per_in": ("lbf/in", "figure 33 total curve: second segment stiffness"),
    "total_k3_lbf_per_in": ("lbf/in", "figure 33 total curve: third segment stiffness"),
    "actuator_f1_lbf": ("lbf", "figure 33 actuator (LVDT) curve: first breakpoint force"),
    "actuator_f2_lbf": ("lbf", "figure 33 actuator curve: second breakpoint force"),
    "actuator_d1_in": ("in", "figure 33 actuator curve: deflection at the first breakpoint"),
    "actuator_d2_in": ("in", "figure 33 actuator curve: deflection at the second breakpoint"),
    "actuator_c1_in_per_lbf": ("in/lbf", "figure 33 actuator curve: first segment compliance"),
    "actuator_c2_in_per_lbf": ("in/lbf", "figure 33 actuator curve: second segment compliance"),
    "actuator_c3_in_per_lbf": ("in/lbf", "figure 33 actuator curve: third segment compliance"),
    "hysteresis_coefficient_s": ("s", "figure 36 hysteretic damping h/(ω·k_avg); 0: off"),
    "feedback_cal_c0_deg": ("deg", "the channel's feedback calibration, volts to degrees: c0"),
    "feedback_cal_c1_deg_per_v": ("deg/V", "feedback calibration: c1"),
    "feedback_cal_c2_deg_per_v2": ("deg/V²", "feedback calibration: c2"),
    "feedback_cal_c3_deg_per_v3": ("deg/V³", "feedback calibration: c3"),
}
"""Unit and description of every slot no parameter fills as it is (derived, converted, or an option)."""
NONNEGATIVE = ("hysteresis_coefficient_s", "hinge_friction_lbf", "half_backlash_in")
"""Derived slots that may be zero; the other derived slots of positive quantities must be positive."""
UNBOUNDED = ("position_min_in", "position_max_in", "feedback_cal_c0_deg", "feedback_cal_c1_deg_per_v",
             "feedback_cal_c2_deg_per_v2", "feedback_cal_c3_deg_per_v3")
"""Derived slots of either sign."""


@dataclass(frozen=True)
class SlotRow:
    """One kernel slot as the C model and the FMU declare it.

    Parameters
    ----------
    name : str
        The slot (``EMA_P_<name>``).
    unit : str
        Its unit (``-``: none).
    description : str
        What it is.
    lo, hi : float
        Its valid range.
    lo_exclusive : bool
        ``lo`` itself is not valid.
    off : float or None
        The value that switches its stage off (allowed whatever the range).
    """

    name: str
    unit: str
    description: str
    lo: float
    hi: float
    lo_exclusive: bool
    off: float | None


def slot_rows() -> list[SlotRow]:
    """Every slot of :data:`P` in slot order with its unit, range and description.

    Returns
    -------
    list of SlotRow
        One per slot.
    """
    by_slot = {m.kernel: m for m in pm.metas(HighOrderParams).values() if m.kernel is not None}
    rows = []
    for name in SLOTS:
        m = by_slot.get(name)
        if m is not None and name not in DERIVED:
            rows.append(SlotRow(name, m.unit, m.description, m.min, m.max, m.min_exclusive, m.off))
            continue
        unit, desc = DERIVED[name]
        if name == "figure33":
            rows.append(SlotRow(name, unit, desc, 0.0, 1.0, False, None))
        elif name in UNBOUNDED:
            rows.append(SlotRow(name, unit, desc, -math.inf, math.inf, False, None))
        else:
            rows.append(SlotRow(name, unit, desc, 0.0, math.inf, name not in NONNEGATIVE, None))
    return rows


def _tables() -> str:
    """The ziggurat's tables as exact literals (:mod:`ema_sim.models.noise`)."""
    out = []
    for name, table in (("ema_zig_k", nz._ZIG_K), ("ema_zig_w", nz._ZIG_W), ("ema_zig_f", nz._ZIG_F)):
        values = ", ".join(c_double(float(v)) for v in np.asarray(table))
        out.append(f"static const double {name}[{len(table)}] = {{{values}}};")
    return "\n".join(out) + "\n"


EXTRA_API = r"""
/* ---- the high-order model's own calls ---- */
#include <stdint.h>
extern const double ema_command_cal[4];          /* the channel's command calibration, degrees to volts */
extern const long long ema_default_seed;         /* the noise seed (ema_sim's seed= option) */
/* ema_new with a noise seed other than ema_default_seed. */
ema_model *ema_new_seeded(const double *params, double rate_hz, int backward, double command_deg,
                          double hinge_moment_inlb, long long seed, char *msg, size_t msg_size);
/* n steps of 1/rate with the command and hinge moment held over them (one frame); the outputs at its end. */
void ema_advance(ema_model *m, double command_deg, double hinge_moment_inlb, long n);
/* Motor power from now: 1 on, 0 off (the bridge opens, the brake holds, the bus reads 0 V). */
void ema_set_power(ema_model *m, int on);
"""
"""The high-order model's calls beyond the shared API."""


def header() -> str:
    """``ema_actuator.h`` of a high-order export: the slots, constants and API.

    Returns
    -------
    str
        C source text.
    """
    lines = [
        "/* The X-43A EMA high-order discrete model (NASA/TM-2008-214637 figures 30, 32, 33; HOAD2, HOAD3) as",
        " * exported by ema_sim. Generated: the slots below are ema_sim's kernel layout. Do not edit. */",
        "#ifndef EMA_ACTUATOR_H",
        "#define EMA_ACTUATOR_H",
        "#include <stddef.h>",
        "#include <stdint.h>",
        "",
        f"#define EMA_N_PARAMS {len(P)}",
        *(f"#define EMA_P_{name} {i}" for i, name in enumerate(SLOTS)),
        f"#define EMA_N_OUT {len(OUTPUT_FIELDS)}",
        *(f"#define EMA_O_{name.upper()} {i}" for i, name in enumerate(OUTPUT_FIELDS)),
        "",
        "#define EMA_HIGH_ORDER 1",
        f"#define EMA_TIME_EPS_S {c_double(st.TIME_EPS_S)}",
        f"#define EMA_TWO_PI {c_double(st.TWO_PI)}",
        f"#define EMA_HISTORY_START_S {c_double(HISTORY_START_S)}",
        f"#define EMA_NEWTON_STEPS {cal.NEWTON_STEPS}",
        f"#define EMA_FEEDBACK_TOL {c_double(FEEDBACK_TOL)}",
        f"#define EMA_DELAY_STEP_EPS {c_double(DELAY_STEP_EPS)}",
        f"#define EMA_U53 {c_double(nz._U53)}",
        f"#define EMA_ZIG_R {c_double(nz._ZIG_R)}",
        f"#define EMA_SEED_FACTOR {SEED_FACTOR}ULL",
        *(f"#define EMA_{flag} {getattr(st, flag)}" for flag in
          ("FLAG_RATE", "FLAG_POSITION", "FLAG_FREE_PLAY", "FLAG_CURRENT", "FLAG_PWM_DEAD_BAND", "FLAG_BRAKE",
           "FLAG_STALL")),
        *(f"#define EMA_{name} {getattr(f30, name)}" for name in ("MOTOR_STOP_LOW", "MOTOR_STUCK", "MOTOR_STOP_HIGH")),
        "",
        API,
        EXTRA_API,
        "#endif",
        "",
    ]
    return "\n".join(lines)


STAGES_PREAMBLE = r"""/* Figures 30, 32 and 33's stages, each the transcription of one numba function of ema_sim
 * (named in ema_sim.export.hoad_stages). Generated by ema_sim. */
#include <math.h>
#include <stdint.h>
#include "ema_actuator.h"

#define PP(name) p[EMA_P_##name]
"""

KERNEL = r"""/* HOAD2/HOAD3: figure 30 at a fixed 10 kHz step, one instance
 * (ema_sim.models.high_order.hoad.run_discrete, cut at its step). Generated by ema_sim. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "ema_actuator.h"

#define PP(name) p[EMA_P_##name]

/* the stages (ema_hoad_stages.c) the kernel calls */
double ema_cubic(double c0, double c1, double c2, double c3, double x);
uint64_t ema_splitmix64(uint64_t seed);
double ema_band_limited_step(double value, double decay, double innovation, uint64_t *state);
void ema_servo_drive(double kp, double vmax, double kv, double imax, double kc, double r, double ke, double vdb,
                     double duty, double x_command_in, double lvdt_in, double integral_in_s, double v_motor_in_s,
                     double current_a, double bus_v, int rate_segment, int current_segment, int pwm_region,
                     int classify, double *values, int *segments);
int ema_integrating(int rate_segment, int current_segment, int pwm_region);
int ema_drive_flags(int rate_segment, int current_segment, int pwm_region, double v_motor_in_s);
double ema_motor_current_step(double v_applied, double i_a, double v_motor_in_s, double conductance,
                              double ke_v_per_in_s, double decay);
double ema_bus_current(double v_applied, double i_a, double v_bus);
double ema_bus_voltage_step(double v_bus, double i_bus_a, double v_supply, double r_source_ohm, double decay);
double ema_friction_step(double v, double f_applied, double coulomb_lbf, double stiction_lbf, double dt_per_mass,
                         double damping_dt_per_mass);
double ema_gear_train(const double *p, double xm, double xs, double *damping, double *lvdt, int *free);
double ema_command_in(const double *p, double c0, double c1, double c2, double c3, double u, double *slope);
double ema_feedback_deg(const double *p, double lvdt_in, double noise_v);
long ema_split_delay(double delay_s, double dt, double *share);
void ema_equilibrium(const double *p, double x_command_in, double hinge_moment_inlb, int powered, double *values,
                     int *motor_out, int *flags_out);

static double ema_max(double a, double b) { return b > a ? b : a; }
static double ema_min(double a, double b) { return b < a ? b : a; }

struct ema_model {
    double p[EMA_N_PARAMS];
    double dt;
    /* per run, as the kernel computes them before its loop */
    double kp, vmax, kv, imax, kc, vdb, duty, ki_dt, r, ke, kf, arm, vsup, rsrc, xmin, xmax, delay, dt_m, dt_s;
    double inv_arm, inv_r, decay_i, g_lf, decay_bus, a_cmd, w_cmd, w_fbn, w_fb, w_cmd_delay, delay_lo, delay_hi;
    long n_delay;
    /* the state (ema_sim.models.high_order.params.X) */
    double xm, vm, xs, vs, cur, lf, vbus, ncmd, nfb, xi;
    int flags, on;
    long head, nbuf;
    double *buf;
    uint64_t rng;
    /* the input breakpoints, one per frame after the trim's: time, command after stage 2 (in), its inches per
     * volt, hinge moment; a ring indexed by breakpoint number */
    double *bp_t, *bp_x, *bp_s, *bp_h;
    long bp_cap, bp_count, jd, jd_hi, jh;
    long k;
    double out[EMA_N_OUT];
};

""" + PARAM_INDEX + r"""
int ema_check_params(const double *p, double rate_hz, char *msg, size_t msg_size) {
    if (!(isfinite(rate_hz) && rate_hz > 0.0)) {
        snprintf(msg, msg_size, "rate must be a positive number of Hz, got %g", rate_hz);
        return 1;
    }
    for (int i = 0; i < EMA_N_PARAMS; i++) {
        double v = p[i], lo = ema_param_min[i], hi = ema_param_max[i], off = ema_param_off[i];
        int is_off = !isnan(off) && v == off;
        if (!isfinite(v)) {
            snprintf(msg, msg_size, "parameter %s must be finite", ema_param_names[i]);
            return 1;
        }
        if (is_off) continue;
        if (v < lo || (ema_param_min_exclusive[i] && v == lo) || v > hi) {
            const char *unit = strcmp(ema_param_units[i], "-") == 0 ? "" : ema_param_units[i];
            snprintf(msg, msg_size, "parameter %s = %g is outside its range %s%g, %g] %s", ema_param_names[i], v,
                     ema_param_min_exclusive[i] ? "(" : "[", lo, hi, unit);
            return 1;
        }
    }
    if (!(PP(position_min_in) < PP(position_max_in))) {
        snprintf(msg, msg_size, "parameter position_min_in must be below position_max_in");
        return 1;
    }
    if (!(PP(coulomb_friction_lbf) <= PP(stiction_lbf))) {
        snprintf(msg, msg_size, "parameter coulomb_friction_lbf must not exceed stiction_lbf");
        return 1;
    }
    return 0;
}

/* a breakpoint: the frame's command through stage 2 and its load, from time t */
static void ema_breakpoint(ema_model *m, double t, double command_deg, double hinge_moment_inlb) {
    long slot = m->bp_count % m->bp_cap;
    m->bp_t[slot] = t;
    m->bp_x[slot] = ema_command_in(m->p, ema_command_cal[0], ema_command_cal[1], ema_command_cal[2],
                                   ema_command_cal[3], command_deg, &m->bp_s[slot]);
    m->bp_h[slot] = hinge_moment_inlb;
    m->bp_count++;
}

/* the latest breakpoint at or before t, searching forward from j (stages.zoh_index) */
static long ema_zoh(const ema_model *m, double t, long j) {
    while (j + 1 < m->bp_count && m->bp_t[(j + 1) % m->bp_cap] <= t + EMA_TIME_EPS_S) j++;
    return j;
}

/* a sample of the state now (the kernel's samples: stages 16-17 on the delayed filtered LVDT) */
static void ema_sample(ema_model *m) {
    const double *p = m->p;
    const double *buf = m->buf;
    long head = m->head, n_delay = m->n_delay, nbuf = m->nbuf;
    double lagged = buf[head >= n_delay ? head - n_delay : head - n_delay + nbuf];
    if (m->w_fb > 0.0) {
        double older = buf[head > n_delay ? head - n_delay - 1 : head - n_delay - 1 + nbuf];
        lagged += m->w_fb * (older - lagged);
    }
    m->out[EMA_O_POSITION_DEG] = ema_feedback_deg(p, lagged, m->nfb);
    m->out[EMA_O_SURFACE_DEG] = m->xs * PP(deg_per_in);
    m->out[EMA_O_RATE_DPS] = m->vm * PP(deg_per_in);
    m->out[EMA_O_CURRENT_A] = m->cur;
    m->out[EMA_O_BUS_V] = m->on ? m->vbus : 0.0;
    m->out[EMA_O_FLAGS] = (double)m->flags;
}

ema_model *ema_new_seeded(const double *params, double rate_hz, int backward, double command_deg,
                          double hinge_moment_inlb, long long seed, char *msg, size_t msg_size) {
    if (backward) {
        snprintf(msg, msg_size, "the high-order model has no backward Euler: it steps its own 10 kHz kernel");
        return NULL;
    }
    if (!params) params = ema_default_params;
    if (ema_check_params(params, rate_hz, msg, msg_size)) return NULL;
    if (!(isfinite(command_deg) && isfinite(hinge_moment_inlb))) {
        snprintf(msg, msg_size, "trim needs a finite command and hinge moment");
        return NULL;
    }
    ema_model *m = calloc(1, sizeof(ema_model));
    if (!m) {
        snprintf(msg, msg_size, "out of memory");
        return NULL;
    }
    memcpy(m->p, params, sizeof(m->p));
    const double *p = m->p;
    double dt = 1.0 / rate_hz;
    m->dt = dt;
    m->kp = PP(position_gain_per_s);
    m->vmax = PP(rate_limit_in_s);
    m->kv = PP(velocity_gain_a_per_in_s);
    m->imax = PP(current_limit_a);
    m->kc = PP(current_gain_v_per_a);
    m->vdb = PP(pwm_dead_band_v);
    m->duty = PP(pwm_max_duty_ratio);
    m->ki_dt = PP(position_integral_per_s2) * dt;
    m->r = PP(stator_resistance_ohm);
    m->ke = PP(back_emf_v_per_in_s);
    m->kf = PP(force_per_amp_lbf_per_a);
    m->arm = PP(crank_arm_in);
    m->vsup = PP(bus_supply_v);
    m->rsrc = PP(bus_source_resistance_ohm);
    m->xmin = PP(position_min_in);
    m->xmax = PP(position_max_in);
    m->delay = PP(command_delay_s);
    m->dt_m = dt / PP(motor_mass_lbs2_per_in);
    m->dt_s = dt / PP(surface_mass_lbs2_per_in);
    m->inv_arm = 1.0 / m->arm;
    m->inv_r = 1.0 / m->r;
    m->decay_i = exp(-m->r * dt / PP(inductance_h));
    m->g_lf = 1.0 - exp(-PP(lvdt_filter_rad_s) * dt);
    m->decay_bus = exp(-dt / (m->rsrc * PP(bus_capacitance_f)));
    m->a_cmd = PP(noise_bandwidth_hz) > 0.0 ? exp(-EMA_TWO_PI * PP(noise_bandwidth_hz) * dt) : 0.0;
    m->w_cmd = PP(command_noise_v) * sqrt(1.0 - m->a_cmd * m->a_cmd);
    m->w_fbn = PP(feedback_noise_v) * sqrt(1.0 - m->a_cmd * m->a_cmd);
    m->nbuf = (long)floor(PP(feedback_delay_s) / dt + EMA_DELAY_STEP_EPS) + 2;
    m->n_delay = ema_split_delay(PP(feedback_delay_s), dt, &m->w_fb);
    if (m->n_delay > m->nbuf - 2) m->n_delay = m->nbuf - 2;
    ema_split_delay(m->delay, dt, &m->w_cmd_delay);
    m->delay_lo = m->delay - m->w_cmd_delay * dt;
    m->delay_hi = m->delay_lo + dt;
    m->bp_cap = (long)ceil(m->delay_hi / dt) + 4;
    m->buf = calloc((size_t)m->nbuf, sizeof(double));
    m->bp_t = calloc((size_t)m->bp_cap, sizeof(double));
    m->bp_x = calloc((size_t)m->bp_cap, sizeof(double));
    m->bp_s = calloc((size_t)m->bp_cap, sizeof(double));
    m->bp_h = calloc((size_t)m->bp_cap, sizeof(double));
    if (!m->buf || !m->bp_t || !m->bp_x || !m->bp_s || !m->bp_h) {
        ema_delete(m);
        snprintf(msg, msg_size, "out of memory");
        return NULL;
    }
    /* trim (models.HighOrderModel._equilibria, Hoad2._trim_states) under the trim's breakpoint */
    m->on = 1;
    ema_breakpoint(m, EMA_HISTORY_START_S, command_deg, hinge_moment_inlb);
    double eq[6];
    int motor, flags;
    ema_equilibrium(p, m->bp_x[0], hinge_moment_inlb, 1, eq, &motor, &flags);
    m->xm = eq[0];
    m->xs = eq[1];
    m->cur = eq[2];
    m->lf = eq[3];
    m->vbus = eq[4];
    m->xi = eq[5];
    m->flags = flags;
    for (long j = 0; j < m->nbuf; j++) m->buf[j] = eq[3];
    m->rng = ema_splitmix64(((uint64_t)seed * EMA_SEED_FACTOR) & 0x7FFFFFFFFFFFFFFFULL);
    m->k = 0;
    ema_sample(m);
    return m;
}

ema_model *ema_new(const double *params, double rate_hz, int backward, double command_deg,
                   double hinge_moment_inlb, char *msg, size_t msg_size) {
    return ema_new_seeded(params, rate_hz, backward, command_deg, hinge_moment_inlb, ema_default_seed, msg,
                          msg_size);
}

void ema_delete(ema_model *m) {
    if (!m) return;
    free(m->buf);
    free(m->bp_t);
    free(m->bp_x);
    free(m->bp_s);
    free(m->bp_h);
    free(m);
}

void ema_set_power(ema_model *m, int on) {
    m->on = on != 0;
    if (!m->on) m->cur = 0.0;
}

/* one step of the kernel's loop (run_discrete's body) */
static void ema_kernel_step(ema_model *m) {
    const double *p = m->p;
    double dt = m->dt;
    double t = (double)m->k * dt;
    double xm = m->xm, vm = m->vm, xs = m->xs, vs = m->vs, cur = m->cur, lf = m->lf, vbus = m->vbus;
    double xi = m->xi, xmin = m->xmin, xmax = m->xmax;
    int on = m->on;
    double brake = on ? 0.0 : PP(brake_holding_lbf);
    double fc = PP(coulomb_friction_lbf) + brake;
    double fs = PP(stiction_lbf) + brake;
    double fh = PP(hinge_friction_lbf);
    m->jd = ema_zoh(m, t - m->delay_lo, m->jd);
    m->jh = ema_zoh(m, t, m->jh);
    double hm = m->bp_h[m->jh % m->bp_cap];
    int flags = 0;
    /* stages 1-3: delayed, quantized command with noise (volts to inches at its calibration slope) */
    m->ncmd = ema_band_limited_step(m->ncmd, m->a_cmd, m->w_cmd, &m->rng);
    m->nfb = ema_band_limited_step(m->nfb, m->a_cmd, m->w_fbn, &m->rng);
    long jd = m->jd % m->bp_cap;
    double xc = m->bp_x[jd] + m->ncmd * m->bp_s[jd];
    double xc_hi = xc;
    if (m->w_cmd_delay > 0.0) {
        m->jd_hi = ema_zoh(m, t - m->delay_hi, m->jd_hi);
        if (m->jd_hi != m->jd) {
            long jh = m->jd_hi % m->bp_cap;
            xc_hi = ema_min(ema_max(m->bp_x[jh] + m->ncmd * m->bp_s[jh], xmin), xmax);
        }
    }
    if (xc > xmax) {
        xc = xmax;
        flags |= EMA_FLAG_POSITION;
    } else if (xc < xmin) {
        xc = xmin;
        flags |= EMA_FLAG_POSITION;
    }
    /* stages 12, 15: gear train, LVDT and its filter */
    double c, lvdt;
    int free;
    double fk = ema_gear_train(p, xm, xs, &c, &lvdt, &free);
    if (free) flags |= EMA_FLAG_FREE_PLAY;
    lf += m->g_lf * (lvdt - lf);
    m->head += 1;
    if (m->head == m->nbuf) m->head = 0;
    m->buf[m->head] = lf;
    /* stages 4-8: controller electronics, current loop, PWM, motor */
    double v;
    int sv, si, sp;
    if (on) {
        double err = xc - lf;
        double values[4];
        int seg[3];
        ema_servo_drive(m->kp, m->vmax, m->kv, m->imax, m->kc, m->r, m->ke, m->vdb, m->duty, xc, lf, xi, vm, cur,
                        vbus, 0, 0, 0, 1, values, seg);
        v = values[3];
        sv = seg[0];
        si = seg[1];
        sp = seg[2];
        if (xc_hi != xc) {
            double hi[4];
            int seg_hi[3];
            ema_servo_drive(m->kp, m->vmax, m->kv, m->imax, m->kc, m->r, m->ke, m->vdb, m->duty, xc_hi, lf, xi, vm,
                            cur, vbus, 0, 0, 0, 1, hi, seg_hi);
            v += m->w_cmd_delay * (hi[3] - v);
            err += m->w_cmd_delay * (xc_hi - xc);
        }
        cur = ema_motor_current_step(v, cur, vm, m->inv_r, m->ke, m->decay_i);
        if (ema_integrating(sv, si, sp)) xi += m->ki_dt * err;
    } else {
        v = 0.0;
        cur = 0.0;
        sv = si = 0;
        sp = 1;
        flags |= EMA_FLAG_BRAKE;
    }
    /* stages 10-11, 13-14: motor and screw with friction (symplectic Euler), surface */
    vm = ema_friction_step(vm, m->kf * cur - fk + c * vs, fc, fs, m->dt_m, c * m->dt_m);
    xm += vm * dt;
    if (xm >= xmax) {
        xm = xmax;
        vm = ema_min(vm, 0.0);
        flags |= EMA_FLAG_POSITION;
    } else if (xm <= xmin) {
        xm = xmin;
        vm = ema_max(vm, 0.0);
        flags |= EMA_FLAG_POSITION;
    }
    flags |= ema_drive_flags(sv, si, sp, vm);
    vs = ema_friction_step(vs, fk + c * vm + hm * m->inv_arm, fh, fh, m->dt_s, c * m->dt_s);
    xs += vs * dt;
    /* stage 9: the bus */
    vbus = ema_bus_voltage_step(vbus, ema_bus_current(v, cur, vbus), m->vsup, m->rsrc, m->decay_bus);
    m->xm = xm;
    m->vm = vm;
    m->xs = xs;
    m->vs = vs;
    m->cur = cur;
    m->lf = lf;
    m->vbus = vbus;
    m->xi = xi;
    m->flags = flags;
    m->k++;
}

void ema_advance(ema_model *m, double command_deg, double hinge_moment_inlb, long n) {
    ema_breakpoint(m, (double)m->k * m->dt, command_deg, hinge_moment_inlb);
    for (long j = 0; j < n; j++) ema_kernel_step(m);
    ema_sample(m);
}

void ema_step(ema_model *m, double command_deg, double hinge_moment_inlb) {
    ema_advance(m, command_deg, hinge_moment_inlb, 1);
}

void ema_outputs(const ema_model *m, double *out) { memcpy(out, m->out, sizeof(m->out)); }
double ema_output(const ema_model *m, int index) {
    return index >= 0 && index < EMA_N_OUT ? m->out[index] : NAN;
}
double ema_time(const ema_model *m) { return (double)m->k * m->dt; }
long ema_steps(const ema_model *m) { return m->k; }
double ema_step_size(const ema_model *m) { return m->dt; }
"""
"""``ema_hoad.c``: the kernel around the stages."""


@dataclass(frozen=True)
class HoadValues:
    """What ``ema_hoad_config.c`` holds: one high-order model's kernel vector, calibration and seed.

    Parameters
    ----------
    name : str
        ``hoad2`` or ``hoad3``.
    description : str
        One line: model, channel, where the values come from.
    vector : numpy.ndarray
        The kernel parameters (:data:`P`).
    command_cal : tuple of float
        The channel's command calibration (degrees → volts).
    seed : int
        The noise seed.
    rate_hz : float
        The model's rate.
    """

    name: str
    description: str
    vector: np.ndarray
    command_cal: tuple[float, float, float, float]
    seed: int
    rate_hz: float = RATE_HZ


def _array(ctype: str, name: str, values: list[str]) -> str:
    body = "".join(f"    {v},\n" for v in values)
    return f"const {ctype} {name}[EMA_N_PARAMS] = {{\n{body}}};\n"


def config(values: HoadValues) -> str:
    """``ema_hoad_config.c``: the model's values and its slots' metadata.

    Parameters
    ----------
    values : HoadValues
        The model.

    Returns
    -------
    str
        C source text.
    """
    rows = slot_rows()
    return "\n".join([
        "/* The exported model's own values and its parameters' metadata. Generated by ema_sim. */",
        "#include <math.h>",
        f'#include "{HEADER}"',
        "",
        f"const char *const ema_model_name = {c_string(values.name)};",
        f"const char *const ema_model_description = {c_string(values.description)};",
        f"const double ema_default_rate_hz = {c_double(values.rate_hz)};",
        "const int ema_default_backward = 0;",
        f"const long long ema_default_seed = {int(values.seed)}LL;",
        "const double ema_command_cal[4] = {" + ", ".join(c_double(float(c)) for c in values.command_cal) + "};",
        _array("double", "ema_default_params", [f"{c_double(float(v))} /* {r.name} */" for v, r in zip(
            values.vector, rows, strict=True)]),
        _array("char *const", "ema_param_names", [c_string(r.name) for r in rows]),
        _array("char *const", "ema_param_units", [c_string(r.unit) for r in rows]),
        _array("char *const", "ema_param_descriptions", [c_string(r.description) for r in rows]),
        _array("double", "ema_param_min", [c_double(r.lo) for r in rows]),
        _array("double", "ema_param_max", [c_double(r.hi) for r in rows]),
        _array("int", "ema_param_min_exclusive", [str(int(r.lo_exclusive)) for r in rows]),
        _array("double", "ema_param_off", [c_double(math.nan if r.off is None else r.off) for r in rows]),
    ])


def write_sources(directory: Path, values: HoadValues) -> list[Path]:
    """Write the header and the high-order model's C files into ``directory``.

    Parameters
    ----------
    directory : pathlib.Path
        Where (created).
    values : HoadValues
        The model.

    Returns
    -------
    list of pathlib.Path
        The files written, header first.
    """
    directory.mkdir(parents=True, exist_ok=True)
    texts = {HEADER: header(), STAGES_FILE: STAGES_PREAMBLE + _tables() + stages_c(), KERNEL_FILE: KERNEL,
             CONFIG_FILE: config(values)}
    return write_texts(directory, texts)


FRAME_HZ = 1_000.0
"""The frame ``ema verify`` drives an exported high-order model at (10 of its steps; any whole number works)."""


def target_values(target: ExportTarget) -> HoadValues:
    """What the C sources of a high-order target hold: its truth's kernel vector, the channel's command calibration.

    Parameters
    ----------
    target : ExportTarget
        A high-order target.

    Returns
    -------
    HoadValues
        Name, description, kernel vector, calibration, seed, rate.
    """
    if not target.high_order:
        raise ExportError(f"{target.model} is not a high-order model")
    model = target.truth_model()
    c = model.channel.command_cal
    vector = target.kernel_vector()
    return HoadValues(target.model, target.description, vector, (c.c0, c.c1, c.c2, c.c3),
                      int(target.options.get("seed", 0.0)), target.rate_hz)

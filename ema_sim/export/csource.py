"""The exported C model: header, stages, the fixed-step kernel and the model's own values, and gcc.

The sources are the same for every second-order export; only ``ema_config.c`` (the parameter values,
the rate, the method and the parameter metadata) is generated per model. The layout macros come
from the declared layouts (:data:`~ema_sim.models.second_order.params.P`,
:data:`~ema_sim.models.second_order.params.X`, :data:`~ema_sim.models.base.OUTPUT_FIELDS`), the
constants from the Python values themselves (hexadecimal literals: the same bits).

``ema_actuator.c`` is :func:`ema_sim.models.second_order.loada.make_euler`'s kernel for one
instance, cut at its step: :c:func:`ema_new` trims and samples time 0 (the kernel's first
iteration), :c:func:`ema_step` holds the command and hinge moment over one step and samples its end.
A host calls it once per step of the model's own rate, which is the kernel's run with an input
breakpoint at every step (``ema simulate --frame-hz`` equal to the rate).
"""

from __future__ import annotations

import math
import shutil
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ema_sim import parameters as pm
from ema_sim.export.cstages import stages_c
from ema_sim.models import stages as st
from ema_sim.models.base import HISTORY_START_S, OUTPUT_FIELDS
from ema_sim.models.second_order.figure26 import HISTORY_SIZE, NEVER_S
from ema_sim.models.second_order.params import N_STATE, P, SecondOrderParams, X

CFLAGS: tuple[str, ...] = ("-std=c11", "-O2", "-fno-fast-math", "-ffp-contract=off", "-Wall", "-Wextra",
                           "-Wno-unused-function", "-Werror=implicit-function-declaration")
"""gcc's flags: IEEE arithmetic as written, no fused multiply-adds (the numba kernel has none)."""
HEADER = "ema_actuator.h"
STAGES_FILE = "ema_stages.c"
KERNEL_FILE = "ema_actuator.c"
CONFIG_FILE = "ema_config.c"
SOURCES: tuple[str, ...] = (STAGES_FILE, KERNEL_FILE, CONFIG_FILE)
"""The model's C files (with :data:`HEADER`)."""


class CompileError(RuntimeError):
    """gcc failed on the generated sources (a bug of the generator, or no compiler)."""


def c_double(x: float) -> str:
    """A C literal of exactly this double.

    Parameters
    ----------
    x : float
        The value.

    Returns
    -------
    str
        A hexadecimal floating literal, ``INFINITY``, ``-INFINITY`` or ``NAN``.
    """
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return float(x).hex()


def c_string(text: str) -> str:
    """A C string literal (UTF-8 kept, quotes and backslashes escaped).

    Parameters
    ----------
    text : str
        The text.

    Returns
    -------
    str
        ``"..."``.
    """
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _fields(layout: pm.Slots) -> list[str]:
    """A layout's slot names in slot order."""
    names: tuple[str, ...] = getattr(layout, "_fields")  # noqa: B009 - a namedtuple's, not in the Slots protocol
    return list(names)


def header() -> str:
    """``ema_actuator.h``: the layouts, the constants and the API.

    Returns
    -------
    str
        C source text.
    """
    lines = [
        "/* The X-43A EMA second-order model (NASA/TM-2008-214637 figure 26) as exported by ema_sim.",
        " * Generated: the slots below are ema_sim's kernel layouts. Do not edit. */",
        "#ifndef EMA_ACTUATOR_H",
        "#define EMA_ACTUATOR_H",
        "#include <stddef.h>",
        "",
        f"#define EMA_N_PARAMS {len(P)}",
        *(f"#define EMA_P_{name} {i}" for i, name in enumerate(_fields(P))),
        f"#define EMA_N_STATE {N_STATE}",
        *(f"#define EMA_X_{name} {i}" for i, name in enumerate(_fields(X))),
        f"#define EMA_N_OUT {len(OUTPUT_FIELDS)}",
        *(f"#define EMA_O_{name.upper()} {i}" for i, name in enumerate(OUTPUT_FIELDS)),
        "",
        f"#define EMA_TIME_EPS_S {c_double(st.TIME_EPS_S)}",
        f"#define EMA_TWO_PI {c_double(st.TWO_PI)}",
        f"#define EMA_RAD2DEG {c_double(st.RAD2DEG)}",
        f"#define EMA_DEG2RAD {c_double(st.DEG2RAD)}",
        f"#define EMA_HISTORY_SIZE {HISTORY_SIZE}",
        f"#define EMA_NEVER_S {c_double(NEVER_S)}",
        f"#define EMA_HISTORY_START_S {c_double(HISTORY_START_S)}",
        *(f"#define EMA_{flag} {getattr(st, flag)}" for flag in
          ("FLAG_RATE", "FLAG_POSITION", "FLAG_FREE_PLAY", "FLAG_THRESHOLD", "FLAG_CURRENT")),
        "",
        API,
        "#endif",
        "",
    ]
    return "\n".join(lines)


PARAM_INDEX = r"""int ema_param_index(const char *name) {
    for (int i = 0; i < EMA_N_PARAMS; i++) {
        if (strcmp(name, ema_param_names[i]) == 0) return i;
    }
    return -1;
}
"""
"""The C API's parameter lookup by name, shared by every kernel an export writes (figure 26's, the linear models')."""

API = r"""/* ---- the model's own values (ema_config.c) ---- */
extern const char *const ema_model_name;        /* "loada", "loadf" */
extern const char *const ema_model_description;
extern const double ema_default_rate_hz;        /* the model's step is 1/rate */
extern const int ema_default_backward;          /* 0: LOADA's forward Euler, 1: LOADF's backward Euler */
extern const double ema_default_params[EMA_N_PARAMS];
extern const char *const ema_param_names[EMA_N_PARAMS];
extern const char *const ema_param_units[EMA_N_PARAMS];
extern const char *const ema_param_descriptions[EMA_N_PARAMS];
extern const double ema_param_min[EMA_N_PARAMS];  /* valid range; the off value (NAN: none) is also allowed */
extern const double ema_param_max[EMA_N_PARAMS];
extern const int ema_param_min_exclusive[EMA_N_PARAMS];
extern const double ema_param_off[EMA_N_PARAMS];

/* ---- the model ---- */
typedef struct ema_model ema_model;

/* Index of a parameter by name, -1 when unknown. */
int ema_param_index(const char *name);
/* 0 when every parameter is in range; else 1 and the reason in msg. */
int ema_check_params(const double *params, double rate_hz, char *msg, size_t msg_size);
/* A model trimmed at rest under a held command (deg) and hinge moment (in.lb, positive aids positive
 * deflection), its outputs at time 0 ready. NULL on a bad parameter or no memory (reason in msg). */
ema_model *ema_new(const double *params, double rate_hz, int backward, double command_deg,
                   double hinge_moment_inlb, char *msg, size_t msg_size);
void ema_delete(ema_model *m);
/* One step of 1/rate with the command and the hinge moment held over it; the outputs at its end. */
void ema_step(ema_model *m, double command_deg, double hinge_moment_inlb);
/* The outputs now: EMA_O_POSITION_DEG (LVDT), EMA_O_SURFACE_DEG, EMA_O_RATE_DPS, current and bus (NAN:
 * none in this model), EMA_O_FLAGS (limit flags as a number). */
void ema_outputs(const ema_model *m, double *out);
double ema_output(const ema_model *m, int index);
/* Model time (s) and steps taken since ema_new. */
double ema_time(const ema_model *m);
long ema_steps(const ema_model *m);
double ema_step_size(const ema_model *m);
"""
"""The public API (declared in :data:`HEADER`)."""

KERNEL = r"""/* LOADA/LOADF: figure 26 stepped by Euler at a fixed rate, one instance
 * (ema_sim.models.second_order.loada.make_euler, cut at its step). Generated by ema_sim. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "ema_actuator.h"

#define PP(name) p[EMA_P_##name]

/* the stages (ema_stages.c) the kernel calls */
double ema_lag_gain(double corner_hz, double dt);
double ema_first_order_lag(double y, double u, double gain);
int ema_limited_integrator(double *x, double *v, double lo, double hi);
void ema_euler_pair(double *x, double *v, double a, double dt, int backward);
double ema_free_play_accel(double hinge_moment_inlb, double inertia_inlbs2);
void ema_free_play_euler(double *fp, double *v, double accel, double dt, double half, int backward);
double ema_command_path(const double *p, double u);
double ema_surface_compliance(const double *p, double hinge_moment_inlb);
int ema_drive_on(const double *p);
double ema_servo(const double *p, double u_in, double x, double v, const double *y, double hinge_moment_inlb,
                 double dt, int *flags, int *piece, double *integral_rate, double *drive_accel);
double ema_lvdt(const double *p, double x_pos, double hinge_moment_inlb);
double ema_compliance_time_constant_s(const double *p);
int ema_free_play_subsystem(const double *p);
void ema_linkage_steps(const double *p, double dt, double *steps);
void ema_linkage_step(const double *p, const double *y, double hinge_moment_inlb, double actuator_accel,
                      const double *steps, double *deflection, double *rate);
void ema_history_write(const double *p, double *y, double *hist, double t, double value, double rate, int force);
double ema_history_read(const double *y, const double *hist, double t);
void ema_write_outputs(const double *p, const double *x, double position_fb, double hinge_moment_inlb, int flags,
                       double *row);
double ema_compliance_gain(const double *p, double dt);
void ema_trim(const double *p, double command_deg, double hinge_moment_inlb, double *x, double *hist, long entries);

struct ema_model {
    double p[EMA_N_PARAMS];
    double x[EMA_N_STATE];
    double dt;
    int backward;
    /* per run, as the kernel computes them before its loop */
    double g_cmd, g_fb, g_c, half, fp_acc_per_inlb, fb_delay;
    int free_play, linkage, in_loop, integral, drive, damped;
    double link_steps[18];
    /* stage 14's ring */
    double *hist;
    long hist_entries;
    /* the command's breakpoints, one per step after the trim's (stage 1 reads them delayed) */
    double *bp_t, *bp_u;
    long bp_cap, bp_count, jd;
    long k;
    double hm;
    int flags;
    double fb_prev;
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
        if (isnan(v) || (isinf(v) && !is_off)) {
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
    if (!(PP(position_min_deg) < PP(position_max_deg))) {
        snprintf(msg, msg_size, "parameter position_min_deg must be below position_max_deg");
        return 1;
    }
    return 0;
}

/* the kernel's first part of an iteration: stage 14 records the reading, the outputs are sampled */
static void ema_sample(ema_model *m) {
    const double *p = m->p;
    double *x = m->x;
    double t = 0.0 + (double)m->k * m->dt;
    double fb = x[EMA_X_feedback_lag_deg];
    if (m->fb_delay > 0.0) ema_history_write(p, x, m->hist, t, fb, (fb - m->fb_prev) / m->dt, 0);
    m->fb_prev = fb;
    if (m->fb_delay > 0.0) fb = ema_history_read(x, m->hist, t - m->fb_delay);
    ema_write_outputs(p, x, fb, m->hm, m->flags, m->out);
}

ema_model *ema_new(const double *params, double rate_hz, int backward, double command_deg,
                   double hinge_moment_inlb, char *msg, size_t msg_size) {
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
    m->backward = backward != 0;
    m->g_cmd = ema_lag_gain(PP(command_lag_hz), dt);
    m->g_fb = ema_lag_gain(PP(feedback_lag_hz), dt);
    m->g_c = ema_compliance_gain(p, dt);
    m->free_play = ema_free_play_subsystem(p);
    m->half = m->free_play ? 0.5 * PP(free_play_deg) : 0.0;
    m->fp_acc_per_inlb = ema_free_play_accel(1.0, PP(surface_inertia_inlbs2));
    m->linkage = PP(linkage_freq_hz) > 0.0;
    if (m->linkage) ema_linkage_steps(p, dt, m->link_steps);
    m->in_loop = PP(feedback_filter_in_loop) > 0.5;
    m->fb_delay = PP(feedback_delay_s);
    m->integral = PP(integral_hz) > 0.0;
    m->drive = ema_drive_on(p);
    m->damped = ema_compliance_time_constant_s(p) > 0.0;
    m->hist_entries = m->fb_delay > 0.0 ? EMA_HISTORY_SIZE : 1;
    m->bp_cap = (long)ceil(PP(delay_s) / dt) + 4;
    m->hist = calloc((size_t)(3 * m->hist_entries), sizeof(double));
    m->bp_t = calloc((size_t)m->bp_cap, sizeof(double));
    m->bp_u = calloc((size_t)m->bp_cap, sizeof(double));
    if (!m->hist || !m->bp_t || !m->bp_u) {
        ema_delete(m);
        snprintf(msg, msg_size, "out of memory");
        return NULL;
    }
    ema_trim(p, command_deg, hinge_moment_inlb, m->x, m->hist, m->hist_entries);
    m->bp_t[0] = EMA_HISTORY_START_S;
    m->bp_u[0] = command_deg;
    m->bp_count = 1;
    m->jd = 0;
    m->k = 0;
    m->hm = hinge_moment_inlb;
    int piece;
    double integrand, drive_accel;
    double *x = m->x;
    ema_servo(p, x[EMA_X_command_lag_deg], x[EMA_X_position_deg], x[EMA_X_rate_dps], x, m->hm, dt, &m->flags,
              &piece, &integrand, &drive_accel);
    m->fb_prev = x[EMA_X_feedback_lag_deg];
    ema_sample(m);
    return m;
}

void ema_delete(ema_model *m) {
    if (!m) return;
    free(m->hist);
    free(m->bp_t);
    free(m->bp_u);
    free(m);
}

void ema_step(ema_model *m, double command_deg, double hinge_moment_inlb) {
    const double *p = m->p;
    double *x = m->x;
    double dt = m->dt;
    int backward = m->backward;
    double t = 0.0 + (double)m->k * dt;
    /* this step's breakpoint */
    long slot = m->bp_count % m->bp_cap;
    m->bp_t[slot] = t;
    m->bp_u[slot] = command_deg;
    m->bp_count++;
    /* stages 1-4: delayed command, command error, quantizer, command lag */
    double when = t - PP(delay_s);
    while (m->jd + 1 < m->bp_count && m->bp_t[(m->jd + 1) % m->bp_cap] <= when + EMA_TIME_EPS_S) m->jd++;
    double u_del = m->bp_u[m->jd % m->bp_cap];
    double hm = hinge_moment_inlb;
    m->hm = hm;
    x[EMA_X_command_lag_deg] = ema_first_order_lag(x[EMA_X_command_lag_deg], ema_command_path(p, u_del), m->g_cmd);
    /* stages 5-11: the servo on the position (LOADF: one frame ahead), drive, limited integrators */
    double pos = x[EMA_X_position_deg], rate = x[EMA_X_rate_dps];
    int piece;
    double integrand, drive_accel;
    double a = ema_servo(p, x[EMA_X_command_lag_deg], backward ? pos + dt * rate : pos, rate, x, hm, dt, &m->flags,
                         &piece, &integrand, &drive_accel);
    ema_euler_pair(&pos, &rate, a, dt, backward);
    ema_limited_integrator(&pos, &rate, PP(position_min_deg), PP(position_max_deg));
    x[EMA_X_position_deg] = pos;
    x[EMA_X_rate_dps] = rate;
    if (m->integral) x[EMA_X_integral_deg_s] = x[EMA_X_integral_deg_s] + dt * integrand;
    if (m->drive) x[EMA_X_drive_rate_dps] = x[EMA_X_drive_rate_dps] + dt * drive_accel;
    /* stage 15: free play; 17: the linkage mode */
    if (m->free_play) {
        ema_free_play_euler(&x[EMA_X_free_play_deg], &x[EMA_X_free_play_rate_dps], hm * m->fp_acc_per_inlb, dt,
                            m->half, backward);
    }
    if (m->linkage) {
        double e, v;
        ema_linkage_step(p, x, hm, m->in_loop ? drive_accel : a, m->link_steps, &e, &v);
        x[EMA_X_linkage_deg] = e;
        x[EMA_X_linkage_rate_dps] = v;
    }
    /* stages 12-13: LVDT and its feedback lag; 16: compliance */
    double fb_pos = backward ? x[EMA_X_position_deg] + dt * x[EMA_X_rate_dps] : x[EMA_X_position_deg];
    x[EMA_X_feedback_lag_deg] = ema_first_order_lag(x[EMA_X_feedback_lag_deg], ema_lvdt(p, fb_pos, hm), m->g_fb);
    if (m->damped) {
        x[EMA_X_compliance_deg] = ema_first_order_lag(x[EMA_X_compliance_deg], ema_surface_compliance(p, hm),
                                                      m->g_c);
    }
    m->k++;
    ema_sample(m);
}

void ema_outputs(const ema_model *m, double *out) { memcpy(out, m->out, sizeof(m->out)); }
double ema_output(const ema_model *m, int index) { return m->out[index]; }
double ema_time(const ema_model *m) { return 0.0 + (double)m->k * m->dt; }
long ema_steps(const ema_model *m) { return m->k; }
double ema_step_size(const ema_model *m) { return m->dt; }
"""
"""``ema_actuator.c``: the kernel around the stages."""

STAGES_PREAMBLE = r"""/* Figure 26's stages, each the transcription of one numba function of ema_sim (named in
 * ema_sim.export.cstages). Generated by ema_sim. */
#include <math.h>
#include "ema_actuator.h"

#define PP(name) p[EMA_P_##name]
"""


@dataclass(frozen=True)
class ModelValues:
    """What ``ema_config.c`` holds: one model's parameter values, rate and method.

    Parameters
    ----------
    name : str
        Registry name (``loada``, ``loadf``).
    description : str
        One line: model, channel, where the values come from.
    params : SecondOrderParams
        The values.
    rate_hz : float
        The model's rate.
    backward : bool
        LOADF's backward Euler with the look-ahead feedback.
    """

    name: str
    description: str
    params: SecondOrderParams
    rate_hz: float
    backward: bool


def _array(ctype: str, name: str, values: Sequence[str]) -> str:
    body = "".join(f"    {v},\n" for v in values)
    return f"const {ctype} {name}[EMA_N_PARAMS] = {{\n{body}}};\n"


def config(values: ModelValues) -> str:
    """``ema_config.c``: the model's values and the parameters' metadata.

    Parameters
    ----------
    values : ModelValues
        The model.

    Returns
    -------
    str
        C source text.
    """
    metas = pm.metas(SecondOrderParams)
    vector = values.params.kernel_vector()
    names = _fields(P)
    by_slot = {m.kernel: (n, m) for n, m in metas.items() if m.kernel is not None}
    rows = [by_slot[k] for k in names]
    parts = [
        "/* The exported model's own values and its parameters' metadata. Generated by ema_sim. */",
        "#include <math.h>",
        f'#include "{HEADER}"',
        "",
        f"const char *const ema_model_name = {c_string(values.name)};",
        f"const char *const ema_model_description = {c_string(values.description)};",
        f"const double ema_default_rate_hz = {c_double(values.rate_hz)};",
        f"const int ema_default_backward = {int(values.backward)};",
        _array("double", "ema_default_params", [f"{c_double(float(v))} /* {n} */" for v, n in zip(
            vector, names, strict=True)]),
        "const char *const ema_param_names[EMA_N_PARAMS] = {\n" + "".join(
            f"    {c_string(n)},\n" for n in names) + "};\n",
        "const char *const ema_param_units[EMA_N_PARAMS] = {\n" + "".join(
            f"    {c_string(m.unit)},\n" for _, m in rows) + "};\n",
        "const char *const ema_param_descriptions[EMA_N_PARAMS] = {\n" + "".join(
            f"    {c_string(m.description)},\n" for _, m in rows) + "};\n",
        _array("double", "ema_param_min", [c_double(m.min) for _, m in rows]),
        _array("double", "ema_param_max", [c_double(m.max) for _, m in rows]),
        _array("int", "ema_param_min_exclusive", [str(int(m.min_exclusive)) for _, m in rows]),
        _array("double", "ema_param_off", [c_double(math.nan if m.off is None else m.off) for _, m in rows]),
    ]
    return "\n".join(parts)


def stages_file() -> str:
    """``ema_stages.c``.

    Returns
    -------
    str
        C source text.
    """
    return STAGES_PREAMBLE + stages_c()


def write_sources(directory: Path, values: ModelValues) -> list[Path]:
    """Write the header and the model's C files into ``directory``.

    Parameters
    ----------
    directory : pathlib.Path
        Where (created).
    values : ModelValues
        The model.

    Returns
    -------
    list of pathlib.Path
        The files written, header first.
    """
    directory.mkdir(parents=True, exist_ok=True)
    texts = {HEADER: header(), STAGES_FILE: stages_file(), KERNEL_FILE: KERNEL, CONFIG_FILE: config(values)}
    return write_texts(directory, texts)


def write_texts(directory: Path, texts: dict[str, str]) -> list[Path]:
    """Write each named text into ``directory``, in order.

    Parameters
    ----------
    directory : pathlib.Path
        Where (it exists).
    texts : dict
        File name → its text.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    out = []
    for name, text in texts.items():
        path = directory / name
        path.write_text(text, encoding="utf-8")
        out.append(path)
    return out


def compiler() -> str:
    """The C compiler the exports build with.

    Returns
    -------
    str
        Its path.
    """
    found = shutil.which("gcc") or shutil.which("cc")
    if found is None:
        raise CompileError("no C compiler (gcc or cc) on PATH")
    return found


def compile_c(sources: Sequence[Path], out: Path, *, shared: bool, include: Sequence[Path] = (),
              defines: Sequence[str] = ()) -> Path:
    """Compile C files into a shared library or an executable with :data:`CFLAGS`.

    Parameters
    ----------
    sources : sequence of pathlib.Path
        The C files.
    out : pathlib.Path
        The library or program to write.
    shared : bool
        A shared library (position independent) rather than a program.
    include : sequence of pathlib.Path
        Include directories.
    defines : sequence of str
        Preprocessor definitions (``NAME=value``).

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    cmd = [compiler(), *CFLAGS, *(f"-I{d}" for d in include), *(f"-D{d}" for d in defines)]
    if shared:
        cmd += ["-fPIC", "-shared", "-fvisibility=default"]
    cmd += ["-o", str(out), *(str(s) for s in sources), "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise CompileError(f"{' '.join(cmd)}\n{done.stderr}")
    return out

"""The C of a linear model (``loes``, ``hoalm``, ``sloac``): its zero-order-hold state space and delay lines.

:class:`ema_sim.models.linear.LinearModel` steps ``x ← Ad·x + Bd·u`` at its rate (:func:`run_lti`), each
system input the command or the hinge moment delayed by a whole number of steps. The C here holds the
very matrices the numba kernel uses (``Ad``, ``Bd``, ``Cd``, ``Dd``, ``Crate``, ``Drate``, as
hexadecimal literals) and performs the kernel's operations in its order, so with
:data:`~ema_sim.export.csource.CFLAGS` (no fused multiply-adds) it reproduces the kernel bit for bit.
It declares the API of :data:`~ema_sim.export.csource.API`, so the FMI wrapper and the harness are the
second-order export's own.

Two things are exact only under a condition checked here or said in the notes:

* the outputs at a step boundary read the delayed inputs the kernel reads at that instant; an
  undelayed input is known only up to the step just taken, so the export is refused when such an input
  feeds an output directly (``Dd``/``Drate`` non-zero: none of the three models does);
* the trim (``A·x + B·u = 0``) is a precomputed ``−A⁻¹B`` times the first inputs: exact at rest under
  zero inputs, within rounding otherwise (numpy's ``solve`` sums in another order).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ema_sim.export.csource import API, HEADER, PARAM_INDEX, c_double, c_string
from ema_sim.export.target import LINEAR, ExportError, ExportTarget
from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import OUTPUT_FIELDS
from ema_sim.models.linear import LinearModel
from ema_sim.models.stages import TIME_EPS_S

LTI_FILE = "ema_lti.c"
SOURCES: tuple[str, ...] = (LTI_FILE,)
"""A linear model's C files (with the header)."""
PARAMS: tuple[tuple[str, str, str], ...] = (
    ("delay_s", "s", "command delay (fixed: the matrices and delay lines were computed for it)"),
    ("position_delay_s", "s", "further delay of the position output (fixed)"),
)
"""The parameters a linear export declares (name, unit, description); fixed at their exported values."""
CHECK_STEPS = 1_000_000
"""The delay of every input is checked to be a constant number of steps over this many steps."""


def delay_steps(delay_s: float, dt: float, n: int = CHECK_STEPS) -> int:
    """The steps an input delay holds, as the kernel's zero-order hold reads it (``zoh_index``).

    At step ``k`` (time ``k·dt``) the kernel reads the input of the latest breakpoint ``m·dt`` at or
    before ``k·dt − delay`` (``TIME_EPS_S`` slack); the export holds ``k − m`` constant.

    Parameters
    ----------
    delay_s : float
        The delay (s).
    dt : float
        The step (s).
    n : int
        Steps checked.

    Returns
    -------
    int
        ``k − m``.
    """
    k = np.arange(n, dtype=np.int64)
    t = k.astype(float) * dt - delay_s + TIME_EPS_S
    m = np.floor(t / dt).astype(np.int64)
    m = np.where((m + 1).astype(float) * dt <= t, m + 1, m)
    m = np.where(m.astype(float) * dt > t, m - 1, m)
    d = k - m
    start = int(np.ceil(delay_s / dt)) + 2
    steps = set(np.unique(d[start:]).tolist())
    if len(steps) != 1:
        raise ExportError(f"a delay of {delay_s!r} s is not a constant number of {dt!r} s steps on the kernel's "
                          f"grid ({sorted(steps)}): not exported")
    return int(steps.pop())


def linear_model(target: ExportTarget) -> LinearModel:
    """The truth of a linear target (its matrices are what the C holds).

    Parameters
    ----------
    target : ExportTarget
        A ``loes``, ``hoalm`` or ``sloac`` target.

    Returns
    -------
    LinearModel
        One instance.
    """
    model = target.truth_model()
    if not isinstance(model, LinearModel):
        raise ExportError(f"{target.model} is not a linear model")
    return model


def _matrix(name: str, m: FloatArray) -> str:
    rows = m.reshape(m.shape[0], -1) if m.ndim == 2 else m.reshape(1, -1)
    body = ",\n".join("    {" + ", ".join(c_double(float(v)) for v in row) + "}" for row in rows)
    dims = "".join(f"[{s}]" for s in m.shape)
    return f"static const double {name}{dims} = {{\n{body}\n}};\n" if m.ndim == 2 else (
        f"static const double {name}{dims} = {{" + ", ".join(c_double(float(v)) for v in m) + "};\n")


def header() -> str:
    """``ema_actuator.h`` of a linear export: the second-order export's API, the linear model's constants.

    Returns
    -------
    str
        C source text.
    """
    lines = [
        "/* An X-43A EMA linear model (NASA/TM-2008-214637 sections 3.4, 4.2.7) as exported by ema_sim: its",
        " * zero-order-hold state space and delay lines. Generated. Do not edit. */",
        "#ifndef EMA_ACTUATOR_H",
        "#define EMA_ACTUATOR_H",
        "#include <stddef.h>",
        "",
        f"#define EMA_N_PARAMS {len(PARAMS)}",
        *(f"#define EMA_P_{name} {i}" for i, (name, _, _) in enumerate(PARAMS)),
        f"#define EMA_N_OUT {len(OUTPUT_FIELDS)}",
        *(f"#define EMA_O_{name.upper()} {i}" for i, name in enumerate(OUTPUT_FIELDS)),
        "",
        API,
        "#endif",
        "",
    ]
    return "\n".join(lines)


KERNEL = r"""
struct ema_model {
    double x[EMA_NX], xn[EMA_NX];
    double hist[EMA_HIST][2];  /* ring of the inputs: step i in slot i % EMA_HIST (command, hinge moment) */
    double dt;
    long k;
    double out[EMA_N_OUT];
};

""" + PARAM_INDEX + r"""
int ema_check_params(const double *params, double rate_hz, char *msg, size_t msg_size) {
    for (int j = 0; j < EMA_N_PARAMS; j++) {
        if (params[j] != ema_default_params[j]) {
            snprintf(msg, msg_size, "%s is fixed at %.17g (the matrices and delay lines were computed for it): "
                     "export the model again with the value wanted", ema_param_names[j], ema_default_params[j]);
            return 1;
        }
    }
    if (rate_hz != ema_default_rate_hz) {
        snprintf(msg, msg_size, "the rate is fixed at %.17g Hz (the zero-order hold was computed for it): export "
                 "the model again with --rate", ema_default_rate_hz);
        return 1;
    }
    return 0;
}

/* the input j reads at step k (its delay line; before the record, the trim's inputs) */
static double input_at(const ema_model *m, int j, long k) {
    long i = k - ema_delay_steps[j];
    long slot = ((i % EMA_HIST) + EMA_HIST) % EMA_HIST;
    return m->hist[slot][ema_source[j]];
}

/* the outputs at step boundary k: run_lti's sample (Dd·u first, then Cd·x) */
static void sample(ema_model *m) {
    double u[EMA_NU];
    long known = m->k - 1;  /* an undelayed input is known up to the step just taken (its Dd, Drate are 0) */
    for (int j = 0; j < EMA_NU; j++) {
        long k = m->k;
        if (k - ema_delay_steps[j] > known) k = known + ema_delay_steps[j];
        u[j] = input_at(m, j, k);
    }
    double pos = 0.0, surf = 0.0, rate = 0.0;
    for (int j = 0; j < EMA_NU; j++) {
        pos += ema_Dd[0][j] * u[j];
        surf += ema_Dd[1][j] * u[j];
        rate += ema_Drate[j] * u[j];
    }
    for (int a = 0; a < EMA_NX; a++) {
        pos += ema_Cd[0][a] * m->x[a];
        surf += ema_Cd[1][a] * m->x[a];
        rate += ema_Crate[a] * m->x[a];
    }
    for (int o = 0; o < EMA_N_OUT; o++) m->out[o] = NAN;
    m->out[EMA_O_POSITION_DEG] = pos;
    m->out[EMA_O_SURFACE_DEG] = surf;
    m->out[EMA_O_RATE_DPS] = rate;
    m->out[EMA_O_FLAGS] = 0.0;
}

ema_model *ema_new(const double *params, double rate_hz, int backward, double command_deg,
                   double hinge_moment_inlb, char *msg, size_t msg_size) {
    if (backward) {
        snprintf(msg, msg_size, "a linear model has no backward Euler: it steps its zero-order hold");
        return NULL;
    }
    if (!params) params = ema_default_params;
    if (ema_check_params(params, rate_hz, msg, msg_size)) return NULL;
    ema_model *m = calloc(1, sizeof(ema_model));
    if (!m) {
        snprintf(msg, msg_size, "no memory");
        return NULL;
    }
    m->dt = 1.0 / rate_hz;
    for (int i = 0; i < EMA_HIST; i++) {
        m->hist[i][0] = command_deg;
        m->hist[i][1] = hinge_moment_inlb;
    }
    double u0[2] = {command_deg, hinge_moment_inlb};
    for (int a = 0; a < EMA_NX; a++) {  /* at rest: A.x + B.u = 0 */
        double acc = 0.0;
        for (int j = 0; j < EMA_NU; j++) acc += ema_trim[a][j] * u0[ema_source[j]];
        m->x[a] = acc;
    }
    m->k = 0;
    sample(m);
    return m;
}

void ema_delete(ema_model *m) { free(m); }

void ema_step(ema_model *m, double command_deg, double hinge_moment_inlb) {
    long slot = m->k % EMA_HIST;
    m->hist[slot][0] = command_deg;
    m->hist[slot][1] = hinge_moment_inlb;
    double u[EMA_NU];
    for (int j = 0; j < EMA_NU; j++) u[j] = input_at(m, j, m->k);
    for (int a = 0; a < EMA_NX; a++) {
        double acc = 0.0;
        for (int j = 0; j < EMA_NU; j++) acc += ema_Bd[a][j] * u[j];
        for (int b = 0; b < EMA_NX; b++) acc += ema_Ad[a][b] * m->x[b];
        m->xn[a] = acc;
    }
    for (int a = 0; a < EMA_NX; a++) m->x[a] = m->xn[a];
    m->k++;
    sample(m);
}

void ema_outputs(const ema_model *m, double *out) { memcpy(out, m->out, sizeof m->out); }

double ema_output(const ema_model *m, int index) {
    return index >= 0 && index < EMA_N_OUT ? m->out[index] : NAN;
}

double ema_time(const ema_model *m) { return (double)m->k * m->dt; }
long ema_steps(const ema_model *m) { return m->k; }
double ema_step_size(const ema_model *m) { return m->dt; }
"""
"""The stepping (matrices and delay lines come before it in ``ema_lti.c``)."""


def lti_source(target: ExportTarget) -> str:
    """``ema_lti.c``: the model's values, matrices, delay lines and stepping.

    Parameters
    ----------
    target : ExportTarget
        A linear target.

    Returns
    -------
    str
        C source text.
    """
    model = linear_model(target)
    dt = 1.0 / model.rate_hz
    source = np.asarray(model._source, dtype=np.int64)
    delays = np.asarray(model._delays, dtype=float)
    Ad, Bd, Cd, Dd = model._Ad, model._Bd, model._Cd, model._Dd
    Crate, Drate = model._Crate, model._Drate
    steps = [delay_steps(float(d), dt) for d in delays]
    for j, d in enumerate(steps):
        if d == 0 and (np.any(Dd[:, j] != 0.0) or Drate[j] != 0.0):
            raise ExportError(f"{target.model}: an undelayed input feeds an output directly; the exported outputs "
                              "read the inputs of the step taken, not the next one: not exported")
    trim = -np.linalg.solve(model._A, model._B)
    values = (float(model.delay_s), float(model.position_delay_s))
    parts = [
        f"/* {target.model} ({target.channel}): x <- Ad.x + Bd.u at {model.rate_hz:g} Hz, as "
        "ema_sim.models.linear.run_lti steps it. Generated by ema_sim. */",
        "#include <math.h>", "#include <stdio.h>", "#include <stdlib.h>", "#include <string.h>",
        f'#include "{HEADER}"', "",
        f"#define EMA_NX {Ad.shape[0]}",
        f"#define EMA_NU {source.size}",
        f"#define EMA_HIST {max(steps) + 1}",
        "",
        f"const char *const ema_model_name = {c_string(target.model)};",
        f"const char *const ema_model_description = {c_string(target.description)};",
        f"const double ema_default_rate_hz = {c_double(model.rate_hz)};",
        "const int ema_default_backward = 0;",
        "const double ema_default_params[EMA_N_PARAMS] = {" + ", ".join(c_double(v) for v in values) + "};",
        "const char *const ema_param_names[EMA_N_PARAMS] = {" + ", ".join(c_string(n) for n, _, _ in PARAMS) + "};",
        "const char *const ema_param_units[EMA_N_PARAMS] = {" + ", ".join(c_string(u) for _, u, _ in PARAMS) + "};",
        "const char *const ema_param_descriptions[EMA_N_PARAMS] = {"
        + ", ".join(c_string(d) for _, _, d in PARAMS) + "};",
        "const double ema_param_min[EMA_N_PARAMS] = {" + ", ".join(c_double(v) for v in values) + "};",
        "const double ema_param_max[EMA_N_PARAMS] = {" + ", ".join(c_double(v) for v in values) + "};",
        "const int ema_param_min_exclusive[EMA_N_PARAMS] = {0, 0};",
        "const double ema_param_off[EMA_N_PARAMS] = {NAN, NAN};",
        "",
        "static const int ema_source[EMA_NU] = {" + ", ".join(str(int(s)) for s in source) + "};",
        "static const long ema_delay_steps[EMA_NU] = {" + ", ".join(str(d) for d in steps) + "};",
        _matrix("ema_Ad", Ad), _matrix("ema_Bd", Bd), _matrix("ema_Cd", Cd), _matrix("ema_Dd", Dd),
        _matrix("ema_Crate", Crate), _matrix("ema_Drate", Drate), _matrix("ema_trim", trim),
        KERNEL,
    ]
    return "\n".join(parts)


def write_sources(directory: Path, target: ExportTarget) -> list[Path]:
    """Write the header and ``ema_lti.c`` into ``directory``.

    Parameters
    ----------
    directory : pathlib.Path
        Where (created).
    target : ExportTarget
        A linear target.

    Returns
    -------
    list of pathlib.Path
        The files written, header first.
    """
    if target.model not in LINEAR:
        raise ExportError(f"{target.model} is not a linear model")
    directory.mkdir(parents=True, exist_ok=True)
    out = []
    for name, text in ((HEADER, header()), (LTI_FILE, lti_source(target))):
        path = directory / name
        path.write_text(text, encoding="utf-8")
        out.append(path)
    return out


def parameter_rows(target: ExportTarget) -> list[tuple[str, str, str, float]]:
    """The FMU parameters of a linear export: (name, unit, description, value), fixed.

    Parameters
    ----------
    target : ExportTarget
        A linear target.

    Returns
    -------
    list of tuple
        One per :data:`PARAMS`.
    """
    model = linear_model(target)
    values = (float(model.delay_s), float(model.position_delay_s))
    return [(n, u, d, v) for (n, u, d), v in zip(PARAMS, values, strict=True)]


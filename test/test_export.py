"""`ema export` and `ema verify` (issue 28): the C stages against their numba twins bit for bit, the kernel
against LOADA/LOADF's, the FMU validated and simulated by FMPy against `ema simulate`, the JSBSim system in
JSBSim, the sign and unit check on deliberately broken exports, and planted faults in a host's integration.

Every C file is compiled once per module (fixtures); maneuvers are short.
"""

from __future__ import annotations

import ctypes
import json
import math
import zipfile

import numpy as np
import pytest

from ema_sim import parameters as pm
from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.errors import EmaError
from ema_sim.export import csource, fmu, harness, jsbsim_system, lti
from ema_sim.export.artefacts import open_artefact
from ema_sim.export.cstages import STAGES
from ema_sim.export.diagnose import diagnose
from ema_sim.export.target import LINEAR, NOT_EXPORTABLE, ExportError, resolve
from ema_sim.export.verify import compare, sign_and_units, verify
from ema_sim.io.csv import write_csv
from ema_sim.io.measured import MeasuredData
from ema_sim.models import create
from ema_sim.models.second_order.figure26 import HISTORY_SIZE
from ema_sim.models.second_order.params import N_STATE, P, SecondOrderParams
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import simulate

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("jsbsim")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

N_CASES = 300
"""Random cases per stage."""
SHORT = [("steps:amps_deg=1/20,lead_s=0.1,hold_s=0.3", None),
         ("square:freq_hz=2,amp_deg=8,cycles=2,lead_s=0.1", "sine:amp_inlb=1500,freq_hz=1.5")]
"""Short maneuvers for the artefact runs."""


# ------------------------------------------------------------------------------------------ random values
FINITE: dict[str, tuple[float, float]] = {
    "wn_rad_s": (20.0, 150.0), "zeta": (0.3, 1.2), "rate_limit_dps": (20.0, 300.0), "k2_dps_per_lb": (0.0, 0.1),
    "moment_arm_in": (1.0, 3.0), "kb": (-0.05, 0.05), "offset_deg": (-0.05, 0.05), "quantization_deg": (0.001, 0.05),
    "free_play_deg": (0.01, 0.5), "surface_inertia_inlbs2": (1.0, 5.0), "kcp_per_kinlb": (-0.5, 0.5),
    "delay_s": (0.0, 0.02), "command_lag_hz": (5.0, 200.0), "feedback_lag_hz": (5.0, 200.0),
    "threshold_deg": (0.0, 0.1), "compliance_deg_per_kinlb": (0.0, 2.0), "lvdt_compliance_deg_per_kinlb": (0.0, 1.0),
    "hysteresis_h_lb_per_in": (10.0, 1e4), "hysteresis_freq_hz": (0.01, 1.0), "feedback_delay_s": (0.0005, 0.01),
    "feedback_filter_in_loop": (0.0, 1.0), "integral_hz": (0.01, 2.0), "servo_compliance_deg_per_kinlb": (0.0, 1.0),
    "accel_limit_dps2": (2e3, 1e5), "velocity_loop_hz": (20.0, 400.0), "linkage_freq_hz": (20.0, 100.0),
    "linkage_zeta": (0.05, 1.0), "compliance_knee_inlb": (50.0, 3000.0), "compliance_stiff_deg_per_kinlb": (0.0, 1.0),
    "lvdt_compliance_knee_inlb": (50.0, 3000.0), "lvdt_compliance_stiff_deg_per_kinlb": (0.0, 1.0),
}
"""Where a random parameter is drawn (inside its declared range; bounded where the range is not)."""


def random_params(rng: np.random.Generator, p_off: float = 0.4) -> SecondOrderParams:
    """Every parameter drawn at random, each switchable stage off with probability ``p_off``."""
    base = SecondOrderParams.from_channel(load_channel("left_wing"))
    values = {}
    for name, m in pm.metas(SecondOrderParams).items():
        if name in FINITE:
            lo, hi = FINITE[name]
            v = float(rng.uniform(lo, hi))
            if name == "feedback_filter_in_loop":
                v = float(rng.random() < 0.5)
            values[name] = m.off if (m.off is not None and rng.random() < p_off) else v
    values["position_min_deg"] = float(rng.uniform(-43.0, -5.0))
    values["position_max_deg"] = float(rng.uniform(5.0, 43.0))
    return base.replace(**values)


def special(rng: np.random.Generator, scale: float, size: int) -> np.ndarray:
    """Random values with exact zeros and repeats mixed in (the branches' edges)."""
    x = rng.normal(0.0, scale, size)
    x[rng.random(size) < 0.1] = 0.0
    return x


# ------------------------------------------------------------------------------------------ the C library
@pytest.fixture(scope="module")
def clib(tmp_path_factory):
    """Every stage and the kernel in one shared library (compiled once)."""
    d = tmp_path_factory.mktemp("clib")
    target = resolve("loada", "left_wing")
    csource.write_sources(d, target.values())
    lib = csource.compile_c([d / f for f in csource.SOURCES], d / "libema.so", shared=True, include=[d])
    return ctypes.CDLL(str(lib))


class Out:
    """An output argument of a C stage: ``n`` doubles, or ints."""

    def __init__(self, kind: str = "d", n: int = 1):
        self.kind, self.n = kind, n


class Long(int):
    """A C ``long`` argument."""


def ccall(lib, name, restype, *args):
    """Call a C stage: numbers by value, arrays by pointer to a copy, :class:`Out` as outputs.

    Returns the result, the outputs (a list each) and the arrays after the call.
    """
    cargs, outs, arrays = [], [], []
    for a in args:
        if isinstance(a, Out):
            buf = (ctypes.c_double * a.n)() if a.kind == "d" else (ctypes.c_int * a.n)()
            cargs.append(buf)
            outs.append(buf)
        elif isinstance(a, np.ndarray):
            buf = (ctypes.c_double * a.size)(*a.ravel().tolist())
            cargs.append(buf)
            arrays.append((buf, a.shape))
        elif isinstance(a, Long):
            cargs.append(ctypes.c_long(int(a)))
        elif isinstance(a, bool | int):
            cargs.append(ctypes.c_int(int(a)))
        else:
            cargs.append(ctypes.c_double(float(a)))
    fn = getattr(lib, name)
    fn.restype = restype
    ret = fn(*cargs)
    return ret, [list(o) for o in outs], [np.frombuffer(b, dtype=float).reshape(s).copy() for b, s in arrays]


D, INT, V = ctypes.c_double, ctypes.c_int, None


def _state(rng):
    y = rng.normal(0.0, 2.0, N_STATE)
    y[-2:] = 0.0
    return y


def _history(rng):
    hist = np.zeros((HISTORY_SIZE, 3))
    t = np.sort(rng.uniform(-0.05, 0.05, HISTORY_SIZE))
    hist[:, 0], hist[:, 1], hist[:, 2] = t, rng.normal(0, 1, HISTORY_SIZE), rng.normal(0, 50, HISTORY_SIZE)
    return hist


CASES: dict = {}
"""Stage name → ``(draw(rng) -> args, run(lib, args) -> (C's values, the numba twin's values))``."""


def case(name, draw):
    """Register the differential case of one C stage."""
    def register(run):
        CASES[name] = (draw, run)
        return run
    return register


def twin(name):
    """The numba function a C stage mirrors."""
    return next(s for s in STAGES if s.name == name).twin


def _u(rng):
    return float(special(rng, 5.0, 1)[0])


def _hm(rng):
    return float(special(rng, 800.0, 1)[0])


def _p(rng):
    return random_params(rng).kernel_vector()


def _dt(rng):
    return float(rng.uniform(1e-4, 0.01))


def _scalar(name, restype, draw):
    """A stage returning one number."""
    @case(name, draw)
    def run(lib, a):
        return [ccall(lib, name, restype, *a)[0]], [twin(name)(*a)]
    return run


_scalar("ema_quantize", D, lambda r: (_u(r), float(r.choice([0.0, 0.02, 0.005, -1.0, r.uniform(0, 0.1)]))))
_scalar("ema_lag_gain", D, lambda r: (float(r.choice([0.0, r.uniform(0, 500)])), _dt(r)))
_scalar("ema_first_order_lag", D, lambda r: (_u(r), _u(r), float(r.uniform(0, 1))))
_scalar("ema_band_side", INT, lambda r: (_u(r), float(r.choice([0.0, 1.0]))))
_scalar("ema_rate_loop", D, lambda r: (_u(r) * 50, _u(r) * 50, float(r.uniform(5, 500)), float(r.uniform(0.05, 3))))
_scalar("ema_free_play_accel", D, lambda r: (_hm(r), float(r.uniform(0.1, 10))))
_scalar("ema_command_error", D, lambda r: (_u(r), float(r.uniform(-0.5, 0.5)), float(r.uniform(-5, 5))))
_scalar("ema_compliance_correction", D, lambda r: (_u(r), _hm(r), float(r.choice([0.0, r.uniform(-1, 1)]))))
_scalar("ema_compliance_deflection", D, lambda r: (_hm(r), float(r.choice([0.0, r.uniform(0, 2)])),
                                                    float(r.choice([math.inf, r.uniform(1, 1000)])),
                                                    float(r.uniform(0, 1))))
_scalar("ema_command_path", D, lambda r: (_p(r), _u(r)))
_scalar("ema_surface_compliance", D, lambda r: (_p(r), _hm(r)))
_scalar("ema_drive_on", INT, lambda r: (_p(r),))
_scalar("ema_lvdt", D, lambda r: (_p(r), _u(r), _hm(r)))
_scalar("ema_actuator_position", D, lambda r: (_p(r), _u(r), _u(r) * 30))
_scalar("ema_compliance_time_constant_s", D, lambda r: (_p(r),))
_scalar("ema_free_play_subsystem", INT, lambda r: (_p(r),))
_scalar("ema_linkage_slope", D, lambda r: (_p(r), int(r.integers(0, 3))))
_scalar("ema_linkage_damping", D, lambda r: (_p(r),))
_scalar("ema_history_spacing_s", D, lambda r: (_p(r),))
_scalar("ema_compliance_gain", D, lambda r: (_p(r), _dt(r)))
_scalar("ema_linkage_rest", D, lambda r: (_p(r), _hm(r)))
_scalar("ema_linkage_accel", D, lambda r: (_p(r), _state(r), _hm(r), _u(r) * 100))


def _with_outputs(name, restype, draw, *outs):
    """A stage returning one number (or none) and writing ``outs``; its twin returns them as a tuple."""
    @case(name, draw)
    def run(lib, a):
        ret, values, _ = ccall(lib, name, restype, *a, *outs)
        got = ([] if restype is None else [ret]) + [v for vs in values for v in vs]
        want = twin(name)(*a)
        return got, list(np.ravel(want))
    return run


_with_outputs("ema_dead_zone", D, lambda r: (float(r.choice([_u(r), 0.5, -0.5])), 0.5), Out("i"))
_with_outputs("ema_oscillator_step", None, lambda r: (float(r.choice([0.0, r.uniform(0, 1e6), 2500.0])),
                                                      float(r.choice([0.0, r.uniform(0, 3000), 100.0])), _dt(r)),
              Out("d", 5))
_with_outputs("ema_load_rate_limits", None, lambda r: (float(r.uniform(1, 300)), float(r.uniform(0, 0.1)),
                                                       _hm(r) * 5, float(r.uniform(1, 3))), Out(), Out())
_with_outputs("ema_velocity_command", D, lambda r: (_u(r), _u(r), float(r.uniform(5, 500)), float(r.uniform(0.05, 3)),
                                                    float(r.uniform(0, 300)), float(r.uniform(0, 300))), Out("i"))
_with_outputs("ema_velocity_demand", D, lambda r: (_p(r), _u(r), _u(r), _u(r) * 0.1, _hm(r)),
              Out(), Out("i"), Out("i"), Out())
_with_outputs("ema_drive_step", D, lambda r: (_p(r), float(r.choice([0.0, _dt(r)]))), Out())
_with_outputs("ema_current_limited_drive", D, lambda r: (_p(r), _u(r) * 50, _u(r), _u(r) * 50,
                                                         float(r.uniform(10, 3000))), Out("i"))
_with_outputs("ema_servo", D, lambda r: (_p(r), _u(r), _u(r), _u(r) * 30, _state(r), _hm(r),
                                         float(r.choice([0.0, 1 / 800, 1 / 200]))), Out("i"), Out("i"), Out(), Out())
_with_outputs("ema_linkage_spring", D, lambda r: (_p(r), _u(r) * 0.5), Out("i"))
_with_outputs("ema_linkage_steps", None, lambda r: (_p(r), _dt(r)), Out("d", 18))
_with_outputs("ema_feedback_value", D, lambda r: (_p(r), _state(r), _hm(r)), Out())


@case("ema_limited_integrator", lambda r: (float(r.choice([_u(r), 1.0, -1.0])), _u(r), -1.0, 1.0))
def _limited_integrator(lib, a):
    ret, _, (x, v) = ccall(lib, "ema_limited_integrator", INT, np.array([a[0]]), np.array([a[1]]), a[2], a[3])
    x1, v1, at_stop = twin("ema_limited_integrator")(*a)
    return [ret, x[0], v[0]], [at_stop, x1, v1]


@case("ema_euler_pair", lambda r: (_u(r), _u(r), _u(r), _dt(r), bool(r.random() < 0.5)))
def _euler_pair(lib, a):
    _, _, (x, v) = ccall(lib, "ema_euler_pair", V, np.array([a[0]]), np.array([a[1]]), *a[2:])
    return [x[0], v[0]], list(twin("ema_euler_pair")(*a))


@case("ema_free_play_euler", lambda r: (float(r.choice([_u(r) * 0.05, 0.1, -0.1])), _u(r), _hm(r), _dt(r), 0.1,
                                        bool(r.random() < 0.5)))
def _free_play_euler(lib, a):
    _, _, (fp, v) = ccall(lib, "ema_free_play_euler", V, np.array([a[0]]), np.array([a[1]]), *a[2:])
    return [fp[0], v[0]], list(twin("ema_free_play_euler")(*a))


def _linkage_step_args(r):
    p = _p(r)
    p[P.linkage_freq_hz] = r.uniform(5, 100)
    return p, _state(r), _hm(r), _u(r) * 100, twin("ema_linkage_steps")(p, 1 / 800)


@case("ema_linkage_step", _linkage_step_args)
def _linkage_step(lib, a):
    _, (e, v), _ = ccall(lib, "ema_linkage_step", V, *a[:4], a[4].ravel(), Out(), Out())
    return [e[0], v[0]], list(twin("ema_linkage_step")(*a))


def _history_write_args(r):
    p = _p(r)
    p[P.feedback_delay_s] = float(r.choice([0.0, r.uniform(1e-3, 0.01)]))
    y = _state(r)
    y[-2] = float(r.integers(0, HISTORY_SIZE))
    y[-1] = float(r.uniform(-0.01, 0.01))
    t = float(y[-1] + r.choice([0.0, 1e-10, 1e-5, r.uniform(0, 0.01)]))
    return p, y, _history(r), t, _u(r), _u(r) * 30, bool(r.random() < 0.3)


@case("ema_history_write", _history_write_args)
def _history_write(lib, a):
    _, _, (_, y, hist) = ccall(lib, "ema_history_write", V, *a)
    y1, hist1 = a[1].copy(), a[2].copy()
    twin("ema_history_write")(a[0], y1, hist1, *a[3:])
    return [*y, *hist.ravel()], [*y1, *hist1.ravel()]


def _history_read_args(r):
    y = _state(r)
    y[-2] = float(r.integers(0, HISTORY_SIZE))
    hist = np.roll(_history(r), int(y[-2]) + 1, axis=0)
    return y, hist, float(r.uniform(-0.06, 0.06))


_scalar("ema_history_read", D, _history_read_args)


@case("ema_write_outputs", lambda r: (_p(r), _state(r), _u(r), _hm(r), int(r.integers(0, 32))))
def _write_outputs(lib, a):
    _, (row,), _ = ccall(lib, "ema_write_outputs", V, *a, Out("d", 6))
    row1 = np.zeros(6)
    twin("ema_write_outputs")(*a, row1)
    return row, list(row1)


@case("ema_trim", lambda r: (random_params(r).kernel_vector(), _u(r), _hm(r)))
def _trim(lib, a):
    _, _, (_, x, hist) = ccall(lib, "ema_trim", V, a[0], a[1], a[2], np.zeros(N_STATE), np.zeros((HISTORY_SIZE, 3)),
                               Long(HISTORY_SIZE))
    states, history = np.zeros((1, N_STATE)), np.zeros((1, HISTORY_SIZE, 3))
    twin("ema_trim")(a[0][None, :], np.array([a[1]]), np.array([a[2]]), states, history)
    return [*x, *hist.ravel()], [*states[0], *history[0].ravel()]


def test_every_c_stage_has_a_differential_test():
    assert sorted(CASES) == sorted(s.name for s in STAGES)


def same_bits(a, b) -> bool:
    """Equal as IEEE doubles: every bit, NaN payloads aside (and -0.0 told from 0.0)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both_nan = np.isnan(x) & np.isnan(y)
    return x.shape == y.shape and bool(np.all(both_nan | (x.view(np.int64) == y.view(np.int64))))


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_c_stage_is_its_numba_twin_bit_for_bit(clib, name):
    draw, run = CASES[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    n = N_CASES if name not in ("ema_history_write", "ema_history_read", "ema_trim") else 40
    for k in range(n):
        got, want = run(clib, draw(rng))
        assert same_bits(got, want), (name, k, got[:8], want[:8])


def _c_kernel(lib, p, rate, backward, cmd, hm):
    lib.ema_new.restype = ctypes.c_void_p
    lib.ema_new.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_double, ctypes.c_int, ctypes.c_double,
                            ctypes.c_double, ctypes.c_char_p, ctypes.c_size_t]
    lib.ema_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
    lib.ema_outputs.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    lib.ema_delete.argtypes = [ctypes.c_void_p]
    msg = ctypes.create_string_buffer(256)
    m = lib.ema_new((ctypes.c_double * len(p))(*p), rate, backward, cmd[0], hm[0], msg, 256)
    assert m, msg.value
    out, row = np.empty((cmd.size + 1, 6)), (ctypes.c_double * 6)()
    lib.ema_outputs(m, row)
    out[0] = row[:]
    for k in range(cmd.size):
        lib.ema_step(m, cmd[k], hm[k])
        lib.ema_outputs(m, row)
        out[k + 1] = row[:]
    lib.ema_delete(m)
    return out


@pytest.mark.parametrize(("name", "rate", "backward"), [("loada", 800.0, 0), ("loadf", 200.0, 1)])
def test_the_c_kernel_is_loada_and_loadf_bit_for_bit(clib, name, rate, backward):
    """Random parameter sets (every stage on or off at random, identification's included) and random inputs:
    the C model stepped once per input against the numba kernel run with a breakpoint per step."""
    rng = np.random.default_rng(28 + backward)
    n = int(1.5 * rate)
    dt = 1.0 / rate
    for trial in range(12):
        prm = random_params(rng, p_off=0.5)
        if backward:  # LOADF's look-ahead loop at 200 Hz needs a slower servo to stay bounded
            prm = prm.replace(wn_rad_s=float(rng.uniform(20, 60)), zeta=float(rng.uniform(0.5, 0.9)))
        levels = rng.normal(0.0, 3.0, 8)
        cmd = levels[np.minimum((np.arange(n) * 8) // n, 7)] + 0.5 * np.sin(np.arange(n) * dt * rng.uniform(1, 20))
        hm = rng.normal(0.0, 600.0) + 500.0 * np.sign(np.sin(np.arange(n) * dt * rng.uniform(1, 8)))
        model = create(name, "left_wing", params=prm)
        model.trim(cmd[0], hm[0])
        want = model.run_outputs(np.arange(n) * dt, cmd, hm, sample_times=np.arange(n + 1) * dt, end_s=n * dt)[0]
        got = _c_kernel(clib, prm.kernel_vector(), rate, backward, cmd, hm)
        assert np.all(np.isfinite(want[:, :3])), trial
        assert same_bits(got, want), (trial, np.max(np.abs(got - want), axis=0))


def test_the_c_model_rejects_a_parameter_outside_its_range(clib):
    p = resolve("loada").params.kernel_vector()
    p[P.zeta] = 7.0
    msg = ctypes.create_string_buffer(256)
    clib.ema_check_params.restype = ctypes.c_int
    assert clib.ema_check_params((ctypes.c_double * len(p))(*p), ctypes.c_double(800.0), msg, 256) == 1
    assert b"zeta" in msg.value


# ------------------------------------------------------------------------------------------ the FMU
@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """LOADA's and LOADF's FMUs for left_wing (built once)."""
    d = tmp_path_factory.mktemp("fmu")
    return {name: fmu.build_fmu(resolve(name, "left_wing"), d / f"{name}.fmu") for name in ("loada", "loadf")}


@pytest.mark.parametrize("name", ["loada", "loadf"])
def test_the_fmu_validates_clean(fmus, name):
    assert validate_fmu(str(fmus[name])) == []
    with zipfile.ZipFile(fmus[name]) as zf:
        names = zf.namelist()
    ident = f"ema_{name}_left_wing"
    assert f"binaries/linux64/{ident}.so" in names
    assert {"sources/ema_stages.c", "sources/ema_actuator.c", "sources/ema_fmi2.c", "sources/fmi2Functions.h"} <= \
        set(names)


def test_the_fmu_exposes_inputs_outputs_and_every_parameter_with_its_metadata(fmus):
    md = fmpy.read_model_description(str(fmus["loada"]))
    by = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["command_deg", "hinge_moment_inlb"]
    assert [v.name for v in md.modelVariables if v.causality == "output"] == ["position_deg", "surface_deg",
                                                                             "rate_dps", "flags"]
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    assert len(params) == len(P)
    assert by["wn_rad_s"].unit == "rad/s"
    assert float(by["wn_rad_s"].min) == 5.0
    assert float(by["wn_rad_s"].max) == 500.0
    assert by["delay_s"].unit == "s"
    assert float(by["delay_s"].start) == 0.004
    assert by["command_lag_hz"].min is not None
    assert float(by["command_lag_hz"].min) == 0.0
    assert float(md.defaultExperiment.stepSize) == 1.0 / 800.0
    assert md.coSimulation.canHandleVariableCommunicationStepSize is False


@pytest.mark.parametrize(("name", "rate"), [("loada", 800.0), ("loadf", 200.0)])
def test_simulate_fmu_is_ema_simulate_at_the_models_rate(fmus, name, rate):
    """FMPy's simulate_fmu against `ema simulate` (frame and sample rate the model's): within 1e-9° (measured: 0)."""
    man, load = "pid:sweep_s=2,gap_s=0.2,doublet_s=0.3", "sine:amp_inlb=1200,freq_hz=0.8"
    _, record, _ = simulate(name, parse_maneuver(man), parse_load(load), frame_hz=rate, sample_hz=rate)
    n = record.time_s.size - 1
    sig = np.zeros(n, dtype=[("time", float), ("command_deg", float), ("hinge_moment_inlb", float)])
    sig["time"] = np.arange(n) / rate
    sig["command_deg"] = record.command_deg[0, :n]
    sig["hinge_moment_inlb"] = record.hinge_moment_inlb[0, :n]
    res = fmpy.simulate_fmu(str(fmus[name]), stop_time=n / rate, output_interval=1.0 / rate, input=sig,
                            output=["position_deg", "surface_deg", "rate_dps", "flags"])
    assert res.size == n + 1
    for o in ("position_deg", "surface_deg", "rate_dps"):
        assert np.max(np.abs(res[o] - getattr(record, o)[0])) <= 1e-9, o
    assert np.array_equal(res["flags"], record.flags[0])


def test_the_fmu_refuses_a_step_that_is_not_the_models(fmus):
    with pytest.raises(FMICallException):
        fmpy.simulate_fmu(str(fmus["loada"]), stop_time=0.05, output_interval=1.0 / 200.0)


def test_the_fmu_takes_its_parameters_from_the_host(fmus, capsys):
    res = fmpy.simulate_fmu(str(fmus["loada"]), stop_time=0.5, output_interval=1.0 / 800.0,
                            start_values={"delay_s": 0.0, "quantization_deg": 0.0},
                            input=np.array([(0.0, 2.0, 0.0)], dtype=[("time", float), ("command_deg", float),
                                                                     ("hinge_moment_inlb", float)]))
    model = create("loada", "left_wing", delay_s=0.0, quantization_deg=0.0)
    model.trim(2.0, 0.0)
    want = model.run_outputs([0.0], [2.0], [0.0], sample_times=np.arange(401) / 800.0, end_s=0.5)[0]
    assert np.max(np.abs(res["position_deg"] - want[:, 0])) <= 1e-12
    capsys.readouterr()
    with pytest.raises(Exception, match="ExitInitializationMode"):
        fmpy.simulate_fmu(str(fmus["loada"]), stop_time=0.01, output_interval=1.0 / 800.0, start_values={"zeta": 9.0})
    assert "parameter zeta = 9 is outside its range [0.05, 3]" in capsys.readouterr().out


def test_verify_runs_the_fmu_against_the_truth(fmus):
    art = open_artefact(fmus["loadf"])
    result = verify(art, SHORT)
    assert result.passed
    assert result.tolerance_deg == 1e-9
    assert all(v == 0.0 for c in result.comparisons for v in c.max_abs_deg.values())


# ------------------------------------------------------------------------------------------ C export and JSBSim
@pytest.fixture(scope="module")
def c_export(tmp_path_factory):
    """LOADA's C export with a compiled harness (once)."""
    d = tmp_path_factory.mktemp("c") / "loada_c"
    harness.write_c(resolve("loada", "left_wing"), d)
    return d


def test_the_c_export_and_its_harness_are_the_truth(c_export):
    assert {"ema_actuator.h", "ema_stages.c", "ema_actuator.c", "ema_config.c", "ema_harness.c", "Makefile",
            "README.md", "ema_export.json"} <= {p.name for p in c_export.iterdir()}
    art = open_artefact(c_export)
    try:
        result = verify(art, SHORT)
    finally:
        art.close()
    assert result.passed, "\n".join(result.lines())


@pytest.mark.parametrize("name", ["loada", "loadf"])
def test_the_jsbsim_system_in_jsbsim_is_the_truth(tmp_path, name):
    """Every stage the system expresses is the kernel's step: measured bit for bit, with the report's stages
    and identification's lags, threshold, integral, droop and compliance curves on."""
    extra = {"integral_hz": 0.5, "kcp_per_kinlb": 0.3, "compliance_deg_per_kinlb": 0.5, "threshold_deg": 0.03,
             "command_lag_hz": 40.0, "feedback_lag_hz": 60.0, "servo_compliance_deg_per_kinlb": 0.2,
             "lvdt_compliance_deg_per_kinlb": 0.1,
             "hysteresis_h_lb_per_in": 3000.0, "compliance_knee_inlb": 800.0, "compliance_stiff_deg_per_kinlb": 0.1}
    target = resolve(name, "left_wing", overrides=extra)
    path = tmp_path / f"{name}.xml"
    path.write_text(jsbsim_system.system_xml(target))
    art = open_artefact(path)
    try:
        result = verify(art, SHORT)
    finally:
        art.close()
    assert art.not_expressed == []
    assert result.passed, "\n".join(result.lines())
    assert all(v == 0.0 for c in result.comparisons for v in c.max_abs_deg.values())


def test_a_stage_jsbsim_cannot_carry_is_listed_and_its_error_measured(tmp_path):
    target = resolve("loada", "left_wing", overrides={"feedback_delay_s": 0.004})
    path = tmp_path / "delayed.xml"
    path.write_text(jsbsim_system.system_xml(target))
    assert "feedback_delay_s" in path.read_text()
    art = open_artefact(path)
    try:
        result = verify(art, SHORT[:1])
    finally:
        art.close()
    assert art.not_expressed == ["feedback_delay_s"]
    assert result.tolerance_deg is None  # reported, not judged
    worst = result.comparisons[0].max_abs_deg
    assert 1e-3 < worst["position_deg"] < 1.0  # the LVDT read 4 ms late, missing
    assert worst["surface_deg"] == 0.0  # the surface does not see the feedback delay


# ------------------------------------------------------------------------------------------ broken exports
def test_a_flipped_hinge_moment_and_a_volt_command_fail_loudly(tmp_path, monkeypatch):
    """Section 4.4.1's fault planted in an export, and a ±10 V command taken for degrees: each named."""
    target = resolve("loada", "left_wing")
    good = csource.KERNEL
    faults = {"sign": good.replace("double hm = hinge_moment_inlb;", "double hm = -hinge_moment_inlb;"),
              "units": good.replace("m->bp_u[slot] = command_deg;", "m->bp_u[slot] = -0.23577 * command_deg;")}
    for fault, kernel in faults.items():
        assert kernel != good
        monkeypatch.setattr(csource, "KERNEL", kernel)
        d = tmp_path / fault
        harness.write_c(target, d)
        art = open_artefact(d)
        try:
            checks = {c.name: c for c in sign_and_units(art)}
        finally:
            art.close()
        failed = [c for c in checks.values() if not c.passed]
        assert failed, checks
        assert failed[0].fault == fault, failed[0]
        if fault == "sign":
            assert not checks["hinge moment"].passed
            assert "sign is flipped" in checks["hinge moment"].detail
        else:
            assert not checks["command"].passed
            assert "volts" in checks["command"].detail


def test_a_jsbsim_system_with_its_hinge_moment_reversed_fails(tmp_path):
    path = tmp_path / "flipped.xml"
    text = jsbsim_system.system_xml(resolve("loada", "left_wing", overrides={"compliance_deg_per_kinlb": 0.4}))
    path.write_text(text.replace("<property>ema/hinge-moment-inlb</property>",
                                 "<product><value>-1.0</value><property>ema/hinge-moment-inlb</property></product>"))
    art = open_artefact(path)
    try:
        hinge = sign_and_units(art)[1]
    finally:
        art.close()
    assert not hinge.passed
    assert hinge.fault == "sign"


# ------------------------------------------------------------------------------------------ a host's integration
def _host_record(*, hm_sign=1.0, cmd_scale=1.0, late_s=0.0, rate_hz=800.0):
    """What a host logged: the inputs it meant (the contract's columns) and what its integration read back."""
    t = np.arange(2400) / 1000.0
    cmd = np.where(t < 0.2, 0.0, np.where(t < 1.0, 2.0, np.where(t < 1.6, -6.0, 1.0)))
    hm = 1200.0 * np.sin(2 * np.pi * 1.3 * t)
    model = create("loada", "left_wing", rate_hz=rate_hz)
    model.trim(cmd[0] * cmd_scale, hm[0] * hm_sign)
    out = model.run_outputs(t, cmd * cmd_scale, hm * hm_sign, sample_times=t, end_s=float(t[-1]))[0]
    lag = round(late_s * 1000.0)
    pos = np.concatenate([np.full(lag, out[0, 0]), out[: t.size - lag, 0]])
    surf = np.concatenate([np.full(lag, out[0, 1]), out[: t.size - lag, 1]])
    return MeasuredData(time_s=t, command_deg=cmd, position_deg=pos, surface_deg=surf, hinge_moment_inlb=hm,
                        source="host.csv")


@pytest.mark.parametrize(("planted", "fault", "words"), [
    ({}, None, None),
    ({"hm_sign": -1.0}, "sign", "hinge moment reversed"),
    ({"cmd_scale": -0.23577}, "units", "command given in volts"),
    ({"late_s": 0.01}, "delay", "10 ms late"),
    ({"rate_hz": 200.0}, "rate", "200 Hz"),
])
def test_a_hosts_integration_is_judged_and_its_fault_named(planted, fault, words):
    found = diagnose(_host_record(**planted), resolve("loada", "left_wing"), tolerance_deg=1e-4)
    if fault is None:
        assert found.matches
        assert found.as_is.rms_deg < 1e-9
        return
    assert not found.matches
    assert found.fault is not None, found.lines()
    assert found.fault.fault == fault, found.lines()
    assert words in found.fault.detail


def test_verify_names_the_fault_of_a_host_csv(tmp_path, capsys):
    data = _host_record(hm_sign=-1.0)
    path = tmp_path / "host.csv"
    write_csv(path, {"time_s": data.time_s, "command_deg": data.command_deg, "position_deg": data.position_deg,
                     "surface_deg": data.surface_deg, "hinge_moment_inlb": data.hinge_moment_inlb},
              {"channel": "left_wing"})
    assert main(["verify", str(path), "--model", "loada"]) == 1
    out = capsys.readouterr().out
    assert "likely fault: sign: the hinge moment reversed" in out


# ------------------------------------------------------------------------------------------ what is exported
def _report(tmp_path, final, baseline="second_order", channel="left_wing"):
    path = tmp_path / "report.json"
    path.write_text(json.dumps({"channel": channel, "baseline": {"model": baseline}, "final": final}))
    return path


def test_an_identification_reports_final_model_is_exported_with_its_fitted_values(tmp_path):
    """The vocabulary's names and units back to the model's: K2 per 1000 in·lb to per lbf at the moment arm."""
    path = _report(tmp_path, {
        "model": "second_order + time_delay + rate_limit + command_lag", "hinge_moment_reversed": True,
        "params": {"wn_rad_s": 61.0, "zeta": 0.7, "delay_s": 0.006, "rate_dps": 110.0, "dps_per_kinlb": 20.0,
                   "corner_hz": 35.0},
        "fields": {"wn_rad_s": "wn_rad_s", "zeta": "zeta", "delay_s": "delay_s", "rate_dps": "rate_limit_dps",
                   "dps_per_kinlb": "k2_dps_per_lb", "corner_hz": "command_lag_hz"}})
    target = resolve(str(path))
    marm = load_channel("left_wing").crank_arm_in
    assert (target.model, target.truth, target.rate_hz) == ("loada", "second_order", 800.0)
    assert target.params.k2_dps_per_lb == pytest.approx(20.0 * marm / 1000.0)
    assert target.params.command_lag_hz == 35.0
    assert target.params.delay_s == 0.006
    assert target.params.quantization_deg == 0.0  # second_order's basic model: its other stages off
    assert any("reversed" in n for n in target.notes)
    art_path = tmp_path / "r.xml"
    art_path.write_text(jsbsim_system.system_xml(target))
    art = open_artefact(art_path)
    try:
        comparison = compare(art, "steps:amps_deg=1,lead_s=0.1,hold_s=0.3")
    finally:
        art.close()
    assert comparison.max_abs_deg["position_deg"] < 0.2  # LOADA's Euler against the continuous fit: measured


@pytest.mark.parametrize(("final", "words"), [
    ({"model": "second_order + discovered: sign(rate) (position) inside the loop", "params": {}}, "discovered"),
    ({"model": "hoad3 (physical parameters fitted)", "params": {}, "curves": {}}, "high-order"),
])
def test_a_final_model_without_a_c_stage_is_refused(tmp_path, final, words):
    with pytest.raises(ExportError, match=words):
        resolve(str(_report(tmp_path, final)))


@pytest.mark.parametrize("name", ["hoac1"])
def test_a_model_not_exportable_says_why_in_one_line(tmp_path, capsys, name):
    assert main(["export", name, "--c", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "not exportable" in err
    with pytest.raises(EmaError):
        resolve(name)


def test_the_cli_exports_and_verifies(tmp_path, capsys):
    xml = tmp_path / "loada.xml"
    assert main(["export", "loada", "--channel", "right_rudder", "--set", "delay_s=0.006", "--jsbsim", str(xml)]) == 0
    assert main(["verify", str(xml), "--maneuver", "steps:amps_deg=1,lead_s=0.1,hold_s=0.2",
                 "--json", str(tmp_path / "v.json")]) == 0
    report = json.loads((tmp_path / "v.json").read_text())
    assert report["passed"]
    assert report["channel"] == "right_rudder"
    assert report["model"] == "loada"
    assert main(["verify", str(xml), "--channel", "left_wing"]) == 2
    assert "right_rudder" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------ linear models
@pytest.fixture(scope="module")
def linear_exports(tmp_path_factory):
    """LOES's, HOALM's and SLOAC's FMUs and C exports for left_wing (built once)."""
    d = tmp_path_factory.mktemp("linear")
    out = {}
    for name in LINEAR:
        target = resolve(name, "left_wing")
        harness.write_c(target, d / f"{name}_c")
        out[name] = (fmu.build_fmu(target, d / f"{name}.fmu"), d / f"{name}_c")
    return out


@pytest.mark.parametrize("name", LINEAR)
def test_a_linear_models_fmu_and_c_are_its_zoh_kernel_bit_for_bit(linear_exports, name):
    """The state space, the delay lines and the sampling of run_lti: every difference 0, the checks passed."""
    path, c_dir = linear_exports[name]
    assert validate_fmu(str(path)) == []
    assert name not in NOT_EXPORTABLE
    for where in (path, c_dir):
        art = open_artefact(where)
        try:
            assert art.target.model == art.target.truth == name
            result = verify(art, SHORT[1:])
        finally:
            art.close()
        assert result.passed, "\n".join(result.lines())
        assert result.tolerance_deg == 1e-9
        assert all(v == 0.0 for c in result.comparisons for v in c.max_abs_deg.values()), "\n".join(result.lines())


def test_a_linear_fmu_declares_its_delays_fixed_and_refuses_another_value(linear_exports, capsys):
    path, _ = linear_exports["hoalm"]
    md = fmpy.read_model_description(str(path))
    params = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    assert set(params) == {"delay_s", "position_delay_s"}
    assert all(v.variability == "fixed" for v in params.values())
    assert float(params["delay_s"].start) == 0.004
    assert float(params["position_delay_s"].start) == 0.002
    assert float(md.defaultExperiment.stepSize) == 1e-4
    capsys.readouterr()
    with pytest.raises(Exception, match="ExitInitializationMode"):
        fmpy.simulate_fmu(str(path), stop_time=0.01, output_interval=1e-4, start_values={"delay_s": 0.01})
    assert "export the model again" in capsys.readouterr().out


def test_a_linear_models_delays_are_whole_steps_as_the_kernel_reads_them():
    assert lti.delay_steps(0.004, 1e-4) == 40
    assert lti.delay_steps(0.0, 1e-4) == 0
    assert lti.delay_steps(0.00852325, 1e-4) == 86  # the latest breakpoint at or before k·dt − delay
    assert lti.delay_steps(0.00123, 1.0 / 3000.0) == 4


def test_a_linear_model_has_no_jsbsim_system_and_says_why(tmp_path, capsys):
    assert main(["export", "loes", "--jsbsim", str(tmp_path / "loes.xml"), "--c", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "no discrete state-space component" in err
    assert not (tmp_path / "loes.xml").exists()
    with pytest.raises(ExportError, match="no JSBSim system"):
        jsbsim_system.system_xml(resolve("sloac"))


def test_a_linear_models_overrides_and_rate_reach_its_truth(tmp_path):
    target = resolve("loes", "left_wing", rate_hz=3000.0, overrides={"delay_s": 0.00123})
    assert target.truth_model().delay_s == 0.00123
    harness.write_c(target, tmp_path / "c")
    art = open_artefact(tmp_path / "c")
    try:
        assert art.target.options == {"delay_s": 0.00123}
        assert art.rate_hz == 3000.0
        result = verify(art, [("hold:value_deg=2,hold_s=0.2", None), SHORT[0]])
    finally:
        art.close()
    assert result.passed, "\n".join(result.lines())
    with pytest.raises(ExportError, match="unknown LOES parameter"):
        resolve("loes", overrides={"nope": 1.0})

"""HOAD2 and HOAD3 exported: every C stage against its numba twin bit for bit, the C kernel against the numba kernel
(reversing loads, stops, stick-slip, power cycles and the brake, noise on), the FMU validated by FMPy and simulated
against `ema simulate`, the C export and the FMU through `ema verify`, and the CLI.

The C library and the FMUs are built once per module (fixtures); records are short.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from ema_sim.cli import main
from ema_sim.errors import EmaError
from ema_sim.export import csource, fmu, harness, hoad_c
from ema_sim.export.artefacts import open_artefact
from ema_sim.export.hoad_stages import STAGES
from ema_sim.export.target import NOT_EXPORTABLE, resolve
from ema_sim.export.verify import DEFAULT_MANEUVERS, maneuver_inputs, verify
from ema_sim.models import create
from ema_sim.models import noise as nz
from ema_sim.models.high_order.params import P
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import simulate

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

N_CASES = 300
"""Random cases per stage."""
CHANNELS = ("left_wing", "right_wing", "left_rudder", "right_rudder")
DT = 1e-4
"""The high-order models' step (10 kHz)."""


def same_bits(a, b) -> bool:
    """Equal as IEEE doubles: every bit (NaN payloads aside, -0.0 told from 0.0)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both_nan = np.isnan(x) & np.isnan(y)
    return x.shape == y.shape and bool(np.all(both_nan | (x.view(np.int64) == y.view(np.int64))))


# ------------------------------------------------------------------------------------------ the C library
def _values(name="hoad3", channel="left_wing", **options):
    target = resolve(name, channel, overrides=options or None)
    return hoad_c.target_values(target)


def _compile(d, channel):
    hoad_c.write_sources(d, _values("hoad3", channel))
    lib = csource.compile_c([d / f for f in hoad_c.SOURCES], d / "libhoad.so", shared=True, include=[d])
    return ctypes.CDLL(str(lib))


@pytest.fixture(scope="module")
def clib(tmp_path_factory):
    """Every stage and the kernel in one shared library (compiled once)."""
    return _compile(tmp_path_factory.mktemp("hoad_clib"), "left_wing")


@pytest.fixture(scope="module")
def channel_libs(tmp_path_factory):
    """The kernel of each channel (its command calibration is the export's), compiled on first use."""
    libs: dict = {}

    def get(channel):
        if channel not in libs:
            libs[channel] = _compile(tmp_path_factory.mktemp(f"hoad_{channel}"), channel)
        return libs[channel]

    return get


class Out:
    """An output argument of a C stage: ``n`` doubles (``d``), ints (``i``) or longs (``l``)."""

    def __init__(self, kind="d", n=1):
        self.kind, self.n = kind, n


class Long(int):
    """A C ``long`` argument."""


class U64(int):
    """A C ``uint64_t`` argument."""


class State:
    """A ``uint64_t *`` generator state, read back after the call."""

    def __init__(self, value):
        self.value = int(value)


def ccall(lib, name, restype, *args):
    """Call a C stage: numbers by value, arrays by pointer, :class:`Out` and :class:`State` as outputs."""
    cargs, outs = [], []
    for a in args:
        if isinstance(a, Out):
            ctype = {"d": ctypes.c_double, "i": ctypes.c_int, "l": ctypes.c_long}[a.kind]
            buf = (ctype * a.n)()
            cargs.append(buf)
            outs.append(buf)
        elif isinstance(a, State):
            buf = (ctypes.c_uint64 * 1)(a.value)
            cargs.append(buf)
            outs.append(buf)
        elif isinstance(a, np.ndarray):
            cargs.append((ctypes.c_double * a.size)(*a.ravel().tolist()))
        elif isinstance(a, U64):
            cargs.append(ctypes.c_uint64(int(a)))
        elif isinstance(a, Long):
            cargs.append(ctypes.c_long(int(a)))
        elif isinstance(a, bool | int):
            cargs.append(ctypes.c_int(int(a)))
        else:
            cargs.append(ctypes.c_double(float(a)))
    fn = getattr(lib, name)
    fn.restype = restype
    return fn(*cargs), [list(o) for o in outs]


D, INT, LONG, U64T = ctypes.c_double, ctypes.c_int, ctypes.c_long, ctypes.c_uint64
CASES: dict = {}
"""Stage name → ``(draw(rng) -> args, run(lib, args) -> (C's values, the twin's values))``."""


def case(name, draw):
    """Register the differential case of one C stage."""
    def register(run):
        CASES[name] = (draw, run)
        return run
    return register


def twin(name):
    """The numba (or Python) function a C stage mirrors."""
    return next(s for s in STAGES if s.name == name).twin


def _x(rng, scale=1.0):
    """A random number with exact zeros mixed in (the branches' edges)."""
    return 0.0 if rng.random() < 0.1 else float(rng.normal(0.0, scale))


def _pos(rng, lo, hi):
    return float(rng.uniform(lo, hi))


BASE_VECTORS: list[np.ndarray] = []
"""Kernel vectors of HOAD2 and HOAD3 on every channel (figure 36 on and off), drawn from by the stage cases."""


def _p(rng):
    if not BASE_VECTORS:
        for ch in CHANNELS:
            BASE_VECTORS.append(create("hoad2", ch)._P[0].copy())
            BASE_VECTORS.append(create("hoad3", ch)._P[0].copy())
            BASE_VECTORS.append(create("hoad3", ch, hysteresis=True, bound="upper")._P[0].copy())
    p = BASE_VECTORS[rng.integers(len(BASE_VECTORS))].copy()
    scale = rng.uniform(0.7, 1.3, p.size)
    keep = [P.figure33, P.feedback_cal_c0_deg, P.feedback_cal_c1_deg_per_v, P.feedback_cal_c2_deg_per_v2,
            P.feedback_cal_c3_deg_per_v3, P.position_min_in, P.position_max_in]
    scale[keep] = 1.0
    p *= scale
    for slot in (P.quantization_v, P.command_noise_v, P.feedback_noise_v, P.half_backlash_in,
                 P.position_integral_per_s2, P.hysteresis_coefficient_s, P.pwm_dead_band_v):
        if rng.random() < 0.3:
            p[slot] = 0.0
    return p


def _cal(rng):
    ch = create("hoad3", CHANNELS[rng.integers(len(CHANNELS))]).channel
    c = ch.command_cal
    return (c.c0, c.c1, c.c2, c.c3)


def _scalar(name, restype, draw):
    """A stage returning one number."""
    @case(name, draw)
    def run(lib, a):
        return [ccall(lib, name, restype, *a)[0]], [twin(name)(*a)]
    return run


_scalar("ema_quantize", D, lambda r: (_x(r, 5.0), float(r.choice([0.0, 0.005, -1.0, r.uniform(0, 0.1)]))))
_scalar("ema_band_side", INT, lambda r: (_x(r), float(r.choice([0.0, 1.0, r.uniform(0, 2)]))))
_scalar("ema_cubic", D, lambda r: (*_cal(r), _x(r, 20.0)))
_scalar("ema_cubic_slope", D, lambda r: (*_cal(r), _x(r, 20.0)))
_scalar("ema_cubic_inverse", D, lambda r: (*_cal(r), _x(r, 5.0), float(r.choice([0.0, 1e-15]))))
_scalar("ema_saturate", D, lambda r: (_x(r, 3.0), _pos(r, 0, 3), int(r.integers(-1, 2))))
_scalar("ema_pwm_segment", INT, lambda r: (_x(r, 100.0), float(r.choice([0.0, r.uniform(0, 5)])), _pos(r, 10, 150)))
_scalar("ema_pwm", D, lambda r: (_x(r, 100.0), float(r.choice([0.0, r.uniform(0, 5)])), _pos(r, 10, 150),
                                 int(r.integers(-2, 3))))
_scalar("ema_position_loop", D, lambda r: (_x(r), _x(r), _pos(r, 1, 100), _x(r)))
_scalar("ema_integrating", INT, lambda r: tuple(int(v) for v in r.integers(-2, 3, 3)))
_scalar("ema_velocity_loop", D, lambda r: (_x(r, 5.0), _x(r, 5.0), _pos(r, 0.1, 20)))
_scalar("ema_current_loop", D, lambda r: (_x(r, 10.0), _x(r, 10.0), _x(r, 5.0), _pos(r, 0, 20), _pos(r, 0.1, 2),
                                          _pos(r, 0.1, 30)))
_scalar("ema_drive_flags", INT, lambda r: (int(r.integers(-1, 2)), int(r.integers(-1, 2)), int(r.integers(-2, 3)),
                                           _x(r)))
_scalar("ema_motor_current_step", D, lambda r: (_x(r, 100.0), _x(r, 10.0), _x(r, 5.0), _pos(r, 0.5, 2),
                                                _pos(r, 1, 30), _pos(r, 0, 1)))
_scalar("ema_bus_current", D, lambda r: (_x(r, 100.0), _x(r, 10.0), _pos(r, 100, 190)))
_scalar("ema_bus_voltage_step", D, lambda r: (_pos(r, 100, 190), _x(r, 10.0), 150.0, _pos(r, 0.01, 2), _pos(r, 0, 1)))
_scalar("ema_steady_bus_voltage", D, lambda r: (150.0, _pos(r, 0.01, 2), float(r.choice([_x(r, 2000.0), 1e5]))))
_scalar("ema_lvdt_fig32", D, lambda r: (_x(r), _x(r, 500.0), _pos(r, 1e4, 1e6)))
_scalar("ema_hysteretic_damping", D, lambda r: (_pos(r, 0, 1e-3), _pos(r, 1e3, 1e5)))
_scalar("ema_three_segment_deflection", D, lambda r: (_x(r, 600.0), 25.0, 342.6, 25.0 / 8272.0,
                                                      25.0 / 8272.0 + 317.6 / 36348.0, 1 / 8272.0, 1 / 36348.0,
                                                      1 / 70000.0))
_scalar("ema_lvdt_fig33", D, lambda r: (_x(r), _x(r, 600.0), 50.0, 400.0, 50.0 / 2e4, 50.0 / 2e4 + 350 / 6e4,
                                        1 / 2e4, 1 / 6e4, 1 / 1e5))
_scalar("ema_total_deflection", D, lambda r: (_p(r), _x(r, 600.0)))
_scalar("ema_actuator_deflection", D, lambda r: (_p(r), _x(r, 600.0)))
_scalar("ema_feedback_deg", D, lambda r: (_p(r), _x(r, 0.5), _x(r, 0.003)))


@case("ema_friction_step", lambda r: (float(r.choice([0.0, _x(r, 2.0), 1e-7])), _x(r, 300.0), _pos(r, 0, 50),
                                      _pos(r, 50, 80), _pos(r, 1e-5, 1e-2), float(r.choice([0.0, r.uniform(0, 3)]))))
def _friction(lib, a):
    return [ccall(lib, "ema_friction_step", D, *a)[0]], [twin("ema_friction_step")(*a)]


@case("ema_splitmix64", lambda r: (int(r.integers(0, 2**63)),))
def _splitmix(lib, a):
    got = ccall(lib, "ema_splitmix64", U64T, U64(a[0]))[0]
    return [float(got >> 11)], [float(int(twin("ema_splitmix64")(a[0])) >> 11)]


def _draws(lib, name, seed, n):
    """``n`` draws of a generator stage from one state, both sides: the draws and the states."""
    state = int(nz.splitmix64(seed))
    c_state = State(state)
    c_out, c_states = [], []
    for _ in range(n):
        ret, outs = ccall(lib, name, D if name != "ema_next_u64" else U64T, c_state)
        c_state.value = outs[0][0]
        c_out.append(float(ret >> 11) if name == "ema_next_u64" else ret)
        c_states.append(float(c_state.value >> 11))
    py_state = np.array([state], dtype=np.uint64)
    py_out, py_states = [], []
    for _ in range(n):
        v = twin(name)(py_state)
        py_out.append(float(int(v) >> 11) if name == "ema_next_u64" else v)
        py_states.append(float(int(py_state[0]) >> 11))
    return [*c_out, *c_states], [*py_out, *py_states]


for _name in ("ema_next_u64", "ema_uniform", "ema_normal"):
    case(_name, lambda r: (int(r.integers(0, 2**62)),))(
        lambda lib, a, _n=_name: _draws(lib, _n, a[0], 60))


@case("ema_band_limited_step", lambda r: (_x(r, 0.003), float(r.choice([0.0, r.uniform(0, 1)])),
                                          float(r.choice([0.0, r.uniform(0, 0.003)])), int(r.integers(0, 2**62))))
def _band(lib, a):
    state = int(nz.splitmix64(a[3]))
    ret, outs = ccall(lib, "ema_band_limited_step", D, a[0], a[1], a[2], State(state))
    py_state = np.array([state], dtype=np.uint64)
    want = twin("ema_band_limited_step")(a[0], a[1], a[2], py_state)
    return [ret, float(outs[0][0] >> 11)], [want, float(int(py_state[0]) >> 11)]


def _servo_args(r):
    return (_pos(r, 1, 100), _pos(r, 0.5, 5), _pos(r, 0.1, 20), _pos(r, 5, 30), _pos(r, 0, 20), _pos(r, 0.5, 2),
            _pos(r, 1, 30), float(r.choice([0.0, r.uniform(0, 5)])), _pos(r, 0.5, 1), _x(r), _x(r), _x(r, 0.5),
            _x(r, 3), _x(r, 10), _pos(r, 100, 190), int(r.integers(-1, 2)), int(r.integers(-1, 2)),
            int(r.integers(-2, 3)), bool(r.random() < 0.5))


@case("ema_servo_drive", _servo_args)
def _servo(lib, a):
    _, outs = ccall(lib, "ema_servo_drive", None, *a, Out("d", 4), Out("i", 3))
    return [*outs[0], *outs[1]], list(twin("ema_servo_drive")(*a))


@case("ema_gear_train_fig32", lambda r: (_x(r, 0.01), _x(r), float(r.choice([0.0, r.uniform(0, 0.003)])),
                                         _pos(r, 1e4, 1e6), _pos(r, 0, 50), int(r.integers(-1, 2))))
def _fig32(lib, a):
    ret, outs = ccall(lib, "ema_gear_train_fig32", D, *a, Out())
    return [ret, outs[0][0]], list(twin("ema_gear_train_fig32")(*a))


def _segment_args(r):
    f1, f2 = sorted(r.uniform(5, 500, 2))
    k1, k2, k3 = r.uniform(1e3, 1e5, 3)
    d1 = f1 / k1
    return (float(r.choice([_x(r, 0.02), d1, -d1])), float(f1), float(f2), float(d1), float(d1 + (f2 - f1) / k2),
            float(k1), float(k2), float(k3))


@case("ema_three_segment_force", _segment_args)
def _three(lib, a):
    ret, outs = ccall(lib, "ema_three_segment_force", D, *a, Out(), Out("i"))
    return [ret, outs[0][0], outs[1][0]], list(twin("ema_three_segment_force")(*a))


@case("ema_total_force", lambda r: (_p(r), _x(r, 0.02)))
def _total(lib, a):
    ret, outs = ccall(lib, "ema_total_force", D, *a, Out(), Out("i"))
    return [ret, outs[0][0], outs[1][0]], list(twin("ema_total_force")(*a))


@case("ema_gear_train", lambda r: (_p(r), _x(r, 0.5), _x(r, 0.5)))
def _gear(lib, a):
    ret, outs = ccall(lib, "ema_gear_train", D, *a, Out(), Out(), Out("i"))
    return [ret, outs[0][0], outs[1][0], outs[2][0]], list(twin("ema_gear_train")(*a))


@case("ema_command_in", lambda r: (_p(r), *_cal(r), _x(r, 15.0)))
def _command(lib, a):
    ret, outs = ccall(lib, "ema_command_in", D, *a, Out())
    x, s = np.empty((1, 1)), np.empty((1, 1))
    twin("ema_command_in")(a[0][None, :], *a[1:5], np.array([[a[5]]]), x, s)
    return [ret, outs[0][0]], [x[0, 0], s[0, 0]]


@case("ema_split_delay", lambda r: (float(r.choice([0.0, 0.004, 0.002, 0.0021, r.uniform(0, 0.01)])),
                                    float(r.choice([1e-4, r.uniform(1e-5, 1e-3)]))))
def _split(lib, a):
    ret, outs = ccall(lib, "ema_split_delay", LONG, *a, Out())
    return [float(ret), outs[0][0]], [float(v) for v in twin("ema_split_delay")(*a)]


@case("ema_positions_from_lvdt", lambda r: (_p(r), _x(r, 0.5), _x(r, 600.0)))
def _positions(lib, a):
    _, outs = ccall(lib, "ema_positions_from_lvdt", None, *a, Out(), Out())
    return [outs[0][0], outs[1][0]], list(twin("ema_positions_from_lvdt")(*a))


@case("ema_at_stop", lambda r: (_p(r), _x(r, 0.5), _x(r, 0.5), _x(r, 600.0)))
def _stop(lib, a):
    _, outs = ccall(lib, "ema_at_stop", None, *a, Out(), Out(), Out())
    return [o[0] for o in outs], list(twin("ema_at_stop")(*a))


@case("ema_equilibrium", lambda r: (_p(r), _x(r, 0.6), float(r.choice([_x(r, 1500.0), 5e4, -5e4])),
                                    bool(r.random() < 0.8)))
def _equilibrium(lib, a):
    _, outs = ccall(lib, "ema_equilibrium", None, *a, Out("d", 6), Out("i"), Out("i"))
    eq = twin("ema_equilibrium")(*a)
    return [*outs[0], outs[1][0], outs[2][0]], [eq[k] for k in ("xm", "xs", "cur", "lf", "vbus", "xi", "motor",
                                                                "flags")]


def test_every_c_stage_has_a_differential_test():
    assert sorted(CASES) == sorted(s.name for s in STAGES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_c_stage_is_its_numba_twin_bit_for_bit(clib, name):
    draw, run = CASES[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    for k in range(N_CASES):
        got, want = run(clib, draw(rng))
        assert same_bits(got, want), (name, k, got[:8], want[:8])


# ------------------------------------------------------------------------------------------ the whole kernel
class CModel:
    """The C kernel through ctypes: trim, frames, power."""

    def __init__(self, lib, p, cmd0, hm0, seed):
        lib.ema_new_seeded.restype = ctypes.c_void_p
        lib.ema_new_seeded.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_double, ctypes.c_int,
                                       ctypes.c_double, ctypes.c_double, ctypes.c_longlong, ctypes.c_char_p,
                                       ctypes.c_size_t]
        lib.ema_advance.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_long]
        lib.ema_set_power.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.ema_outputs.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
        lib.ema_delete.argtypes = [ctypes.c_void_p]
        self.lib = lib
        msg = ctypes.create_string_buffer(256)
        self.m = lib.ema_new_seeded((ctypes.c_double * len(p))(*p), 1.0 / DT, 0, cmd0, hm0, seed, msg, 256)
        assert self.m, msg.value
        self.row = (ctypes.c_double * 6)()

    def outputs(self):
        self.lib.ema_outputs(self.m, self.row)
        return list(self.row)

    def frame(self, cmd, hm, steps):
        self.lib.ema_advance(self.m, cmd, hm, steps)
        return self.outputs()

    def power(self, on):
        self.lib.ema_set_power(self.m, int(on))

    def close(self):
        self.lib.ema_delete(self.m)


SCENARIOS = ("reversing load", "stops", "stick-slip", "power cycles and brake")


def _scenario(rng, kind, n):
    """Command, hinge moment and power per frame for one kind of record."""
    k = np.arange(n)
    levels = rng.normal(0.0, 4.0, 6)
    cmd = levels[np.minimum(k * 6 // n, 5)] + 0.3 * np.sin(k * rng.uniform(0.002, 0.05))
    hm = np.full(n, rng.normal(0.0, 300.0))
    power = np.ones(n)
    if kind == "reversing load":
        hm = 1500.0 * np.sign(np.sin(k * rng.uniform(0.003, 0.02))) + rng.normal(0, 50.0, n)
    elif kind == "stops":
        cmd = np.where(k < n // 2, 60.0, -60.0) * rng.choice([1.0, -1.0])
        hm = rng.uniform(-3000, 3000) * np.ones(n)
    elif kind == "stick-slip":
        cmd = 0.02 * np.sin(k * rng.uniform(0.002, 0.01)) + 0.05 * np.floor(k / rng.integers(50, 200))
        hm = rng.normal(0.0, 100.0) + 50.0 * np.sin(k * 0.01)
    else:
        power[(k > n // 4) & (k < n // 2)] = 0.0
        power[k > 3 * n // 4] = 0.0
        hm = 2500.0 * np.sin(k * rng.uniform(0.005, 0.02))
    return cmd, hm, power


def _random_model(rng, name, channel):
    """A high-order model with random environment, friction and options (noise on or off, a random seed)."""
    overrides = {
        "command_delay_s": float(rng.choice([0.0, 0.004, rng.uniform(0, 0.006)])),
        "feedback_delay_s": float(rng.choice([0.0, 0.002, rng.uniform(0, 0.004)])),
        "quantization_v": float(rng.choice([0.0, 0.005])),
        "command_noise_v": float(rng.choice([0.0, 0.001, 0.003])),
        "feedback_noise_v": float(rng.choice([0.0, 0.002])),
        "noise_bandwidth_hz": float(rng.choice([0.0, 500.0, 2000.0])),
    }
    base = create(name, channel)
    prm = base.params[0]
    stiction = float(prm.stiction_lbf * rng.uniform(0.5, 4.0))
    overrides.update(stiction_lbf=stiction, coulomb_friction_lbf=float(stiction * rng.uniform(0.3, 1.0)),
                     hinge_friction_inlb=float(prm.hinge_friction_inlb * rng.uniform(0.0, 3.0)),
                     position_integral_per_s2=float(prm.position_integral_per_s2 * rng.choice([0.0, 1.0, 2.0])))
    options = {"noise": bool(rng.random() < 0.7), "seed": int(rng.integers(0, 1000))}
    if name == "hoad3":
        options.update(hysteresis=bool(rng.random() < 0.5), bound=float(rng.choice([-1.0, 0.0, 0.5, 1.0])))
    return create(name, channel, params=prm.replace(**overrides), **options), options["seed"]


@pytest.mark.parametrize("name", ["hoad2", "hoad3"])
@pytest.mark.parametrize("kind", SCENARIOS)
def test_the_c_kernel_is_the_numba_kernel_bit_for_bit(channel_libs, name, kind):
    """Random parameters, options and frames of 1 to 25 steps: the C model frame by frame against the numba
    model stepped frame by frame (its power switched at the same frames): every output, every frame, every bit."""
    rng = np.random.default_rng(sum(map(ord, name + kind)))
    for trial in range(3):
        channel = CHANNELS[(trial + len(kind)) % len(CHANNELS)]
        model, seed = _random_model(rng, name, channel)
        steps = int(rng.choice([1, 10, 7, 25]))
        n = int(0.8 / (steps * DT))
        cmd, hm, power = _scenario(rng, kind, n)
        model.trim(cmd[0], hm[0])
        c = CModel(channel_libs(channel), model._P[0], cmd[0], hm[0], seed)
        try:
            want, got = [], []
            for k in range(n):
                if k == 0 or power[k] != power[k - 1]:
                    model.set_power(bool(power[k]))
                    c.power(power[k])
                want.append(model.step_values(float(cmd[k]), float(hm[k]), steps * DT))
                got.append(c.frame(cmd[k], hm[k], steps))
        finally:
            c.close()
        want_a, got_a = np.array(want), np.array(got)
        assert np.all(np.isfinite(want_a[:, :3])), (kind, trial)
        assert same_bits(got_a, want_a), (kind, trial, steps, np.max(np.abs(got_a - want_a), axis=0))


def test_the_c_model_rejects_a_parameter_outside_its_range(clib):
    p = _values().vector.copy()
    p[P.pwm_max_duty_ratio] = 1.5
    msg = ctypes.create_string_buffer(256)
    clib.ema_check_params.restype = ctypes.c_int
    assert clib.ema_check_params((ctypes.c_double * len(p))(*p), ctypes.c_double(1e4), msg, 256) == 1
    assert b"pwm_max_duty_ratio = 1.5 is outside its range (0, 1]" in msg.value


# ------------------------------------------------------------------------------------------ the FMU
@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """HOAD2's and HOAD3's FMUs for left_wing (built once)."""
    d = tmp_path_factory.mktemp("hoad_fmu")
    return {name: fmu.build_fmu(resolve(name, "left_wing"), d / f"{name}.fmu") for name in ("hoad2", "hoad3")}


@pytest.mark.parametrize("name", ["hoad2", "hoad3"])
def test_the_fmu_validates_clean(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


def test_the_fmu_declares_every_slot_with_its_unit_range_and_description(fmus):
    md = fmpy.read_model_description(str(fmus["hoad3"]))
    by = {v.name: v for v in md.modelVariables}
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    assert len(params) == len(P) + 1  # every kernel slot and the noise seed
    assert by["command_delay_s"].unit == "s"
    assert float(by["command_delay_s"].start) == 0.004
    assert by["pwm_max_duty_ratio"].max is not None
    assert float(by["pwm_max_duty_ratio"].max) == 1.0
    assert "figure 33" in by["total_k2_lbf_per_in"].description
    assert by["noise_seed"].type == "Integer"
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["command_deg", "hinge_moment_inlb",
                                                                            "motor_power"]
    assert [v.name for v in md.modelVariables if v.causality == "output"] == [
        "position_deg", "surface_deg", "rate_dps", "flags", "current_a", "bus_v"]


OUTS = ("position_deg", "surface_deg", "rate_dps", "current_a", "bus_v")


def _signals(cmd, hm, power=None, rate=1000.0):
    n = cmd.size
    sig = np.zeros(n, dtype=[("time", float), ("command_deg", float), ("hinge_moment_inlb", float),
                             ("motor_power", float)])
    sig["time"] = np.arange(n) / rate
    sig["command_deg"] = cmd
    sig["hinge_moment_inlb"] = hm
    sig["motor_power"] = 1.0 if power is None else power
    return sig


@pytest.mark.parametrize("name", ["hoad2", "hoad3"])
def test_simulate_fmu_is_ema_simulate_on_the_reports_maneuvers(fmus, name):
    """FMPy's simulate_fmu against `ema simulate` at a 1 kHz frame, noise on: 0 difference on every output."""
    for man, load in DEFAULT_MANEUVERS:
        _, record, _ = simulate(name, parse_maneuver(man), parse_load(load) if load else None, duration_s=1.0,
                                frame_hz=1000.0, sample_hz=1000.0)
        n = record.time_s.size - 1
        res = fmpy.simulate_fmu(str(fmus[name]), stop_time=n / 1000.0, output_interval=1e-3,
                                input=_signals(record.command_deg[0, :n], record.hinge_moment_inlb[0, :n]),
                                output=[*OUTS, "flags"])
        assert res.size == n + 1
        for o in OUTS:
            assert np.array_equal(res[o], getattr(record, o)[0]), (man, o)
        assert np.array_equal(res["flags"], record.flags[0]), man


def test_the_fmus_power_input_is_the_models_power(fmus):
    """Power off (the brake holds against a load) and on again: the FMU's input against set_power."""
    n = 600
    k = np.arange(n)
    cmd = np.where(k < 100, 0.0, 3.0)
    hm = 2000.0 * np.sin(k * 0.01)
    power = np.where((k >= 200) & (k < 400), 0.0, 1.0)
    res = fmpy.simulate_fmu(str(fmus["hoad3"]), stop_time=n / 1000.0, output_interval=1e-3,
                            input=_signals(cmd, hm, power), output=list(OUTS))
    model = create("hoad3", "left_wing")
    at_trim = model.trim(cmd[0], hm[0])
    want = [[float(getattr(at_trim, o)[0]) for o in OUTS]]
    for j in range(n):
        model.set_power(bool(power[j]))
        want.append(model.step_values(float(cmd[j]), float(hm[j]), 1e-3))
    want_a = np.array([row[:len(OUTS)] for row in want])
    for i, o in enumerate(OUTS):
        assert np.array_equal(res[o], want_a[:, i]), o
    assert np.all(res["bus_v"][201:400] == 0.0)


def test_the_fmu_takes_any_whole_number_of_steps_and_refuses_the_rest(fmus):
    res = fmpy.simulate_fmu(str(fmus["hoad3"]), stop_time=0.05, output_interval=2.5e-3, output=["position_deg"])
    assert res.size == 21
    with pytest.raises(FMICallException):
        fmpy.simulate_fmu(str(fmus["hoad3"]), stop_time=0.01, output_interval=1.5e-4)


def test_the_fmus_seed_picks_the_noise_stream(fmus):
    def run(seed):
        return fmpy.simulate_fmu(str(fmus["hoad3"]), stop_time=0.2, output_interval=1e-3,
                                 start_values={"noise_seed": seed}, output=["position_deg"])["position_deg"]

    model = create("hoad3", "left_wing", seed=7)
    model.trim(0.0, 0.0)
    want = model.run_outputs([0.0], [0.0], [0.0], sample_times=np.arange(201) * 1e-3, end_s=0.2)[0][:, 0]
    assert np.array_equal(run(7), want)
    assert not np.array_equal(run(0), want)


def test_verify_runs_the_hoad_fmu_and_c_export_against_the_truth(fmus, tmp_path):
    d = tmp_path / "hoad2_c"
    harness.write_c(resolve("hoad2", "left_wing"), d)
    for path in (fmus["hoad3"], d):
        art = open_artefact(path)
        try:
            result = verify(art, DEFAULT_MANEUVERS[:2], duration_s=1.0)
        finally:
            art.close()
        assert result.passed, "\n".join(result.lines())
        assert all(v == 0.0 for c in result.comparisons for v in c.max_abs_deg.values())


# ------------------------------------------------------------------------------------------ the CLI
def test_the_cli_exports_hoad3_and_hoad2(tmp_path, capsys):
    assert main(["export", "hoad3", "--fmu", str(tmp_path / "h3.fmu"), "--set", "seed=3"]) == 0
    out = capsys.readouterr().out
    assert "fmpy.validate_fmu: clean" in out
    assert main(["export", "hoad2", "--set", "noise=0", "--c", str(tmp_path / "h2")]) == 0
    assert "noise off" in capsys.readouterr().out
    assert (tmp_path / "h2" / hoad_c.KERNEL_FILE).is_file()


def test_hoac1_and_a_jsbsim_hoad_are_refused_with_why(tmp_path, capsys):
    assert main(["export", "hoac1", "--c", str(tmp_path / "x")]) == 2
    assert "Dormand-Prince" in capsys.readouterr().err
    assert "hoac1" in NOT_EXPORTABLE
    assert main(["export", "hoad3", "--jsbsim", str(tmp_path / "x.xml")]) == 2
    assert "no JSBSim system" in capsys.readouterr().err
    with pytest.raises(EmaError, match="unknown high-order"):
        resolve("hoad3", overrides={"wn_rad_s": 50.0})


def test_maneuver_inputs_of_a_hoad_export_are_frames():
    target = resolve("hoad3")
    assert target.frame_hz == 1000.0
    assert target.steps_per_frame == 10
    cmd, _ = maneuver_inputs("steps:amps_deg=1,lead_s=0.1,hold_s=0.2", None, target.frame_hz, duration_s=0.5)
    assert cmd.size == round(0.5 * target.frame_hz)

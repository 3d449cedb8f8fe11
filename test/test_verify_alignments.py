"""`ema verify` on a host's record knows how hosts log a step: honest hosts in each of the usual alignments pass with
the alignment named, planted faults are still named (hinge moment reversed, command in volts) and so is a host that
left out HOAD3's 2 ms feedback delay. The hosts are the exported C kernel (HOAD3, noise on) and the exported LOADA
FMU stepped by FMPy, logged the way a host logs.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from ema_sim.cli import main
from ema_sim.export import csource, fmu, hoad_c
from ema_sim.export.diagnose import diagnose
from ema_sim.export.target import resolve
from ema_sim.export.verify import unit_ratios
from ema_sim.io.csv import write_csv
from ema_sim.io.measured import MeasuredData
from ema_sim.models.high_order.params import P

fmpy = pytest.importorskip("fmpy")

FRAME_S = 1e-3
"""The host's frame (10 steps of HOAD3)."""
N = 1500
TOL = 1e-4


@pytest.fixture(scope="module")
def hoad3_lib(tmp_path_factory):
    """HOAD3's exported C model for left_wing (compiled once)."""
    d = tmp_path_factory.mktemp("hoad3_host")
    hoad_c.write_sources(d, hoad_c.target_values(resolve("hoad3", "left_wing")))
    lib = ctypes.CDLL(str(csource.compile_c([d / f for f in hoad_c.SOURCES], d / "lib.so", shared=True,
                                            include=[d])))
    lib.ema_new.restype = ctypes.c_void_p
    lib.ema_new.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_double, ctypes.c_int, ctypes.c_double,
                            ctypes.c_double, ctypes.c_char_p, ctypes.c_size_t]
    lib.ema_advance.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_long]
    lib.ema_output.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.ema_output.restype = ctypes.c_double
    lib.ema_delete.argtypes = [ctypes.c_void_p]
    return lib


def _inputs():
    t = np.arange(N) * FRAME_S
    cmd = np.where(t < 0.2, 0.0, np.where(t < 0.7, 2.0, np.where(t < 1.1, -4.0, 1.0))) + 0.2 * np.sin(9.0 * t)
    hm = 1200.0 * np.sin(2 * np.pi * 1.3 * t)
    return t, cmd, hm


def _host(lib, cmd, hm, *, half=False, params=None):
    """A host stepping the C model a frame per input: the outputs at every frame boundary (or half a frame in)."""
    p = hoad_c.target_values(resolve("hoad3", "left_wing")).vector if params is None else params
    msg = ctypes.create_string_buffer(256)
    m = lib.ema_new((ctypes.c_double * len(p))(*p), 1e4, 0, cmd[0], hm[0], msg, 256)
    assert m, msg.value
    out = np.empty((cmd.size + 1, 2))
    try:
        out[0] = [lib.ema_output(m, 0), lib.ema_output(m, 1)]
        for k in range(cmd.size):
            if half:
                lib.ema_advance(m, cmd[k], hm[k], 5)
                out[k] = [lib.ema_output(m, 0), lib.ema_output(m, 1)]
                lib.ema_advance(m, cmd[k], hm[k], 5)
            else:
                lib.ema_advance(m, cmd[k], hm[k], 10)
                out[k + 1] = [lib.ema_output(m, 0), lib.ema_output(m, 1)]
    finally:
        lib.ema_delete(m)
    return out


def _record(t, cmd, hm, out):
    return MeasuredData(time_s=t, command_deg=cmd, position_deg=out[:, 0], surface_deg=out[:, 1],
                        hinge_moment_inlb=hm, source="host.csv")


def _logged(lib, how):
    """What a host that logs ``how`` writes: (time, command, hinge moment, outputs) per row."""
    t, cmd, hm = _inputs()
    if how == "half frame":
        out = _host(lib, cmd, hm, half=True)
        return _record(t, cmd, hm, out[:N])
    out = _host(lib, cmd, hm)
    if how == "as logged":  # the command of a step with the outputs before it
        return _record(t, cmd, hm, out[:N])
    if how == "one step late":  # the time after the step, its command, the outputs after it
        return _record(t + FRAME_S, cmd, hm, out[1:])
    if how == "one step early":  # the outputs of the step before
        return _record(t, cmd, hm, np.vstack([out[:1], out[: N - 1]]))
    # time stamped at the frame end: the command logged with the time its frame ended
    return _record(np.append(0.0, t + FRAME_S)[:N], np.append(cmd[0], cmd)[:N], np.append(hm[0], hm)[:N], out[:N])


@pytest.mark.parametrize(("how", "named"), [
    ("as logged", None),
    ("one step late", "logged one step late: with the outputs shifted 1 ms"),
    ("one step early", "logged one step early"),
    ("frame end", "time stamped at the frame end"),
    ("half frame", "a half-frame offset: with the outputs shifted 0.5 ms"),
])
def test_an_honest_host_passes_in_each_usual_alignment_with_it_named(hoad3_lib, how, named):
    found = diagnose(_logged(hoad3_lib, how), resolve("hoad3", "left_wing"), tolerance_deg=TOL)
    assert found.matches, found.lines()
    if named is None:
        assert found.alignment is None
        assert found.as_is.rms_deg == 0.0
        return
    assert found.as_is.rms_deg > TOL
    assert found.alignment is not None
    assert found.alignment.detail.startswith(named)
    assert found.alignment.rms_deg == 0.0
    assert "  MATCHES the truth in that alignment" in found.lines()


@pytest.mark.parametrize(("plant", "fault", "words"), [
    ("hinge moment", "sign", "hinge moment reversed"),
    ("volts", "units", "command given in volts"),
    ("feedback delay", "delay left out", "2 ms feedback delay left out"),
])
def test_a_faulty_host_is_named_before_any_alignment(hoad3_lib, plant, fault, words):
    t, cmd, hm = _inputs()
    params = None
    fed_cmd, fed_hm = cmd, hm
    if plant == "hinge moment":
        fed_hm = -hm
    elif plant == "volts":
        fed_cmd = unit_ratios("left_wing")["the command given in volts, taken as degrees"] * cmd
    else:
        params = hoad_c.target_values(resolve("hoad3", "left_wing")).vector.copy()
        params[P.feedback_delay_s] = 0.0
    out = _host(hoad3_lib, fed_cmd, fed_hm, params=params)
    found = diagnose(_record(t, cmd, hm, out[:N]), resolve("hoad3", "left_wing"), tolerance_deg=TOL)
    assert not found.matches, found.lines()
    assert found.fault is not None, found.lines()
    assert found.fault.fault == fault, found.lines()
    assert words in found.fault.detail


def test_the_loada_fmu_logged_after_each_step_passes_with_the_alignment_named(tmp_path, capsys):
    """The host of the report: LOADA's FMU stepped at 800 Hz by FMPy, each step logged as (time after the step,
    the command of that step, the outputs after it)."""
    path = fmu.build_fmu(resolve("loada", "left_wing"), tmp_path / "loada.fmu")
    n = 1600
    t = np.arange(n) / 800.0
    cmd = np.where(t < 0.2, 0.0, np.where(t < 1.0, 2.0, -6.0))
    hm = 1200.0 * np.sin(2 * np.pi * 1.3 * t)
    sig = np.zeros(n, dtype=[("time", float), ("command_deg", float), ("hinge_moment_inlb", float)])
    sig["time"], sig["command_deg"], sig["hinge_moment_inlb"] = t, cmd, hm
    res = fmpy.simulate_fmu(str(path), stop_time=n / 800.0, output_interval=1 / 800.0, input=sig,
                            output=["position_deg", "surface_deg"])
    csv = tmp_path / "host.csv"
    write_csv(csv, {"time_s": res["time"][1:], "command_deg": cmd, "position_deg": res["position_deg"][1:],
                    "surface_deg": res["surface_deg"][1:], "hinge_moment_inlb": hm}, {"channel": "left_wing"})
    capsys.readouterr()
    assert main(["verify", str(csv), "--model", "loada"]) == 0
    out = capsys.readouterr().out
    assert "logged one step late: matches with the outputs shifted 1.25 ms" in out
    assert "PASS" in out

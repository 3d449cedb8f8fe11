"""A JSBSim ``<system>`` of flight-control components for figure 26, and running it in JSBSim.

Each stage is the JSBSim component that computes what the kernel computes, in the kernel's order and
with its constants (Python's own doubles, written to round-trip): the delay an ``<actuator>``'s
``<delay>`` in whole frames (exact when the inputs change at the model's own steps), the command
error a ``<pure_gain>`` and a ``<summer>`` with its bias, the servo error a ``<summer>``, the
threshold a ``<deadband>``, the rate limit with its K2 load dependence a ``<pure_gain>`` whose
``<clipto>`` limits are ``<fcs_function>`` properties, the rate loop a ``<pure_gain>``. JSBSim's
``<integrator>`` (trapezoidal), ``<lag_filter>`` (Tustin) and sensor quantization (truncating on a
bit grid) are not the kernel's Euler steps, exact lags and mid-tread quantizer: those stages, the
position and free-play stops that stop the rate, K_CP and the compliance curves are
``<fcs_function>`` s with the kernel's own step (a function reads its own property, last frame's value,
as the state). What JSBSim is not given is listed in :data:`NOT_EXPRESSED`; a model that has such a
stage on is written without it, and the manifest says so (``ema verify`` measures the error it leaves).

The system runs at the model's rate only (its constants are for that step): ``ema verify`` hosts it
in a bare airframe, sets the states to the model's rest (:data:`STATE_PROPERTIES`) and steps it.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from ema_sim.export.target import LINEAR_NO_JSBSIM, ExportError, ExportTarget
from ema_sim.jsontypes import JsonObject
from ema_sim.models.arrays import FloatArray
from ema_sim.models.second_order.figure26 import (
    HISTORY_SIZE,
    compliance_gain,
    compliance_time_constant_s,
    drive_on,
    free_play_subsystem,
    trim,
)
from ema_sim.models.second_order.figure29 import free_play_accel
from ema_sim.models.second_order.params import N_STATE, SecondOrderParams, X
from ema_sim.models.stages import TIME_EPS_S, TWO_PI, lag_gain

Expr = str | float | tuple["Expr", ...]
"""A JSBSim function: a property name, a number, or ``(operation, *arguments)``."""

INPUT_COMMAND = "ema/command-deg"
INPUT_HINGE_MOMENT = "ema/hinge-moment-inlb"
OUTPUTS: dict[str, str] = {"position_deg": "ema/position-deg", "surface_deg": "ema/surface-deg",
                           "rate_dps": "ema/rate-dps"}
"""Output → its property."""
STATE_PROPERTIES: dict[int, str] = {
    X.position_deg: "ema/state/position-deg", X.rate_dps: "ema/state/rate-dps",
    X.free_play_deg: "ema/state/free-play-deg", X.free_play_rate_dps: "ema/state/free-play-rate-dps",
    X.command_lag_deg: "ema/state/command-lag-deg", X.feedback_lag_deg: "ema/state/feedback-lag-deg",
    X.compliance_deg: "ema/state/compliance-deg", X.integral_deg_s: "ema/state/integral-deg-s",
}
"""State slot → the property that holds it (set these to the model's rest before the first frame)."""
NOT_EXPRESSED: dict[str, str] = {
    "accel_limit_dps2": "the current-limited drive (stage 9, its exact velocity-loop step): not written",
    "feedback_filter_in_loop": "the in-loop feedback filter (actuator ahead of the position): not written",
    "feedback_delay_s": "the feedback delay (stage 14, a Hermite-interpolated history ring): JSBSim's <delay> holds "
                        "whole frames of one value, not the kernel's interpolated reading; not written",
    "linkage_freq_hz": "the linkage mode (stage 17, an exact oscillator step per spring segment): not written",
}
"""Stages the system does not carry: parameter that switches it on → why."""
ALWAYS_MISSING: tuple[str, ...] = (
    "the limit flags (rate, position, free play, threshold): not computed",
    "trim: JSBSim's components start at zero; set the ema/state/* properties to the model's rest (ema verify does) "
    "or hold the first inputs until it settles",
    "the rate: the constants are for the model's own step; at another JSBSim dt the system is not the model",
)
"""What no system written here has."""
MANIFEST_TAG = "ema_export"
AIRFRAME = """<?xml version="1.0"?>
<fdm_config name="ema_host" version="2.0" release="BETA">
  <metrics>
    <wingarea unit="FT2"> 1.0 </wingarea><wingspan unit="FT"> 1.0 </wingspan><chord unit="FT"> 1.0 </chord>
    <location name="AERORP" unit="IN"><x>0</x><y>0</y><z>0</z></location>
  </metrics>
  <mass_balance>
    <ixx unit="SLUG*FT2"> 1 </ixx><iyy unit="SLUG*FT2"> 1 </iyy><izz unit="SLUG*FT2"> 1 </izz>
    <emptywt unit="LBS"> 100 </emptywt>
    <location name="CG" unit="IN"><x>0</x><y>0</y><z>0</z></location>
  </mass_balance>
  <ground_reactions/>
  <propulsion/>
  <system file="ema_system"/>
  <aerodynamics>
    <axis name="DRAG"/><axis name="SIDE"/><axis name="LIFT"/>
    <axis name="ROLL"/><axis name="PITCH"/><axis name="YAW"/>
  </aerodynamics>
</fdm_config>
"""
"""A bare airframe hosting the system (as bench/jsbsim/aircraft/ema_actuator does)."""


def fn(e: Expr) -> str:
    """A JSBSim function element for an expression.

    Parameters
    ----------
    e : str, float or tuple
        A property name, a number, or ``(operation, *arguments)`` (``sum``, ``product``, ``ifthen``...).

    Returns
    -------
    str
        XML.
    """
    if isinstance(e, str):
        return f"<property>{e}</property>"
    if isinstance(e, float | int):
        if not math.isfinite(e):
            raise ValueError(f"a JSBSim constant must be finite, got {e}")
        return f"<value>{float(e)!r}</value>"
    op, *args = e
    return f"<{op}>{''.join(fn(a) for a in args)}</{op}>"


class _System:
    """The components of one system, in execution order."""

    def __init__(self) -> None:
        self.parts: list[str] = []

    def fcs(self, name: str, expr: Expr, what: str) -> str:
        self.parts.append(f"      <!-- {escape(what)} -->\n      <fcs_function name=\"{name}\">\n"
                          f"        <function>{fn(expr)}</function>\n      </fcs_function>")
        return name

    def summer(self, name: str, inputs: Sequence[str], what: str, bias: float | None = None) -> str:
        body = "".join(f"<input>{i}</input>" for i in inputs)
        if bias is not None:
            body += f"<bias>{bias!r}</bias>"
        self.parts.append(f"      <!-- {escape(what)} -->\n      <summer name=\"{name}\">{body}</summer>")
        return name

    def gain(self, name: str, source: str, gain: float, what: str, clip: tuple[str, str] | None = None) -> str:
        body = f"<input>{source}</input><gain>{gain!r}</gain>"
        if clip is not None:
            body += f"<clipto><min>{clip[0]}</min><max>{clip[1]}</max></clipto>"
        self.parts.append(f"      <!-- {escape(what)} -->\n      <pure_gain name=\"{name}\">{body}</pure_gain>")
        return name

    def deadband(self, name: str, source: str, width: float, what: str) -> str:
        self.parts.append(f"      <!-- {escape(what)} -->\n      <deadband name=\"{name}\"><input>{source}</input>"
                          f"<width>{width!r}</width></deadband>")
        return name

    def delay(self, name: str, source: str, frames: int, what: str) -> str:
        # JSBSim's delay of N holds N values: the output is the input N - 1 frames ago
        self.parts.append(f"      <!-- {escape(what)} -->\n      <actuator name=\"{name}\"><input>{source}</input>"
                          f"<delay type=\"frames\">{frames + 1}</delay></actuator>")
        return name


def delay_frames(delay_s: float, rate_hz: float) -> int:
    """The whole frames stage 1 delays by when the inputs change at the model's steps (the kernel's lookup).

    Parameters
    ----------
    delay_s : float
        The delay (s).
    rate_hz : float
        The model's rate.

    Returns
    -------
    int
        Frames.
    """
    dt = 1.0 / rate_hz
    k = 100_000
    t = 0.0 + k * dt
    j = k
    while j > 0 and not (0.0 + j * dt) <= t - delay_s + TIME_EPS_S:
        j -= 1
    return k - j


def _neg(e: Expr) -> Expr:
    return ("product", -1.0, e)


def _deflection(sys: _System, name: str, hm: str, c: float, knee: float, stiff: float, what: str) -> str:
    """Stages 12 and 16's curve: ``copysign(d·1e-3, hm)``, d linear up to the knee, stiffer beyond it."""
    a: Expr = ("abs", hm)
    d: Expr = ("product", c, a)
    if math.isfinite(knee):
        d = ("ifthen", ("le", a, knee), d, ("sum", ("product", c, knee), ("product", stiff, ("difference", a, knee))))
    raw = sys.fcs(f"{name}-raw", d, f"{what}: |deflection| per 1000 in.lb of |hm|")
    scaled: Expr = ("product", raw, 1e-3)
    return sys.fcs(name, ("ifthen", ("nq", raw, 0.0), ("ifthen", ("lt", hm, 0.0), _neg(scaled), scaled), 0.0),
                   f"{what}: with the sign of the hinge moment")


def _euler(sys: _System, x: str, v: str, a: Expr, dt: float, lo: float, hi: float, backward: bool,
           what: str) -> None:
    """An Euler pair and its stops (``euler_pair`` then ``limited_integrator``) writing states ``x`` and ``v``."""
    if backward:
        v_raw = sys.fcs(f"{v}-raw", ("sum", v, ("product", dt, a)), f"{what}: backward Euler, the rate first")
        x_raw = sys.fcs(f"{x}-raw", ("sum", x, ("product", dt, v_raw)), f"{what}: then the position")
    else:
        x_raw = sys.fcs(f"{x}-raw", ("sum", x, ("product", dt, v)), f"{what}: forward Euler, the position")
        v_raw = sys.fcs(f"{v}-raw", ("sum", v, ("product", dt, a)), f"{what}: and the rate")
    sys.fcs(x, ("ifthen", ("ge", x_raw, hi), hi, ("ifthen", ("le", x_raw, lo), lo, x_raw)), f"{what}: stops")
    sys.fcs(v, ("ifthen", ("ge", x_raw, hi), ("min", v_raw, 0.0), ("ifthen", ("le", x_raw, lo), ("max", v_raw, 0.0),
                                                                     v_raw)), f"{what}: the rate stops at a stop")


def not_expressed(params: SecondOrderParams) -> list[str]:
    """The stages of a parameter set the system leaves out.

    Parameters
    ----------
    params : SecondOrderParams
        The model's values.

    Returns
    -------
    list of str
        Parameter names of the stages that are on (:data:`NOT_EXPRESSED`).
    """
    p = params.kernel_vector()
    on = {"accel_limit_dps2": bool(drive_on(p)),
          "feedback_filter_in_loop": params.feedback_filter_in_loop > 0.5,
          "feedback_delay_s": params.feedback_delay_s > 0.0, "linkage_freq_hz": params.linkage_freq_hz > 0.0}
    return [k for k, v in on.items() if v]


def expressed_params(params: SecondOrderParams) -> SecondOrderParams:
    """The parameter set the system carries: the stages it leaves out switched off.

    Parameters
    ----------
    params : SecondOrderParams
        The model's values.

    Returns
    -------
    SecondOrderParams
        The same with :func:`not_expressed`'s stages off.
    """
    off = {"accel_limit_dps2": math.inf, "feedback_filter_in_loop": 0.0, "feedback_delay_s": 0.0,
           "linkage_freq_hz": 0.0}
    return params.replace(**{k: off[k] for k in not_expressed(params)})


def system_xml(target: ExportTarget) -> str:  # noqa: PLR0912, PLR0915 - figure 26, one component after another
    """The ``<system>`` file of a target.

    Parameters
    ----------
    target : ExportTarget
        What is exported.

    Returns
    -------
    str
        The XML text, its manifest in a comment.
    """
    if target.linear:
        raise ExportError(f"{target.model}: {LINEAR_NO_JSBSIM}")
    dropped = not_expressed(target.params)
    prm = expressed_params(target.params)
    p = prm.kernel_vector()
    dt = 1.0 / target.rate_hz
    backward = target.backward
    hm = INPUT_HINGE_MOMENT
    s = _System()
    # stages 1-4: delay, command error, quantizer, command lag
    frames = delay_frames(prm.delay_s, target.rate_hz)
    u = INPUT_COMMAND
    if frames > 0:
        u = s.delay("ema/command-delayed-deg", u, frames, f"stage 1: delay {prm.delay_s:g} s = {frames} frames at "
                                                          f"{target.rate_hz:g} Hz")
    scaled = s.gain("ema/command-scaled-deg", u, 1.0 + prm.kb, "stage 2: command error (1 + Kb)·u")
    u = s.summer("ema/command-error-deg", [scaled], "stage 2: + offset", bias=prm.offset_deg)
    if prm.quantization_deg > 0.0:
        q = prm.quantization_deg
        u = s.fcs("ema/command-quantized-deg", ("product", q, ("floor", ("sum", ("quotient", u, q), 0.5))),
                  "stage 3: mid-tread quantizer")
    cmd_lag = STATE_PROPERTIES[X.command_lag_deg]
    s.fcs(cmd_lag, ("sum", cmd_lag, ("product", lag_gain(prm.command_lag_hz, dt), ("difference", u, cmd_lag))),
          "stage 4: command lag, its exact step (gain 1: off)")
    u_in = cmd_lag
    # stages 5-10: K_CP, servo error, threshold, rate limit with K2, droop, rate loop
    if prm.kcp_per_kinlb != 0.0:
        aiding: Expr = ("ifthen", ("gt", u_in, 0.0), hm, _neg(hm))
        u_in = s.fcs("ema/servo-input-deg", ("ifthen", ("eq", u_in, 0.0), u_in, (
            "product", u_in, ("sum", 1.0, ("product", prm.kcp_per_kinlb, aiding, 1e-3)))),
            "stage 5: K_CP = 1 + kcp·(aiding load)/1000")
    pos = STATE_PROPERTIES[X.position_deg]
    rate = STATE_PROPERTIES[X.rate_dps]
    x_loop = pos
    if backward:
        x_loop = s.fcs("ema/loop-position-deg", ("sum", pos, ("product", dt, rate)),
                       "LOADF: the loop closes on the position one frame ahead")
    e = s.summer("ema/servo-error-deg", [u_in, f"-{x_loop}"], "stage 6: servo error")
    e_dz = e
    if prm.threshold_deg > 0.0:
        e_dz = s.deadband("ema/servo-error-dz-deg", e, 2.0 * prm.threshold_deg, "stage 6: threshold (dead zone)")
    wi = TWO_PI * prm.integral_hz
    integral = STATE_PROPERTIES[X.integral_deg_s]
    terms = [x_loop, e_dz]
    if wi > 0.0:
        terms.append(s.fcs("ema/integral-term-deg", ("product", wi, integral), "stage 7: integral action ωi·∫error"))
    target_deg = s.summer("ema/servo-target-deg", terms, "stage 7: the position the loop drives to")
    error = s.summer("ema/servo-target-error-deg", [target_deg, f"-{x_loop}"], "stage 7: its error")
    clip = None
    if math.isfinite(prm.rate_limit_dps):
        f_lb: Expr = ("product", prm.k2_dps_per_lb, ("quotient", hm, prm.moment_arm_in))
        up = s.fcs("ema/rate-limit-up-dps", ("max", ("sum", prm.rate_limit_dps, f_lb), 0.0),
                   "stage 7: rate limit rl + K2·hm/marm, never below 0")
        down = s.fcs("ema/rate-limit-down-dps", ("max", ("difference", prm.rate_limit_dps, f_lb), 0.0),
                     "stage 7: rate limit rl − K2·hm/marm (negative direction), never below 0")
        clip = (f"-{down}", up)
    gain = prm.wn_rad_s / (2.0 * prm.zeta)
    integrand = None
    if wi > 0.0:  # it integrates while nothing limits: the demand inside its limits, the error outside the threshold
        raw = s.gain("ema/velocity-demand-dps", error, gain, "stage 7: velocity demand ωn/(2ζ)·error")
        vc = s.gain("ema/velocity-command-dps", raw, 1.0, "stage 7: rate-limited", clip) if clip else raw
        running: list[Expr] = [("le", raw, clip[1]), ("ge", raw, _neg(clip[0][1:]))] if clip else []
        if prm.threshold_deg > 0.0:
            running.append(("or", ("gt", e, prm.threshold_deg), ("lt", e, -prm.threshold_deg)))
        cond: Expr = ("and", *running) if len(running) > 1 else (running[0] if running else 1.0)
        integrand = s.fcs("ema/integrand-deg", ("ifthen", cond, e, 0.0), "stage 7: the integral's input")
    else:
        vc = s.gain("ema/velocity-command-dps", error, gain, "stage 7: velocity command ωn/(2ζ)·error, rate-limited",
                    clip)
    if prm.servo_compliance_deg_per_kinlb != 0.0:
        c1 = prm.wn_rad_s / (2.0 * prm.zeta) * prm.servo_compliance_deg_per_kinlb
        vc = s.fcs("ema/drive-rate-dps", ("sum", vc, ("product", c1, hm, 1e-3)), "stage 8: servo compliance droop")
    rate_error = s.summer("ema/rate-error-dps", [vc, f"-{rate}"], "stage 10: rate error")
    accel = s.gain("ema/acceleration-dps2", rate_error, 2.0 * prm.zeta * prm.wn_rad_s, "stage 10: rate loop 2ζωn")
    # stage 11: the integrators and their stops
    _euler(s, pos, rate, accel, dt, prm.position_min_deg, prm.position_max_deg, backward, "stage 11")
    if integrand is not None:
        s.fcs(integral, ("sum", integral, ("product", dt, integrand)), "stage 7: the integral, Euler")
    # stage 15: free play
    fp = STATE_PROPERTIES[X.free_play_deg]
    if free_play_subsystem(p):
        half = 0.5 * prm.free_play_deg
        fp_accel = s.fcs("ema/free-play-accel-dps2", ("product", hm, free_play_accel(1.0, prm.surface_inertia_inlbs2)),
                         "stage 15: hm/Is")
        _euler(s, fp, STATE_PROPERTIES[X.free_play_rate_dps], fp_accel, dt, -half, half, backward,
               "stage 15: free play")
    # stages 12-13: LVDT, feedback lag; 16: compliance
    lvdt_on = prm.lvdt_compliance_deg_per_kinlb != 0.0 or prm.lvdt_compliance_stiff_deg_per_kinlb != 0.0
    lvdt_defl = (_deflection(s, "ema/lvdt-compliance-deg", hm, prm.lvdt_compliance_deg_per_kinlb,
                             prm.lvdt_compliance_knee_inlb, prm.lvdt_compliance_stiff_deg_per_kinlb,
                             "stage 12: LVDT compliance") if lvdt_on else None)
    fb_pos = pos
    if backward:
        fb_pos = s.fcs("ema/feedback-position-deg", ("sum", pos, ("product", dt, rate)),
                       "LOADF: the feedback one frame ahead")
    reading = s.fcs("ema/lvdt-reading-deg", ("sum", fb_pos, lvdt_defl), "stage 12: the LVDT reads") if lvdt_defl \
        else fb_pos
    fb = STATE_PROPERTIES[X.feedback_lag_deg]
    s.fcs(fb, ("sum", fb, ("product", lag_gain(prm.feedback_lag_hz, dt), ("difference", reading, fb))),
          "stage 13: feedback lag, its exact step (gain 1: off)")
    comp_on = prm.compliance_deg_per_kinlb != 0.0 or prm.compliance_stiff_deg_per_kinlb != 0.0
    compliance = None
    if comp_on:
        compliance = _deflection(s, "ema/compliance-static-deg", hm, prm.compliance_deg_per_kinlb,
                                 prm.compliance_knee_inlb, prm.compliance_stiff_deg_per_kinlb,
                                 "stage 16: compliance outside the loop")
        if compliance_time_constant_s(p) > 0.0:
            state = STATE_PROPERTIES[X.compliance_deg]
            compliance = s.fcs(state, ("sum", state, ("product", compliance_gain(p, dt), ("difference", compliance,
                                                                                          state))),
                               "stage 16: hysteretic damping, the compliance a lag")
    # outputs
    s.summer(OUTPUTS["position_deg"], [fb], "output: the LVDT position")
    actuator = s.fcs("ema/actuator-lvdt-deg", ("sum", pos, lvdt_defl), "the actuator as the LVDT sees it") if \
        lvdt_defl else pos
    surface = [actuator] + ([fp] if free_play_subsystem(p) else []) + ([compliance] if compliance else [])
    s.summer(OUTPUTS["surface_deg"], surface, "output: the surface (free play and compliance included)")
    s.summer(OUTPUTS["rate_dps"], [rate], "output: the actuator rate")
    manifest = target.manifest("jsbsim", {"not_expressed": [*dropped], "delay_frames": frames})
    text = json.dumps(manifest, ensure_ascii=True).replace("--", "-\\u002d")
    missing = [f"{k}: {NOT_EXPRESSED[k]}" for k in dropped] + list(ALWAYS_MISSING)
    notes = "".join(f"       - {escape(m)}\n" for m in missing)
    return (
        '<?xml version="1.0"?>\n'
        f"<!-- {escape(target.description)}\n"
        f"     Inputs {INPUT_COMMAND} (deg) and {INPUT_HINGE_MOMENT} (in.lb, positive aids positive deflection);\n"
        f"     outputs {', '.join(OUTPUTS.values())}. Run JSBSim at dt = 1/{target.rate_hz:g} s.\n"
        f"     Not in this system:\n{notes}-->\n"
        f"<!-- {MANIFEST_TAG} {text} -->\n"
        f'<system name="ema_{target.model}_{target.channel}">\n'
        f'  <property value="0"> {INPUT_COMMAND} </property>\n'
        f'  <property value="0"> {INPUT_HINGE_MOMENT} </property>\n'
        '  <channel name="figure 26">\n' + "\n".join(s.parts) + "\n  </channel>\n</system>\n"
    )


def read_manifest(path: Path) -> JsonObject:
    """The manifest a system file carries.

    Parameters
    ----------
    path : pathlib.Path
        The system file.

    Returns
    -------
    dict
        The manifest.
    """
    found = re.search(rf"<!-- {MANIFEST_TAG} (.*?) -->", path.read_text(encoding="utf-8"), re.DOTALL)
    if found is None:
        raise ExportError(f"{path} carries no ema_sim manifest (not written by `ema export --jsbsim`)")
    doc: JsonObject = json.loads(found.group(1))
    return doc


def rest_state(params: SecondOrderParams, command_deg: float, hinge_moment_inlb: float) -> FloatArray:
    """The model's state at rest under a held command and load (the kernel's trim).

    Parameters
    ----------
    params : SecondOrderParams
        The values.
    command_deg : float
        Command (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).

    Returns
    -------
    numpy.ndarray
        The state (:data:`~ema_sim.models.second_order.params.X`).
    """
    states = np.zeros((1, N_STATE))
    history = np.zeros((1, HISTORY_SIZE if params.feedback_delay_s > 0.0 else 1, 3))
    trim(params.kernel_vector()[None, :], np.array([command_deg]), np.array([hinge_moment_inlb]), states, history)
    rest: FloatArray = states[0]
    return rest


class JsbsimRunner:
    """The system hosted in a bare airframe in a temporary JSBSim root, stepped at its rate.

    Parameters
    ----------
    system : pathlib.Path
        The ``<system>`` file.
    rate_hz : float
        The rate JSBSim runs at.
    """

    def __init__(self, system: Path, rate_hz: float) -> None:
        try:
            import jsbsim  # noqa: PLC0415 - JSBSim: a test tool, only to verify a system file
        except ImportError:
            raise ExportError("running a JSBSim system needs the jsbsim package: pip install jsbsim==1.3.3") from None
        self._jsbsim = jsbsim
        self._tmp = tempfile.TemporaryDirectory(prefix="ema_jsbsim_")
        root = Path(self._tmp.name)
        craft = root / "aircraft" / "ema_host"
        (craft / "Systems").mkdir(parents=True)
        (craft / "ema_host.xml").write_text(AIRFRAME, encoding="utf-8")
        shutil.copy(system, craft / "Systems" / "ema_system.xml")
        self.root = root
        self.rate_hz = rate_hz

    def close(self) -> None:
        """Remove the temporary root."""
        self._tmp.cleanup()

    def run(self, params: SecondOrderParams, command_deg: FloatArray, hinge_moment_inlb: FloatArray,
            preroll_frames: int) -> tuple[dict[str, FloatArray], float]:
        """Trim at the first inputs, then one JSBSim frame per input; the outputs after each.

        Parameters
        ----------
        params : SecondOrderParams
            The values whose rest state the states are set to.
        command_deg : numpy.ndarray
            Command per frame (deg).
        hinge_moment_inlb : numpy.ndarray
            Hinge moment per frame (in·lb).
        preroll_frames : int
            Frames held at the first inputs before the record (fills the delay line).

        Returns
        -------
        outputs : dict
            Output → values at the frame boundaries (inputs + 1, time 0 first).
        seconds : float
            Wall time of the stepping.
        """
        jsbsim = self._jsbsim
        jsbsim.FGJSBBase().debug_lvl = 0
        fdm = jsbsim.FGFDMExec(str(self.root), None)
        fdm.set_debug_level(0)
        if not fdm.load_model("ema_host"):
            raise ExportError("JSBSim could not load the system")
        fdm.set_dt(1.0 / self.rate_hz)
        u0, h0 = float(command_deg[0]), float(hinge_moment_inlb[0])
        fdm[INPUT_COMMAND] = u0
        fdm[INPUT_HINGE_MOMENT] = h0
        fdm.run_ic()
        rest = rest_state(params, u0, h0)
        for _ in range(preroll_frames + 1):
            for slot, prop in STATE_PROPERTIES.items():
                fdm[prop] = float(rest[slot])
            fdm.run()
        for slot, prop in STATE_PROPERTIES.items():
            fdm[prop] = float(rest[slot])
        n = command_deg.size
        out = {k: np.empty(n + 1) for k in OUTPUTS}
        props = list(OUTPUTS.items())
        for k, prop in props:
            out[k][0] = fdm[prop]
        t0 = time.perf_counter()
        for i in range(n):
            fdm[INPUT_COMMAND] = float(command_deg[i])
            fdm[INPUT_HINGE_MOMENT] = float(hinge_moment_inlb[i])
            fdm.run()
            for k, prop in props:
                out[k][i + 1] = fdm[prop]
        return out, time.perf_counter() - t0

"""``ema verify``: an exported artefact against the truth model on the report's maneuvers, and its sign and units.

The truth is ema_sim's own model with the artefact's values (its manifest), driven by the same
inputs at the artefact's rate and sampled at every step. For each maneuver the rms and the largest
difference of every output are reported, with the steps per second of both. Section 4.5's lesson is
why the sign and unit check runs too: the hinge-moment sign error of 4.4.1 passed verification and
reached flight 2. A +1° command must read back what the truth reads (a sign flip reads −1°, a ±10 V
signal taken for degrees reads the calibration's volts per degree), and a hinge moment must move the
outputs the way the truth's move (a reversed sign moves them the other way): either failure names
the fault.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ema_sim.config import load_channel
from ema_sim.export.artefacts import OUTPUT_NAMES, Artefact, steps_per_second
from ema_sim.export.target import ExportTarget
from ema_sim.models.arrays import FloatArray
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import frame_inputs

DEFAULT_MANEUVERS: tuple[tuple[str, str | None], ...] = (
    ("steps:amps_deg=0.5/1/20,lead_s=0.2,hold_s=0.6", None),
    ("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=20,lead_s=0.5", None),
    ("schroeder:f0_hz=0.2,f1_hz=18,amp_deg=1,period_s=10,periods=2,lead_s=0.5", None),
    ("pid:sweep_s=10,gap_s=1", None),
    ("hold:value_deg=0,hold_s=6", "sine:amp_inlb=1780,freq_hz=0.5,cycles=3"),
    ("square:freq_hz=1,amp_deg=10,cycles=3,lead_s=0.2", "sine:amp_inlb=1000,freq_hz=0.7"),
)
"""(maneuver, load) pairs: section 2's steps, sweep, Schroeder multisine and PID sequence, a held command
under a sine hinge moment (2.9's load sine, faster), and rate-limited moves under a reversing load (K2)."""
EXACT_DEG = 1e-9
"""The default tolerance of an artefact that computes what its truth computes (the same kernel)."""
HINGE_MOMENT_INLB = 1000.0
"""The load of the hinge-moment check (in·lb)."""
STEP_DEG = 1.0
"""The command of the command check (deg)."""
RATIO_TOL = 0.02
"""How far the artefact's response may be from the truth's in the sign and unit checks (fraction)."""
NM_PER_INLB = 0.1129848290276167
HINGE_MOMENT_UNITS: dict[str, float] = {
    "the hinge moment given in N·m, taken as in·lb": NM_PER_INLB,
    "the hinge moment given in ft·lb, taken as in·lb": 1.0 / 12.0,
    "the hinge moment given in in·lb, taken as N·m": 1.0 / NM_PER_INLB,
    "the hinge moment given in in·lb, taken as ft·lb": 12.0,
}
"""The factors a hinge-moment unit mix-up scales the load by."""


@dataclass(frozen=True)
class Comparison:
    """One maneuver: the artefact's outputs against the truth's.

    Parameters
    ----------
    maneuver : str
        Its spec.
    load : str
        The load's spec (``none``).
    steps : int
        Steps taken.
    rms_deg : dict
        Output → rms difference (deg, deg/s for the rate).
    max_abs_deg : dict
        Output → largest difference.
    steps_per_s : float
        The artefact's steps per wall-clock second.
    truth_steps_per_s : float
        The truth's.
    """

    maneuver: str
    load: str
    steps: int
    rms_deg: dict[str, float]
    max_abs_deg: dict[str, float]
    steps_per_s: float
    truth_steps_per_s: float


@dataclass(frozen=True)
class Check:
    """One sign or unit check.

    Parameters
    ----------
    name : str
        ``command`` or ``hinge moment``.
    passed : bool
        Whether it passed.
    detail : str
        What was measured.
    fault : str or None
        The fault named when it failed (``sign``, ``units``...).
    """

    name: str
    passed: bool
    detail: str
    fault: str | None = None


@dataclass
class Verification:
    """Everything ``ema verify`` found about one artefact.

    Parameters
    ----------
    artefact : str
        Its path.
    kind : str
        ``fmu``, ``c`` or ``jsbsim``.
    target : ExportTarget
        What it says it is.
    tolerance_deg : float or None
        The largest difference allowed (None: reported, not judged).
    comparisons : list of Comparison
        One per maneuver.
    checks : list of Check
        The sign and unit checks.
    not_expressed : list of str
        Stages the artefact leaves out (a JSBSim system's).
    """

    artefact: str
    kind: str
    target: ExportTarget
    tolerance_deg: float | None
    comparisons: list[Comparison] = field(default_factory=list)
    checks: list[Check] = field(default_factory=list)
    not_expressed: list[str] = field(default_factory=list)

    @property
    def within_tolerance(self) -> bool:
        """Every difference within the tolerance (True when there is none)."""
        if self.tolerance_deg is None:
            return True
        return all(v <= self.tolerance_deg for c in self.comparisons for v in c.max_abs_deg.values())

    @property
    def passed(self) -> bool:
        """Within tolerance and every check passed."""
        return self.within_tolerance and all(c.passed for c in self.checks)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready.

        Returns
        -------
        dict
            The figures.
        """
        return {
            "artefact": self.artefact, "kind": self.kind, "model": self.target.model, "truth": self.target.truth,
            "channel": self.target.channel, "rate_hz": self.target.rate_hz, "tolerance_deg": self.tolerance_deg,
            "passed": self.passed, "not_expressed": self.not_expressed,
            "comparisons": [c.__dict__ for c in self.comparisons],
            "checks": [c.__dict__ for c in self.checks],
        }

    def lines(self) -> list[str]:
        """The report as text lines.

        Returns
        -------
        list of str
            A table of differences, then the checks and the verdict.
        """
        t = self.target
        out = [f"{self.artefact}: {self.kind} of {t.model} ({t.channel}) at {t.rate_hz:g} Hz against ema_sim's "
               f"{t.truth}"]
        out += [f"  not in the artefact: {', '.join(self.not_expressed)}"] if self.not_expressed else []
        head = f"  {'maneuver':58s} {'steps':>7s}" + "".join(f" {o + ' rms/max':>24s}" for o in OUTPUT_NAMES)
        out.append(head + f" {'steps/s':>10s} {'truth':>10s}")
        for c in self.comparisons:
            name = c.maneuver if c.load == "none" else f"{c.maneuver} + {c.load}"
            cells = "".join(f" {c.rms_deg[o]:11.3g} /{c.max_abs_deg[o]:10.3g}" for o in OUTPUT_NAMES)
            out.append(f"  {name[:58]:58s} {c.steps:7d}{cells} {c.steps_per_s:10.3g} {c.truth_steps_per_s:10.3g}")
        for ch in self.checks:
            out.append(f"  {'PASS' if ch.passed else 'FAIL'} {ch.name}: {ch.detail}")
        if self.tolerance_deg is None:
            out.append("  differences reported, not judged (no tolerance: give --tol)")
        else:
            worst = max((v for c in self.comparisons for v in c.max_abs_deg.values()), default=0.0)
            mark = "within" if self.within_tolerance else "OUTSIDE"
            out.append(f"  largest difference {worst:.3g}: {mark} the tolerance {self.tolerance_deg:g}")
        out.append("PASS" if self.passed else "FAIL")
        return out


Runner = Callable[[FloatArray, FloatArray], dict[str, FloatArray]]
"""Steps a model once per input (command, hinge moment) and returns its outputs at every step boundary."""


def truth_runner(target: ExportTarget) -> Callable[[FloatArray, FloatArray], tuple[dict[str, FloatArray], float]]:
    """The truth as a runner: ema_sim's model trimmed at the first inputs, an input breakpoint at every step.

    Parameters
    ----------
    target : ExportTarget
        What the artefact says it is.

    Returns
    -------
    callable
        ``run(command, hinge_moment) -> (outputs, seconds)``.
    """
    model = target.truth_model()
    dt = 1.0 / target.frame_hz

    def run(command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> tuple[dict[str, FloatArray], float]:
        n = command_deg.size
        t0 = time.perf_counter()
        model.trim(command_deg[0], hinge_moment_inlb[0])
        block = model.run_outputs(np.arange(n) * dt, command_deg, hinge_moment_inlb,
                                  sample_times=np.arange(n + 1) * dt, end_s=n * dt)[0]
        seconds = time.perf_counter() - t0
        return {o: block[:, i] for i, o in enumerate(OUTPUT_NAMES)}, seconds

    return run


def maneuver_inputs(maneuver: str, load: str | None, rate_hz: float,
                    duration_s: float | None = None) -> tuple[FloatArray, FloatArray]:
    """A maneuver's command and load at every step of the model's rate.

    Parameters
    ----------
    maneuver : str
        Maneuver spec (``ema_sim.signals``).
    load : str or None
        Load spec.
    rate_hz : float
        The model's rate.
    duration_s : float, optional
        Length (the maneuver's own by default).

    Returns
    -------
    command : numpy.ndarray
        deg.
    hinge_moment : numpy.ndarray
        in·lb.
    """
    inputs = frame_inputs(parse_maneuver(maneuver), parse_load(load) if load else None, duration_s=duration_s,
                          frame_hz=rate_hz)
    return inputs.command_deg, inputs.hinge_moment_inlb


def compare(artefact: Artefact, maneuver: str, load: str | None = None,
            duration_s: float | None = None) -> Comparison:
    """One maneuver through the artefact and the truth.

    Parameters
    ----------
    artefact : Artefact
        The exported model.
    maneuver : str
        Maneuver spec.
    load : str, optional
        Load spec.
    duration_s : float, optional
        Length (the maneuver's own by default).

    Returns
    -------
    Comparison
        The differences.
    """
    cmd, hm = maneuver_inputs(maneuver, load, artefact.rate_hz, duration_s)
    got = artefact.run(cmd, hm)
    truth, seconds = truth_runner(artefact.target)(cmd, hm)
    rms, worst = {}, {}
    for o in OUTPUT_NAMES:
        e = got[o] - truth[o]
        rms[o] = float(np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) else math.inf
        worst[o] = float(np.max(np.abs(e))) if np.all(np.isfinite(e)) else math.inf
    steps = cmd.size * artefact.target.steps_per_frame
    return Comparison(maneuver, load or "none", steps, rms, worst, steps_per_second(steps, artefact.seconds),
                      steps_per_second(steps, seconds))


def unit_ratios(channel: str) -> dict[str, float]:
    """The factors a degree/volt mix-up scales a reading by (the channel's ±10 V calibrations at zero).

    Parameters
    ----------
    channel : str
        The channel.

    Returns
    -------
    dict
        What was mixed → factor.
    """
    ch = load_channel(channel)
    cmd_v_per_deg = float(ch.deg_to_v(1.0) - ch.deg_to_v(0.0))
    fb_v_per_deg = float(ch.position_deg_to_v(1.0) - ch.position_deg_to_v(0.0))
    return {
        "the command given in volts, taken as degrees": cmd_v_per_deg,
        "the position read in volts, taken as degrees": fb_v_per_deg,
        "the command given in degrees, taken as volts": 1.0 / cmd_v_per_deg,
        "the position read in degrees, taken as volts": 1.0 / fb_v_per_deg,
    }


def name_ratio(ratio: float, channel: str) -> tuple[str, str]:
    """The fault a response ratio (artefact over truth) points to.

    Parameters
    ----------
    ratio : float
        The artefact's response over the truth's.
    channel : str
        The channel (its calibrations).

    Returns
    -------
    fault : str
        ``sign``, ``units`` or ``scale``.
    why : str
        In words.
    """
    if abs(ratio + 1.0) <= 0.05:
        return "sign", "the sign is flipped (the response is the truth's negated)"
    for what, k in unit_ratios(channel).items():
        for sign in (1.0, -1.0):
            if abs(ratio - sign * k) <= 0.05 * abs(k):
                return "units", f"degrees and volts mixed: {what} (ratio {ratio:.4g} ≈ {sign * k:.4g})"
    return "scale", f"the response is {ratio:.4g} times the truth's"


def _ratio(a: FloatArray, b: FloatArray) -> float:
    den = float(np.dot(b, b))
    return float(np.dot(a, b)) / den if den > 0.0 else math.nan


def command_check(run: Runner, truth: Runner, rate_hz: float, channel: str) -> Check:
    """A +1° step must read back what the truth reads (about +1°: the command error and quantizer move it).

    Parameters
    ----------
    run : callable
        The artefact (or integration) under test.
    truth : callable
        The truth.
    rate_hz : float
        The rate both step at.
    channel : str
        The channel (its calibrations name a unit mix-up).

    Returns
    -------
    Check
        Passed, or the fault named.
    """
    n = round(1.0 * rate_hz)
    cmd = np.where(np.arange(n) >= round(0.1 * rate_hz), STEP_DEG, 0.0)
    hm = np.zeros(n)
    got, ref = run(cmd, hm)["position_deg"], truth(cmd, hm)["position_deg"]
    tail = slice(-max(round(0.1 * rate_hz), 1), None)
    got_step = float(np.mean(got[tail]) - got[0])
    ref_step = float(np.mean(ref[tail]) - ref[0])
    detail = f"+{STEP_DEG:g}° reads {got_step:+.4f}° back (the truth {ref_step:+.4f}°)"
    if abs(ref_step - STEP_DEG) > 0.1 * STEP_DEG:
        return Check("command", False, detail + ": the truth itself does not read +1° back", "truth")
    ratio = got_step / ref_step
    if abs(ratio - 1.0) <= RATIO_TOL:
        return Check("command", True, detail)
    fault, why = name_ratio(ratio, channel)
    return Check("command", False, f"{detail}: {why}", fault)


def hinge_moment_check(run: Runner, truth: Runner, rate_hz: float, leaves_out: Sequence[str] = ()) -> Check:
    """An aiding hinge moment must move the outputs as the truth's: the surface toward the aiding side.

    The load steps to ±:data:`HINGE_MOMENT_INLB`, then a 10° command moves under it (the rate limit's K2
    term); the difference between the two loads is compared with the truth's difference.

    Parameters
    ----------
    run : callable
        The artefact (or integration) under test.
    truth : callable
        The truth.
    rate_hz : float
        The rate both step at.
    leaves_out : sequence of str
        Stages the artefact leaves out (said when the responses differ).

    Returns
    -------
    Check
        Passed, or ``sign``, ``units`` or ``scale`` named.
    """
    n = round(1.0 * rate_hz)
    k = np.arange(n)
    cmd = np.where(k >= round(0.3 * rate_hz), 10.0, 0.0)
    load = np.where(k >= round(0.05 * rate_hz), HINGE_MOMENT_INLB, 0.0)
    diffs, shifts = {}, {}
    before_move = round(0.29 * rate_hz)
    for name, runner in (("artefact", run), ("truth", truth)):
        up, down = runner(cmd, load), runner(cmd, -load)
        diffs[name] = np.concatenate([up[o] - down[o] for o in ("position_deg", "surface_deg")])
        shifts[name] = float(up["surface_deg"][before_move] - up["surface_deg"][0])
    static, got_static = shifts["truth"], shifts["artefact"]
    scale = float(np.max(np.abs(diffs["truth"])))
    if scale < 1e-9:
        return Check("hinge moment", True, "the model has no path from the hinge moment to its outputs: the check "
                                           "cannot see a sign")
    ratio = _ratio(diffs["artefact"], diffs["truth"])
    detail = (f"+{HINGE_MOMENT_INLB:g} in·lb moves the surface {got_static:+.4f}° (the truth {static:+.4f}°), "
              f"response {ratio:.4g}× the truth's")
    if static < 0.0:
        return Check("hinge moment", False, detail + ": the truth does not deflect toward the aiding side", "truth")
    if abs(ratio - 1.0) <= RATIO_TOL:
        return Check("hinge moment", True, detail)
    if ratio < 0.0:
        return Check("hinge moment", False, detail + ": the hinge-moment sign is flipped (an aiding load acts as an "
                                                     "opposing one, the fault of section 4.4.1)", "sign")
    for what, factor in HINGE_MOMENT_UNITS.items():
        if abs(ratio - factor) <= 0.05 * factor:
            return Check("hinge moment", False, f"{detail}: {what}", "units")
    why = (f"the artefact leaves out {', '.join(leaves_out)}" if leaves_out
           else "the load acts with the right sign but not by the truth's amount")
    return Check("hinge moment", False, f"{detail}: {why}", "scale")


def sign_and_units(artefact: Artefact) -> list[Check]:
    """The command and hinge-moment checks of an artefact.

    Parameters
    ----------
    artefact : Artefact
        The exported model.

    Returns
    -------
    list of Check
        Command, then hinge moment.
    """
    truth_run = truth_runner(artefact.target)

    def truth(cmd: FloatArray, hm: FloatArray) -> dict[str, FloatArray]:
        return truth_run(cmd, hm)[0]

    return [command_check(artefact.run, truth, artefact.rate_hz, artefact.target.channel),
            hinge_moment_check(artefact.run, truth, artefact.rate_hz, artefact.not_expressed)]


def verify(artefact: Artefact, maneuvers: Sequence[tuple[str, str | None]] = DEFAULT_MANEUVERS, *,
           tolerance_deg: float | None = None, duration_s: float | None = None) -> Verification:
    """Run the artefact and the truth on the maneuvers, then the sign and unit checks.

    Parameters
    ----------
    artefact : Artefact
        The exported model.
    maneuvers : sequence of (str, str or None)
        (maneuver, load) specs.
    tolerance_deg : float, optional
        Largest difference allowed; by default :data:`EXACT_DEG` when the artefact computes its truth's
        kernel with every stage, else none (reported only).
    duration_s : float, optional
        Cut every maneuver to this length.

    Returns
    -------
    Verification
        The figures and the verdict.
    """
    t = artefact.target
    if tolerance_deg is None and t.truth == t.model and not artefact.not_expressed:
        tolerance_deg = EXACT_DEG
    result = Verification(str(artefact.path), artefact.kind, t, tolerance_deg,
                          not_expressed=list(artefact.not_expressed))
    for maneuver, load in maneuvers:
        result.comparisons.append(compare(artefact, maneuver, load, duration_s))
    result.checks = sign_and_units(artefact)
    return result

"""The tests of section 2 as plans: which channel gets which command and which load, for how long.

A plan drives one or more channels; every other channel is held at 0° (the FMU commands every
actuator every frame). Each test is named as in the report and has defaults from it; the maneuver
and the load of the driven channels can be overridden with spec strings. Dynamic tests (threshold,
crosstalk, timing, regeneration, steps, sweeps, Schroeder sweeps, the PID sequence) honour the 60 s
limit of section 2.7: a longer one is refused with the way to shorten it.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.config import CHANNELS, load_channel
from ema_sim.errors import SpecError, UnknownNameError
from ema_sim.signals.loads import Load, NoLoad, parse_load
from ema_sim.signals.maneuvers import Maneuver, parse_maneuver
from ema_sim.signals.spec import split

FloatArray = NDArray[np.float64]
DYNAMIC_LIMIT_S = 60.0
"""Section 2.7: dynamic tests were limited to 60 s each."""
SURFACES4 = ("right_wing", "left_wing", "right_rudder", "left_rudder")
"""The four surfaces of the crosstalk matrices, tables 2 and 3 (column order)."""
CROSSTALK_SQUARE = "square:freq_hz=2,amp_deg=8,cycles=20,lead_s=0.5"
"""Dynamic channels of the crosstalk tests: the largest, fastest square wave that still follows
(8° steps slew in 0.14 s of a 0.25 s half period at 115.8 °/s): just below saturation (2.2.1)."""


@dataclass(frozen=True)
class Preset:
    """A section-2 test: where it is in the report, its default signals, whether it is dynamic."""

    section: str
    title: str
    maneuver: str
    load: str = "none"
    dynamic: bool = True


PRESETS: dict[str, Preset] = {
    "static_threshold": Preset("2.1.1", "static threshold: slow triangles of rising amplitude",
                               "static_threshold", dynamic=False),
    "dynamic_threshold": Preset("2.1.2", "dynamic threshold: 5 Hz sine from 1 % FS upward",
                                "dynamic_threshold:ramp_s=30"),
    "static_crosstalk": Preset("2.2.1", "static crosstalk (table 2): observed channel held, three others square",
                               "hold:value_deg=0,hold_s=10"),
    "dynamic_crosstalk": Preset("2.2.2", "dynamic crosstalk (table 3): observed 0.5 Hz triangle, three others square",
                                "triangle:freq_hz=0.5,amp_deg=2.15,cycles=5"),
    "timing": Preset("2.3", "command-to-surface timing: 1 Hz square, 10 % of travel", "square:freq_hz=1,amp_deg=4.3"),
    "free_play": Preset("2.4", "free play: surface at 0°, small load reversed", "hold:value_deg=0,hold_s=11",
                        "reversal:inlb=50,period_s=2,reversals=4", dynamic=False),
    "regen": Preset("2.5", "voltage regeneration: 5 % FS square swept 0.1–5 Hz", "regen:sweep_s=59"),
    "calibration": Preset("2.6", "calibration staircase ±40° in 5° steps", "staircase", dynamic=False),
    "steps": Preset("2.7", "steps 0.5°, 1°, 20°", "steps:amps_deg=0.5/1/20"),
    "sweep": Preset("2.7", "sine sweep 0.2–18 Hz (±1°; ±0.4° with amp_deg=0.4)",
                    "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=58,lead_s=1"),
    "schroeder": Preset("2.7", "Schroeder sweep 0.2–18 Hz", "schroeder:f0_hz=0.2,f1_hz=18,amp_deg=1,period_s=20"),
    "ramp": Preset("2.7", "slow ramp 0 → 2 → 0° at 0.01 °/s (0.005 with rate_dps=0.005)",
                   "ramp:rate_dps=0.01,peak_deg=2", dynamic=False),
    "compliance": Preset("2.8", "compliance: load staircase ±1780 in·lb (wings), ±470 (rudders)", "hold:value_deg=0",
                         "steps:step_inlb=222.5,max_inlb=1780,hold_s=2", dynamic=False),
    "hysteresis": Preset("2.9", "hysteresis: three sinusoidal load cycles at 0.0125 Hz", "hold:value_deg=0",
                         "sine:amp_inlb=1780,freq_hz=0.0125,cycles=3", dynamic=False),
    "pid": Preset("2.10", "PID maneuver sequence of figure 20: doublet, sweep, Schroeder", "pid"),
}
MANEUVER_TESTS = {
    "static_threshold": "static_threshold", "dynamic_threshold": "dynamic_threshold", "square": "timing",
    "regen": "regen", "staircase": "calibration", "step": "steps", "steps": "steps", "sweep": "sweep",
    "schroeder": "schroeder", "ramp": "ramp", "pid": "pid",
}
"""The test a bare maneuver belongs to (others are ``custom``)."""
RUDDER_MAX_INLB = 470.0
"""Section 2.8: rudders were loaded to ±470 in·lb (wings ±1780)."""
RUDDER_HYSTERESIS_INLB = 400.0
"""Section 2.9: rudders ±100, 200, ±400 in·lb."""


@dataclass(frozen=True)
class ChannelPlan:
    """What one driven channel gets."""

    maneuver: Maneuver
    load: Load


@dataclass(frozen=True)
class TestPlan:
    """A test of section 2 on chosen channels."""

    test: str
    section: str
    title: str
    channel: str
    """The primary channel: the driven one, or the observed one of a crosstalk test."""
    channels: dict[str, ChannelPlan]
    duration_s: float
    dynamic: bool

    def command_deg(self, channel: str, t: ArrayLike) -> FloatArray:
        """Command of ``channel`` at times ``t`` (0° for a channel the test does not drive).

        Parameters
        ----------
        channel : str
            Channel name.
        t : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            Command (deg).
        """
        t = np.asarray(t, dtype=float)
        plan = self.channels.get(channel)
        return np.zeros_like(t) if plan is None else plan.maneuver.command_deg(t)

    def hinge_moment_inlb(self, channel: str, t: ArrayLike) -> FloatArray:
        """Load of ``channel`` at times ``t``.

        Parameters
        ----------
        channel : str
            Channel name.
        t : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            Hinge moment (in·lb).
        """
        t = np.asarray(t, dtype=float)
        plan = self.channels.get(channel)
        return np.zeros_like(t) if plan is None else plan.load.hinge_moment_inlb(t, plan.maneuver.command_deg(t))

    def metadata(self) -> dict[str, str]:
        """The bag's test metadata (data-contract keys plus the per-channel signals)."""
        main = self.channels[self.channel]
        return {
            "test": self.test,
            "section": self.section,
            "title": self.title,
            "channel": self.channel,
            "channels": ",".join(self.channels),
            "maneuver": main.maneuver.spec(),
            "load": main.load.spec(),
            "duration_s": f"{self.duration_s:g}",
            "dynamic": str(self.dynamic).lower(),
            "plan": json.dumps({ch: {"maneuver": p.maneuver.spec(), "load": p.load.spec()}
                                for ch, p in self.channels.items()}),
        }


def channel_list(names: Sequence[str]) -> list[str]:
    """Channel names from repeatable, comma-separated arguments (``all``: the five).

    Parameters
    ----------
    names : sequence of str
        The arguments.

    Returns
    -------
    list of str
        Channel names, each once, in the order given.
    """
    out: list[str] = []
    for name in names:
        for item in (n.strip() for n in name.split(",")):
            if item == "all":
                out.extend(c for c in CHANNELS if c not in out)
            elif item:
                if item not in CHANNELS:
                    raise UnknownNameError("channel", item, CHANNELS)
                if item not in out:
                    out.append(item)
    return out


def build_plan(test: str | None = None, *, maneuver: str | None = None, load: str | None = None,
               channels: Sequence[str] = ("left_wing",), duration_s: float | None = None) -> TestPlan:
    """A plan from a test spec (``steps``, ``static_crosstalk:observed=right_wing``...) and/or a maneuver.

    ``maneuver`` and ``load`` override the test's defaults for the driven channels; without ``test``
    the maneuver's kind names the test.

    Parameters
    ----------
    test : str, optional
        Test spec (``ema tests`` lists them).
    maneuver : str, optional
        Maneuver spec for the driven channels.
    load : str, optional
        Load spec for the driven channels.
    channels : sequence of str
        The driven channels (``all`` for five).
    duration_s : float, optional
        Length of the plan (s); the test's own otherwise.

    Returns
    -------
    TestPlan
        Each channel's maneuver and load.
    """
    if test is None and maneuver is None:
        raise SpecError("give a test or a maneuver")
    fields: dict[str, str] = {}
    if test is None:
        name = MANEUVER_TESTS.get(parse_maneuver(maneuver or "").kind, "custom")
    else:
        name, fields = split(test, "test")
        if name not in PRESETS:
            raise UnknownNameError("test", name, PRESETS)
    preset = PRESETS.get(name, Preset("2", "custom maneuver", maneuver or "hold", dynamic=False))
    allowed = {"observed", "observed_deg"} if name.endswith("crosstalk") else {"position_deg"}
    unknown = set(fields) - allowed
    if unknown:
        raise SpecError(f"test {name!r}: unknown field {sorted(unknown)[0]!r} (fields: {', '.join(sorted(allowed))})")
    driven = channel_list(channels) or ["left_wing"]
    if name.endswith("crosstalk"):
        primary, plans = _crosstalk(name, preset, fields, driven, maneuver, load)
    else:
        plans = {}
        for ch in driven:
            man_spec = maneuver or preset.maneuver
            if "position_deg" in fields:
                man_spec = f"hold:value_deg={_number(name, fields['position_deg']):g}"
            plans[ch] = ChannelPlan(parse_maneuver(man_spec), parse_load(load or _load_for(preset, name, ch)))
        primary = driven[0]
    natural = max(max(p.maneuver.duration_s, p.load.duration_s) for p in plans.values())
    if name in ("compliance", "hysteresis", "free_play"):
        natural = max(p.load.duration_s for p in plans.values()) + 1.0
    duration = natural if duration_s is None else float(duration_s)
    if not duration > 0.0:
        raise SpecError(f"duration must be positive, got {duration:g} s")
    if preset.dynamic and duration > DYNAMIC_LIMIT_S + 1e-9:
        raise SpecError(
            f"test {name!r} lasts {duration:g} s; section 2.7 limits dynamic tests to {DYNAMIC_LIMIT_S:g} s "
            "(shorten the maneuver or give a duration of at most 60 s)")
    return TestPlan(name, preset.section, preset.title, primary, plans, duration, preset.dynamic)


def _crosstalk(name: str, preset: Preset, fields: dict[str, str], driven: list[str], maneuver: str | None,
               load: str | None) -> tuple[str, dict[str, ChannelPlan]]:
    """Tables 2 and 3: the observed channel gets the test's signal, the other three surfaces square waves."""
    observed = fields.get("observed", driven[0] if driven[0] in SURFACES4 else "right_wing")
    if observed not in SURFACES4:
        raise SpecError(f"test {name!r}: observed must be one of {', '.join(SURFACES4)} (tables 2 and 3)")
    man = preset.maneuver
    if "observed_deg" in fields:
        value = _number(name, fields["observed_deg"])
        man = f"hold:value_deg={value:g},hold_s=10" if name == "static_crosstalk" else f"{man},bias_deg={value:g}"
    plans = {observed: ChannelPlan(parse_maneuver(maneuver or man), parse_load(load or "none"))}
    for other in SURFACES4:
        if other != observed:
            plans[other] = ChannelPlan(parse_maneuver(CROSSTALK_SQUARE), NoLoad())
    return observed, plans


def _number(test: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise SpecError(f"test {test!r}: expected a number, got {text!r}") from None


def _load_for(preset: Preset, name: str, channel: str) -> str:
    """The report's load levels differ for rudders (sections 2.8 and 2.9)."""
    if load_channel(channel).surface != "rudder":
        return preset.load
    if name == "compliance":
        return preset.load.replace("max_inlb=1780", f"max_inlb={RUDDER_MAX_INLB:g}")
    if name == "hysteresis":
        return preset.load.replace("amp_inlb=1780", f"amp_inlb={RUDDER_HYSTERESIS_INLB:g}")
    return preset.load


def test_help() -> str:
    """Every test with its section and defaults."""
    lines = []
    for name, p in PRESETS.items():
        extra = " (fields: observed=<surface>, observed_deg=<deg>)" if name.endswith("crosstalk") else ""
        lines.append(f"{name:18s} §{p.section:6s} {p.title}{extra}\n    maneuver {p.maneuver}; load {p.load}"
                     f"{'; ≤ 60 s' if p.dynamic else ''}")
    return "\n".join(lines)


def as_json(plan: TestPlan) -> dict[str, str]:
    """The plan's metadata as plain JSON.

    Parameters
    ----------
    plan : TestPlan
        The plan.

    Returns
    -------
    dict
        Its metadata.
    """
    return dict(plan.metadata())

"""The report's campaigns, built in: each a campaign mapping (the YAML form) and what it finds afterwards.

* ``second-order-bounds`` (3.1.1, figures 23-24): ωn, ζ and delay uniform over the spread of the test
  estimates (``--analysis`` JSON of ``ema analyze``) or the declared figure-23 box → gain and phase
  envelopes over 0.1-20 Hz (a Schroeder multisine read at its harmonics), −3 dB bandwidth and −90°
  frequency distributions, step-response envelopes; checked against the analytic second order at the
  corners of the box.
* ``command-error`` (3.1.2.2, figures 27-28): the four Kb/offset corners (the largest |Kb| and |offset|
  of the four control surfaces' calibrations, or of ``--analysis`` calibrations) on a calibration
  staircase → the settled error against angle; checked against the four-corner lines.
* ``compliance-bounds`` (3.2.1, 3.4, figure 35): HOAD3 anywhere between its lower and upper compliance
  curves under loads up to the section-2.8 test load → sine-dwell responses → the LOES parameters'
  distribution (the report's use of LOES in linear Monte Carlo); the LOES of the mean curve unloaded
  checked against ``ema loes``.
* ``ail-dither`` (2.10, 4.3): the AIL set-up's delay, lag corner, quantization, noise level and bungee,
  and the PWM dead band, dispersed around their configured values → the probability of dither, its
  size, and which elements it depends on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ema_sim.ail.params import WINGS
from ema_sim.analysis.studies.loes import fit_band, fit_loes
from ema_sim.calibration import CommandError, four_corner_bounds
from ema_sim.config import load_channel
from ema_sim.errors import UnknownNameError
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models.high_order.params import HighOrderParams
from ema_sim.montecarlo import output
from ema_sim.montecarlo.campaign import Campaign
from ema_sim.montecarlo.summary import merged_envelopes

BANDWIDTH_AT_HZ = (1.0, 2.0, 5.0, 8.0, 10.0)
FOUR_SURFACES = ("left_wing", "right_wing", "left_rudder", "right_rudder")
"""The four control surfaces whose calibrations set section 3.1.2.2's Kb/offset bounds (not the cowl door)."""


def _bounds(key: str, analysis: Mapping[str, tuple[float, float]] | None) -> str:
    return "analysis" if analysis and key in analysis else "report"


def second_order_bounds(channel: str, analysis: Mapping[str, tuple[float, float]] | None) -> JsonObject:
    """The ``second-order-bounds`` campaign mapping.

    Parameters
    ----------
    channel : str
        The channel.
    analysis : mapping, optional
        Spread from ``ema analyze`` JSON (else the declared uncertainty).

    Returns
    -------
    dict
        The campaign's YAML form.
    """
    return {
        "campaign": "second-order-bounds",
        "description": "ωn, ζ and delay uniform over the spread of the test estimates (figure 23): frequency and "
                       "step-response envelopes of the basic second order plus delay (figure 24)",
        "model": "second_order", "channel": channel,
        "experiments": {
            "response": {"multisine": "schroeder:f0_hz=0.1,f1_hz=20,amp_deg=0.5,period_s=10,periods=2,lead_s=0",
                         "frame_hz": 1000.0},
            "step": {"maneuver": "step:amp_deg=1,lead_s=0.1,hold_s=1.4,back=false", "frame_hz": 1000.0,
                     "sample_hz": 1000.0},
        },
        "dispersions": [{"parameter": k, "uniform": _bounds(k, analysis)} for k in ("wn_rad_s", "zeta", "delay_s")],
        "metrics": [{"metric": "bandwidth_3db", "experiment": "response"},
                    {"metric": "phase_90", "experiment": "response"},
                    {"metric": "gain_phase", "experiment": "response", "at_hz": [*BANDWIDTH_AT_HZ]},
                    {"metric": "step", "experiment": "step"},
                    {"metric": "error", "experiment": "step"}],
        "batch": 100,
    }


def command_error_corners() -> tuple[float, float]:
    """The largest |Kb| and |offset| over the four control surfaces' configured calibrations (3.1.2.2).

    Returns
    -------
    tuple of float
        |Kb|, |offset| (deg).
    """
    sections = [load_channel(ch).section("second_order") for ch in FOUR_SURFACES]
    return max(abs(float(s["kb"])) for s in sections), max(abs(float(s["offset_deg"])) for s in sections)


def command_error(channel: str, analysis: Mapping[str, tuple[float, float]] | None) -> JsonObject:
    """The ``command-error`` campaign mapping.

    Parameters
    ----------
    channel : str
        The channel whose LOADA runs the staircase.
    analysis : mapping, optional
        ``kb``/``offset_deg`` bounds from ``ema analyze`` calibrations (else the four surfaces' configured ones).

    Returns
    -------
    dict
        The campaign's YAML form.
    """
    if analysis and "kb" in analysis and "offset_deg" in analysis:
        box: list[JsonValue] = [[*analysis["kb"]], [*analysis["offset_deg"]]]
    else:
        kb, off = command_error_corners()
        box = [[-kb, kb], [-off, off]]
    return {
        "campaign": "command-error",
        "description": "the four Kb/offset corners (section 3.1.2.2) on a calibration staircase: the settled error "
                       "against angle, the Monte Carlo command-error bounds (figures 27-28)",
        "model": "loada", "channel": channel,
        "experiments": {"staircase": {"maneuver": "staircase:step_deg=5,max_deg=40,hold_s=2", "sample_hz": 200.0}},
        "dispersions": [{"parameters": ["kb", "offset_deg"], "corners": box}],
        "metrics": ["settled_error"],
        "batch": 4,
    }


def test_load_inlb(channel: str) -> float:
    """The section-2.8 test load of a channel (wings and cowl 1,780 in·lb, rudders 470): its HOAD3 reference load.

    Parameters
    ----------
    channel : str
        The channel.

    Returns
    -------
    float
        in·lb.
    """
    return float(HighOrderParams.from_channel(load_channel(channel)).hysteresis_reference_load_inlb)


def compliance_bounds(channel: str, analysis: Mapping[str, tuple[float, float]] | None) -> JsonObject:
    """The ``compliance-bounds`` campaign mapping.

    Parameters
    ----------
    channel : str
        The channel.
    analysis : mapping, optional
        Unused (the compliance bounds are HOAD3's curves).

    Returns
    -------
    dict
        The campaign's YAML form.
    """
    del analysis
    freq, amp = fit_band(channel)
    return {
        "campaign": "compliance-bounds",
        "description": "HOAD3 between its lower and upper compliance curves (figure 35) under loads up to the 2.8 "
                       "test load: sine-dwell responses and the LOES fitted to each (sections 3.2.1, 3.4)",
        "model": "hoad3", "channel": channel, "options": {"noise": False},
        "experiments": {"dwells": {"dwell": [float(f) for f in freq], "amp_deg": float(amp), "load_inlb": 0.0}},
        "dispersions": [{"parameter": "bound", "uniform": [-1.0, 1.0]},
                        {"parameter": "dwells.load_inlb", "uniform": [0.0, test_load_inlb(channel)]}],
        "metrics": ["loes", "bandwidth_3db", "phase_90", {"metric": "gain_phase", "at_hz": [1.0, 5.0, 10.0]}],
        "batch": 2,
    }


def ail_dither(channel: str, analysis: Mapping[str, tuple[float, float]] | None) -> JsonObject:
    """The ``ail-dither`` campaign mapping.

    Parameters
    ----------
    channel : str
        Unused (both wings are measured).
    analysis : mapping, optional
        Unused.

    Returns
    -------
    dict
        The campaign's YAML form.
    """
    del channel, analysis
    return {
        "campaign": "ail-dither",
        "description": "closed-loop AIL with its delay, lag corner, quantization, noise level and bungee, and the "
                       "PWM dead band dispersed (section 4.3): probability of dither, its size, what it depends on",
        "kind": "ail", "model": "hoad3", "profile": "ail", "duration_s": 24.0,
        "dispersions": [
            {"parameter": "command.delay_s", "uniform": [0.013, 0.039]},
            {"parameter": "environment.lag_hz", "uniform": [25.0, 100.0]},
            {"parameter": "environment.quantization_v", "uniform": [0.0, 0.010]},
            {"parameter": "environment.noise_rms_v", "uniform": [0.0005, 0.006]},
            {"parameter": "setup.bungee_inlb", "uniform": [0.0, 100.0]},
            {"parameter": "pwm_dead_band_v", "uniform": [4.85, 14.55]},
        ],
        "metrics": ["dither"],
        "batch": 2,
    }


BUILTIN: dict[str, Callable[[str, Mapping[str, tuple[float, float]] | None], JsonObject]] = {
    "second-order-bounds": second_order_bounds, "command-error": command_error,
    "compliance-bounds": compliance_bounds, "ail-dither": ail_dither,
}
"""Name → the function that writes the campaign mapping."""


def builtin_campaign(name: str, channel: str = "left_wing",
                     analysis: Mapping[str, tuple[float, float]] | None = None) -> JsonObject:
    """A built-in campaign's mapping by name (an unknown name lists the known ones).

    Parameters
    ----------
    name : str
        One of :data:`BUILTIN`.
    channel : str
        The channel.
    analysis : mapping, optional
        Bounds from ``ema analyze`` JSON.

    Returns
    -------
    dict
        The campaign's YAML form.
    """
    if name not in BUILTIN:
        raise UnknownNameError("campaign", name, BUILTIN)
    return BUILTIN[name](channel, analysis)


# ------------------------------------------------------------------------------------------- findings
def second_order_bandwidth_hz(wn_rad_s: float, zeta: float) -> float:
    """The analytic −3 dB bandwidth of ωn²/(s² + 2ζωn·s + ωn²) (a delay leaves the gain alone).

    Parameters
    ----------
    wn_rad_s : float
        ωn.
    zeta : float
        ζ.

    Returns
    -------
    float
        Hz.
    """
    a = 1.0 - 2.0 * zeta**2
    return wn_rad_s * math.sqrt(a + math.sqrt(a * a + 1.0)) / (2.0 * math.pi)


def second_order_phase90_hz(wn_rad_s: float, zeta: float, delay_s: float) -> float:
    """Where the phase of the second order plus delay passes −90° (bisection).

    Parameters
    ----------
    wn_rad_s : float
        ωn.
    zeta : float
        ζ.
    delay_s : float
        τ.

    Returns
    -------
    float
        Hz.
    """
    def phase(w: float) -> float:
        return -math.atan2(2.0 * zeta * wn_rad_s * w, wn_rad_s**2 - w * w) - w * delay_s + math.pi / 2.0

    lo, hi = 1e-3, wn_rad_s
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if phase(mid) > 0.0 else (lo, mid)
    return 0.5 * (lo + hi) / (2.0 * math.pi)


def _box(c: Campaign) -> dict[str, tuple[float, float]]:
    return {n: (float(lo), float(hi)) for d in c.dispersions if d.kind in ("uniform", "corners")
            for n, lo, hi in zip(d.names, d.low, d.high, strict=True)}


def findings_second_order(c: Campaign, out: Path) -> JsonObject:
    """The spread of bandwidth and −90° frequency against the analytic second order at the box's corners.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory.

    Returns
    -------
    dict
        For each figure: the campaign's min and max and the analytic corner values.
    """
    box = _box(c)
    (w0, w1), (z0, z1) = box["wn_rad_s"], box["zeta"]
    d0, d1 = box.get("delay_s", (0.0, 0.0))
    bw = output.read_column(out, "response.bandwidth_3db_hz")
    p90 = output.read_column(out, "response.phase_minus_90_hz")
    return {
        "bandwidth_3db_hz": {"campaign_min": float(np.nanmin(bw)), "campaign_max": float(np.nanmax(bw)),
                             "analytic_min (ωn low, ζ high)": second_order_bandwidth_hz(w0, z1),
                             "analytic_max (ωn high, ζ low)": second_order_bandwidth_hz(w1, z0)},
        "phase_minus_90_hz": {"campaign_min": float(np.nanmin(p90)), "campaign_max": float(np.nanmax(p90)),
                              "analytic_min (ωn low, ζ high, τ high)": second_order_phase90_hz(w0, z1, d1),
                              "analytic_max (ωn high, ζ low, τ low)": second_order_phase90_hz(w1, z0, d0)},
        "box": {k: list(v) for k, v in box.items()},
    }


def findings_command_error(c: Campaign, out: Path) -> JsonObject:
    """The settled error's range at each angle against section 3.1.2.2's four-corner lines.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory.

    Returns
    -------
    dict
        Angles, the campaign's lowest and highest error, the four-corner bounds and the largest difference.
    """
    box = _box(c)
    cols = [n for n in output.column_names(out) if n.startswith("error_deg@")]
    angles = np.array([float(n.split("@")[1].removesuffix("deg")) for n in cols])
    order = np.argsort(angles)
    angles = angles[order]
    lo = np.array([np.nanmin(output.read_column(out, cols[i])) for i in order])
    hi = np.array([np.nanmax(output.read_column(out, cols[i])) for i in order])
    kb, off = max(np.abs(box["kb"])), max(np.abs(box["offset_deg"]))
    blo, bhi = four_corner_bounds([CommandError(kb, off)], angles)
    return {"angle_deg": angles.tolist(), "campaign_lower_deg": lo.tolist(), "campaign_upper_deg": hi.tolist(),
            "four_corner_lower_deg": blo.tolist(), "four_corner_upper_deg": bhi.tolist(),
            "kb_max_abs": kb, "offset_max_abs_deg": off,
            "max_difference_deg": float(max(np.max(np.abs(lo - blo)), np.max(np.abs(hi - bhi))))}


def findings_compliance(c: Campaign, out: Path) -> JsonObject:
    """The LOES parameters' spread, and the nominal (mean curve, unloaded) LOES against ``ema loes``.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory.

    Returns
    -------
    dict
        The nominal run's LOES, ``ema loes``'s fit of the channel, and their largest difference.
    """
    _, nominal, _, _, _ = merged_envelopes(out)
    ref = fit_loes(c.channel).coefficients
    pairs = {"loes_wn_rad_s": "wn_rad_s", "loes_zeta": "zeta", "loes_delay_s": "delay_s", "loes_gain": "dc_gain_ratio"}
    nom = {k: nominal.get(k, math.nan) for k in pairs}
    diff = max(abs(nom[k] - ref[v]) for k, v in pairs.items())
    return {"nominal_loes": _json(nom), "ema_loes": {k: ref[v] for k, v in pairs.items()}, "max_abs_difference": diff,
            "loes_ranges": {k: [float(np.nanmin(v)), float(np.nanmax(v))] for k in pairs
                            for v in [output.read_column(out, k)]}}


def _json(values: Mapping[str, float | None]) -> JsonObject:
    """Named numbers as a JSON object (a dict of floats is one, but ``dict`` is invariant in its values)."""
    return dict(values)


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return math.nan, math.nan
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return centre - half, centre + half


LARGE_OSCILLATION_DEG = 0.5
"""Peak to peak above which a limit cycle is not the AIL dither (≈ 0.1°, 4.3) but the loop near instability."""


def findings_ail(c: Campaign, out: Path) -> JsonObject:
    """Probability of dither over wing-runs, its size, and each dispersed element's effect.

    A wing-run is one of three: **dither** (the :mod:`ema_sim.ail.measure` verdict with a peak to peak of at
    most :data:`LARGE_OSCILLATION_DEG`), a **large oscillation** (a limit cycle above it: the vehicle loop
    near instability, not section 4.3's dither) or **none**.

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory.

    Returns
    -------
    dict
        Each category's probability (with a 95 % Wilson interval), peak to peak and frequency of the
        dithering wings, and per parameter each category's probability in the lower and upper third of its
        range.
    """
    verdict = np.concatenate([output.read_column(out, f"{w}.dither") for w in WINGS]) > 0.5
    pp = np.concatenate([output.read_column(out, f"{w}.pp_deg") for w in WINGS])
    freq = np.concatenate([output.read_column(out, f"{w}.freq_hz") for w in WINGS])
    large = verdict & (pp > LARGE_OSCILLATION_DEG)
    cats = {"dither": verdict & ~large, "large_oscillation": large, "none": ~verdict}
    n = int(pp.size)
    box = _box(c)
    effect: JsonObject = {}
    for p in c.parameters:
        x = np.tile(output.read_column(out, p), len(WINGS))
        lo, hi = box[p]
        thirds = {"lower_third": x <= lo + (hi - lo) / 3.0, "upper_third": x >= hi - (hi - lo) / 3.0}
        row: JsonObject = {f"p_{cat}_{where}": float(np.mean(mask[sel])) if sel.any() else None
                           for cat, mask in cats.items() for where, sel in thirds.items()}
        row.update({f"pp_median_dither_{where}_deg": float(np.median(pp[sel & cats["dither"]]))
                    if (sel & cats["dither"]).any() else None for where, sel in thirds.items()})
        effect[p] = row
    doc: JsonObject = {"wing_runs": n, "large_oscillation_above_deg": LARGE_OSCILLATION_DEG}
    for cat, mask in cats.items():
        k = int(mask.sum())
        doc[cat] = {"count": k, "probability": k / n if n else None, "probability_95": list(_wilson(k, n))}
    doc["pp_deg_dither"] = _json(output.statistics(pp[cats["dither"]]))
    doc["freq_hz_dither"] = _json(output.statistics(freq[cats["dither"]]))
    doc["pp_deg_large_oscillation"] = _json(output.statistics(pp[large]))
    doc["freq_hz_large_oscillation"] = _json(output.statistics(freq[large]))
    doc["by_parameter"] = effect
    return doc


FINDINGS: dict[str, Callable[[Campaign, Path], JsonObject]] = {
    "second-order-bounds": findings_second_order, "command-error": findings_command_error,
    "compliance-bounds": findings_compliance, "ail-dither": findings_ail,
}
"""Built-in campaign → what it concludes and cross-checks after the runs."""


def findings(c: Campaign, out: Path, names: Sequence[str] | None = None) -> JsonObject:
    """The conclusions of a built-in campaign (empty for a YAML one).

    Parameters
    ----------
    c : Campaign
        The campaign.
    out : pathlib.Path
        Its directory.
    names : sequence of str, optional
        Override of which findings apply (default: the campaign's name).

    Returns
    -------
    dict
        The findings.
    """
    out_: JsonObject = {}
    for name in names or [c.name]:
        if name in FINDINGS:
            out_.update(FINDINGS[name](c, out))
    return out_

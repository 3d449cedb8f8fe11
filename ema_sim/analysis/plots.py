"""PNG plots of ``ema analyze --report`` (matplotlib, Agg backend: no display needed).

One figure per result, drawn the way the report draws it: Bode plots with coherence and the fitted
second order overlaid (figures 24, 25), step responses against the fit (figure 22), the spread of
estimates (figure 23), command error and its four-corner bounds (figure 27), compliance curves
(figure 16) and the three-segment model (figure 35), hysteresis loops (figure 17), and time
histories for timing, thresholds, crosstalk, dither, free play and regeneration.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ema_sim.analysis.frequency_response import low_frequency_gain_db
from ema_sim.analysis.pipeline import RecordAnalysis
from ema_sim.analysis.second_order_fit import response, simulate

COLORS = {"position_deg": "tab:blue", "surface_deg": "tab:orange", "model": "tab:green", "fit": "k"}
SEGMENT_COLORS = ("#e8f0fe", "#fde8e8", "#e8fde9", "#fdf6e3", "#f1e8fd")


def _plt() -> Any:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def _save(fig: Any, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path.name


def _overview(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    d = ra.data
    t = d.time_s
    loaded = d.hinge_moment_inlb is not None and bool(np.ptp(d.hinge_moment_inlb) > 0)
    rows = 2 + loaded
    fig, ax = plt.subplots(rows, 1, figsize=(10, 2.2 * rows + 0.5), sharex=True)
    ax[0].plot(t, d.command_deg, color="0.3", lw=0.8, label="command")
    for name in d.outputs:
        ax[0].plot(t, getattr(d, name), color=COLORS[name], lw=0.7, label=name)
    ax[0].set_ylabel("deg")
    ax[0].legend(loc="upper right", fontsize=8)
    main = d.position_deg if d.position_deg is not None else d.surface_deg
    ax[1].plot(t, main - d.command_deg, color="tab:red", lw=0.6)
    ax[1].set_ylabel("output − command, deg")
    if loaded:
        assert d.hinge_moment_inlb is not None
        ax[2].plot(t, d.hinge_moment_inlb, color="tab:purple", lw=0.8)
        ax[2].set_ylabel("hinge moment, in·lb")
    for k, s in enumerate(ra.recognition.segments):
        for a in ax:
            a.axvspan(t[s.start], t[s.stop - 1], color=SEGMENT_COLORS[k % len(SEGMENT_COLORS)], zorder=0)
        ax[0].text(t[s.start], ax[0].get_ylim()[1], f" {s.kind}", va="top", fontsize=8)
    ax[-1].set_xlabel("time, s")
    ax[0].set_title(f"{Path(d.source).name or 'record'}: {ra.channel.channel}")
    return _save(fig, path)


def _bode(ra: RecordAnalysis, j: int, path: Path) -> str:
    plt = _plt()
    fr = ra.frequency[j]
    r = fr.response
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.4]})
    color = COLORS.get(r.output, "tab:blue")
    ax[0].semilogx(r.freq_hz, r.gain_db, color=color, lw=1.2, label=f"measured ({r.output})")
    ax[1].semilogx(r.freq_hz, r.phase_deg, color=color, lw=1.2)
    ax[2].semilogx(r.freq_hz, r.coherence, color=color, lw=1.0)
    if fr.fit:
        f = fr.fit
        h = response(r.freq_hz, f.wn_rad_s.value, f.zeta.value, f.delay_s.value, f.gain.value)
        lab = f"2nd order: ωn {f.wn_rad_s.value:.1f} rad/s, ζ {f.zeta.value:.3f}, τ {1e3 * f.delay_s.value:.2f} ms"
        ax[0].semilogx(r.freq_hz, 20 * np.log10(np.abs(h)), "k--", lw=1.0, label=lab)
        ph = np.degrees(np.unwrap(np.angle(h)))
        ax[1].semilogx(r.freq_hz, ph - 360 * np.round((ph[0] - r.phase_deg[0]) / 360), "k--", lw=1.0)
        for a in ax[:2]:
            a.axvspan(fr.fit_band_hz[0], fr.fit_band_hz[1], color="0.95", zorder=0)
    if fr.overlay is not None:
        o = fr.overlay
        ax[0].semilogx(o.freq_hz, o.gain_db, color=COLORS["model"], lw=1.0, ls=":", label=f"{fr.overlay_model} "
                       "simulated on the same command")
        ax[1].semilogx(o.freq_hz, o.phase_deg, color=COLORS["model"], lw=1.0, ls=":")
    ref = low_frequency_gain_db(r)
    if ref is not None:
        ax[0].axhline(ref - 3.0, color="0.6", lw=0.6, ls="-.")
    if fr.bandwidth_hz and ref is not None:
        ax[0].axvline(fr.bandwidth_hz, color="0.6", lw=0.6, ls="-.")
        ax[0].text(fr.bandwidth_hz, ref - 3.0, f" −3 dB at {fr.bandwidth_hz:.2f} Hz", fontsize=8, va="bottom")
    ax[2].axhline(0.8, color="r", lw=0.6, ls="--")
    ax[0].set_ylabel("gain, dB")
    ax[1].set_ylabel("phase, deg")
    ax[2].set_ylabel("coherence")
    ax[2].set_ylim(0, 1.05)
    ax[2].set_xlabel("frequency, Hz")
    ax[0].legend(fontsize=8, loc="lower left")
    ax[0].set_title(f"{fr.kind}: command → {r.output}")
    for a in ax:
        a.grid(True, which="both", lw=0.3)
    return _save(fig, path)


def _steps(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    d = ra.data
    n = len(ra.steps)
    cols = min(n, 3)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    y = getattr(d, ra.steps[0].output)
    dt = float(np.median(np.diff(d.time_s)))
    for k, s in enumerate(ra.steps):
        a = axes[k // cols][k % cols]
        stop = min(s.stop, s.start + round(0.6 / dt))
        sl = slice(s.start, stop)
        tt = d.time_s[sl] - s.time_s
        a.plot(1e3 * tt, d.command_deg[sl], color="0.4", lw=0.8, label="command")
        a.plot(1e3 * tt, y[sl], color=COLORS.get(s.output, "tab:blue"), lw=1.0, label=s.output)
        if s.fit:
            f = s.fit
            model = f.gain.value * simulate(d.command_deg[sl], dt, f.wn_rad_s.value, f.zeta.value, f.delay_s.value) \
                + (f.bias_deg.value if f.bias_deg else 0.0)
            a.plot(1e3 * tt, model, "k--", lw=0.9, label="2nd-order fit")
        title = s.label + (" (rate-limited)" if s.rate_limited else "")
        a.set_title(title, fontsize=9)
        a.set_xlabel("ms from the edge")
        a.grid(lw=0.3)
        if k == 0:
            a.legend(fontsize=7)
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].axis("off")
    return _save(fig, path)


def _spread(records: Sequence[RecordAnalysis], path: Path) -> str:
    plt = _plt()
    fits = [f for r in records for f in r.fits]
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.8))
    for a, key, scale, label in ((ax[0], "wn_rad_s", 1.0, "ωn, rad/s"), (ax[1], "zeta", 1.0, "ζ"),
                                 (ax[2], "delay_s", 1e3, "delay, ms")):
        seen: set[str] = set()
        for k, f in enumerate(fits):
            e = getattr(f, key)
            mark = "o" if f.method.startswith("time") else "s"
            a.errorbar(k, scale * e.value, yerr=scale * e.sigma, fmt=mark, color=COLORS.get(f.output, "k"), ms=4,
                       label=None if f.output in seen else f.output)
            seen.add(f.output)
        vals = [scale * getattr(f, key).value for f in fits]
        for v in (min(vals), max(vals)):
            a.axhline(v, color="0.4", ls="--", lw=0.8)
        a.set_ylabel(label)
        a.set_xlabel("test (o step, □ frequency response)")
        a.grid(lw=0.3)
    ax[0].set_title("second-order estimates across tests (figure 23)", fontsize=9)
    ax[0].legend(fontsize=7)
    return _save(fig, path)


def _timing(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    d, tm = ra.data, ra.timing
    assert tm is not None
    e = next((x for x in tm.edges if x.command_to_motion_s is not None), tm.edges[0])
    sl = (d.time_s >= e.time_s - 0.005) & (d.time_s <= e.time_s + 0.03)
    tt = 1e3 * (d.time_s[sl] - e.time_s)
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.step(tt, d.command_deg[sl], where="post", color="0.4", label="command")
    for name in d.outputs:
        ax.plot(tt, getattr(d, name)[sl], ".-", ms=3, lw=0.8, color=COLORS[name], label=name)
    if e.command_to_motion_s is not None:
        ax.axvline(1e3 * e.command_to_motion_s, color=COLORS[tm.motion_signal], ls="--",
                   label=f"first motion {1e3 * e.command_to_motion_s:.2f} ms")
        if e.motion_to_feedback_s is not None:
            ax.axvline(1e3 * (e.command_to_motion_s + e.motion_to_feedback_s), color=COLORS["position_deg"], ls=":",
                       label=f"feedback moves +{1e3 * e.motion_to_feedback_s:.2f} ms")
    ax.set_xlabel("ms from the command edge")
    ax.set_ylabel("deg")
    ax.legend(fontsize=8)
    ax.grid(lw=0.3)
    ax.set_title(f"command-to-surface timing, median over {len(tm.edges)} edges: "
                 f"{1e3 * (tm.command_to_motion_s or np.nan):.2f} ms to first motion")
    return _save(fig, path)


def _command_error(ra: RecordAnalysis, k: int, path: Path) -> str:
    plt = _plt()
    c = ra.calibration[k]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    cmd = np.array(c.levels["command_deg"])
    meas = np.array(c.levels[c.direct_reference])
    ax[0].plot(cmd, meas - cmd, "o", ms=4, label=f"settled {c.direct_reference} − command")
    ax[0].plot(c.nominal_deg, c.direct(c.nominal_deg) - c.nominal_deg, "-", lw=1, label="direct line")
    if c.curve_error:
        ax[0].plot(c.nominal_deg, c.curve_error(c.nominal_deg) - c.nominal_deg, "-", lw=1.5,
                   label=f"curves: Kb {c.curve_error.kb:+.5f}, offset {c.curve_error.offset_deg:+.4f}°")
    ax[0].fill_between(c.nominal_deg, c.bounds_deg[0], c.bounds_deg[1], color="0.9", label="four-corner bounds")
    ax[0].set_xlabel("nominal command, deg")
    ax[0].set_ylabel("error, deg")
    ax[0].legend(fontsize=8)
    ax[0].grid(lw=0.3)
    if c.command_curve and c.feedback_curve and "command_v" in c.levels and "position_v" in c.levels:
        cv, pv = np.array(c.levels["command_v"]), np.array(c.levels["position_v"])
        ax[1].plot(cmd, 1e3 * (cv - c.command_curve(cmd)), "o-", ms=4, lw=0.8,
                   label=f"command curve, deg → V (RMS {1e3 * (c.command_curve_rms_v or 0):.2g} mV)")
        ax[1].plot(meas, 1e3 * (meas - c.feedback_curve(pv)) * abs(float(c.command_curve.c1)), "s-", ms=3, lw=0.8,
                   label=f"feedback curve, V → deg (RMS {1e3 * (c.feedback_curve_rms_deg or 0):.2g} m°), in mV")
        ax[1].set_xlabel("degrees")
        ax[1].set_ylabel("third-order fit residual, mV")
        ax[1].set_title("calibration curves: what the third-order fits leave", fontsize=9)
        ax[1].legend(fontsize=8)
        ax[1].grid(lw=0.3)
    else:
        ax[1].axis("off")
    ax[0].set_title("command error (figure 27)")
    return _save(fig, path)


def _thresholds(ra: RecordAnalysis, kind: str, path: Path) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    if kind == "static":
        s = ra.static_threshold[0]
        ax.plot(s.swing_deg / 2, s.output_swing_deg / 2, "o", ms=4, label="half cycles")
        if s.onset_deg is not None and s.gain:
            a = np.linspace(0, s.swing_deg.max() / 2, 50)
            ax.plot(a, np.maximum(s.gain * (a - s.onset_deg), 0), "k--", lw=1, label=f"dead zone {s.onset_deg:.4f}°")
        ax.set_xlabel("command amplitude (half swing), deg")
    else:
        s2 = ra.dynamic_threshold[0]
        ax.plot(s2.command_amp_deg, s2.output_amp_deg, "o", ms=3, label="output amplitude")
        twin = ax.twinx()
        twin.plot(s2.command_amp_deg, np.clip(s2.r2, 0, 1), "-", color="0.6", lw=0.8)
        twin.set_ylim(0, 1.05)
        twin.set_ylabel(f"R² of the {s2.freq_hz:g} Hz tone in the output (grey)")
        if s2.onset_deg is not None:
            ax.axvline(s2.onset_deg, color="r", ls="--", lw=0.8, label=f"onset {s2.onset_deg:.4f}°")
        ax.set_xlabel("command amplitude, deg")
    lim = ax.get_xlim()
    ax.plot(lim, lim, ":", color="0.5", lw=0.8, label="1:1")
    ax.set_ylabel("output amplitude, deg")
    ax.legend(fontsize=8)
    ax.grid(lw=0.3)
    ax.set_title(f"{kind} threshold")
    return _save(fig, path)


def _crosstalk(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    c = ra.crosstalk[0]
    seg = next(s for s in ra.recognition.segments if s.kind in ("hold", "triangle"))
    t = ra.data.time_s[seg.start:seg.stop]
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, c.residual, lw=0.6, label=f"{c.output} noise ({c.kind})")
    for v in (-c.threshold_deg / 2, c.threshold_deg / 2):
        ax.axhline(v, color="r", ls="--", lw=0.8)
    ax.set_xlabel("time, s")
    ax.set_ylabel("deg")
    ax.set_title(f"crosstalk: {c.peak_to_peak_deg:.4f}° p-p vs threshold {c.threshold_deg:.4f}° (dashed: ±half)")
    ax.legend(fontsize=8)
    ax.grid(lw=0.3)
    return _save(fig, path)


def _dither(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    from ema_sim.analysis import spectra  # noqa: PLC0415

    x = ra.dither[0]
    d = ra.data
    sl = (d.time_s >= x.start_s) & (d.time_s <= x.end_s)
    y = getattr(d, x.output)[sl]
    y = y - y.mean()
    fs = d.sample_hz
    sp = spectra.welch(y, y[None, :], fs, min(8.0, y.size / fs / 2), overlap=0.5)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    ax[0].loglog(sp.freq_hz[1:], sp.gxx[1:], lw=0.8)
    ax[0].axvline(x.peak_hz, color="r", ls="--", lw=0.8)
    ax[0].set_xlabel("frequency, Hz")
    ax[0].set_ylabel("deg²/Hz")
    ax[0].set_title(x.statement, fontsize=8)
    ax[0].grid(which="both", lw=0.3)
    if x.waveform_deg is not None:
        ph = np.linspace(0, 1, x.waveform_deg.size, endpoint=False)
        ax[1].plot(ph, x.waveform_deg, "o-", ms=3)
        ax[1].set_xlabel("phase of the limit cycle, cycles")
        ax[1].set_ylabel("deg (synchronous average)")
        ax[1].grid(lw=0.3)
    else:
        ax[1].axis("off")
    return _save(fig, path)


def _compliance(ra: RecordAnalysis, k: int, path: Path) -> str:
    plt = _plt()
    c = ra.compliance[k]
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    for cur, col in ((c.lvdt, COLORS["position_deg"]), (c.total, COLORS["surface_deg"])):
        if cur is None:
            continue
        label = "LVDT (inside the servo loop)" if cur.name == "lvdt" else "total (surface)"
        ax[0].plot(cur.load_inlb, cur.deflection_deg, "o-", ms=3, lw=0.8, color=col, label=label)
        if cur.mean is not None:
            f = cur.bisector_load_inlb / c.crank_arm_in
            ff = np.linspace(f.min(), f.max(), 400)
            ax[1].plot(f, cur.bisector_deg, "o", ms=3, color=col, label=f"{cur.name} bisector")
            ax[1].plot(ff, cur.mean(ff), "-", color=col, lw=1.2, label=f"{cur.name} three-segment mean")
            if cur.upper and cur.lower:
                ax[1].plot(ff, cur.upper(ff), "--", color=col, lw=0.8, label=f"{cur.name} upper / lower")
                ax[1].plot(ff, cur.lower(ff), "--", color=col, lw=0.8)
    ax[0].set_xlabel("hinge moment, in·lb")
    ax[0].set_ylabel("deflection, deg")
    ax[0].set_title("compliance curves (figure 16)")
    ax[1].set_xlabel("force at the crank arm, lb")
    ax[1].set_ylabel("deflection, deg")
    ax[1].set_title("three-segment model (figure 35)")
    for a in ax:
        a.legend(fontsize=7)
        a.grid(lw=0.3)
    return _save(fig, path)


def _hysteresis(ra: RecordAnalysis, k: int, path: Path) -> str:
    plt = _plt()
    h = ra.hysteresis[k]
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(h.deflection_in - h.deflection_in.mean(), h.force_lb, lw=0.7)
    ax.set_xlabel("deflection at the actuator, in")
    ax.set_ylabel("force at the crank arm, lb")
    ax.set_title(f"hysteresis loop, {2 * np.pi * h.freq_hz:.4g} rad/s: A {h.area_inlb:.3g} in·lb, "
                 f"Pk {h.peak_in:.4g} in, h {h.h_lb_per_in:,.0f} lb/in", fontsize=9)
    ax.grid(lw=0.3)
    return _save(fig, path)


def _free_play(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    d = ra.data
    fp = ra.free_play[0]
    seg = next(s for s in ra.recognition.segments if s.kind == "load_reversal")
    sl = slice(seg.start, seg.stop)
    assert d.surface_deg is not None
    assert d.hinge_moment_inlb is not None
    rel = d.surface_deg[sl] - (d.position_deg[sl] if d.position_deg is not None else 0.0)
    fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    ax[0].plot(d.time_s[sl], rel, lw=0.7, color=COLORS["surface_deg"])
    ax[0].set_ylabel("surface − LVDT, deg")
    ax[0].set_title(f"free play {fp.width_deg:.4f}° (median of {len(fp.reversals)} reversals)")
    ax[1].plot(d.time_s[sl], d.hinge_moment_inlb[sl], color="tab:purple", lw=0.8)
    ax[1].set_ylabel("hinge moment, in·lb")
    ax[1].set_xlabel("time, s")
    for a in ax:
        a.grid(lw=0.3)
    return _save(fig, path)


def _regeneration(ra: RecordAnalysis, path: Path) -> str:
    plt = _plt()
    d, g = ra.data, ra.regeneration
    assert g is not None
    assert d.bus_v is not None
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(d.time_s, d.bus_v, lw=0.6)
    ax.axhline(g.limit_v, color="r", ls="--", label=f"{g.limit_v:g} V limit")
    ax.plot(g.peak_time_s, g.peak_v, "rv", label=f"peak {g.peak_v:.1f} V")
    ax.set_xlabel("time, s")
    ax.set_ylabel("bus, V")
    ax.legend(fontsize=8)
    ax.grid(lw=0.3)
    return _save(fig, path)


def write_plots(records: Sequence[RecordAnalysis], out_dir: Path) -> dict[str, str]:
    """Draw every plot into ``out_dir``; returns key → file name (relative to ``out_dir``)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    made: dict[str, str] = {}
    per_record: list[tuple[str, Any, Any]] = [
        ("overview", lambda _ra: True, _overview),
        ("steps", lambda ra: bool(ra.steps), _steps),
        ("timing", lambda ra: bool(ra.timing and ra.timing.edges), _timing),
        ("command_error", lambda ra: bool(ra.calibration), lambda ra, p: _command_error(ra, 0, p)),
        ("static_threshold", lambda ra: bool(ra.static_threshold), lambda ra, p: _thresholds(ra, "static", p)),
        ("dynamic_threshold", lambda ra: bool(ra.dynamic_threshold), lambda ra, p: _thresholds(ra, "dynamic", p)),
        ("crosstalk", lambda ra: bool(ra.crosstalk), _crosstalk),
        ("dither", lambda ra: bool(ra.dither), _dither),
        ("compliance", lambda ra: bool(ra.compliance), lambda ra, p: _compliance(ra, 0, p)),
        ("hysteresis", lambda ra: bool(ra.hysteresis), lambda ra, p: _hysteresis(ra, 0, p)),
        ("free_play", lambda ra: bool(ra.free_play), _free_play),
        ("regeneration", lambda ra: ra.regeneration is not None, _regeneration),
    ]
    for i, ra in enumerate(records):
        for name, wanted, draw in per_record:
            if wanted(ra):
                key = f"r{i}_{name}"
                made[key] = draw(ra, out_dir / f"{key}.png")
        for j in range(len(ra.frequency)):
            made[f"r{i}_bode{j}"] = _bode(ra, j, out_dir / f"r{i}_bode{j}.png")
    if sum(len(r.fits) for r in records) > 1:
        made["spread"] = _spread(records, out_dir / "spread.png")
    return made

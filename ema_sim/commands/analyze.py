"""``ema analyze``: turn a bag or a rig's CSV into the report's results (JSON, Markdown and PNG)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ema_sim.errors import SpecError


def _floats(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise SpecError(f"--at-hz expects comma-separated frequencies, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise SpecError(f"--at-hz expects positive frequencies, got {text!r}")
    return values


def _summary(ra: Any) -> list[str]:
    """A few lines per record for the terminal."""
    lines = [f"{ra.data.source}: {len(ra.data)} samples at {ra.data.sample_hz:.6g} Hz, channel {ra.channel.channel}; "
             f"tests: {', '.join(s.kind for s in ra.recognition.segments) or 'none recognised'}"]
    for fr in ra.frequency:
        bw = f"{fr.bandwidth_hz:.2f} Hz" if fr.bandwidth_hz else "—"
        fit = fr.fit
        fit_s = (f"; ωn {fit.wn_rad_s.value:.2f} ± {fit.wn_rad_s.sigma:.2g} rad/s, ζ {fit.zeta.value:.3f} ± "
                 f"{fit.zeta.sigma:.2g}, delay {1e3 * fit.delay_s.value:.2f} ± {1e3 * fit.delay_s.sigma:.2g} ms"
                 if fit else "")
        lines.append(f"  {fr.kind} → {fr.response.output}: −3 dB {bw}; {fr.coherence_note}{fit_s}")
    for s in ra.steps:
        f = s.fit
        extra = (f"; fit ωn {f.wn_rad_s.value:.2f} ± {f.wn_rad_s.sigma:.2g}, ζ {f.zeta.value:.3f}, delay "
                 f"{1e3 * f.delay_s.value:.2f} ms" if f else f"; {s.fit_note}")
        lines.append(f"  {s.label}: peak rate {s.peak_rate_dps:.1f} °/s{extra}")
    if ra.timing and ra.timing.command_to_motion_s is not None:
        m2f = ra.timing.motion_to_feedback_s
        lines.append(f"  timing: command → first motion {1e3 * ra.timing.command_to_motion_s:.2f} ms, motion → "
                     f"feedback {'—' if m2f is None else f'{1e3 * m2f:.2f} ms'}")
    for c in ra.calibration:
        lines.append(f"  command error: Kb {c.error.kb:+.5f}, offset {c.error.offset_deg:+.4f}°")
    for s in ra.static_threshold:
        lines.append(f"  static threshold: onset {s.onset_deg}, follows from {s.follow_deg}")
    for s in ra.dynamic_threshold:
        lines.append(f"  dynamic threshold: onset {s.onset_deg}, follows from {s.follow_deg}")
    for c in ra.crosstalk:
        lines.append(f"  crosstalk: {c.peak_to_peak_deg:.4f}° p-p, {'below' if c.below_threshold else 'ABOVE'} "
                     f"threshold {c.threshold_deg:.4f}°")
    for x in ra.dither:
        lines.append(f"  dither: {x.statement}")
    for c in ra.compliance:
        share = "—" if c.share_outside is None else f"{100 * c.share_outside:.1f} %"
        lines.append(f"  compliance: share outside the servo loop {share}")
    for h in ra.hysteresis:
        lines.append(f"  hysteresis: A {h.area_inlb:.4g} in·lb, Pk {h.peak_in:.5f} in, h {h.h_lb_per_in:,.2f} lb/in")
    for fp in ra.free_play:
        lines.append(f"  free play: {fp.width_deg:.4f}°")
    if ra.regeneration:
        g = ra.regeneration
        lines.append(f"  regeneration: peak {g.peak_v:.1f} V, margin {g.margin_v:.1f} V to {g.limit_v:g} V")
    lines += [f"  not computed: {k}: {v}" for k, v in ra.not_computed.items()]
    return lines


def run(args: argparse.Namespace) -> int:
    """Analyse every DATA and write what was asked."""
    from ema_sim.analysis.loading import load_record  # noqa: PLC0415 - keep `ema --help` fast
    from ema_sim.analysis.pipeline import Options, analyze_records  # noqa: PLC0415
    from ema_sim.analysis.report import to_json, to_markdown  # noqa: PLC0415

    options = Options(at_hz=_floats(args.at_hz), model=args.model, threshold_deg=args.threshold_deg,
                      compliance_deg_per_kinlb=args.compliance, channel=args.channel)
    if args.model:
        from ema_sim.models import model_class  # noqa: PLC0415

        model_class(args.model)  # an unknown name is one clear error before any work
    records = analyze_records([load_record(path, args.channel) for path in args.data], options)
    for ra in records:
        print("\n".join(_summary(ra)))
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(to_json(records), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        print(f"wrote {out}")
    if args.report:
        from ema_sim.analysis.plots import write_plots  # noqa: PLC0415

        folder = Path(args.report)
        plots = write_plots(records, folder)
        (folder / "report.md").write_text(to_markdown(records, plots), encoding="utf-8")
        print(f"wrote {folder / 'report.md'} and {len(plots)} plot(s)")
    return 0


def register(sub: Any) -> None:
    """Add ``analyze`` to the ``ema`` parser."""
    p = sub.add_parser(
        "analyze", help="offline analysis of a bag or a rig's CSV: the report's results",
        description="Recognise the section-2 tests in each record and compute their results: frequency response, "
                    "second-order fits with uncertainty, step metrics, command error, compliance, hysteresis, "
                    "thresholds, crosstalk, timing, free play, regeneration, dither.")
    p.add_argument("data", nargs="+", help="measured-data CSV or rosbag2 directory (several: spread across tests)")
    p.add_argument("--channel", default=None, help="channel to read from a multi-channel bag (and its config)")
    p.add_argument("--json", default=None, help="write every figure as JSON")
    p.add_argument("--report", default=None, help="write report.md and PNG plots into this directory")
    p.add_argument("--model", default=None, help="also simulate this model on the measured command; overlay it")
    p.add_argument("--at-hz", default="1,2,5,7.5,10",
                   help="frequencies for gain and phase, comma-separated (default 1,2,5,7.5,10)")
    p.add_argument("--threshold-deg", type=float, default=None,
                   help="threshold the crosstalk noise is judged against (default: measured, else table A2)")
    p.add_argument("--compliance", type=float, default=None, metavar="DEG_PER_KINLB",
                   help="compliance taken out of free-play jumps (default: measured in the same record)")
    p.set_defaults(func=run)

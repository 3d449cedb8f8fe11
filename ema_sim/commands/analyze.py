"""``ema analyze``: turn a bag or a rig's CSV into the report's results (JSON, Markdown and PNG)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ema_sim.analysis.formatting.units import in_unit
from ema_sim.commands.common import Subparsers, add_data_args, check_channel, check_outputs, rig_format
from ema_sim.errors import SpecError
from ema_sim.models import model_class
from ema_sim.progress import ProgressBar

if TYPE_CHECKING:
    from ema_sim.analysis.section2.base import RecordAnalysis
    from ema_sim.io.measured import MeasuredData

PROGRESS_S = 3.0
"""A record longer than this says on stderr, at once, that it is being analysed, and shows a progress bar."""


def _floats(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise SpecError(f"--at-hz expects comma-separated frequencies, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise SpecError(f"--at-hz expects positive frequencies, got {text!r}")
    return values


def _summary(ra: RecordAnalysis) -> list[str]:
    """A few lines per record for the terminal."""
    from ema_sim.analysis.records.series import SAID  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
    from ema_sim.analysis.registry import TESTS  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
    from ema_sim.analysis.report import slope_statement  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    d = ra.data
    count = f"{len(d)} samples" if ra.logged is None else f"{ra.logged} samples logged, resampled onto {len(d)}"
    lines = [f"{d.source}: {count} at {d.sample_hz:.6g} Hz, channel {ra.channel_name}; "
             f"tests: {', '.join(s.kind for s in ra.recognition.segments) or 'none recognised'}"]
    lines += [f"  {k}: {d.metadata[k]}" for k in SAID if k in d.metadata]
    lines.append(f"  command: {ra.command.statement}")
    if ra.command.leads:
        lines.append(f"  causality: {ra.command.leads}")
    for f in ra.other_timing:
        scale, unit = (1e3, "ms") if f["quantity"] == "delay_s" else (1.0, "°")
        lines.append(f"  taken as held / as sampled: {f['figure']}: {scale * f['held']:+.2f} / "
                     f"{scale * f['sampled']:+.2f} {unit}")
    counts = {k: v for k, v in ra.resolution_deg.items() if v}
    if counts:
        lines.append("  resolution: " + ", ".join(f"{k} {v:g}" for k, v in counts.items()))
    lines += [f"  at rest: {line}" for k, nf in ra.noise.items() for line in nf.findings(k, d.unit)]
    lines.append(f"  slope of the rate-limited moves: {slope_statement(ra)}")
    for test in TESTS:
        for r in ra.of(test):
            lines += [f"  {line}" for line in test.summary(ra, r)]
    absent = [k for k, v in ra.not_computed.items() if "recognised" in v and not v.startswith("no hinge")]
    lines += [f"  not computed: {k}: {v}" for k, v in ra.not_computed.items() if k not in absent]
    if absent:
        lines.append(f"  not in this record: {', '.join(absent)}")
    return lines


def _progress(d: MeasuredData) -> ProgressBar | None:
    """Say on stderr at once that a long record is being analysed; its bar shows after a second."""
    span = float(d.time_s[-1] - d.time_s[0])
    if span <= PROGRESS_S:
        return None
    print(f"analysing {d.source}: {len(d):,} samples over {span:.1f} s", file=sys.stderr, flush=True)
    return ProgressBar(f"  {Path(d.source).name}", delay_s=1.0)


def run(args: argparse.Namespace) -> int:
    """Analyse every DATA and write what was asked.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    from ema_sim.analysis.pipeline import Options, analyze_records  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
    from ema_sim.analysis.records.loading import load_record  # noqa: PLC0415 - keep `ema --help` fast
    from ema_sim.analysis.report import to_json, to_markdown  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    check_channel(args.channel)
    check_outputs([args.json], [args.report])
    rig = rig_format(args)
    options = Options(at_hz=_floats(args.at_hz), model=args.model, threshold_deg=args.threshold_deg,
                      compliance_deg_per_kinlb=args.compliance, channel=args.channel, command=args.command_hold)
    if args.model:

        model_class(args.model)  # an unknown name is one clear error before any work
    data = [load_record(path, args.channel, rig) for path in args.data]
    bars: dict[int, ProgressBar | None] = {}

    def progress(i: int, share: float) -> None:
        if i not in bars:
            bars[i] = _progress(data[i])
        bar = bars[i]
        if bar is not None:
            bar(share)
            if share >= 1.0:
                bar.close()

    records = analyze_records(data, options, progress)
    for ra in records:
        print("\n".join(in_unit(line, ra.data.unit) for line in _summary(ra)))
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(to_json(records), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        print(f"wrote {out}")
    if args.report:
        from ema_sim.analysis.plots import write_plots  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        folder = Path(args.report)
        plots = write_plots(records, folder)
        (folder / "report.md").write_text(to_markdown(records, plots), encoding="utf-8")
        print(f"wrote {folder / 'report.md'} and {len(plots)} plot(s)")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``analyze`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser(
        "analyze", help="offline analysis of a bag or a rig's CSV: the report's results",
        description="Recognise the section-2 tests in each record and compute their results: frequency response, "
                    "second-order fits with uncertainty, step metrics, command error, compliance, hysteresis, "
                    "thresholds, crosstalk, timing, free play, regeneration, dither.")
    p.add_argument("data", nargs="+", help="measured-data CSV or rosbag2 directory (several: spread across tests)")
    p.add_argument("--channel", default=None,
                   help="the X-43A channel the record is of (its config and tables; without it, and without a "
                        "channel in the record, no X-43A threshold applies); picks a channel of a multi-channel bag")
    p.add_argument("--json", default=None, help="write every figure as JSON")
    p.add_argument("--report", default=None, help="write report.md and PNG plots into this directory")
    p.add_argument("--model", default=None, help="also simulate this model on the measured command; overlay it")
    p.add_argument("--at-hz", default="1,2,5,7.5,10",
                   help="frequencies for gain and phase, comma-separated (default 1,2,5,7.5,10)")
    p.add_argument("--threshold-deg", type=float, default=None,
                   help="threshold the crosstalk noise is judged against (default: measured, else table A2 for an "
                        "X-43A channel; crosstalk is judged only when another channel moves)")
    p.add_argument("--compliance", type=float, default=None, metavar="DEG_PER_KINLB",
                   help="compliance taken out of free-play jumps (default: measured in the same record)")
    p.add_argument("--command", dest="command_hold", default="detect", choices=("detect", "held", "sampled"),
                   help="how the rig logged its command: held between samples (the data contract), sampled from a "
                        "running demand, or detect it from the record (default)")
    add_data_args(p)
    p.set_defaults(func=run)

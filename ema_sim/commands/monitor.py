"""``ema monitor``: watch a record against its reference model; detect, isolate and re-estimate a fault."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ema_sim.analysis.estimation.prepared import resolve_channel
from ema_sim.commands.common import Subparsers, check_channel
from ema_sim.io import is_bag, load_data
from ema_sim.io.bag import read_fault_truth
from ema_sim.models import model_names
from ema_sim.monitor import Options, check_inputs, from_name, from_report, learn, watch


def truth_columns(path: Path, channel: str = "left_wing", time_s: list[float] | None = None) -> dict[str, list[float]]:
    """The injected truth, ``fault_<kind>`` → size at each sample; none for a record without it.

    A CSV's ``fault_<kind>`` columns (``ema simulate --fault``), or a bag's ``/ema/faults/truth`` for ``channel``
    sampled at ``time_s`` (from the record's start).

    Parameters
    ----------
    path : Path
        The record's file.
    channel : str
        The channel watched.
    time_s : list[float] | None
        The record's sample times, s.
    """
    if is_bag(path):

        changes = read_fault_truth(path, channel)
        if not changes or time_s is None:
            return {}
        t = np.asarray(time_s)
        names = sorted({k for _, d in changes for k in d})
        cols: dict[str, list[float]] = {"time_s": t.tolist()}
        starts = np.array([c[0] for c in changes])
        for name in names:
            values = np.array([c[1].get(name, 0.0) for c in changes])
            idx = np.searchsorted(starts, t, side="right") - 1
            cols[name] = np.where(idx >= 0, values[np.clip(idx, 0, None)], 0.0).tolist()
        return cols
    if path.is_dir() or path.suffix.lower() != ".csv":
        return {}

    with path.open(encoding="utf-8") as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    if not lines:
        return {}
    header = lines[0].strip().split(",")
    keep = [i for i, h in enumerate(header) if h == "time_s" or h.startswith("fault_")]
    if len(keep) < 2:
        return {}
    rows = np.array([[float(ln.split(",")[i]) for i in keep] for ln in lines[1:] if ln.strip()])
    return {header[i]: rows[:, j].tolist() for j, i in enumerate(keep)}


def run(args: argparse.Namespace) -> int:
    """Watch the record, print the verdict; write the JSON and the plot when asked.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success (with or without a detection).
    """
    check_channel(args.channel)
    data = load_data(args.data, channel=args.channel)
    check_inputs(data, assume_no_load=args.assume_no_load)
    channel, note = resolve_channel(data, args.channel)
    if note:
        print(f"note: {note}")
    if args.model is None:
        reference = learn(data, channel, args.healthy_s)
    elif args.model in model_names():
        reference = from_name(args.model, channel)
    else:
        reference = from_report(args.model, channel)
    print(f"reference: {reference.origin}")
    opts = Options(healthy_s=args.healthy_s, false_alarms_per_hour=args.false_alarms_per_hour,
                   block_s=args.block_s, window_s=args.window_s)
    verdict = watch(data, reference, opts)
    print(f"watched {verdict.watched_s:.1f} s after a {opts.healthy_s:g} s healthy window; CUSUM threshold "
          f"{verdict.threshold:.2f} for {opts.false_alarms_per_hour:g} false alarms per hour")
    if not verdict.detections:
        print("no departure from the reference")
    for d in verdict.detections:
        unc = f" ± {d.uncertainty:.3g}" if np.isfinite(d.uncertainty) else ""
        print(f"{d.time_s:.3f} s  {d.output}: {d.kind} ({d.parameter} = {d.estimate:.4g}{unc}, nominal "
              f"{d.nominal:.4g}; size {d.size:.3g}), onset ~{d.onset_s:.3f} s, statistic {d.statistic:.1f}")
    rel_t = (data.time_s - data.time_s[0]).tolist()
    truth = truth_columns(args.data, channel.channel, rel_t)
    tcols = {k: np.asarray(v) for k, v in truth.items() if k != "time_s"}
    tt = np.asarray(truth.get("time_s", []))
    doc = verdict.as_dict()
    doc["data"] = str(args.data)
    if truth:
        t = np.asarray(truth.pop("time_s"))
        doc["truth"] = {k: {"onset_s": float(t[np.argmax(np.asarray(v) != 0.0)]) if np.any(np.asarray(v) != 0.0)
                            else None, "size": float(np.asarray(v)[-1])} for k, v in truth.items()}
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    if args.plot:
        from ema_sim.monitor.plot import timeline_plot  # noqa: PLC0415 - plotting only when asked

        print(f"wrote {timeline_plot(verdict, args.plot, tcols or None, tt - tt[0] if tt.size else None)}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``monitor`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser(
        "monitor", help="watch a record against its model: detect, isolate and re-estimate a fault",
        description="Run a reference model on the record's command and load, detect the first departure of its "
                    "residuals (CUSUM at a false-alarm rate you set), isolate the fault from the candidates the "
                    "reference has a stage for, and re-estimate its parameter with its uncertainty.",
    )
    p.add_argument("data", type=Path, help="a data-contract CSV or a rosbag2 directory")
    p.add_argument("--model", default=None,
                   help="a fidelity (loada, hoad2...) or an `ema identify --json` report; default: learn the basic "
                        "second order on the healthy window")
    p.add_argument("--channel", default=None, help="channel (default: the data's metadata, else left_wing)")
    p.add_argument("--healthy-s", type=float, default=30.0,
                   help="the first seconds, stated healthy: residual spread (and a learned model) come from them (30)")
    p.add_argument("--false-alarms-per-hour", type=float, default=0.1, help="the detector's design rate (0.1)")
    p.add_argument("--block-s", type=float, default=0.02, help="residual block averaged before the test, s (0.02)")
    p.add_argument("--window-s", type=float, default=5.0, help="isolation and re-estimation window, s (5)")
    p.add_argument("--assume-no-load", action="store_true",
                   help="a record without a hinge moment ran unloaded (otherwise it is an error)")
    p.add_argument("--json", type=Path, default=None, help="write the verdict (detections...) as JSON")
    p.add_argument("--plot", type=Path, default=None, help="write the timeline plot (PNG)")
    p.set_defaults(func=run)

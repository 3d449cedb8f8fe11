"""``ema ail``: the aircraft-in-the-loop run offline (no ROS), at full speed, and its dither measurement."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.ail import study
from ema_sim.ail.loop import AilOptions, run_ail
from ema_sim.ail.measure import DITHER_MIN_PP_DEG, measure, vehicle_cycle
from ema_sim.ail.params import load_ail_config
from ema_sim.analysis.section2.dither import DETECT_DB
from ema_sim.commands.common import Subparsers
from ema_sim.errors import EmaError
from ema_sim.io.csv import write_csv
from ema_sim.progress import ProgressBar

MEASURED_STATES = (("q_dps", "pitch rate"), ("p_dps", "roll rate"), ("alpha_deg", "angle of attack"))


FIGURE_CASES = ("ail", "ail_open_loop", "flight", "no_dead_band", "loada")
"""The study's figure: the finding, its controls, and the pre-flight-1 model."""


def run(args: argparse.Namespace) -> int:
    """Run the loop (or the study), print the dither per surface, write what was asked for.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    if args.study:
        return _study(args)

    cfg = load_ail_config(args.vehicle_config)
    setup = cfg.setup(args.profile, aero_input=args.aero_input, surface_load=args.surface_load,
                      bungee_inlb=args.bungee)
    settle = cfg.settle_s if args.settle is None else float(args.settle)
    if settle + 4.0 > args.duration:
        raise EmaError(f"--duration must leave at least 4 s of trimmed flight after the {settle:g} s settle")
    options = AilOptions(profile=args.profile, model=args.model, open_loop=args.open_loop, duration_s=args.duration,
                         seed=args.seed, disable=tuple(args.disable), setup=setup, sim_model=args.sim_model,
                         config=cfg)
    bar = ProgressBar(f"ail {args.profile} {args.model}")
    try:
        result = run_ail(options, progress=bar)
    finally:
        bar.close()
    meta = result.metadata
    print(f"ema ail: profile {args.profile}, {meta['mode']}"
          f"{' (simulation model ' + meta['sim_model'] + ')' if args.open_loop else ''}, {args.model}, "
          f"{meta['duration_s']} s, seed {meta['seed']}; {setup.describe()}")
    print(f"  command path: {meta['command_path']}; feedback path: {meta['feedback_path']}; "
          f"disabled: {meta['disabled']} (model: {meta['model_overrides']})")
    print(f"  ran in {result.wall_s:.1f} s ({float(meta['duration_s']) / max(result.wall_s, 1e-9):.1f}× real time)")
    found = measure(result, settle)
    print(f"LVDT position, trimmed flight {settle:g}–{meta['duration_s']} s "
          f"(dither: a peak ≥ {DETECT_DB:g} dB above the floor and ≥ {DITHER_MIN_PP_DEG:g}° peak to peak):")
    for ch, d in found.items():
        print(f"  {ch:13s} {d.statement}")
    states = {}
    for name, title in MEASURED_STATES:
        cyc = vehicle_cycle(result, settle, name)
        if cyc is not None:
            states[name] = cyc.as_dict()
            print(f"  {title:13s} {cyc.statement}")
    meta = {**meta, "channel": args.channel,
            **{f"dither.{ch}": d.statement for ch, d in found.items()}}
    if args.csv:
        write_csv(args.csv, result.csv_columns(args.channel), meta)
        print(f"wrote {args.csv}: {result.time_s.size} frames; contract columns of {args.channel}, every channel's "
              "signals as <channel>.<signal>, the vehicle states")
    if args.json:
        doc = {"metadata": meta, "settle_s": settle, "surfaces": {ch: d.as_dict() for ch, d in found.items()},
               "vehicle": {k: {kk: vv for kk, vv in v.items() if kk != "waveform_deg"} for k, v in states.items()}}
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(doc, indent=2), encoding="utf-8")
        print(f"wrote {args.json}")
    if args.plot:
        from ema_sim.ail.plot import plot_dither  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        label = f"{args.profile}, {meta['mode']}, {args.model}"
        print(f"wrote {plot_dither([(label, result)], args.plot, channel=args.channel, settle_s=settle)}")
    return 0


def _study(args: argparse.Namespace) -> int:
    """Section 4.3's table: every case over several seeds (``ema_sim.ail.study``)."""
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        raise EmaError(f"--seeds takes comma-separated integers, got {args.seeds!r}") from None
    if not seeds:
        raise EmaError("--seeds needs at least one seed")
    cases = study.select([c for item in args.cases for c in item.split(",") if c])
    cfg = load_ail_config(args.vehicle_config)
    print(f"ema ail --study: {len(cases)} cases × seeds {', '.join(map(str, seeds))}, {args.duration:g} s each, "
          f"measured after {cfg.settle_s:g} s on both wings; default model {args.model}", flush=True)
    print(study.table_header(), flush=True)
    results = study.run_study(cases, model=args.model, seeds=seeds, duration_s=args.duration, config=cfg,
                              keep_runs=FIGURE_CASES if args.plot else (),
                              progress=lambda row: print(row, flush=True))
    wall = sum(r.wall_s for r in results)
    print(f"{sum(len(r.wings) // 2 for r in results)} runs in {wall:.1f} s of loop time")
    if args.markdown:
        Path(args.markdown).parent.mkdir(parents=True, exist_ok=True)
        Path(args.markdown).write_text(study.table(results) + "\n", encoding="utf-8")
        print(f"wrote {args.markdown}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        doc = {"seeds": seeds, "duration_s": args.duration, "settle_s": cfg.settle_s,
               "cases": [r.as_dict() for r in results]}
        Path(args.json).write_text(json.dumps(doc, indent=2), encoding="utf-8")
        print(f"wrote {args.json}")
    if args.plot:
        from ema_sim.ail.plot import plot_dither  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        shown = [(f"{r.case.name} ({r.model})", r.runs[0]) for r in results if r.runs]
        if shown:
            print(f"wrote {plot_dither(shown, args.plot, channel=args.channel, settle_s=cfg.settle_s)}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``ail`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("ail", help="aircraft-in-the-loop: vehicle, autopilot and actuators, offline; the dither",
                       description="Run the closed-loop (or open-loop) aircraft-in-the-loop set-up of sections 2.10 "
                                   "and 4.3 offline, frame by frame as the lockstep node suite does, write a "
                                   "data-contract CSV and print each surface's limit cycle (the AIL dither).")
    p.add_argument("--profile", default="ail", help="test environment: ail, flight or none (config/<profile>.yaml)")
    p.add_argument("--open-loop", action="store_true",
                   help="drive the simulated vehicle with a model actuator; the real surfaces follow the commands")
    p.add_argument("--model", default="hoad3", help="model of every EMAC channel (ema models; default hoad3)")
    p.add_argument("--duration", type=float, default=24.0, help="simulated seconds (default 24)")
    p.add_argument("--seed", type=int, default=None, help="test-environment noise seed (default: the profile's)")
    p.add_argument("--disable", action="append", default=[], metavar="ELEMENT",
                   help="switch an element off (repeatable, comma-separated): delay, lag, quantization, noise (test "
                        "environment and the model's own), dead_band (the PWM's), or one path's: command.delay ...")
    p.add_argument("--settle", type=float, default=None, help="seconds left out before measuring (default: config)")
    p.add_argument("--bungee", type=float, default=None, metavar="INLB",
                   help="load the wings with a bungee of this many in·lb (section 4.3: 50–100)")
    p.add_argument("--aero-input", choices=("feedback", "surface"), default=None,
                   help="what drives the simulated aerodynamics (default: the profile's setup)")
    p.add_argument("--surface-load", choices=("aerodynamic", "bungee"), default=None,
                   help="what loads the real surfaces (default: the profile's setup)")
    p.add_argument("--sim-model", default=None, help="open loop: the simulation's model actuator (default loada)")
    p.add_argument("--vehicle-config", default=None, help="parameter file (default config/ail_vehicle.yaml)")
    p.add_argument("--channel", default="left_wing", help="the CSV's data-contract channel (default left_wing)")
    p.add_argument("--csv", type=Path, default=None, help="write the run as a data-contract CSV")
    p.add_argument("--json", type=Path, default=None, help="write the measurement as JSON")
    p.add_argument("--plot", type=Path, default=None, help="write the dither figure (PNG)")
    p.add_argument("--study", action="store_true",
                   help="section 4.3's table instead of one run: configurations, elements switched off one at a "
                        "time, every model (--cases, --seeds; --markdown, --json, --plot)")
    p.add_argument("--cases", action="append", default=[],
                   help="with --study: the cases to run, comma-separated (default all: ail, ail_open_loop, flight, "
                        "no_delay, no_lag, no_quantization, no_noise, no_dead_band, bungee, hoad2, hoac1, loada, "
                        "loadf, loac)")
    p.add_argument("--seeds", default="43,44,45", help="with --study: noise seeds, comma-separated (default 43,44,45)")
    p.add_argument("--markdown", type=Path, default=None, help="with --study: write the table (Markdown)")
    p.set_defaults(func=run)


"""``ema export`` and ``ema verify``: a model as an FMU, a JSBSim system or C, checked against the truth model.

``ema verify`` also takes a host's record of its own integration (.csv or a bag) and names its likely fault.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.commands.common import Subparsers, check_channel, parse_overrides


def run_export(args: argparse.Namespace) -> int:
    """Write the artefacts asked for.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    from ema_sim.export.target import ExportError, resolve  # noqa: PLC0415 - keep `ema --help` fast

    if not (args.fmu or args.jsbsim or args.c):
        raise ExportError("say what to write: --fmu OUT.fmu, --jsbsim OUT.xml and/or --c DIR")
    target = resolve(args.model, args.channel, rate_hz=args.rate, overrides=parse_overrides(args.overrides))
    if args.jsbsim and target.linear:
        from ema_sim.export.target import LINEAR_NO_JSBSIM  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        raise ExportError(f"{target.model}: {LINEAR_NO_JSBSIM}")
    if args.jsbsim and target.high_order:
        from ema_sim.export.target import HIGH_ORDER_NO_JSBSIM  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        raise ExportError(f"{target.model}: {HIGH_ORDER_NO_JSBSIM}")
    print(target.description)
    for note in target.notes:
        print(f"  note: {note}")
    if args.fmu:
        from ema_sim.export.fmu import build_fmu, validation_problems  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        path = build_fmu(target, Path(args.fmu))
        problems = validation_problems(path)
        print(f"wrote {path} (FMI 2.0 co-simulation; fmpy.validate_fmu: "
              f"{'clean' if not problems else '; '.join(problems)})")
    if args.jsbsim:
        from ema_sim.export.jsbsim_system import ALWAYS_MISSING, NOT_EXPRESSED, not_expressed, system_xml  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        path = Path(args.jsbsim)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(system_xml(target), encoding="utf-8")
        print(f"wrote {path} (JSBSim <system>; run JSBSim at dt = 1/{target.rate_hz:g} s)")
        for key in not_expressed(target.params):
            print(f"  not in the system: {key}: {NOT_EXPRESSED[key]}")
        for what in ALWAYS_MISSING:
            print(f"  not in the system: {what}")
    if args.c:
        from ema_sim.export.harness import write_c  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        files = write_c(target, Path(args.c))
        print(f"wrote {len(files)} files to {args.c} (C sources, ema_actuator.h, ema_harness.c, Makefile)")
    return 0


def _maneuvers(items: list[str] | None) -> list[tuple[str, str | None]] | None:
    if not items:
        return None
    out: list[tuple[str, str | None]] = []
    for item in items:
        maneuver, _, load = item.partition("@")
        out.append((maneuver.strip(), load.strip() or None))
    return out


def run_verify(args: argparse.Namespace) -> int:
    """Verify an artefact (or diagnose a host's record) and print the report.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 when the artefact passes, 1 otherwise.
    """
    from ema_sim.export.target import ExportError, resolve  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
    from ema_sim.io import is_bag  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    check_channel(args.channel)
    path = Path(args.artefact)
    report: dict[str, object]
    if path.suffix.lower() == ".csv" or is_bag(path):
        from ema_sim.export.diagnose import TOLERANCE_DEG, diagnose  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
        from ema_sim.io import load_data  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        data = load_data(path, args.channel)
        channel = args.channel or data.metadata.get("channel") or "left_wing"
        target = resolve(args.model or "loada", channel, rate_hz=args.rate, overrides=parse_overrides(args.overrides))
        found = diagnose(data, target, tolerance_deg=args.tol if args.tol is not None else TOLERANCE_DEG)
        lines, passed, report = found.lines(), found.matches, found.as_dict()
    else:
        from ema_sim.export.artefacts import open_artefact  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
        from ema_sim.export.verify import DEFAULT_MANEUVERS, verify  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

        if args.model or args.overrides or args.rate:
            raise ExportError("an artefact carries its model, values and rate: --model, --set and --rate are for a "
                              "host's record (.csv or a bag)")
        artefact = open_artefact(path)
        try:
            if args.channel is not None and args.channel != artefact.target.channel:
                raise ExportError(f"{path} was exported for channel {artefact.target.channel}, not {args.channel}")
            result = verify(artefact, _maneuvers(args.maneuver) or DEFAULT_MANEUVERS, tolerance_deg=args.tol,
                            duration_s=args.duration)
        finally:
            artefact.close()
        lines, passed, report = result.lines(), result.passed, result.as_dict()
    print("\n".join(lines))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2, default=str) + "\n", encoding="utf-8")
    return 0 if passed else 1


def register(sub: Subparsers) -> None:
    """Add ``export`` and ``verify`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("export", help="export a model as an FMI 2.0 FMU, a JSBSim system or C sources",
                       description="Export a second-order model (loada, loadf; loac and second_order through LOADA's "
                                   "kernel), a linear model (loes, hoalm, sloac: its zero-order-hold state space; "
                                   "FMU and C), a high-order discrete model (hoad2, hoad3: its 10 kHz kernel; FMU "
                                   "and C) or an `ema identify --json` report's final model.")
    p.add_argument("model", metavar="MODEL_OR_REPORT",
                   help="loada, loadf, loac, second_order, loes, hoalm, sloac, hoad2, hoad3, or a report .json")
    p.add_argument("--channel", default=None, help="EMAC channel (default left_wing; a report's own)")
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="override a model parameter (repeatable)")
    p.add_argument("--rate", type=float, default=None, help="the model's rate, Hz (default: its own)")
    p.add_argument("--fmu", default=None, metavar="OUT.fmu", help="write an FMI 2.0 co-simulation FMU")
    p.add_argument("--jsbsim", default=None, metavar="OUT.xml", help="write a JSBSim <system> file")
    p.add_argument("--c", default=None, metavar="DIR", help="write C sources, header, harness and Makefile")
    p.set_defaults(func=run_export)

    v = sub.add_parser("verify", help="verify an exported artefact (or a host's recorded integration) against the "
                                      "truth model",
                       description="Run an .fmu (FMPy), a JSBSim .xml system or a C export directory (its harness) "
                                   "and the truth on the report's maneuvers, with a sign and unit check; or say "
                                   "whether a host's record (.csv, bag) of its own integration matches the truth "
                                   "and name the likely fault.")
    v.add_argument("artefact", metavar="ARTEFACT", help=".fmu, .xml, a C export directory, or a host's .csv / bag")
    v.add_argument("--channel", default=None, help="EMAC channel (an artefact's own; a record's metadata)")
    v.add_argument("--model", default=None, metavar="MODEL_OR_REPORT",
                   help="the truth of a host's record (default loada), or a report .json")
    v.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="override a truth parameter for a host's record (repeatable)")
    v.add_argument("--rate", type=float, default=None, help="the truth's rate for a host's record, Hz")
    v.add_argument("--maneuver", action="append", metavar="SPEC[@LOAD]",
                   help="a maneuver, with an optional load after @ (repeatable; default: the report's set)")
    v.add_argument("--duration", type=float, default=None, help="cut every maneuver to this many seconds")
    v.add_argument("--tol", type=float, default=None,
                   help="largest difference allowed, deg (default 1e-9 for an exact artefact; 0.01 rms for a record)")
    v.add_argument("--json", default=None, metavar="OUT.json", help="write the figures as JSON")
    v.set_defaults(func=run_verify)

"""``ema schema``: the published JSON Schema of a report (``ema identify --json``, ``ema analyze --json``)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

from ema_sim.analysis.contract import analyze_schema
from ema_sim.commands.common import Subparsers
from ema_sim.identify.contract import identify_schema

SCHEMAS: dict[str, Callable[[], dict[str, object]]] = {"identify": identify_schema, "analyze": analyze_schema}
"""Report → its schema, generated from the report's TypedDicts."""


def text(report: str) -> str:
    """The schema of ``report`` as the indented JSON the docs publish (``docs/schema/REPORT.schema.json``).

    Parameters
    ----------
    report : str
        Which report: ``identify`` or ``analyze``.
    """
    return json.dumps(SCHEMAS[report](), indent=2, ensure_ascii=False) + "\n"


def schema(args: argparse.Namespace) -> int:
    """Print or write a report's JSON Schema.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    out = text(args.report)
    if args.out:
        Path(args.out).write_text(out, encoding="utf-8")
        print(f"wrote {args.out}")
    else:
        sys.stdout.write(out)
    return 0


def register(sub: Subparsers) -> None:
    """Add ``schema`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("schema", help="the JSON Schema of a report (identify, analyze)",
                       description="Print the JSON Schema (draft 2020-12) that every `ema identify --json` or "
                                   "`ema analyze --json` report matches; generated from the report's types.")
    p.add_argument("report", choices=sorted(SCHEMAS), help="which report")
    p.add_argument("--out", metavar="FILE.json", help="write it here instead of printing it")
    p.set_defaults(func=schema)

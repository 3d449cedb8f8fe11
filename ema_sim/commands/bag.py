"""``ema bag``: bag maintenance; ``ema bag reindex DIR`` repairs a bag whose writer was killed."""

from __future__ import annotations

import argparse

from ema_sim.commands.common import Subparsers
from ema_sim.io.bag import reindex_bag


def _reindex(args: argparse.Namespace) -> int:
    """Rebuild the index, summary, footer and ``metadata.yaml`` of each bag; print what was recovered."""
    for path in args.bags:
        report = reindex_bag(path, keep_original=not args.no_backup)
        cut = (f"; {report.partial_chunk_messages} message(s) from the chunk cut short, "
               f"{report.dropped_bytes} byte(s) of an incomplete record dropped") if report.dropped_bytes else ""
        print(f"{report.path}: {report.message_count} messages on {len(report.messages)} topics from "
              f"{report.chunks} complete chunk(s){cut}" + (f"; original kept as {report.backup.name}"
                                                           if report.backup else ""))
        for topic, count in sorted(report.messages.items()):
            print(f"  {topic:28s} {count}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``bag`` (``reindex``) to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("bag", help="bag maintenance: reindex a bag whose writer was killed",
                       description="Bag maintenance for rosbag2 (MCAP) bags.")
    cmds = p.add_subparsers(dest="bag_command", required=True)
    r = cmds.add_parser("reindex", aliases=["repair"],
                        help="make a bag whose writer was killed readable by mcap and rosbags again",
                        description="Rebuild the MCAP index, summary and footer and the bag's metadata.yaml from "
                                    "every complete record (as ros2 bag reindex does); nothing complete is lost.")
    r.add_argument("bags", nargs="+", metavar="DIR", help="bag directory (or its .mcap file)")
    r.add_argument("--no-backup", action="store_true", help="do not keep the original file as <name>.mcap.orig")
    r.set_defaults(func=_reindex)

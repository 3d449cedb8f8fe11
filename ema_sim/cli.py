"""``ema``: the command-line entry point; each subcommand lives in :mod:`ema_sim.commands`.

Every user error (unknown model, malformed spec or data...) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from collections.abc import Sequence
from importlib import import_module
from types import FrameType
from typing import NoReturn

from ema_sim import __version__
from ema_sim.commands import COMMANDS, SUBCOMMANDS
from ema_sim.errors import EmaError


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr and exit status 2, like every user error."""

    def error(self, message: str) -> NoReturn:
        """Print ``<prog>: error: message`` (no usage block) and exit 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _chosen(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names (its first word that is not an option), None when it names none we know."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in SUBCOMMANDS else None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``ema`` parser: with ``argv`` naming a subcommand, that command's module only, else every one.

    Parameters
    ----------
    argv : Sequence[str], optional
        The arguments after ``ema``; None for the parser of every subcommand (``ema --help``).
    """
    parser = _Parser(
        prog="ema", description="X-43A electromechanical actuator emulation (NASA/TM-2008-214637)."
    )
    parser.add_argument("--version", action="version", version=f"ema_sim {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = _chosen(argv) if argv is not None else None
    for name in COMMANDS if chosen is None else (SUBCOMMANDS[chosen],):
        import_module(f"ema_sim.commands.{name}").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ema``.

    Parameters
    ----------
    argv : Sequence[str], optional
        The arguments after ``ema`` (default: the command line's).

    Returns
    -------
    int
        The exit status: 0 on success, 2 for a user error (one line on stderr), 130 when interrupted.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    interrupted: list[int] = []

    def on_interrupt(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001
        interrupted.append(signum)
        raise KeyboardInterrupt

    # a Ctrl-C the shell ignores for this process (a background job's SIG_IGN) stays ignored
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, on_interrupt)
    try:
        parser = build_parser(argv)  # a second of imports: Ctrl-C here is an interruption too, not a traceback
        args = parser.parse_args(argv)
        if interrupted:  # raised inside a library's import that swallowed it (a bare ``except:``): still Ctrl-C
            raise KeyboardInterrupt
    except BaseException as exc:  # a Ctrl-C raised in some import's machinery may come out as another error
        if not interrupted and not isinstance(exc, KeyboardInterrupt):  # (RuntimeError from __set_name__)
            raise
        print("ema: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, previous)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except EmaError as exc:
        print(f"ema {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ema {args.command}: interrupted", file=sys.stderr)
        return 130


def entry() -> NoReturn:
    """Console script ``ema``: :func:`main`'s status as the process's exit status, 130 included.

    A Ctrl-C raised inside an import that runs code through CPython's embedded-evaluation calls leaves the
    interpreter's "unhandled KeyboardInterrupt" mark set even though :func:`main` handled it; at exit CPython
    would then kill the process with SIGINT instead of returning 130 (measured: 4 of 25 launches interrupted
    at ``import numpy`` on a loaded machine). An interrupted run ends here, its output flushed, without
    that last step.
    """
    status = main()
    if status == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(status)


if __name__ == "__main__":
    entry()

"""Argument helpers shared by several subcommands."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

from ema_sim.config import CHANNELS
from ema_sim.errors import DataError, EmaError, SpecError, UnknownNameError

if TYPE_CHECKING:
    from ema_sim.io.csv import RigFormat

Subparsers: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"
"""What each command's ``register`` adds its parser to (``ArgumentParser.add_subparsers``)."""


def parse_overrides(items: Sequence[str] | None) -> dict[str, float]:
    """``--set name=value`` pairs as model parameter overrides.

    Parameters
    ----------
    items : Sequence[str] or None
        The ``--set`` values as given.

    Returns
    -------
    dict[str, float]
        Parameter name → value.

    Raises
    ------
    SpecError
        An item that is not ``name=number``.
    """
    out: dict[str, float] = {}
    for item in items or []:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise SpecError(f"--set expects name=value, got {item!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise SpecError(f"--set {key.strip()}: not a number: {value!r}") from None
    return out


def add_model_args(p: argparse.ArgumentParser) -> None:
    """Add ``--channel`` and ``--set``, for commands that build a model.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The command's parser.
    """
    p.add_argument("--channel", default="left_wing", help="EMAC channel (default left_wing)")
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="override a model parameter (repeatable), e.g. --set delay_s=0")


def add_data_args(p: argparse.ArgumentParser) -> None:
    """Add ``--columns``, ``--delimiter`` and ``--crank-arm-in``, for commands that read a rig's own file.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The command's parser.
    """
    p.add_argument("--columns", default=None, metavar="NAME=COLUMN,...",
                   help="map a rig file's columns onto the contract's, with units: e.g. "
                        "time_ms=t,command_deg=demand,position_deg=pos (position_mm, position_in: linear)")
    p.add_argument("--delimiter", default=None, choices=("tab", "comma", "semicolon"),
                   help="the file's delimiter (default: sniffed from its header, comma first)")
    p.add_argument("--crank-arm-in", type=float, default=None, metavar="IN",
                   help="turn linear positions (mm, in) into degrees through this crank arm (default: keep them)")


def rig_format(args: argparse.Namespace) -> RigFormat | None:
    """The rig-file layout the arguments describe.

    Parameters
    ----------
    args : argparse.Namespace
        A command line with the options of :func:`add_data_args`.

    Returns
    -------
    RigFormat or None
        The layout; None for a data-contract CSV or a bag.

    Raises
    ------
    DataError
        A crank arm that is not positive, or a malformed ``--columns``.
    """
    from ema_sim.io.csv import RigFormat, parse_columns  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    if args.crank_arm_in is not None and not args.crank_arm_in > 0:
        raise DataError(f"--crank-arm-in must be positive, got {args.crank_arm_in:g}")
    if args.columns is None and args.delimiter is None and args.crank_arm_in is None:
        return None
    columns = parse_columns(args.columns) if args.columns else {}
    return RigFormat(columns, args.delimiter, args.crank_arm_in)


def check_channel(name: str | None) -> None:
    """An unknown ``--channel`` is one clear error (exit 2), never a silent stand-in.

    Parameters
    ----------
    name : str or None
        The ``--channel`` given (None: none given).

    Raises
    ------
    UnknownNameError
        ``name`` is not one of the five channels.
    """
    if name is not None and name not in CHANNELS:
        raise UnknownNameError("channel", name, CHANNELS)


def check_outputs(files: Sequence[str | Path | None] = (), folders: Sequence[str | Path | None] = ()) -> None:
    """Make sure what a command will write can be written, before its work: one clear error now, not after a fit.

    Each file's folder and each folder are created when missing (as the writers do).

    Parameters
    ----------
    files : sequence of path or None
        Files the command will write (None: not asked for).
    folders : sequence of path or None
        Folders it will write into.

    Raises
    ------
    EmaError
        A folder cannot be created, or is not writable, or a file names a folder.
    """
    wanted: list[tuple[Path, Path | None]] = [(Path(f).parent, Path(f)) for f in files if f is not None]
    wanted += [(Path(d), None) for d in folders if d is not None]
    for folder, file in wanted:
        blocker = next((a for a in (folder, *folder.parents) if a.exists() and not a.is_dir()), None)
        if blocker is not None:
            raise EmaError(f"cannot write {file or folder}: {blocker} is a file, not a folder")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise EmaError(f"cannot write {file or folder}: {exc.strerror or exc} ({folder})") from None
        if not os.access(folder, os.W_OK):
            raise EmaError(f"cannot write {file or folder}: the folder {folder} is not writable")
        if file is not None and file.is_dir():
            raise EmaError(f"cannot write {file}: it is a folder")

"""The measured-data CSV of ``../shared/data-contract.md``: strict reading, faithful writing, rig files.

Reading checks every rule of the contract and fails with one :class:`~ema_sim.errors.DataError`
that names the file line and the column; it never returns partial data. One exception: a last line with
no line end that is cut short (fewer cells than the header, or a cell with fewer decimals than the same
column's two lines before: a logger stopped while writing) is no row; it is left out and said in the
record's ``truncated`` metadata, which both tools print.

A contract file saved with tabs or semicolons (a spreadsheet's export; then a decimal comma is read as
a decimal point) is read as well, the delimiter sniffed from the header; a ``#`` line before the header
that is not ``# key: value`` (a rig's banner) is kept as the ``comment`` metadata.

Rig files as they come (:class:`RigFormat`, :func:`read_rig`): tab, comma or semicolon separated (sniffed
from the header), columns under the rig's own names mapped onto the contract's by an option such as
``time_ms=t,command_deg=demand,position_deg=pos`` (:func:`parse_columns`), time in seconds or
milliseconds, positions in degrees or in a linear unit (``_mm``, ``_in``). Linear positions are
turned into surface degrees through the crank arm when one is given (``deg = x/arm`` in radians, the
arc at the crank), else kept as logged: the record's :attr:`MeasuredData.unit` then names the unit
and the report says so. Every rule of the contract still holds, and every error names the file's
line and the rig's own column.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import DataError
from ema_sim.io.measured import KNOWN, OPTIONAL, OUTPUTS, REQUIRED, MeasuredData

FloatArray = NDArray[np.float64]

TIME_UNITS = {"s": 1.0, "ms": 1e-3}
LINEAR_UNITS_IN = {"mm": 1.0 / 25.4, "in": 1.0}
"""Inches per unit of each linear unit a rig may log positions in."""
POSITIONAL = ("command", "position", "surface")
DELIMITERS = {"tab": "\t", "comma": ",", "semicolon": ";"}
MIN_ROWS = 100
SIGNAL_FULL_SCALE_V = 10.0
"""The contract's raw command and LVDT signals are ±10 V: a reading beyond it (with
:data:`SIGNAL_MARGIN` for a converter's own overrange) is not one of them."""
SIGNAL_MARGIN = 0.05
SIGNAL_COLUMNS = ("command_v", "position_v")


def _parse_metadata(line: str) -> tuple[str, str] | None:
    """``# key: value``; a line without a key (a rig's banner, ``# exported by ...``) is a ``comment``."""
    body = line.lstrip("#").strip()
    if not body:
        return None
    key, sep, value = body.partition(":")
    if not sep or not key.strip() or not _is_key(key.strip()):
        return "comment", body
    return key.strip(), value.strip()


def _is_key(text: str) -> bool:
    """A metadata key: one word of letters, digits, ``_``, ``-`` or ``.`` (``# note: 12:30`` is keyed ``note``)."""
    return all(c.isalnum() or c in "_-." for c in text)


@dataclass(frozen=True)
class RigFormat:
    """How a rig's own file maps onto the contract: its columns, its delimiter, its linear positions.

    Parameters
    ----------
    columns : dict
        Contract name with its unit (``time_ms``, ``position_mm``...) → the file's column name.
    delimiter : str or None
        ``tab``, ``comma`` or ``semicolon``; None: sniffed from the header row.
    crank_arm_in : float or None
        Linear positions are turned into degrees through this crank arm; None: kept as logged.
    """

    columns: dict[str, str] = field(default_factory=dict)
    """Contract name with its unit (``time_ms``, ``position_mm``...) → the file's column name."""
    delimiter: str | None = None
    """``tab``, ``comma`` or ``semicolon``; None: sniffed from the header row."""
    crank_arm_in: float | None = None
    """Linear positions are turned into degrees through this crank arm; None: kept as logged."""

    def target(self, name: str) -> tuple[str, str, float]:
        """A mapped name's contract column, unit and factor to the contract's unit.

        Parameters
        ----------
        name : str
            ``time_ms``, ``command_mm``, ``position_deg``, ``hinge_moment_inlb``...

        Returns
        -------
        tuple
            The contract column (``time_s``...), the unit kept (``deg``, ``mm``, ``in``; ``""`` for the
            others) and the factor the file's values are multiplied by.
        """
        base, _, unit = name.rpartition("_")
        if base == "time" and unit in TIME_UNITS:
            return "time_s", "", TIME_UNITS[unit]
        if base in POSITIONAL and unit == "deg":
            return f"{base}_deg", "deg", 1.0
        if base in POSITIONAL and unit in LINEAR_UNITS_IN:
            if self.crank_arm_in:
                return f"{base}_deg", "deg", float(np.degrees(LINEAR_UNITS_IN[unit] / self.crank_arm_in))
            return f"{base}_deg", unit, 1.0
        if name in OPTIONAL:
            return name, "", 1.0
        accepted = ["time_s", "time_ms", *(f"{p}_{u}" for p in POSITIONAL for u in ("deg", "mm", "in")), *OPTIONAL]
        raise DataError(f"--columns: unknown column {name!r}; accepted: {', '.join(accepted)}")


def parse_columns(text: str) -> dict[str, str]:
    """``time_ms=t,command_deg=demand,position_deg=pos`` as a mapping (contract name → the file's name).

    Parameters
    ----------
    text : str
        Comma-separated ``name=column`` pairs.

    Returns
    -------
    dict
        The mapping, checked (every name known, none twice).
    """
    out: dict[str, str] = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        name, sep, column = part.partition("=")
        name, column = name.strip(), column.strip()
        if not sep or not name or not column:
            raise DataError(f"--columns: expected name=column pairs separated by commas, got {part!r}")
        RigFormat().target(name)  # an unknown name is one clear error
        if name in out:
            raise DataError(f"--columns: {name!r} given twice")
        out[name] = column
    if not out:
        raise DataError("--columns: no name=column pair given")
    return out


def _read_text(path: Path) -> str:
    source = str(path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"{source}: no such file") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise DataError(f"{source}: cannot read ({exc.strerror})") from None


def read_csv(path: str | Path) -> MeasuredData:
    """Read and validate a measured-data CSV (see the module docstring).

    Parameters
    ----------
    path : str or pathlib.Path
        The file.

    Returns
    -------
    MeasuredData
        Every column of the contract the file has.
    """
    path = Path(path)
    return parse_csv(_read_text(path), str(path))


def read_rig(path: str | Path, fmt: RigFormat) -> MeasuredData:
    """Read a rig's own file: its delimiter, its column names, its units (see the module docstring).

    Parameters
    ----------
    path : str or pathlib.Path
        The file.
    fmt : RigFormat
        How its columns map onto the contract.

    Returns
    -------
    MeasuredData
        In the contract's units, or with ``unit`` naming the linear unit kept.
    """
    path = Path(path)
    return parse_csv(_read_text(path), str(path), fmt)


def _header(lines: list[str], source: str) -> tuple[dict[str, str], int]:
    """Metadata lines before the header, and the header's index."""
    metadata: dict[str, str] = {}
    first = 0
    while first < len(lines) and (lines[first].startswith("#") or not lines[first].strip()):
        if lines[first].startswith("#"):
            kv = _parse_metadata(lines[first])
            if kv:
                key, value = kv
                metadata[key] = f"{metadata[key]} | {value}" if key == "comment" and key in metadata else value
        first += 1
    if first >= len(lines):
        raise DataError(f"{source}: no header row")
    return metadata, first


def _delimiter(header_line: str, fmt: RigFormat | None) -> str:
    """The given delimiter, else the header's: comma first, then tab or semicolon.

    A contract file saved by a spreadsheet in a locale whose decimal mark is the comma is semicolon separated.
    """
    if fmt is not None and fmt.delimiter is not None:
        if fmt.delimiter not in DELIMITERS:
            raise DataError(f"--delimiter: expected one of {', '.join(DELIMITERS)}, got {fmt.delimiter!r}")
        return DELIMITERS[fmt.delimiter]
    for sep in (",", "\t", ";"):
        if sep in header_line:
            return sep
    return ","


def _rig_hint(fmt: RigFormat | None) -> str:
    """A hint when a contract CSV's header lacks the contract's names: a rig's own file."""
    if fmt is None:
        return (" (a rig's own file? map its columns with --columns, e.g. "
                "time_ms=t,command_deg=demand,position_deg=pos)")
    return ""


def _number(cell: str, sep: str) -> float:
    """A cell's value; with a semicolon or tab delimiter, a decimal comma is read as a decimal point."""
    if "_" in cell:  # Python's float() reads 1_0.0 as 10.0; no logger writes digit separators
        raise ValueError(cell)
    try:
        return float(cell)
    except ValueError:
        if sep == "," or "," not in cell or "." in cell:
            raise
        return float(cell.replace(",", "."))


def _mapping(header: list[str], fmt: RigFormat | None, source: str, line: int
             ) -> tuple[dict[str, tuple[int, str, float]], str]:
    """Contract column → (index in the file, the file's name, factor); and the positions' unit."""
    wanted: dict[str, tuple[int, str, float]] = {}
    units: set[str] = set()
    if fmt is not None:
        for name, column in fmt.columns.items():
            if column not in header:
                raise DataError(f"{source}: line {line}: no column {column!r} for {name} "
                                f"(columns: {', '.join(header)})")
            target, unit, factor = fmt.target(name)
            if target in wanted:
                raise DataError(f"--columns: two columns map to {target}")
            wanted[target] = (header.index(column), column, factor)
            if unit:
                units.add(unit)
    for name in KNOWN:
        if name not in wanted and name in header:
            wanted[name] = (header.index(name), name, 1.0)
            if name.endswith("_deg"):
                units.add("deg")
    for name in REQUIRED:
        if name not in wanted:
            raise DataError(f"{source}: line {line}: missing required column {name!r}{_rig_hint(fmt)}")
    if not any(name in wanted for name in OUTPUTS):
        named = [h for h in header if h.split("_")[0] in ("position", "surface") and h not in OUTPUTS]
        hint = (f" ({', '.join(repr(h) for h in named)} in another unit: map it with --columns, e.g. "
                f"{named[0]}={named[0]})" if named else "")
        raise DataError(f"{source}: line {line}: needs a 'position_deg' or 'surface_deg' column{hint}")
    if len(units) > 1:
        raise DataError(f"{source}: positions in {' and '.join(sorted(units))} at once: map them to one unit "
                        "(or give --crank-arm-in to turn the linear ones into degrees)")
    return wanted, units.pop() if units else "deg"


def parse_csv(text: str, source: str = "<csv>", fmt: RigFormat | None = None) -> MeasuredData:
    """Validate CSV text against the contract (a rig's own layout when ``fmt`` is given).

    Parameters
    ----------
    text : str
        The file's text.
    source : str
        Its name, for the messages.
    fmt : RigFormat, optional
        A rig's delimiter, column names and units.

    Returns
    -------
    MeasuredData
        The record.
    """
    lines = text.splitlines()
    metadata, first = _header(lines, source)
    sep = _delimiter(lines[first], fmt)
    reader = csv.reader(io.StringIO("\n".join(lines[first:])), delimiter=sep)
    header = [h.strip() for h in next(reader)]
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{source}: line {first + 1}: column {dup!r} appears twice")
    wanted, unit = _mapping(header, fmt, source, first + 1)
    values: dict[str, list[float]] = {name: [] for name in wanted}
    last = _unterminated_line(text, lines)
    before: list[list[str]] = []
    for offset, row in enumerate(reader, start=first + 2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if offset == last and (why := _cut_short(row, header, before)):
            metadata["truncated"] = (f"line {offset}, the last, has no line end and {why}: cut off while being "
                                     "written, it is left out")
            break
        before = [*before[-1:], row]
        if len(row) != len(header):
            raise DataError(f"{source}: line {offset}: {len(row)} cells, header has {len(header)}")
        for name, (idx, column, factor) in wanted.items():
            cell = row[idx].strip()
            label = repr(column) if column == name else f"{column!r} ({name})"
            try:
                value = _number(cell, sep)
            except ValueError:
                raise DataError(f"{source}: line {offset}, column {label}: not a number: {cell!r}") from None
            if not math.isfinite(value):
                raise DataError(f"{source}: line {offset}, column {label}: {cell!r} is not a finite number")
            values[name].append(value * factor)
    n = len(values["time_s"])
    if n < MIN_ROWS:
        raise DataError(f"{source}: {n} data rows; the contract needs at least {MIN_ROWS}")
    arrays = {name: np.asarray(v, dtype=float) for name, v in values.items()}
    dt = np.diff(arrays["time_s"])
    if np.any(dt <= 0.0):
        bad = int(np.argmax(dt <= 0.0)) + 1
        column = wanted["time_s"][1]
        scale = wanted["time_s"][2]
        raise DataError(
            f"{source}: data row {bad + 1}, column {column!r}: time does not increase "
            f"({values['time_s'][bad - 1] / scale:g} then {values['time_s'][bad] / scale:g})"
        )
    _check_signals(arrays, wanted, source)
    if fmt is not None:
        metadata.setdefault("columns", ", ".join(f"{name}={column}" for name, column in fmt.columns.items()))
        if fmt.crank_arm_in:
            metadata.setdefault("crank_arm_in", f"{fmt.crank_arm_in:g}")
    return MeasuredData(metadata=metadata, source=source, unit=unit, **arrays)  # type: ignore[arg-type]


def _unterminated_line(text: str, lines: list[str]) -> int:
    """The file line number of the last line when the file does not end with a line end (0: it does)."""
    if not text or text.endswith(("\n", "\r")):
        return 0
    return next((k + 1 for k in range(len(lines) - 1, -1, -1) if lines[k].strip()), 0)


def _decimals(cell: str) -> int | None:
    """Digits after the decimal point of a plain decimal number (None: no point, or an exponent)."""
    cell = cell.strip().replace(",", ".")
    if "." not in cell or "e" in cell.lower():
        return None
    return len(cell) - cell.index(".") - 1


def _cut_short(row: list[str], header: list[str], before: list[list[str]]) -> str:
    """Why an unterminated last row was cut short (empty: it looks whole).

    Fewer cells than the header, or a cell with fewer decimals than the same column's two rows before it.
    """
    if len(row) < len(header):
        return f"{len(row)} of the header's {len(header)} cells"
    if len(before) < 2 or len(row) != len(header):
        return ""
    for k, cell in enumerate(row):
        d = _decimals(cell)
        prior = [_decimals(r[k]) for r in before if k < len(r)]
        if d is not None and all(p is not None and p > d for p in prior):
            return f"its cell {cell.strip()!r} in {header[k]!r} has fewer decimals than that column's rows before it"
    return ""


def _check_signals(arrays: Mapping[str, FloatArray], wanted: Mapping[str, tuple[int, str, float]], source: str
                   ) -> None:
    """One clear error for a raw ±10 V signal beyond its full scale (the first such row and its column)."""
    limit = SIGNAL_FULL_SCALE_V * (1.0 + SIGNAL_MARGIN)
    for name in SIGNAL_COLUMNS:
        if name not in arrays:
            continue
        beyond = np.flatnonzero(np.abs(arrays[name]) > limit)
        if beyond.size:
            k = int(beyond[0])
            column = wanted[name][1]
            label = repr(column) if column == name else f"{column!r} ({name})"
            raise DataError(f"{source}: data row {k + 1}, column {label}: {arrays[name][k]:g} V is beyond the "
                            f"contract's ±{SIGNAL_FULL_SCALE_V:g} V signals ({beyond.size} rows are): is the "
                            "column in volts, and the raw signal?")


def write_csv(
    path: str | Path, columns: Mapping[str, FloatArray], metadata: Mapping[str, object] | None = None
) -> None:
    """Write columns (``time_s`` first) with ``# key: value`` metadata lines before the header.

    Parameters
    ----------
    path : str or pathlib.Path
        The file (its folder is created when missing).
    columns : mapping
        Column name → values.
    metadata : mapping, optional
        Written as ``# key: value`` lines.
    """
    names = list(columns)
    if "time_s" in names:
        names.remove("time_s")
        names.insert(0, "time_s")
    data = np.column_stack([np.asarray(columns[name], dtype=float) for name in names])
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8", newline="") as fh:
        for key, value in (metadata or {}).items():
            fh.write(f"# {key}: {value}\n")
        fh.write(",".join(names) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.9g")

"""The measured-data CSV of ``../shared/data-contract.md``: strict reading, faithful writing.

Reading checks every rule of the contract and fails with one :class:`~ema_sim.errors.DataError`
that names the file line and the column; it never returns partial data.
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

FloatArray = NDArray[np.float64]

REQUIRED = ("time_s", "command_deg")
OUTPUTS = ("position_deg", "surface_deg")
OPTIONAL = ("hinge_moment_inlb", "current_a", "command_v", "position_v", "bus_v", "rate_dps")
"""Recognised optional columns; ``bus_v`` (150 V bus, for regeneration) and ``rate_dps`` (surface rate)
extend the contract's table and are read when a file has them."""
KNOWN = REQUIRED + OUTPUTS + OPTIONAL
MIN_ROWS = 100


@dataclass(frozen=True)
class MeasuredData:
    """One record of actuator data: the contract's columns as arrays, plus its metadata."""

    time_s: FloatArray
    command_deg: FloatArray
    position_deg: FloatArray | None = None
    surface_deg: FloatArray | None = None
    hinge_moment_inlb: FloatArray | None = None
    current_a: FloatArray | None = None
    command_v: FloatArray | None = None
    position_v: FloatArray | None = None
    metadata: dict[str, str] = field(default_factory=dict)
    source: str = ""
    bus_v: FloatArray | None = None
    """Motor bus voltage (section 2.5), when the rig or model records it."""
    rate_dps: FloatArray | None = None
    """Surface rate, when recorded."""
    unit: str = "deg"
    """Unit of the command and outputs: ``deg``, or a rig's linear unit (``mm``, ``in``) kept as logged."""
    extra: dict[str, FloatArray] = field(default_factory=dict)
    """Further recorded signals outside the contract's columns (a bag's FMU-side command and feedback)."""

    @property
    def outputs(self) -> list[str]:
        """The output columns present, position first."""
        return [name for name in OUTPUTS if getattr(self, name) is not None]

    @property
    def hinge_moment(self) -> FloatArray:
        """The hinge moment, zeros when the file has none."""
        return self.hinge_moment_inlb if self.hinge_moment_inlb is not None else np.zeros_like(self.time_s)

    def column(self, name: str) -> FloatArray:
        """A present column by name."""
        value = getattr(self, name, None)
        if value is None:
            raise DataError(f"{self.source or 'data'}: no column {name!r}")
        return value

    @property
    def sample_hz(self) -> float:
        """Median sample rate."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    def __len__(self) -> int:
        return int(self.time_s.size)


def _parse_metadata(line: str, lineno: int, source: str) -> tuple[str, str] | None:
    body = line.lstrip("#").strip()
    if not body:
        return None
    key, sep, value = body.partition(":")
    if not sep or not key.strip():
        raise DataError(f"{source}: line {lineno}: metadata must be '# key: value', got {line.strip()!r}")
    return key.strip(), value.strip()


def read_csv(path: str | Path) -> MeasuredData:
    """Read and validate a measured-data CSV (see the module docstring)."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError(f"{source}: no such file") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{source}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise DataError(f"{source}: cannot read ({exc.strerror})") from None
    return parse_csv(text, source)


def parse_csv(text: str, source: str = "<csv>") -> MeasuredData:  # noqa: PLR0912 - one check per contract rule
    """Validate CSV text against the contract."""
    lines = text.splitlines()
    metadata: dict[str, str] = {}
    first = 0
    while first < len(lines) and (lines[first].startswith("#") or not lines[first].strip()):
        if lines[first].startswith("#"):
            kv = _parse_metadata(lines[first], first + 1, source)
            if kv:
                metadata[kv[0]] = kv[1]
        first += 1
    if first >= len(lines):
        raise DataError(f"{source}: no header row")
    reader = csv.reader(io.StringIO("\n".join(lines[first:])))
    header = [h.strip() for h in next(reader)]
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{source}: line {first + 1}: column {dup!r} appears twice")
    for name in REQUIRED:
        if name not in header:
            raise DataError(f"{source}: line {first + 1}: missing required column {name!r}")
    if not any(name in header for name in OUTPUTS):
        raise DataError(f"{source}: line {first + 1}: needs a 'position_deg' or 'surface_deg' column")
    wanted = {name: header.index(name) for name in KNOWN if name in header}
    values: dict[str, list[float]] = {name: [] for name in wanted}
    for offset, row in enumerate(reader, start=first + 2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise DataError(f"{source}: line {offset}: {len(row)} cells, header has {len(header)}")
        for name, idx in wanted.items():
            cell = row[idx].strip()
            try:
                value = float(cell)
            except ValueError:
                raise DataError(f"{source}: line {offset}, column {name!r}: not a number: {cell!r}") from None
            if not math.isfinite(value):
                raise DataError(f"{source}: line {offset}, column {name!r}: {cell!r} is not a finite number")
            values[name].append(value)
    n = len(values["time_s"])
    if n < MIN_ROWS:
        raise DataError(f"{source}: {n} data rows; the contract needs at least {MIN_ROWS}")
    arrays = {name: np.asarray(v, dtype=float) for name, v in values.items()}
    dt = np.diff(arrays["time_s"])
    if np.any(dt <= 0.0):
        bad = int(np.argmax(dt <= 0.0)) + 1
        raise DataError(
            f"{source}: data row {bad + 1}, column 'time_s': time does not increase "
            f"({arrays['time_s'][bad - 1]:g} then {arrays['time_s'][bad]:g})"
        )
    return MeasuredData(metadata=metadata, source=source, **arrays)


def write_csv(
    path: str | Path, columns: Mapping[str, FloatArray], metadata: Mapping[str, object] | None = None
) -> None:
    """Write columns (``time_s`` first) with ``# key: value`` metadata lines before the header."""
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

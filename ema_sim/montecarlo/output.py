"""A campaign's directory: the manifest, the rows in Parquet parts, the envelopes and the summary.

``DIR/campaign.json``
    the campaign (every bound resolved into numbers), the seed, the number of runs and the batch: what
    ``--resume`` checks before it completes a campaign.
``DIR/runs.parquet/part-<first run>.parquet``
    one part per finished task, written as the task finishes (to a temporary name, then renamed: a part
    is there whole or not at all), so an interrupted campaign keeps every finished task. The directory is
    one Parquet dataset (``pandas.read_parquet(DIR / "runs.parquet")``, ``pyarrow.parquet.read_table``):
    a row per run, ``run`` then the dispersed parameters then the metrics.
``DIR/parts/<first run>.npz``
    the task's envelopes (lowest, highest and sum of each signal over its runs), its worker's address
    and time, and, for the task of run 0, the nominal run.
``DIR/summary.json``
    strict JSON (no NaN: null): runs, seed, campaign, workers, wall_s, per-metric statistics, the
    nominal run, each metric's rank correlation with each dispersed parameter.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np

from ema_sim import __version__
from ema_sim.errors import EmaError
from ema_sim.jsontypes import JsonValue
from ema_sim.montecarlo.campaign import Campaign
from ema_sim.montecarlo.runs import Block, Envelope

MANIFEST = "campaign.json"
RUNS = "runs.parquet"
PARTS = "parts"
SUMMARY = "summary.json"
QUANTILES = (0.01, 0.05, 0.5, 0.95, 0.99)
Statistics = dict[str, int | float | None]
"""One column's figures (:func:`statistics`): ``count``, ``nan``, ``mean``, ``std``, ``min``, ``max``, ``p01`` …"""


class EnvelopeMeta(TypedDict):
    """What a task's file keeps of one envelope beside its arrays."""

    count: int
    x_label: str
    y_label: str


class PartMeta(TypedDict):
    """A finished task's metadata (the ``meta`` entry of its ``parts/*.npz``)."""

    start: int
    stop: int
    worker: str
    seconds: float
    peak_rss_mb: NotRequired[float]
    """Absent from the files of campaigns written before it was measured."""
    nominal: dict[str, float]
    envelopes: dict[str, EnvelopeMeta]


def _part(start: int) -> str:
    return f"part-{start:09d}"


def write_manifest(out: Path, c: Campaign, seed: int, runs: int, *, resume: bool) -> None:
    """Create the campaign's directory, or check on ``resume`` that it holds this same campaign.

    Parameters
    ----------
    out : pathlib.Path
        The directory.
    c : Campaign
        The campaign.
    seed : int
        Its seed.
    runs : int
        Its number of runs.
    resume : bool
        Complete the campaign the directory holds.
    """
    manifest = {"tool": "ema montecarlo", "version": __version__, "campaign": json.loads(c.to_json()),
                "seed": int(seed), "runs": int(runs), "batch": int(c.batch)}
    path = out / MANIFEST
    if resume:
        if not path.is_file():
            raise EmaError(f"{out}: nothing to resume (no {MANIFEST})")
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
        except ValueError:
            raise EmaError(f"{path}: unreadable manifest") from None
        for key in ("campaign", "seed", "runs", "batch"):
            if old.get(key) != manifest[key]:
                raise EmaError(f"{out} holds another campaign ({key} differs): resume it with the same campaign, "
                               "--runs and --seed, or use another directory")
        return
    if path.exists() or (out / RUNS).exists():
        raise EmaError(f"{out} already holds a campaign: --resume completes it, or choose another --out")
    (out / RUNS).mkdir(parents=True, exist_ok=True)
    (out / PARTS).mkdir(exist_ok=True)
    _write_json(path, manifest)


def finished(out: Path) -> set[int]:
    """The first runs of the tasks whose parts are on disk.

    Parameters
    ----------
    out : pathlib.Path
        The directory.

    Returns
    -------
    set of int
        First run of each finished task.
    """
    return {int(p.stem.split("-")[1]) for p in (out / RUNS).glob("part-*.parquet")}


def write_block(out: Path, block: Block) -> None:
    """Put one finished task on disk: envelopes first, then its rows (renamed into place last).

    Parameters
    ----------
    out : pathlib.Path
        The directory.
    block : Block
        The task's result.
    """
    import pyarrow as pa  # noqa: PLC0415 - 70 ms of import, only when Parquet is written or read (not at ema start)
    import pyarrow.parquet as pq  # noqa: PLC0415 - the same

    arrays: dict[str, np.ndarray] = {}
    for name, e in block.envelopes.items():
        for key in ("x", "lo", "hi", "total"):
            arrays[f"{name}|{key}"] = getattr(e, key)
        if e.nominal is not None:
            arrays[f"{name}|nominal"] = e.nominal
    meta: PartMeta = {"start": block.start, "stop": block.stop, "worker": block.worker, "seconds": block.seconds,
                      "peak_rss_mb": block.peak_rss_mb, "nominal": block.nominal,
                      "envelopes": {n: {"count": e.count, "x_label": e.x_label, "y_label": e.y_label}
                                    for n, e in block.envelopes.items()}}
    arrays["meta"] = np.array(json.dumps(meta))
    tmp = out / PARTS / f".{_part(block.start)}.tmp.npz"
    np.savez(tmp, **arrays)  # type: ignore[arg-type]
    os.replace(tmp, out / PARTS / f"{block.start:09d}.npz")
    table = pa.table({k: pa.array(v) for k, v in block.columns.items()})
    tmp = out / RUNS / f".{_part(block.start)}.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, out / RUNS / f"{_part(block.start)}.parquet")


def part_meta(out: Path) -> Iterator[tuple[PartMeta, dict[str, Envelope]]]:
    """Each finished task's metadata and envelopes, one at a time (memory stays one task's).

    Parameters
    ----------
    out : pathlib.Path
        The directory.

    Yields
    ------
    tuple
        The task's metadata (start, stop, worker, seconds, nominal) and its envelopes.
    """
    for start in sorted(finished(out)):
        with np.load(out / PARTS / f"{start:09d}.npz") as z:
            meta: PartMeta = json.loads(str(z["meta"]))  # what write_block wrote
            envs = {}
            for name, info in meta["envelopes"].items():
                key = f"{name}|nominal"
                nominal = z[key] if key in z.files else None
                envs[name] = Envelope(z[f"{name}|x"], z[f"{name}|lo"], z[f"{name}|hi"], z[f"{name}|total"],
                                      int(info["count"]), nominal, info["x_label"], info["y_label"])
        yield meta, envs


def read_column(out: Path, name: str) -> np.ndarray:
    """One column of every finished run, in run order.

    Parameters
    ----------
    out : pathlib.Path
        The directory.
    name : str
        The column.

    Returns
    -------
    numpy.ndarray
        Its values.
    """
    import pyarrow.parquet as pq  # noqa: PLC0415 - pyarrow only when Parquet is read (see write_block)

    table = pq.read_table(out / RUNS, columns=["run"] if name == "run" else ["run", name])
    order = np.argsort(table.column("run").to_numpy())
    return np.asarray(table.column(name).to_numpy(), dtype=float)[order]


def read_runs(out: Path) -> dict[str, np.ndarray]:
    """Every column of every finished run, in run order (for tests and small campaigns).

    Parameters
    ----------
    out : pathlib.Path
        The directory.

    Returns
    -------
    dict
        Column → values.
    """
    import pyarrow.parquet as pq  # noqa: PLC0415 - pyarrow only when Parquet is read (see write_block)

    table = pq.read_table(out / RUNS)
    order = np.argsort(table.column("run").to_numpy())
    return {name: table.column(name).to_numpy()[order] for name in table.column_names}


def column_names(out: Path) -> list[str]:
    """The dataset's columns (``run``, the parameters, the metrics).

    Parameters
    ----------
    out : pathlib.Path
        The directory.

    Returns
    -------
    list of str
        The column names.
    """
    import pyarrow.parquet as pq  # noqa: PLC0415 - pyarrow only when Parquet is read (see write_block)

    parts = sorted((out / RUNS).glob("part-*.parquet"))
    if not parts:
        return []
    return list(pq.read_schema(parts[0]).names)


def statistics(values: np.ndarray) -> Statistics:
    """Count, NaNs, mean, std, extremes and quantiles of one column (NaNs left out of the figures).

    Parameters
    ----------
    values : numpy.ndarray
        The column.

    Returns
    -------
    dict
        ``count``, ``nan``, ``mean``, ``std``, ``min``, ``max``, ``p01`` … ``p99``.
    """
    ok = values[np.isfinite(values)]
    out: Statistics = {"count": int(values.size), "nan": int(values.size - ok.size)}
    if ok.size:
        out.update(mean=float(ok.mean()), std=float(ok.std(ddof=1)) if ok.size > 1 else None,
                   min=float(ok.min()), max=float(ok.max()))
        for q, v in zip(QUANTILES, np.quantile(ok, QUANTILES), strict=True):
            out[f"p{round(100 * q):02d}"] = float(v)
    return out


def _ranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    ranks = np.empty(x.size)
    ranks[order] = np.arange(x.size, dtype=float)
    xs = x[order]  # ties share their mean rank
    i = 0
    while i < xs.size:
        j = i
        while j + 1 < xs.size and xs[j + 1] == xs[i]:
            j += 1
        if j > i:
            ranks[order[i:j + 1]] = 0.5 * (i + j)
        i = j + 1
    return ranks


def spearman(x: np.ndarray, y: np.ndarray) -> float | None:
    """Spearman's rank correlation over the runs where both are finite (None when it is undefined).

    Parameters
    ----------
    x, y : numpy.ndarray
        Two columns.

    Returns
    -------
    float or None
        ρ in [−1, 1].
    """
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return None
    rx, ry = _ranks(x[ok]), _ranks(y[ok])
    sx, sy = rx.std(), ry.std()
    if sx == 0.0 or sy == 0.0:
        return None
    return float(np.mean((rx - rx.mean()) * (ry - ry.mean())) / (sx * sy))


def clean(value: object) -> JsonValue:
    """Plain JSON values: NaN and ±inf as null, numpy scalars as Python numbers.

    Parameters
    ----------
    value : object
        Nested dicts, lists and numbers.

    Returns
    -------
    object
        The same, strict-JSON safe.
    """
    if isinstance(value, Mapping):
        return {str(k): clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [clean(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, bool | int | float | str):
        return value
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")  # json.dumps' own error


def _write_json(path: Path, doc: Mapping[str, object]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(clean(doc), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def write_summary(out: Path, doc: Mapping[str, object]) -> Path:
    """Write ``summary.json`` (strict JSON).

    Parameters
    ----------
    out : pathlib.Path
        The directory.
    doc : mapping
        The summary.

    Returns
    -------
    pathlib.Path
        The file.
    """
    path = out / SUMMARY
    _write_json(path, doc)
    return path

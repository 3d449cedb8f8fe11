"""A campaign's summary: statistics of every column, the nominal run, the envelopes and the sensitivities.

Read back from the campaign's directory one column and one task at a time (memory does not grow with
the number of runs beyond one column), so a 100,000-run campaign summarises like a 100-run one.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TypedDict

import numpy as np

from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.montecarlo import output
from ema_sim.montecarlo.campaign import Campaign
from ema_sim.montecarlo.engine import EngineResult
from ema_sim.montecarlo.output import Statistics
from ema_sim.montecarlo.runs import Envelope, peak_rss_mb


class CampaignHead(TypedDict):
    """The campaign a summary is of: its name, description and specification."""

    name: str
    description: str
    spec: JsonValue


class Summary(TypedDict):
    """The ``summary.json`` document (:func:`summarize`)."""

    runs: int
    runs_asked: int
    complete: bool
    seed: int
    campaign: CampaignHead
    workers: list[str]
    workers_this_session: list[str]
    scheduler: str
    wall_s: float
    compute_s: float
    task_s: float
    memory: dict[str, float]
    tasks: dict[str, int]
    dispersions: list[JsonObject]
    parameters: dict[str, Statistics]
    metrics: dict[str, Statistics]
    nominal: dict[str, float]
    sensitivity_spearman: dict[str, dict[str, float | None]]
    findings: JsonObject
    plots: list[str]
    rows: str


def merged_envelopes(out: Path) -> tuple[dict[str, Envelope], dict[str, float], list[str], float, float]:
    """Every task's envelopes merged, the nominal run's metrics, the workers and the task time.

    Parameters
    ----------
    out : pathlib.Path
        The campaign's directory.

    Returns
    -------
    envelopes : dict
        Signal → its envelope over every finished run.
    nominal : dict
        The nominal run's metrics.
    workers : list of str
        Addresses of every worker that ran a finished task.
    task_s : float
        Sum of the tasks' times on their workers.
    worker_rss_mb : float
        The largest peak resident memory a worker reported, MiB.
    """
    envelopes: dict[str, Envelope] = {}
    nominal: dict[str, float] = {}
    workers: set[str] = set()
    task_s = 0.0
    rss = 0.0
    for meta, envs in output.part_meta(out):
        workers.add(str(meta["worker"]))
        task_s += float(meta["seconds"])
        rss = max(rss, float(meta.get("peak_rss_mb", 0.0)))
        nominal.update(meta.get("nominal") or {})
        for name, e in envs.items():
            if name in envelopes:
                envelopes[name].merge(e)
            else:
                envelopes[name] = e
    return envelopes, nominal, sorted(workers), task_s, rss


def summarize(out: Path, c: Campaign, *, seed: int, runs: int, engine: EngineResult,
              findings: Mapping[str, JsonValue] | None = None, plots: list[str] | None = None) -> Summary:
    """The ``summary.json`` document of a finished (or partly finished) campaign.

    Parameters
    ----------
    out : pathlib.Path
        The campaign's directory.
    c : Campaign
        The campaign.
    seed : int
        Its seed.
    runs : int
        Runs asked for.
    engine : EngineResult
        This session's tasks and times.
    findings : mapping, optional
        The campaign's own conclusions and cross-checks (built-in campaigns).
    plots : list of str, optional
        The PNG files written.

    Returns
    -------
    dict
        ``runs``, ``seed``, ``campaign``, ``workers``, ``wall_s``, statistics and the rest.
    """
    _, nominal, workers, task_s, worker_rss = merged_envelopes(out)
    names = output.column_names(out)
    params = [n for n in names if n in c.parameters]
    metrics = [n for n in names if n != "run" and n not in c.parameters]
    finished_runs = int(output.read_column(out, "run").size) if names else 0
    param_values = {p: output.read_column(out, p) for p in params}
    stats: dict[str, Statistics] = {}
    sensitivity: dict[str, dict[str, float | None]] = {}
    for m in metrics:
        values = output.read_column(out, m)
        stats[m] = output.statistics(values)
        sensitivity[m] = {p: output.spearman(param_values[p], values) for p in params}
    return {
        "runs": finished_runs,
        "runs_asked": runs,
        "complete": finished_runs == runs,
        "seed": seed,
        "campaign": {"name": c.name, "description": c.description, "spec": json.loads(c.to_json())},
        "workers": workers,
        "workers_this_session": engine.workers,
        "scheduler": engine.scheduler,
        "wall_s": engine.wall_s,
        "compute_s": engine.compute_s,
        "task_s": task_s,
        "memory": {"worker_peak_rss_mb": worker_rss, "client_peak_rss_mb": peak_rss_mb()},
        "tasks": {"run": engine.tasks, "already_done": engine.skipped, "batch": c.batch},
        "dispersions": [d.describe() for d in c.dispersions],
        "parameters": {p: output.statistics(v) for p, v in param_values.items()},
        "metrics": stats,
        "nominal": nominal,
        "sensitivity_spearman": sensitivity,
        "findings": dict(findings or {}),
        "plots": plots or [],
        "rows": str(out / output.RUNS),
    }


def column_statistics(out: Path, name: str) -> Statistics:
    """The statistics of one column (for findings).

    Parameters
    ----------
    out : pathlib.Path
        The campaign's directory.
    name : str
        The column.

    Returns
    -------
    dict
        :func:`~ema_sim.montecarlo.output.statistics`.
    """
    return output.statistics(output.read_column(out, name))


def finite(values: np.ndarray) -> np.ndarray:
    """The finite values of a column.

    Parameters
    ----------
    values : numpy.ndarray
        A column.

    Returns
    -------
    numpy.ndarray
        Its finite values.
    """
    return np.asarray(values[np.isfinite(values)])

"""A campaign's PNG plots: envelopes with the nominal run, histograms of the metrics, sensitivities.

* ``envelope_<signal>.png``: the lowest-to-highest band over the runs, their mean and the nominal run
  (a gain or phase against frequency on a log axis, a record against time);
* ``histograms.png``: every metric's distribution, the nominal value marked;
* ``sensitivity.png``: each metric against each dispersed parameter (one dot per run, at most
  :data:`SCATTER_MAX` runs), the rank correlation in the title.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ema_sim.analysis.formatting import figure
from ema_sim.montecarlo import output
from ema_sim.montecarlo.runs import Envelope

SCATTER_MAX = 5000
"""Runs drawn in a sensitivity scatter (the first ones; the statistics use every run)."""
HIST_MAX_METRICS = 16


def envelope_plot(name: str, env: Envelope, path: Path, extra: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None
                  ) -> None:
    """One envelope: the band, the mean and the nominal run.

    Parameters
    ----------
    name : str
        The signal (the title).
    env : Envelope
        Its envelope.
    path : pathlib.Path
        The PNG.
    extra : mapping, optional
        Label → (x, y) curves drawn on top (a cross-check).
    """
    plt = figure.pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.fill_between(env.x, env.lo, env.hi, color="tab:blue", alpha=0.25, lw=0, label=f"{env.count} runs: range")
    ax.plot(env.x, env.mean, color="tab:blue", lw=0.9, label="mean")
    if env.nominal is not None:
        ax.plot(env.x, env.nominal, color="k", lw=1.0, ls="--", label="nominal")
    for label, (x, y) in (extra or {}).items():
        ax.plot(x, y, lw=0.9, label=label)
    if env.x_label.startswith("frequency"):
        ax.set_xscale("log")
    ax.set_xlabel(env.x_label)
    ax.set_ylabel(env.y_label)
    ax.set_title(name, fontsize=9)
    ax.grid(lw=0.3, which="both")
    ax.legend(fontsize=7)
    figure.save(fig, path)


def histograms(out: Path, metrics: Sequence[str], nominal: Mapping[str, float], path: Path) -> bool:
    """Every metric's histogram (up to :data:`HIST_MAX_METRICS`), the nominal value marked.

    Parameters
    ----------
    out : pathlib.Path
        The campaign's directory.
    metrics : sequence of str
        The metric columns.
    nominal : mapping
        The nominal run's values.
    path : pathlib.Path
        The PNG.

    Returns
    -------
    bool
        False when there was nothing to draw.
    """
    names = list(metrics)[:HIST_MAX_METRICS]
    if not names:
        return False
    plt = figure.pyplot()
    cols = min(4, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.5 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        v = output.read_column(out, name)
        v = v[np.isfinite(v)]
        if v.size:
            ax.hist(v, bins=min(50, max(5, int(np.sqrt(v.size)))), color="tab:blue", alpha=0.8)
        if name in nominal and math.isfinite(nominal[name]):
            ax.axvline(nominal[name], color="k", ls="--", lw=0.9)
        ax.set_title(name, fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    figure.save(fig, path)
    return True


def sensitivity(out: Path, params: Sequence[str], metrics: Sequence[str],
                rho: Mapping[str, Mapping[str, float | None]], path: Path) -> bool:
    """Each metric against each dispersed parameter, the rank correlation in each title.

    Parameters
    ----------
    out : pathlib.Path
        The campaign's directory.
    params : sequence of str
        The dispersed parameters.
    metrics : sequence of str
        The metrics drawn (rows).
    rho : mapping
        Metric → parameter → Spearman ρ.
    path : pathlib.Path
        The PNG.

    Returns
    -------
    bool
        False when there was nothing to draw.
    """
    if not params or not metrics:
        return False
    plt = figure.pyplot()
    fig, axes = plt.subplots(len(metrics), len(params), figsize=(2.6 * len(params), 2.2 * len(metrics)),
                             squeeze=False)
    xs = {p: output.read_column(out, p)[:SCATTER_MAX] for p in params}
    for i, m in enumerate(metrics):
        y = output.read_column(out, m)[:SCATTER_MAX]
        for j, p in enumerate(params):
            ax = axes[i, j]
            ax.plot(xs[p], y, ".", ms=2, alpha=0.5)
            r = rho.get(m, {}).get(p)
            ax.set_title(f"ρ = {r:+.2f}" if r is not None else "ρ undefined", fontsize=7)
            ax.tick_params(labelsize=6)
            if i == len(metrics) - 1:
                ax.set_xlabel(p, fontsize=7)
            if j == 0:
                ax.set_ylabel(m, fontsize=7)
    figure.save(fig, path)
    return True

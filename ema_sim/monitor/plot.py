"""The monitor's timeline plot: residuals, detection statistics, the estimate with its band, and the truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ema_sim.faults.kinds import FloatArray
from ema_sim.monitor.watch import Verdict


def timeline_plot(verdict: Verdict, out: str | Path, truth: dict[str, FloatArray] | None = None,
                  truth_t: FloatArray | None = None) -> Path:
    """Write the timeline PNG.

    Parameters
    ----------
    verdict : Verdict
        The monitor's answer.
    out : str or pathlib.Path
        The PNG to write.
    truth : dict, optional
        Injected truth columns (``fault_<kind>`` → size at each sample), when the record carries them.
    truth_t : numpy.ndarray, optional
        Their sample times (from the record's start).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    import matplotlib as mpl  # noqa: PLC0415 - plotting only when asked

    mpl.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - the same (0.4 s of import)

    tl = verdict.timeline
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    for name, z in tl.z.items():
        axes[0].plot(tl.block_t, z, lw=0.5, label=f"{name} residual / spread")
        axes[1].plot(tl.block_t, tl.statistic[name], lw=0.8, label=f"{name} CUSUM")
    axes[0].axvspan(0.0, verdict.healthy_s, color="0.9", zorder=0, label="healthy window")
    axes[0].set_ylabel("block residual, spreads")
    axes[1].axhline(verdict.threshold, color="k", ls="--", lw=0.8,
                    label=f"threshold {verdict.threshold:.1f} (false alarms set per hour)")
    axes[1].set_ylabel("statistic")
    for d in verdict.detections:
        for ax in axes[:2]:
            ax.axvline(d.time_s, color="tab:red", lw=1.0)
        axes[1].annotate(f"{d.kind} ({d.parameter})", (d.time_s, verdict.threshold), color="tab:red", fontsize=8)
    ax = axes[2]
    if tl.estimate_t:
        e, s = np.array(tl.estimate), np.array(tl.estimate_sigma)
        s = np.where(np.isfinite(s), s, 0.0)
        name = verdict.detections[0].parameter
        ax.plot(tl.estimate_t, e, "o-", color="tab:green", label=f"{name} re-estimated")
        ax.fill_between(tl.estimate_t, e - 2 * s, e + 2 * s, color="tab:green", alpha=0.25, label="±2σ")
        ax.axhline(verdict.detections[0].nominal, color="0.4", ls=":", label="nominal")
    ax.set_ylabel("estimate")
    if truth and truth_t is not None:
        tx = ax.twinx()
        for k, v in truth.items():
            tx.plot(truth_t, v, color="tab:purple", lw=0.8, label=f"injected {k}")
        tx.set_ylabel("injected size")
        tx.legend(loc="lower right", fontsize=8)
    ax.set_xlabel("time, s")
    for a in axes:
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(loc="upper left", fontsize=8)
    fig.suptitle(f"ema monitor against {verdict.reference.origin}", fontsize=9)
    fig.tight_layout()
    path = Path(out)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path

"""The dither figure: one surface's LVDT position in trimmed flight for several runs, and its spectra.

The left panel is what figures 41 and 43 show (the wing's position feedback, open against closed loop,
test against simulation); the right panel is what the measurement sees: the Welch spectrum with the
median floor and the 15 dB detection level of :mod:`ema_sim.analysis.section2.dither`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ema_sim.ail.loop import AilRun
from ema_sim.analysis.estimation import spectra
from ema_sim.analysis.section2.dither import BAND_HZ, DETECT_DB

COLORS = ("tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange", "0.4")


def _plt() -> Any:  # Any: the pyplot module, imported here (a module has no type to name)
    import matplotlib  # noqa: PLC0415 - plotting only for the study's figure (pyplot: 0.4 s of import)

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # noqa: PLC0415 - the same

    return plt


def plot_dither(runs: Sequence[tuple[str, AilRun]], path: str | Path, *, channel: str = "left_wing",
                settle_s: float = 4.0, show_s: float = 2.0) -> Path:
    """Write the figure (PNG) for ``runs`` and return its path.

    Parameters
    ----------
    runs : Sequence[tuple[str, AilRun]]
        (label, run) pairs, one trace and one spectrum each.
    path : str or Path
        The PNG to write (its directory is created).
    channel : str, optional
        The surface shown.
    settle_s : float, optional
        Time left out at each run's start, s.
    show_s : float, optional
        Length of the time traces shown, s.

    Returns
    -------
    Path
        The file written.
    """
    plt = _plt()
    fig, (ax_t, ax_f) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.25, 1]})
    spacing = 0.0
    for i, (label, run) in enumerate(runs):
        keep = run.time_s >= settle_s
        t, y = run.time_s[keep], run.signals[channel]["position_deg"][keep]
        yd = y - np.polyval(np.polyfit(t - t[0], y, 1), t - t[0])
        spacing = max(spacing, 1.2 * float(np.ptp(yd)))
        show = t < t[0] + show_s
        color = COLORS[i % len(COLORS)]
        ax_t.plot(t[show] - t[0], yd[show] - i * max(spacing, 0.25), color=color, lw=0.9, drawstyle="steps-post",
                  label=label)
        sp = spectra.welch(yd, yd[None, :], 1.0 / float(np.median(np.diff(t))), min(8.0, (t[-1] - t[0]) / 2.0),
                           overlap=0.5)
        band = (sp.freq_hz >= BAND_HZ[0]) & (sp.freq_hz <= BAND_HZ[1])
        ax_f.semilogy(sp.freq_hz[band], sp.gxx[band], color=color, lw=0.8, label=label)
        floor = float(np.median(sp.gxx[band]))
        ax_f.axhline(floor * 10 ** (DETECT_DB / 10.0), color=color, lw=0.6, ls=":")
    ax_t.set_xlabel(f"time in trimmed flight, s (after {settle_s:g} s)")
    ax_t.set_ylabel(f"{channel} LVDT position − mean, deg (runs offset)")
    ax_t.legend(fontsize=8, loc="upper right")
    ax_t.grid(alpha=0.3)
    ax_f.set_xlabel("frequency, Hz")
    ax_f.set_ylabel("power spectral density, deg²/Hz")
    ax_f.set_title(f"dotted: {DETECT_DB:g} dB above each run's median floor", fontsize=9)
    ax_f.grid(alpha=0.3, which="both")
    ax_f.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out

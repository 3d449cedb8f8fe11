"""What every plot of ``ema analyze --report`` shares: the Agg backend, colours, saving, zooms.

Matplotlib is imported only when a plot is drawn (``ema --help`` and the JSON path stay fast).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FloatArray = NDArray[np.float64]
COLORS: dict[str, str] = {"position_deg": "tab:blue", "surface_deg": "tab:orange", "model": "tab:green",
                          "fit": "k", "command": "0.35"}


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display needed).

    Returns
    -------
    module
        ``matplotlib.pyplot``.
    """
    import matplotlib  # noqa: PLC0415 - matplotlib loads in ~0.4 s; only plots need it

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # noqa: PLC0415 - after the backend is chosen

    return plt


def save(fig: Figure, path: Path) -> None:
    """Lay out, write and close a figure.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : pathlib.Path
        The PNG to write.
    """
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)


def zoom_window(t: FloatArray, residual: FloatArray, span_s: float) -> slice:
    """The ``span_s`` stretch of a long fit where the residual is largest (what a zoom should show).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    residual : numpy.ndarray
        Measured minus model.
    span_s : float
        Length of the zoom, s.

    Returns
    -------
    slice
        Samples of the zoom.
    """
    dt = float(np.median(np.diff(t)))
    n = max(2, min(t.size, round(span_s / dt)))
    energy = np.convolve(residual * residual, np.ones(n), mode="valid")
    start = int(np.argmax(energy)) if energy.size else 0
    return slice(start, start + n)

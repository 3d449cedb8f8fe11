"""The low-order equivalent system (LOES) of HOAD3, as sections 3.4 and 4.2.8 built it.

HOAD3's frequency response comes from single-frequency sine dwells (:mod:`ema_sim.analysis.section2.sine_dwell`,
all frequencies in one batch run, noise off so the fit is reproducible); a second order plus delay is
fitted to it with :mod:`ema_sim.analysis.estimation.tf_fit`, and the mismatch cost J is reported over the fit band.
The coefficients live in the channel's ``loes`` section, so building the ``loes`` model is cheap;
:func:`write_loes` puts a new fit there (``ema loes --write``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ema_sim.analysis.estimation.tf_fit import TransferFunctionFit, fit_transfer_function, second_order_coefficients
from ema_sim.analysis.section2.sine_dwell import FrequencyResponse, sine_dwell
from ema_sim.config import config_dir, load_channel
from ema_sim.errors import ConfigError
from ema_sim.jsontypes import JsonObject
from ema_sim.models import create

DEFAULT_BAND_HZ = (0.5, 20.0)
DEFAULT_POINTS = 24
DEFAULT_AMP_DEG = 1.0


@dataclass(frozen=True)
class LoesFit:
    """A fitted LOES: coefficients, the data it was fitted to, and its mismatch cost.

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).
    coefficients : dict
        The coefficients ωn, ζ, τ and K as the channel's ``loes`` section stores them.
    cost : float
        J = (20/n)·Σ[(ΔG dB)² + 0.01745·(Δφ deg)²] over the fit band.
    data : FrequencyResponse
        The HOAD3 sine-dwell response fitted.
    fit : TransferFunctionFit
        The transfer-function fit.
    """

    channel: str
    coefficients: dict[str, float]
    cost: float
    """J = (20/n)·Σ[(ΔG dB)² + 0.01745·(Δφ deg)²] over the fit band."""
    data: FrequencyResponse
    fit: TransferFunctionFit

    def model_db_deg(self) -> tuple[np.ndarray, np.ndarray]:
        """The fitted model's gain (dB) and phase (deg) at the dwell frequencies.

        Returns
        -------
        tuple
            Gain (dB) and phase (deg) at the dwell frequencies.
        """
        h = self.fit.response(self.data.freq_hz)
        phase = np.degrees(np.unwrap(np.angle(h)))
        phase += 360.0 * np.round((self.data.phase_deg[0] - phase[0]) / 360.0)
        return 20.0 * np.log10(np.abs(h)), phase

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        gain, phase = self.model_db_deg()
        return {
            "channel": self.channel, **self.coefficients, "cost_j": self.cost,
            "freq_hz": self.data.freq_hz.tolist(), "hoad3_gain_db": self.data.gain_db.tolist(),
            "hoad3_phase_deg": self.data.phase_deg.tolist(), "loes_gain_db": gain.tolist(),
            "loes_phase_deg": phase.tolist(),
        }


def fit_band(channel: str) -> tuple[np.ndarray, float]:
    """The dwell frequencies and amplitude of a channel's LOES fit (its ``loes`` section, or the defaults).

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).

    Returns
    -------
    tuple
        Lowest and highest frequency, Hz.
    """
    sec = load_channel(channel).section("loes")
    f0 = float(sec.get("fit_min_hz", DEFAULT_BAND_HZ[0]))
    f1 = float(sec.get("fit_max_hz", DEFAULT_BAND_HZ[1]))
    amp = float(sec.get("dwell_amp_deg", DEFAULT_AMP_DEG))
    return np.geomspace(f0, f1, DEFAULT_POINTS), amp


def hoad3_response(channel: str = "left_wing", freq_hz: np.ndarray | None = None, amp_deg: float | None = None,
                   *, load_inlb: float = 0.0, **model_kwargs: object) -> FrequencyResponse:
    """HOAD3's command-to-position response from sine dwells, one batch instance per frequency.

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).
    freq_hz : np.ndarray or None
        Frequency, Hz.
    amp_deg : float or None
        Amplitude, deg.
    load_inlb : float
        Hinge moment the dwells run under, in·lb.
    **model_kwargs : object
        Passed to the model.

    Returns
    -------
    FrequencyResponse
        HOAD3's response at the dwell frequencies.
    """
    band, amp = fit_band(channel)
    f = band if freq_hz is None else np.asarray(freq_hz, dtype=float)
    kwargs = {"noise": False, **model_kwargs}
    model = create("hoad3", channel, n=f.size, **kwargs)
    return sine_dwell(model, f, amp if amp_deg is None else amp_deg, hinge_moment_inlb=load_inlb)


def fit_loes(channel: str = "left_wing", freq_hz: np.ndarray | None = None, amp_deg: float | None = None,
             *, load_inlb: float = 0.0, **model_kwargs: object) -> LoesFit:
    """Dwell HOAD3 and fit ``K·ωn²/(s² + 2ζωn·s + ωn²)·e^{−sτ}`` to it (section 3.4).

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).
    freq_hz : np.ndarray or None
        Frequency, Hz.
    amp_deg : float or None
        Amplitude, deg.
    load_inlb : float
        Hinge moment the dwells run under, in·lb.
    **model_kwargs : object
        Passed to the model.

    Returns
    -------
    LoesFit
        The fit.
    """
    data = hoad3_response(channel, freq_hz, amp_deg, load_inlb=load_inlb, **model_kwargs)
    fit = fit_transfer_function(data.freq_hz, data.complex, 0, 2)
    return LoesFit(channel, second_order_coefficients(fit), fit.cost, data, fit)


_NUMBER = r"[-+0-9.eE]+"


def write_loes(fit: LoesFit, path: Path | None = None) -> Path:
    """Put a fit's coefficients and cost into the ``loes`` section of the channel's YAML, comments kept.

    Parameters
    ----------
    fit : LoesFit
        The fit to store.
    path : pathlib.Path or None
        Where to read or write.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = path or config_dir() / f"{fit.channel}.yaml"
    text = path.read_text(encoding="utf-8")
    block = re.search(r"^    loes:\n((?:      .*\n?)+)", text, flags=re.MULTILINE)
    if block is None:
        raise ConfigError(f"{path}: no loes section to update")
    body = block.group(1)
    for key in ("wn_rad_s", "zeta", "delay_s", "dc_gain_ratio"):
        value = fit.coefficients[key]
        body, count = re.subn(rf"^(      {key}: ){_NUMBER}", rf"\g<1>{value:.6g}", body, flags=re.MULTILINE)
        if count != 1:
            raise ConfigError(f"{path}: loes section has no single {key}")
    body = re.sub(r"J = [0-9.]+", f"J = {fit.cost:.3f}", body)
    path.write_text(text[: block.start(1)] + body + text[block.end(1):], encoding="utf-8")
    return path

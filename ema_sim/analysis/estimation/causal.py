"""A servo never leads its command: the check every phase and delay of ``ema analyze`` passes or is flagged by.

A phase above zero, or an actuator delay below zero, beyond :data:`SIGMAS` of the figure's own uncertainty
is no property of an actuator. It says how the record was logged or processed: a command taken as held that
was sampled from a running demand (half a sample of lag divided out that was never there), a resampled log,
columns stamped apart, or a demand that is itself a filtered target the actuator anticipates. Such a figure
gets the quality ``non_causal`` and a note with those causes, never ``ok``
(:mod:`ema_sim.analysis.records.causality` measures the lag each way on the record itself and decides the
logging from it).
"""

from __future__ import annotations

import math

SIGMAS = 2.0
"""A lead beyond this many standard errors of the figure is flagged."""
CAUSES = ("a servo never leads its command: the command's logging (a sampled demand taken as held), a resampled "
          "log, columns stamped apart, or a demand that is itself a filtered target")


def _beyond(value: float, sigma: float | None) -> bool:
    s = 0.0 if sigma is None or not math.isfinite(sigma) else abs(sigma)
    return value > SIGMAS * s and value > 0.0


def phase_leads(phase_deg: float, sigma_deg: float | None) -> bool:
    """Whether a phase leads (is above zero) beyond its uncertainty.

    Parameters
    ----------
    phase_deg : float
        The output's phase against the command, deg (negative: lags).
    sigma_deg : float or None
        Its standard error, deg (None or NaN: taken as 0).

    Returns
    -------
    bool
        True for a lead beyond :data:`SIGMAS` standard errors.
    """
    return _beyond(phase_deg, sigma_deg)


def delay_leads(delay_s: float, sigma_s: float | None) -> bool:
    """Whether an actuator delay is negative beyond its uncertainty.

    Parameters
    ----------
    delay_s : float
        The delay, s.
    sigma_s : float or None
        Its standard error, s.

    Returns
    -------
    bool
        True for a negative delay beyond :data:`SIGMAS` standard errors.
    """
    return _beyond(-delay_s, sigma_s)


def phase_note(phase_deg: float, sigma_deg: float | None, freq_hz: float) -> str:
    """The flag's sentence for a leading phase.

    Parameters
    ----------
    phase_deg : float
        The phase, deg.
    sigma_deg : float or None
        Its standard error, deg.
    freq_hz : float
        Where it was read, Hz.

    Returns
    -------
    str
        The lead, as time, and its likely causes.
    """
    lead_ms = 1e3 * phase_deg / 360.0 / freq_hz if freq_hz > 0 else float("nan")
    sigma = "" if sigma_deg is None or not math.isfinite(sigma_deg) else f" ± {sigma_deg:.2g}"
    return f"phase {phase_deg:+.2f}{sigma}° at {freq_hz:.3g} Hz leads the command by {lead_ms:.2f} ms: {CAUSES}"


def delay_note(delay_s: float, sigma_s: float | None) -> str:
    """The flag's sentence for a negative delay.

    Parameters
    ----------
    delay_s : float
        The delay, s.
    sigma_s : float or None
        Its standard error, s.

    Returns
    -------
    str
        The lead and its likely causes.
    """
    sigma = "" if sigma_s is None or not math.isfinite(sigma_s) else f" ± {1e3 * sigma_s:.2g}"
    return f"delay {1e3 * delay_s:+.2f}{sigma} ms: the output leads the command; {CAUSES}"

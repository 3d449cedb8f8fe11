"""Whether a record's command is held between samples (the data contract) or sampled from a running demand.

The contract's command is a digital value held by the D/A from one sample to the next: the actuator
sees ``u[k]`` from ``t[k]`` on, so nothing it does at ``t[k]`` can answer ``u[k]`` (a physical
actuator's position is continuous in time). Many bench loggers instead *sample* the drive's running
demand, which the drive's own profile generator has been following between log samples: the logged
change at ``t[k]`` happened somewhere in ``(t[k−1], t[k]]``, and the position may already have moved
at the very sample where the logged demand changes.

:func:`detect_command_hold` tests that causality directly. At every *onset* (the command changes
after resting for a few samples while the output rests too) it asks whether the output has left its
resting level, in the direction of the change, at the onset sample itself. Under a held command that
happens only by chance (noise, a count toggling), at the rate measured on the resting samples just
before the onsets; the binomial tail of the observed count against that rate decides (1 in 1000).

Only step-like onsets can tell: under a sampled command the output moves past its noise band at
the onset sample only when the change is large against that band (at least ten times it: the
output then crosses the band once its response reaches a tenth of the change within the sample).
A demand that leaves rest gently (a profile's acceleration, a sine) moves the output by nothing
in one sample either way, and such a record cannot tell: held is assumed, as the contract says.

A second, independent line of evidence is **causality**
(:mod:`ema_sim.analysis.records.causality`): the output's lag behind the command over its rest-to-rest
moves (or, with none, the delay that aligns them), taken both ways. A servo never leads its command, so
an output that would lead a held command beyond the lag's uncertainty refutes the hold: the command was
sampled (a demand whose profile leaves rest gently tells this where no onset can). The decision:

* onsets say sampled: sampled;
* onsets say held, or cannot tell: held stands unless causality refutes it; refuted, sampled when the
  onsets could not tell, undecided when they said held (the two lines of evidence disagree: a log whose
  columns are skewed against each other looks like this);
* the output leads even a sampled command: undecided, flagged (the logged command is not what the
  actuator followed: a filtered target, a resampled log, a late command column);
* nothing refutes either: held when the onsets say so, else undecided, and both tools say so and give
  what each assumption makes of the record.

What a sampled command means for the figures: a response to it is advanced by half a sample on
average against the held-command model (the change happened uniformly within the sample before it
was logged). Frequency responses are then not corrected for a hold; delays are measured against the
sample at which the change was logged and may be negative down to one sample; the actuator's own
delay is that figure plus half a sample, ± a sample/√12.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.records import causality
from ema_sim.analysis.records.causality import Causality
from ema_sim.analysis.records.series import hold_tolerance
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

REST_S = 0.05
"""The command and the output rest this long (at least 3 samples) before an onset."""
MIN_ONSETS = 3
STEP_LIKE = 10.0
"""An onset is step-like when its first change is this many times the output's detection band."""
SIGNIFICANCE = 1e-3
HoldMode = Literal["detect", "held", "sampled"]


@dataclass(frozen=True)
class CommandHold:
    """How the command was logged, and the evidence.

    Parameters
    ----------
    sampled : bool or None
        True: sampled from a running demand; False: held (the contract); None: the record cannot tell.
    onsets : int
        Step-like command changes from rest examined.
    same_sample : int
        Onsets at which the output had already moved at the onset sample.
    chance_rate : float
        Share of resting samples that move as far by chance.
    sample_s : float
        The record's sample interval, s.
    evidence : str
        The finding in words.
    source : str
        ``detected`` from the signals, or ``given`` by the user.
    """

    sampled: bool | None
    """True: sampled from a running demand; False: held (the contract); None: the record cannot tell."""
    onsets: int
    same_sample: int
    """Onsets at which the output had already moved at the onset sample."""
    chance_rate: float
    """Share of resting samples that move as far by chance."""
    sample_s: float
    evidence: str
    source: str = "detected"
    """``detected`` from the signals, or ``given`` by the user."""
    causality: Causality | None = None
    """The output's lag behind the command taken each way (None: not measured, or given by the user)."""
    onset_sampled: bool | None = None
    """What the onsets alone said (True sampled, False held, None could not tell)."""

    @property
    def leads(self) -> str:
        """Why the output leads the command under the assumption taken ("" when it does not)."""
        c = self.causality
        if c is None or not c.measured:
            return ""
        if c.sampled_leads:
            return (f"the output leads the logged command even taken as sampled ({c.statement}): a servo never "
                    "leads its command, so the logged command is not what it followed (a demand that is itself "
                    "a filtered target, a resampled log, or the command's column stamped late)")
        if not self.assumed_sampled and c.held_leads:
            return (f"the output would lead the command taken as held ({c.statement}): a servo never leads its "
                    "command, so either the command was sampled from a running demand or the log is skewed")
        return ""

    @property
    def assumed_sampled(self) -> bool:
        """What the analyses assume: sampled only when detected or given so (held is the contract's default)."""
        return bool(self.sampled)

    @property
    def advance_s(self) -> float:
        """Mean advance of a response to a sampled command against the held-command model: half a sample."""
        return 0.5 * self.sample_s if self.assumed_sampled else 0.0

    @property
    def statement(self) -> str:
        """One line for the report's header."""
        if self.sampled is None:
            return f"undecided, held assumed (the data contract) and sampled given beside it; {self.evidence}"
        word = "sampled (not held)" if self.sampled else "held"
        return f"{word}: {self.evidence}"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            ``sampled`` (true, false or null), the onset counts, the chance rate, the sample interval
            and the evidence.
        """
        return {"sampled": self.sampled, "assumed": "sampled" if self.assumed_sampled else "held",
                "decided": self.sampled is not None, "onsets": self.onsets, "moved_at_onset_sample": self.same_sample,
                "onsets_say": None if self.onset_sampled is None else ("sampled" if self.onset_sampled else "held"),
                "chance_rate": self.chance_rate, "sample_s": self.sample_s, "evidence": self.evidence,
                "source": self.source, "causality": None if self.causality is None else self.causality.as_dict(),
                "leads": self.leads or None}


def given(mode: HoldMode, sample_s: float, lag: Causality | None = None) -> CommandHold:
    """The user's statement of how the command was logged (``--command held|sampled``).

    Parameters
    ----------
    mode : {"held", "sampled"}
        What the user says.
    sample_s : float
        The record's sample interval, s.
    lag : Causality, optional
        The output's lag measured each way, to check the statement against (a lead is flagged, not overruled).

    Returns
    -------
    CommandHold
        With ``source = "given"``.
    """
    why = f"given (--command {mode})"
    if lag is not None and lag.measured:
        why += f"; {lag.statement}"
    return CommandHold(mode == "sampled", 0, 0, 0.0, sample_s, why, "given", causality=lag)


def lag_band(noise_sigma: float, resolution: float | None) -> float:
    """The output's detection band: a change beyond it is motion, not noise or a count toggling.

    Parameters
    ----------
    noise_sigma : float
        The output's noise floor.
    resolution : float, optional
        Its count.

    Returns
    -------
    float
        The band.
    """
    return max(4.0 * noise_sigma, 1.5 * (resolution or 0.0), 1e-12)


def _binomial_tail(k: int, n: int, p: float) -> float:
    """P(X ≥ k) for X ~ Binomial(n, p)."""
    from scipy.stats import binom  # noqa: PLC0415 - scipy.stats loads in ~0.5 s; only this test needs it

    return float(binom.sf(k - 1, n, p))


def detect_command_hold(time_s: FloatArray, command: FloatArray, output: FloatArray, noise_sigma: float,
                        resolution: float | None = None) -> CommandHold:
    """How the command was logged, from the onsets and from causality (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        The record's own stamps, s.
    command : numpy.ndarray
        The logged command.
    output : numpy.ndarray
        The measured output (the LVDT position when there is one).
    noise_sigma : float
        The output's noise floor (:func:`ema_sim.analysis.estimation.noise.output_noise`).
    resolution : float, optional
        The output's count, when it is logged in counts.

    Returns
    -------
    CommandHold
        ``sampled`` True, False, or None when the record cannot tell (or its evidence disagrees).
    """
    onset = onset_test(time_s, command, output, noise_sigma, resolution)
    lag = causality.measure(time_s, command, output, lag_band(noise_sigma, resolution))
    said = onset.sampled
    sampled = said
    why = onset.evidence
    if lag.measured:
        why = f"{why}; {lag.statement}"
        if lag.sampled_leads:
            sampled = None
            why += ("; the output leads even a sampled command, so neither assumption is the actuator's: "
                    "the logged command is not what it followed")
        elif lag.held_leads and said is None:
            sampled = True
            why += "; a servo never leads its command, so it was not held: sampled from a running demand"
        elif lag.held_leads and said is False:
            sampled = None
            why += ("; the onsets look held but the output would lead a held command: the evidence disagrees "
                    "(a log whose columns are skewed against each other?)")
    return CommandHold(sampled, onset.onsets, onset.same_sample, onset.chance_rate, onset.sample_s, why,
                       causality=lag, onset_sampled=said)


def onset_test(time_s: FloatArray, command: FloatArray, output: FloatArray, noise_sigma: float,
               resolution: float | None = None) -> CommandHold:
    """Test whether the output answers command changes at the very sample they are logged.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s (uniform).
    command : numpy.ndarray
        The logged command.
    output : numpy.ndarray
        The measured output (the LVDT position when there is one).
    noise_sigma : float
        The output's noise floor (:func:`ema_sim.analysis.estimation.noise.output_noise`).
    resolution : float, optional
        The output's count, when it is logged in counts.

    Returns
    -------
    CommandHold
        ``sampled`` True, False, or None when there are fewer than 3 onsets from rest.
    """
    dt = float(np.median(np.diff(time_s)))
    rest = max(3, round(REST_S / dt))
    tol_u = hold_tolerance(command)
    du = np.diff(command)
    moving = np.abs(du) > tol_u
    band = lag_band(noise_sigma, resolution)
    onsets = same = 0
    tries = exceed = 0
    # Changes after rest: no change in the rest − 1 steps before (a running count of the moving steps).
    count = np.concatenate([[0], np.cumsum(moving)])
    k_all = np.flatnonzero(moving) + 1
    k_all = k_all[k_all >= rest + 1]
    quiet = count[k_all - 1] - count[k_all - rest] == 0
    step_like = np.abs(du[k_all - 1]) >= STEP_LIKE * band
    for k in k_all[quiet & step_like]:
        pre = output[k - rest:k]
        y0 = float(np.median(pre))
        if np.any(np.abs(pre - y0) > band):
            continue  # the output was not at rest
        direction = np.sign(du[k - 1])
        onsets += 1
        same += int((output[k] - y0) * direction > band)
        # The chance rate: resting samples that sit as far from the resting level, either way.
        tries += 2 * (rest - 1)
        exceed += int(np.sum(np.abs(pre[1:] - y0) > band))
    if onsets < MIN_ONSETS:
        return CommandHold(None, onsets, same, 0.0, dt, f"{onsets} step-like command change(s) from rest: too few "
                           "to test whether the output answers at the sample of the change")
    p0 = (exceed + 1.0) / (tries + 2.0)
    tail = _binomial_tail(same, onsets, p0) if same else 1.0
    sampled = same >= 2 and tail < SIGNIFICANCE
    ms = 1e3 * dt
    if sampled:
        why = (f"the output had already moved at the sample where the command changes at {same} of {onsets} "
               f"step-like changes from rest (chance {p0:.2g} a sample): the demand changed up to one sample "
               f"({ms:.3g} ms) before it was logged")
    else:
        why = (f"the output stays at rest at the sample where the command changes ({same} of {onsets} step-like "
               f"changes from rest moved there, chance {p0:.2g} a sample)")
    return CommandHold(sampled, onsets, same, p0, dt, why)

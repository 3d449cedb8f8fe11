"""Identification as a chain of guarded stages: none can break the run, none can leave a worse model.

``ema identify`` runs its stages in order: the record's artefacts, the declared model's fit (the
baseline), the vocabulary's effects, the declared model as it is, the servo's physics, and discovery
beyond the vocabulary. Each stage starts from the model the stages before it kept and proposes a new one.

* **Guarded**: an exception inside a stage (a non-finite residual, an overflow, a parameter that
  collapses to an invalid value, a singular matrix) ends that stage only. The report says which stage
  failed and why; the model before it stands.
* **Kept only when it pays on the whole record and trades nothing**: the proposal must lower the
  weighted error of all outputs together, and no output's rms may rise above what the model before it,
  the baseline or the reference (position = command) leave on that output, beyond :data:`NO_WORSE` of it;
  against the model before and the baseline (not the reference) a rise of up to :data:`FLOOR_SHARE` of
  the output's noise variance is allowed (a refit sharing its parameters between the outputs may move
  one of them by that much while it clears the other of a real effect). A proposal that improves one
  output at another's expense is reported as a trade, not kept.

Every stage leaves one :class:`Outcome` in the report (``"stages"``), with the rms per output before and
after, so a reader sees the error fall stage by stage.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypeVar

NO_WORSE = 1e-3
"""An output's rms may rise by this share (numerical noise of refits) before a stage counts as worse on it."""
FLOOR_SHARE = 0.05
"""An output's mean square may rise by this share of its noise variance before a stage counts as worse on it:
the least change the effects' acceptance counts as a change (5 % of the noise variance)."""
T = TypeVar("T")


@dataclass(frozen=True)
class Outcome:
    """What one stage did."""

    stage: str
    status: str
    """``kept``, ``not kept``, ``nothing to add``, ``skipped`` or ``failed``."""
    reason: str
    rms_deg_before: dict[str, float]
    rms_deg_after: dict[str, float]
    """Of the model kept after the stage (the one before it unless the stage was kept)."""
    elapsed_s: float

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON."""
        return {"stage": self.stage, "status": self.status, "reason": self.reason,
                "rms_deg_before": dict(self.rms_deg_before), "rms_deg_after": dict(self.rms_deg_after),
                "elapsed_s": round(self.elapsed_s, 3)}


@dataclass(frozen=True)
class Failure:
    """A stage that raised: which, and the error in one line."""

    stage: str
    error: str
    where: str
    """The innermost frame of the project's code it came from (``module.py:line in function``)."""


def ceiling(*levels: Mapping[str, float]) -> dict[str, float]:
    """Per output, the least rms any of ``levels`` leaves: what a new model must not exceed.

    Parameters
    ----------
    *levels : mapping
        Output → rms, one per earlier model (the model before, the baseline, the reference).

    Returns
    -------
    dict
        Output → the lowest of them.
    """
    out: dict[str, float] = {}
    for level in levels:
        for o, v in level.items():
            out[o] = min(out.get(o, v), v)
    return out


def allow(limit: Mapping[str, float], sigma: Mapping[str, float]) -> dict[str, float]:
    """``limit`` widened by :data:`FLOOR_SHARE` of each output's noise variance.

    Parameters
    ----------
    limit : mapping
        Output → the rms a model must not exceed (:func:`ceiling`).
    sigma : mapping
        Output → its noise floor.

    Returns
    -------
    dict
        Output → the rms allowed.
    """
    return {o: (v * v + FLOOR_SHARE * sigma.get(o, 0.0) ** 2) ** 0.5 for o, v in limit.items()}


def worse(rms: Mapping[str, float], limit: Mapping[str, float], tolerance: float = NO_WORSE) -> list[str]:
    """The outputs on which ``rms`` exceeds ``limit`` by more than ``tolerance`` of it.

    Parameters
    ----------
    rms : mapping
        Output → rms of the proposed model.
    limit : mapping
        Output → the rms it must not exceed (:func:`ceiling`).
    tolerance : float
        Relative allowance.

    Returns
    -------
    list of str
        The outputs it is worse on (empty: none).
    """
    return [o for o, v in rms.items() if o in limit and not v <= limit[o] * (1.0 + tolerance) + 1e-15]


def trade(rms: Mapping[str, float], before: Mapping[str, float], limit: Mapping[str, float]) -> str:
    """A proposal that is worse on some outputs, in words (which it improves and which it worsens).

    Parameters
    ----------
    rms : mapping
        Output → rms of the proposal.
    before : mapping
        Output → rms of the model before it.
    limit : mapping
        Output → the ceiling it broke.

    Returns
    -------
    str
        One clause.
    """
    bad = worse(rms, limit)
    better = [o for o in rms if o not in bad and rms[o] < before.get(o, rms[o])]
    gains = ", ".join(f"{o} {before[o]:.4g} → {rms[o]:.4g}" for o in better)
    losses = ", ".join(f"{o} {rms[o]:.4g} against {limit[o]:.4g}" for o in bad)
    return (f"a trade, not kept: it improves {gains} but leaves {losses}" if gains
            else f"worse on {losses}: not kept")


def guarded(stage: str, failures: list[Failure], run: Callable[[], T]) -> T | None:
    """Run one stage; an exception ends it (recorded in ``failures``) and returns None.

    Parameters
    ----------
    stage : str
        The stage's name.
    failures : list of Failure
        Where a failure is recorded.
    run : callable
        The stage.

    Returns
    -------
    object or None
        What the stage returned, or None when it raised.
    """
    try:
        return run()
    except (MemoryError, RecursionError):
        raise
    except Exception as exc:  # a stage's failure is reported: it must not end the run
        failures.append(Failure(stage, f"{type(exc).__name__}: {exc}".strip(), _where(exc)))
        return None


def _where(exc: BaseException) -> str:
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "ema_sim" in f.filename]
    if not frames:
        return ""
    f = frames[-1]
    return f"{f.filename.rsplit('ema_sim/', 1)[-1]}:{f.lineno} in {f.name}"


class Clock:
    """Elapsed time of one stage."""

    def __init__(self) -> None:
        self.t0 = time.perf_counter()

    @property
    def elapsed_s(self) -> float:
        """Seconds since the stage started."""
        return time.perf_counter() - self.t0

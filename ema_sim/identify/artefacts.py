"""The sensors' and the logger's artefacts kept out of the fit: spikes and stale readings.

They are found from the record alone (:mod:`ema_sim.analysis.records.artefacts`, which ``ema analyze`` reads
too). Least squares gives one 5° spike on a 0.002° sensor the weight of thousands of good samples; such
samples are taken out of the fit (the problem's mask), counted and said, never silently.
"""

from __future__ import annotations

from ema_sim.analysis.records import artefacts as records
from ema_sim.analysis.records.artefacts import Artefact
from ema_sim.identify.problem import Problem

__all__ = ["Artefact", "exclude", "find"]


def find(problem: Problem) -> list[Artefact]:
    """Spikes and stale readings on each output, against the problem's noise floors.

    Parameters
    ----------
    problem : Problem
        The record as fitted.

    Returns
    -------
    list of Artefact
        What was found, one entry per output and kind.
    """
    return records.find(problem.time_s, problem.data.command_deg, {o: problem.observed[o] for o in problem.outputs},
                        problem.sigma_deg)


def exclude(problem: Problem, found: list[Artefact]) -> None:
    """Take the artefacts' samples out of the fit (every output loses them: the residual stacks by sample).

    Parameters
    ----------
    problem : Problem
        The record as fitted (its mask is changed).
    found : list of Artefact
        What :func:`find` found.
    """
    for a in found:
        problem.mask[[int(i) for i in a.indices]] = False

"""Section 4.3's finding as a table: which elements the AIL dither needs, and which models can make it.

Every case is the offline loop (:func:`~ema_sim.ail.loop.run_ail`) over several noise seeds, measured on
both wings with :func:`~ema_sim.ail.measure.measure`:

* the three configurations of section 2.10: closed-loop AIL, open-loop AIL, flight;
* closed-loop AIL with one element switched off at a time (the test environment's delay, lag filters,
  quantization, noise; the PWM dead band), which names the elements the limit cycle needs;
* the wing bungee of section 4.3 (still dithers: 100 in·lb keeps the current inside the dead band);
* the same loop with each actuator model: the high-order ones dither, the second-order ones (the
  pre-flight-1 models, which have no PWM dead band) cannot.

A case "dithers" when at least half of its wing-runs meet the verdict of :mod:`.measure`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np

from ema_sim.ail.loop import AilOptions, AilRun, run_ail
from ema_sim.ail.measure import SurfaceDither, measure
from ema_sim.ail.params import WINGS, AilConfig, load_ail_config
from ema_sim.errors import EmaError, UnknownNameError


@dataclass(frozen=True)
class Case:
    """One configuration of the study."""

    name: str
    """Its name (``ema ail --study --cases``)."""
    what: str
    """What it shows, for the table."""
    profile: str = "ail"
    """The test-environment profile."""
    model: str | None = None
    """None: the study's model (hoad3)."""
    open_loop: bool = False
    """The simulation flies its own model actuators."""
    disable: tuple[str, ...] = ()
    """Elements switched off by name."""
    bungee_inlb: float | None = None
    """A bungee on the wings, in·lb."""


CASES: tuple[Case, ...] = (
    Case("ail", "closed-loop AIL (LVDT feedback drives the simulated aerodynamics)"),
    Case("ail_open_loop", "open-loop AIL (a LOADA in the simulation flies the vehicle)", open_loop=True),
    Case("flight", "flight: 7 ms delay, 0.5 mV noise, true surface angle, aerodynamic hinge moments",
         profile="flight"),
    Case("no_delay", "closed-loop AIL without the test set-up's delay", disable=("delay",)),
    Case("no_lag", "… without the 50 Hz lag filters", disable=("lag",)),
    Case("no_quantization", "… without the 5 mV quantization (test set and model)", disable=("quantization",)),
    Case("no_noise", "… without the noise (test set and model)", disable=("noise",)),
    Case("no_dead_band", "… without the PWM dead band", disable=("dead_band",)),
    Case("bungee", "closed-loop AIL, wings loaded by a 100 in·lb bungee (4.3)", bungee_inlb=100.0),
    Case("hoad2", "closed-loop AIL, HOAD2", model="hoad2"),
    Case("hoac1", "closed-loop AIL, HOAC1 (continuous, no test-set converters of its own)", model="hoac1"),
    Case("loada", "closed-loop AIL, LOADA (second order, pre-flight-1)", model="loada"),
    Case("loadf", "closed-loop AIL, LOADF (the flight-1 discrete model)", model="loadf"),
    Case("loac", "closed-loop AIL, LOAC (second order, continuous)", model="loac"),
)
CASE_NAMES = tuple(c.name for c in CASES)


class CaseReport(TypedDict):
    """:meth:`CaseResult.as_dict`: one case's verdict over its seeds."""

    case: str
    what: str
    model: str
    dither: bool
    wing_runs_dithering: int
    wing_runs: int
    freq_hz: float | None
    pp_median_deg: float
    pp_max_deg: float
    wall_s: float


@dataclass
class CaseResult:
    """One case over its seeds."""

    case: Case
    """The configuration."""
    model: str
    """The actuator model run."""
    wings: list[SurfaceDither] = field(default_factory=list)
    """Every wing of every seed."""
    runs: list[AilRun] = field(default_factory=list)
    """The runs, kept only when asked for (the figure)."""
    wall_s: float = 0.0
    """Wall time of the runs, s."""

    @property
    def dithers(self) -> bool:
        """At least half of the wing-runs meet the dither verdict."""
        return 2 * sum(w.dither for w in self.wings) >= len(self.wings) > 0

    def pp_deg(self) -> tuple[float, float]:
        """Median and largest synchronous peak to peak over the wing-runs, deg."""
        pp = np.array([w.peak_to_peak_deg for w in self.wings])
        return float(np.median(pp)), float(pp.max())

    def freq_hz(self) -> float:
        """Median frequency of the wing-runs that dither (NaN when none does)."""
        f = [w.freq_hz for w in self.wings if w.dither and w.freq_hz is not None]
        return float(np.median(f)) if f else float("nan")

    def as_dict(self) -> CaseReport:
        """Plain values for JSON."""
        med, top = self.pp_deg()
        return {"case": self.case.name, "what": self.case.what, "model": self.model, "dither": self.dithers,
                "wing_runs_dithering": sum(w.dither for w in self.wings), "wing_runs": len(self.wings),
                "freq_hz": None if np.isnan(self.freq_hz()) else self.freq_hz(), "pp_median_deg": med,
                "pp_max_deg": top, "wall_s": self.wall_s}


def select(names: Sequence[str] | None) -> tuple[Case, ...]:
    """The cases named.

    Parameters
    ----------
    names : Sequence[str] or None
        Case names (:data:`CASE_NAMES`); every case when empty or None.

    Returns
    -------
    tuple[Case, ...]
        The cases, in the order named.

    Raises
    ------
    UnknownNameError
        A name that is not a case.
    """
    if not names:
        return CASES
    by_name = {c.name: c for c in CASES}
    out = []
    for name in names:
        if name not in by_name:
            raise UnknownNameError("study case", name, CASE_NAMES)
        out.append(by_name[name])
    return tuple(out)


def run_case(case: Case, *, model: str = "hoad3", seeds: Sequence[int] = (43,), duration_s: float = 24.0,
             config: AilConfig | None = None, keep_runs: bool = False) -> CaseResult:
    """Run one case for every seed and measure both wings.

    Parameters
    ----------
    case : Case
        The configuration.
    model : str, optional
        The actuator model, unless the case names its own.
    seeds : Sequence[int], optional
        One run per test-environment noise seed.
    duration_s : float, optional
        Length of each run, s (at least the settling time + 4 s).
    config : AilConfig, optional
        The vehicle's parameters (default ``config/ail_vehicle.yaml``).
    keep_runs : bool, optional
        Keep the runs in the result (for the figure).

    Returns
    -------
    CaseResult
        Both wings of every seed.

    Raises
    ------
    EmaError
        A run too short to measure.
    """
    cfg = config or load_ail_config()
    if duration_s < cfg.settle_s + 4.0:
        raise EmaError(f"the study needs at least {cfg.settle_s + 4.0:g} s per run (settle + 4 s measured)")
    chosen = case.model or model
    result = CaseResult(case, chosen)
    setup = cfg.setup(case.profile, bungee_inlb=case.bungee_inlb)
    for seed in seeds:
        run = run_ail(AilOptions(profile=case.profile, model=chosen, open_loop=case.open_loop, duration_s=duration_s,
                                 seed=seed, disable=case.disable, setup=setup, config=cfg))
        found = measure(run, cfg.settle_s, channels=WINGS)
        result.wings.extend(found[w] for w in WINGS)
        result.wall_s += run.wall_s
        if keep_runs:
            result.runs.append(run)
    return result


def run_study(cases: Sequence[Case] = CASES, *, model: str = "hoad3", seeds: Sequence[int] = (43, 44, 45),
              duration_s: float = 24.0, config: AilConfig | None = None, keep_runs: Sequence[str] = (),
              progress: Callable[[str], None] | None = None) -> list[CaseResult]:
    """Every case (see the module docstring).

    Parameters
    ----------
    cases : Sequence[Case], optional
        The cases run, in order.
    model : str, optional
        The actuator model of the cases that name none.
    seeds : Sequence[int], optional
        One run per seed and case.
    duration_s : float, optional
        Length of each run, s.
    config : AilConfig, optional
        The vehicle's parameters (default ``config/ail_vehicle.yaml``).
    keep_runs : Sequence[str], optional
        The cases whose runs are kept.
    progress : Callable[[str], None], optional
        Called with each case's table row as it finishes.

    Returns
    -------
    list[CaseResult]
        One result per case.
    """
    out = []
    for case in cases:
        res = run_case(case, model=model, seeds=seeds, duration_s=duration_s, config=config,
                       keep_runs=case.name in keep_runs)
        out.append(res)
        if progress is not None:
            progress(table_row(res))
    return out


def table_header() -> str:
    """Markdown header of :func:`table_row`."""
    return ("| case | model | dither | wing-runs dithering | frequency, Hz | peak to peak, deg (median / max) |\n"
            "|---|---|---|---|---|---|")


def table_row(res: CaseResult) -> str:
    """One Markdown row.

    Parameters
    ----------
    res : CaseResult
        A case's result.

    Returns
    -------
    str
        The row of :func:`table_header`'s table.
    """
    med, top = res.pp_deg()
    f = res.freq_hz()
    return (f"| {res.case.what} | {res.model} | {'**yes**' if res.dithers else 'no'} | "
            f"{sum(w.dither for w in res.wings)}/{len(res.wings)} | {'—' if np.isnan(f) else f'{f:.2f}'} | "
            f"{med:.3f} / {top:.3f} |")


def table(results: Sequence[CaseResult]) -> str:
    """The Markdown table.

    Parameters
    ----------
    results : Sequence[CaseResult]
        The rows.

    Returns
    -------
    str
        Header and rows.
    """
    return "\n".join([table_header(), *(table_row(r) for r in results)])

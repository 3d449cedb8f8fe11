"""What every section-2 test of ``ema analyze`` is, and the record it runs on.

Each test of section 2 (frequency response, steps, timing, calibration, thresholds, crosstalk,
dither, compliance, hysteresis, free play, regeneration, profiled moves) is one module holding its
computation and one :class:`Section2Test`: the segment kinds it runs on, how it runs, how its results
go to JSON, to Markdown and to a plot. :mod:`ema_sim.analysis.pipeline` and
:mod:`ema_sim.analysis.report` are loops over :data:`ema_sim.analysis.registry.TESTS`.

:class:`RecordAnalysis` is one record with what the pipeline found before any test ran (its channel,
the recognised segments, each output's noise floor and resolution, whether its command is held or
sampled) and, after, every test's results, what could not be computed and why, and notes.

Every result carries a :data:`~ema_sim.analysis.estimation.quality.Quality` (``ok``, ``on_bound``,
``not_determined``, ``saturated``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypedDict, TypeVar

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.noise import NoiseFloor
from ema_sim.analysis.estimation.quality import QUALITY_WORDS, Quality, worst
from ema_sim.analysis.estimation.slew import Slew
from ema_sim.analysis.records.command_hold import CommandHold, HoldMode
from ema_sim.analysis.section2.segments import Recognition, Segment
from ema_sim.config import GENERIC, ChannelConfig
from ema_sim.io.measured import MeasuredData
from ema_sim.jsontypes import JsonObject

if TYPE_CHECKING:
    from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit

FloatArray = NDArray[np.float64]
DEFAULT_AT_HZ: tuple[float, ...] = (1.0, 2.0, 5.0, 7.5, 10.0)

class Result(Protocol):
    """What every test's result offers: its plain values."""

    def as_dict(self) -> JsonObject:
        """The result as JSON-ready values."""
        ...


R = TypeVar("R", bound=Result)
__all__ = ["QUALITY_WORDS", "Options", "Quality", "RecordAnalysis", "Section2Test", "worst"]


@dataclass(frozen=True)
class Options:
    """What ``ema analyze`` was asked for.

    Parameters
    ----------
    at_hz : tuple
        Frequencies for gain and phase, Hz.
    model : str or None
        A registered model simulated on the measured command and overlaid on the Bode plots.
    threshold_deg : float or None
        Threshold the crosstalk noise is compared with (default: measured, else table A2 for an X-43A channel).
    compliance_deg_per_kinlb : float or None
        Compliance taken out of the free-play jumps (default: measured in the same run, else none).
    channel : str or None
        Channel whose configuration is used (default: the record's, else left_wing as a stand-in, to which
        no X-43A table applies).
    command : HoldMode
        How the command was logged: ``detect`` it, or take it as ``held`` or ``sampled``.
    """

    at_hz: tuple[float, ...] = DEFAULT_AT_HZ
    model: str | None = None
    """A registered model simulated on the measured command and overlaid on the Bode plots."""
    threshold_deg: float | None = None
    """Threshold the crosstalk noise is compared with (default: measured, else table A2 for an X-43A channel)."""
    compliance_deg_per_kinlb: float | None = None
    """Compliance taken out of the free-play jumps (default: measured in the same run, else none)."""
    channel: str | None = None
    command: HoldMode = "detect"
    """How the command was logged: ``detect`` it, or take it as ``held`` or ``sampled``."""


class TimingAlternative(TypedDict):
    """A timing figure of a record analysed with its command taken as held and as sampled."""

    figure: str
    quantity: str
    """``phase_deg`` or ``delay_s``."""
    held: float
    sampled: float
    sigma: float | None


@dataclass
class RecordAnalysis:
    """One record, what the pipeline found in it, and every test's results.

    Parameters
    ----------
    data : MeasuredData
        The record on a uniform grid.
    channel : ChannelConfig
        The channel's configuration (crank arm, calibration slopes).
    recognition : Recognition
        The recognised segments.
    noise : dict
        Each output's noise floor and resolution.
    command : CommandHold
        How the command was logged.
    options : Options
        What was asked.
    results : dict
        Each test's results, by key.
    fits : list
        Every second-order fit of the record (steps, moves and frequency responses).
    not_computed : dict
        What was not computed, and why.
    notes : list
        Notes.
    stamps : numpy.ndarray or None
        The record's own time stamps, as logged, when the samples are those of ``data`` (jittery stamps
        straightened, nothing resampled); None when the record was resampled.
    slew : Slew or None
        The slope of the record's rate-limited moves (:func:`ema_sim.analysis.estimation.slew.measure`, on its
        own stamps).
    stand_in : bool
        The channel's configuration is a stand-in (no ``--channel``, and the record names none of ours): no
        X-43A table applies to it.
    logged : int or None
        The samples as logged, when the record was resampled onto ``data``'s grid (None: they are ``data``'s).
    """

    data: MeasuredData
    """The record on a uniform grid."""
    channel: ChannelConfig
    recognition: Recognition
    noise: dict[str, NoiseFloor]
    command: CommandHold
    options: Options = field(default_factory=Options)
    results: dict[str, list[Any]] = field(default_factory=dict)
    fits: list[SecondOrderFit] = field(default_factory=list)
    """Every second-order fit of the record (steps, moves and frequency responses)."""
    not_computed: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    stamps: FloatArray | None = None
    """The record's own time stamps, as logged (None when it was resampled)."""
    slew: Slew | None = None
    """The slope of the record's rate-limited moves, on its own stamps."""
    stand_in: bool = False
    """The channel's configuration is a stand-in: no X-43A table applies to the record."""
    other_timing: list[TimingAlternative] = field(default_factory=list)
    """When the record cannot tell held from sampled: each timing figure under both assumptions
    (:func:`ema_sim.analysis.pipeline.timing_alternatives`)."""
    logged: int | None = None
    """The samples as logged when the record was resampled (None: ``data`` holds them as logged)."""

    @property
    def channel_named(self) -> bool:
        """The record is of an X-43A channel, named by ``--channel`` or by the record itself."""
        return not self.stand_in

    @property
    def channel_name(self) -> str:
        """What the record is of, as reported: its X-43A channel, or ``generic`` (an actuator of no X-43A channel)."""
        return self.channel.channel if self.channel_named else GENERIC

    @property
    def noise_deg(self) -> dict[str, float]:
        """Each output's noise floor (never below its counts' quantization)."""
        return {k: v.sigma for k, v in self.noise.items()}

    @property
    def resolution_deg(self) -> dict[str, float | None]:
        """Each output's count (None: continuous)."""
        return {k: v.resolution for k, v in self.noise.items()}

    @property
    def unit(self) -> str:
        """The unit the positions are in: ``°`` or the rig's linear unit."""
        return "°" if self.data.unit == "deg" else f" {self.data.unit}"

    def of(self, test: Section2Test[R]) -> list[R]:
        """The results of one test.

        Parameters
        ----------
        test : Section2Test
            The test.

        Returns
        -------
        list
            Its results (empty when it found nothing to run on).
        """
        return self.results.get(test.key, [])

    def segments(self, *kinds: str) -> list[Segment]:
        """Recognised segments of the given kinds.

        Parameters
        ----------
        *kinds : str
            Segment kinds.

        Returns
        -------
        list of Segment
            In time order.
        """
        return self.recognition.of(*kinds)

    def primary(self, prefer: tuple[str, ...]) -> tuple[str, FloatArray]:
        """The first present output of ``prefer``.

        Parameters
        ----------
        prefer : tuple of str
            Output names in order of preference.

        Returns
        -------
        tuple
            Its name and values.
        """
        for name in prefer:
            value = getattr(self.data, name)
            if value is not None:
                return name, value
        raise AssertionError("the data contract guarantees an output column")

    def outputs(self, sl: slice) -> dict[str, FloatArray]:
        """Every output over ``sl``.

        Parameters
        ----------
        sl : slice
            Samples.

        Returns
        -------
        dict
            Output name → values.
        """
        return {name: getattr(self.data, name)[sl] for name in self.data.outputs}

    def sample_s(self) -> float:
        """Median sample interval, s.

        Returns
        -------
        float
            The interval.
        """
        return float(np.median(np.diff(self.data.time_s)))

    def volts_per_deg(self) -> float:
        """Command volts per degree at the centre of the channel's command curve.

        Returns
        -------
        float
            The slope's magnitude.
        """
        return abs(float(self.channel.command_cal.slope(0.0)))


class Section2Test(ABC, Generic[R]):
    """One section-2 test: where it runs, how, and how its results are written and drawn."""

    key: ClassVar[str]
    """Its key in the results, ``not_computed`` and the JSON record."""
    title: ClassVar[str]
    """Its heading in the Markdown report."""
    kinds: ClassVar[tuple[str, ...]] = ()
    """The segment kinds it runs on."""
    absent: ClassVar[str] = ""
    """Why it was not computed when no segment of its kinds was recognised."""

    def __init_subclass__(cls, **kwargs: object) -> None:
        """Give each method a test overrides without a docstring the interface's own.

        Parameters
        ----------
        **kwargs : object
            Passed on to :class:`object`.
        """
        super().__init_subclass__(**kwargs)
        for name, member in vars(cls).items():
            base = getattr(Section2Test, name, None)
            if callable(member) and base is not None and not getattr(member, "__doc__", None):
                member.__doc__ = base.__doc__

    @abstractmethod
    def run(self, ra: RecordAnalysis) -> list[R]:
        """Compute the test's results on a record (adding to ``ra.not_computed`` or ``ra.notes`` what it cannot).

        Parameters
        ----------
        ra : RecordAnalysis
            The record and what earlier tests found.

        Returns
        -------
        list
            The results, in time order.
        """

    def result_json(self, r: R) -> JsonObject:
        """One result as plain values: its own ``as_dict()``.

        Parameters
        ----------
        r : object
            A result of this test.

        Returns
        -------
        dict
            JSON-ready values (numpy scalars and non-finite floats are cleaned later).
        """
        return r.as_dict()

    def as_json(self, results: list[R], ra: RecordAnalysis) -> JsonObject:  # noqa: ARG002 - the default
        """The test's keys in the JSON record.

        Parameters
        ----------
        results : list
            Its results on one record.
        ra : RecordAnalysis
            The record (what a test's summary across its results may need: the record's slope).

        Returns
        -------
        dict
            ``{key: [result, ...]}`` unless the test writes its results differently.
        """
        return {self.key: [self.result_json(r) for r in results]}

    @abstractmethod
    def markdown(self, ra: RecordAnalysis, results: list[R], images: list[str | None]) -> list[str]:
        """The test's section of the Markdown report.

        Parameters
        ----------
        ra : RecordAnalysis
            The record.
        results : list
            Its results on the record.
        images : list of str or None
            Each result's plot (file name relative to the report), None where there is none.

        Returns
        -------
        list of str
            Markdown lines.
        """

    def plot(self, ra: RecordAnalysis, r: R, path: Path) -> bool:  # noqa: ARG002 - the interface's default
        """Draw one result into ``path`` (PNG).

        Parameters
        ----------
        ra : RecordAnalysis
            The record.
        r : object
            One result.
        path : pathlib.Path
            Where to write the PNG.

        Returns
        -------
        bool
            False when the result has no plot.
        """
        return False

    def summary(self, ra: RecordAnalysis, r: R) -> list[str]:  # noqa: ARG002 - the interface's default
        """Lines for the terminal.

        Parameters
        ----------
        ra : RecordAnalysis
            The record.
        r : object
            One result.

        Returns
        -------
        list of str
            One line or a few.
        """
        return []

    def fits(self, r: R) -> list[SecondOrderFit]:  # noqa: ARG002 - the interface's default
        """Second-order fits a result holds (for the spread across tests).

        Parameters
        ----------
        r : object
            One result.

        Returns
        -------
        list of SecondOrderFit
            Its fits (none by default).
        """
        return []

    def share(self, ra: RecordAnalysis, others: list[RecordAnalysis]) -> None:  # noqa: ARG002 - the interface's default
        """Use what other records of the same channel measured (after every record ran).

        Parameters
        ----------
        ra : RecordAnalysis
            This record.
        others : list of RecordAnalysis
            The other records of the same channel.
        """
        return

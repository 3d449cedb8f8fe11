"""Dispersions: which parameters a campaign varies, how, and each run's values from (seed, run index).

A dispersed parameter is a **target** found by name in the metadata that already declares it, never in
a second table: a model parameter (:func:`ema_sim.models.model_parameters`: unit, range, the report's
uncertainty), a model option with a declared range (HOAD3's compliance ``bound``), a field of the
maneuver or load spec (``maneuver.amp_deg``, ``load.inlb``: the spec's bounds), or, in an
aircraft-in-the-loop campaign, a test-environment element (``command.delay_s``... from
:class:`~ema_sim.environment.PathSpec`) or the wing bungee (``setup.bungee_inlb``). Every value drawn is
checked against the target's range.

Distributions (one entry each, in the order the campaign lists them):

* ``uniform: [low, high]`` (or ``report``: the declared uncertainty; ``analysis``: the spread of
  ``ema analyze`` JSON files);
* ``normal: {mean, std}`` truncated to the range (redrawn), several parameters with a ``correlation``
  matrix (a Gaussian copula through its Cholesky factor);
* ``corners: [[low, high], ...]``: the 2^k corners of a box in turn (run ``i`` takes corner ``i mod 2^k``;
  section 3.1.2.2's four Kb/offset lines);
* ``discrete: [values]`` (``weights`` optional).

Run ``i`` of seed ``s`` draws from its own generator, ``PCG64(SeedSequence([s, i]))``: the same seed gives
the same values whatever the batch, the order or the machine.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
KINDS = ("uniform", "normal", "corners", "discrete")
"""The distributions a dispersion entry may name."""
MAX_REDRAWS = 1000
"""Truncated normals redraw at most this many times before a campaign is refused as ill-posed."""


@dataclass(frozen=True)
class Target:
    """One parameter a campaign may disperse, with the range its declaration gives.

    Parameters
    ----------
    name : str
        The name campaigns use (``wn_rad_s``, ``bound``, ``load.inlb``, ``command.delay_s``...).
    unit : str
        Its unit.
    low, high : float
        Valid range (inclusive).
    nominal : float
        The campaign's value when the parameter is not dispersed.
    uncertainty : tuple of float or None
        The report's (low, high) from the metadata, where it gives one.
    source : str
        Where the declaration and the uncertainty come from.
    """

    name: str
    unit: str
    low: float
    high: float
    nominal: float
    uncertainty: tuple[float, float] | None = None
    source: str = ""

    def check(self, values: FloatArray, what: str) -> None:
        """Refuse values outside the declared range (one error naming the parameter).

        Parameters
        ----------
        values : numpy.ndarray
            Values to check.
        what : str
            Where they come from, for the message.
        """
        bad = (values < self.low) | (values > self.high) | ~np.isfinite(values)
        if bad.any():
            v = float(values[np.argmax(bad)])
            raise ConfigError(f"{what}: {self.name} = {v:g} is outside its range [{self.low:g}, {self.high:g}] "
                              f"{self.unit}")


@dataclass(frozen=True)
class Dispersion:
    """One entry of a campaign's ``dispersions``: its parameters and their joint distribution.

    Parameters
    ----------
    targets : tuple of Target
        The parameters, in order.
    kind : str
        One of :data:`KINDS`.
    low, high : numpy.ndarray
        Bounds of ``uniform`` and ``corners`` (one per target).
    mean, std : numpy.ndarray
        Mean and standard deviation of ``normal``.
    chol : numpy.ndarray
        Cholesky factor of the correlation matrix of ``normal`` (identity when uncorrelated).
    values : numpy.ndarray
        The set of ``discrete`` (one target).
    weights : numpy.ndarray
        Its probabilities.
    """

    targets: tuple[Target, ...]
    kind: str
    low: FloatArray
    high: FloatArray
    mean: FloatArray
    std: FloatArray
    chol: FloatArray
    values: FloatArray
    weights: FloatArray

    @property
    def names(self) -> tuple[str, ...]:
        """The dispersed parameters' names."""
        return tuple(t.name for t in self.targets)

    def draw(self, rng: np.random.Generator, run: int) -> FloatArray:
        """This entry's values for one run (one per target).

        Parameters
        ----------
        rng : numpy.random.Generator
            The run's generator (advanced).
        run : int
            The run index (``corners`` enumerates by it).

        Returns
        -------
        numpy.ndarray
            One value per target.
        """
        k = len(self.targets)
        if self.kind == "uniform":
            return np.asarray(self.low + (self.high - self.low) * rng.random(k), dtype=float)
        if self.kind == "corners":
            bits = np.array([(run >> j) & 1 for j in range(k)], dtype=bool)
            return np.where(bits, self.high, self.low)
        if self.kind == "discrete":
            return np.array([self.values[int(rng.choice(self.values.size, p=self.weights))]])
        lo = np.array([t.low for t in self.targets])
        hi = np.array([t.high for t in self.targets])
        for _ in range(MAX_REDRAWS):
            x = self.mean + self.std * (self.chol @ rng.standard_normal(k))
            if np.all((x >= lo) & (x <= hi)):
                return np.asarray(x, dtype=float)
        raise ConfigError(f"normal dispersion of {', '.join(self.names)}: {MAX_REDRAWS} draws fell outside the "
                          "declared ranges; the mean and std do not fit them")

    def describe(self) -> JsonObject:
        """Plain values for ``summary.json``."""
        out: JsonObject = {"parameters": [*self.names], "distribution": self.kind,
                               "units": [t.unit for t in self.targets]}
        if self.kind in ("uniform", "corners"):
            out["bounds"] = [[float(a), float(b)] for a, b in zip(self.low, self.high, strict=True)]
        elif self.kind == "normal":
            out.update(mean=self.mean.tolist(), std=self.std.tolist(), correlation=(self.chol @ self.chol.T).tolist())
        else:
            out.update(values=self.values.tolist(), weights=self.weights.tolist())
        return out


def run_generator(seed: int, run: int) -> np.random.Generator:
    """The generator of run ``run`` of a campaign seeded ``seed``: independent of batches and order.

    Parameters
    ----------
    seed : int
        The campaign's seed.
    run : int
        The run index.

    Returns
    -------
    numpy.random.Generator
        PCG64 seeded from ``SeedSequence([seed, run])``.
    """
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed), int(run)])))


def run_seed(seed: int, run: int) -> int:
    """A 62-bit integer seed for a run's own noise streams (model noise, harness noise), from (seed, run).

    Parameters
    ----------
    seed : int
        The campaign's seed.
    run : int
        The run index (−1: the nominal run).

    Returns
    -------
    int
        The seed.
    """
    state = np.random.SeedSequence([int(seed), int(run) + 1, 7]).generate_state(2, dtype=np.uint32)
    return int((int(state[0]) << 30) ^ int(state[1])) & ((1 << 62) - 1)


def sample(dispersions: Sequence[Dispersion], seed: int, runs: Sequence[int]) -> dict[str, FloatArray]:
    """Every dispersed parameter's value for each run.

    Parameters
    ----------
    dispersions : sequence of Dispersion
        The campaign's entries, in order.
    seed : int
        The campaign's seed.
    runs : sequence of int
        Run indices.

    Returns
    -------
    dict
        Parameter name → one value per run.
    """
    names = [n for d in dispersions for n in d.names]
    out = {n: np.empty(len(runs)) for n in names}
    for j, run in enumerate(runs):
        rng = run_generator(seed, run)
        for d in dispersions:
            for name, value in zip(d.names, d.draw(rng, int(run)), strict=True):
                out[name][j] = value
    return out


# ------------------------------------------------------------------------------------------- parsing
# The parsers below take a dispersion entry's values as YAML gave them (object), each checked where it is read (a
# wrong one is one ConfigError naming its place).
def _pairs(value: object, k: int, what: str) -> tuple[FloatArray, FloatArray]:
    arr = np.asarray(value, dtype=float)
    if k == 1 and arr.shape == (2,):
        arr = arr[None, :]
    if arr.shape != (k, 2):
        raise ConfigError(f"{what}: expected {k} [low, high] pair{'s' if k > 1 else ''}, got {value!r}")
    if np.any(arr[:, 0] > arr[:, 1]):
        raise ConfigError(f"{what}: a low bound is above its high bound: {value!r}")
    return arr[:, 0].copy(), arr[:, 1].copy()


def _bounds(value: object, targets: Sequence[Target], what: str,
            analysis: Mapping[str, tuple[float, float]] | None) -> tuple[FloatArray, FloatArray]:
    """``[low, high]`` pairs, or ``report`` (declared uncertainty) or ``analysis`` (ema analyze spread)."""
    if isinstance(value, str):
        pairs = []
        for t in targets:
            if value == "report":
                if t.uncertainty is None:
                    raise ConfigError(f"{what}: {t.name} declares no uncertainty; give [low, high]")
                pairs.append(t.uncertainty)
            elif value == "analysis":
                if not analysis or t.name not in analysis:
                    raise ConfigError(f"{what}: no ema analyze spread of {t.name} (give --analysis FILE.json with "
                                      "second-order fits or calibrations)")
                pairs.append(analysis[t.name])
            else:
                raise ConfigError(f"{what}: bounds must be [low, high], 'report' or 'analysis', got {value!r}")
        return _pairs(pairs, len(targets), what)
    return _pairs(value, len(targets), what)


def _vector(value: object, k: int, what: str) -> FloatArray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.shape != (k,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{what}: expected {k} finite number{'s' if k > 1 else ''}, got {value!r}")
    return arr


def _entry(entry: object, resolve: Mapping[str, Target], where: str) -> tuple[str, list[Target]]:
    """The distribution named and the targets of a ``dispersions`` entry."""
    if not isinstance(entry, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {entry!r}")
    keys = set(entry)
    names_raw = entry.get("parameters", entry.get("parameter"))
    if names_raw is None or ("parameter" in keys and "parameters" in keys):
        raise ConfigError(f"{where}: give parameter: NAME or parameters: [NAMES]")
    names = [names_raw] if isinstance(names_raw, str) else list(names_raw)
    kinds = [k for k in KINDS if k in keys]
    unknown = sorted(keys - {"parameter", "parameters", "weights", *KINDS})
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (known: parameter(s), {', '.join(KINDS)}, weights)")
    if len(kinds) != 1:
        raise ConfigError(f"{where}: give exactly one distribution of {', '.join(KINDS)}")
    targets = []
    for name in names:
        if not isinstance(name, str) or name not in resolve:
            raise UnknownNameError("dispersed parameter", str(name), resolve)
        targets.append(resolve[name])
    return kinds[0], targets


def _normal(spec: object, targets: Sequence[Target], what: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Mean, std and the correlation's Cholesky factor of a ``normal`` entry."""
    k = len(targets)
    if not isinstance(spec, Mapping) or not {"mean", "std"} <= set(spec):
        raise ConfigError(f"{what}: normal needs mean and std")
    mean, std = _vector(spec["mean"], k, f"{what} mean"), _vector(spec["std"], k, f"{what} std")
    if np.any(std < 0.0):
        raise ConfigError(f"{what}: std must not be negative")
    for t, m in zip(targets, mean, strict=True):
        t.check(np.array([m]), f"{what} mean")
    if "correlation" not in spec:
        return mean, std, np.eye(k)
    corr = np.asarray(spec["correlation"], dtype=float)
    if corr.shape != (k, k) or not np.allclose(corr, corr.T) or not np.allclose(np.diag(corr), 1.0):
        raise ConfigError(f"{what}: correlation must be a symmetric {k}×{k} matrix with ones on its diagonal")
    try:
        return mean, std, np.linalg.cholesky(corr)
    except np.linalg.LinAlgError:
        raise ConfigError(f"{what}: correlation matrix is not positive definite") from None


def _discrete(spec: object, weights_raw: object, target: Target, what: str) -> tuple[FloatArray, FloatArray]:
    """Values and weights of a ``discrete`` entry."""
    values = np.asarray(spec, dtype=float).ravel()
    if values.size == 0:
        raise ConfigError(f"{what}: discrete needs at least one value")
    target.check(values, what)
    weights = (np.full(values.size, 1.0 / values.size) if weights_raw is None
               else _vector(weights_raw, values.size, f"{what} weights"))
    if np.any(weights < 0.0) or not math.isclose(float(weights.sum()), 1.0, rel_tol=1e-9):
        raise ConfigError(f"{what}: weights must be non-negative and add up to 1")
    return values, weights


def parse_dispersion(entry: Mapping[str, object], resolve: Mapping[str, Target], where: str,
                     analysis: Mapping[str, tuple[float, float]] | None = None) -> Dispersion:
    """One ``dispersions`` entry of a campaign YAML, checked against the targets' declarations.

    Parameters
    ----------
    entry : mapping
        ``{parameter: NAME | parameters: [NAMES], <kind>: ...}``.
    resolve : mapping
        Name → :class:`Target`, every parameter the campaign may disperse.
    where : str
        The entry's place, for messages.
    analysis : mapping, optional
        Parameter → (low, high) spread from ``ema analyze`` JSON files.

    Returns
    -------
    Dispersion
        The entry.
    """
    kind, targets = _entry(entry, resolve, where)
    k = len(targets)
    what = f"{where} ({', '.join(t.name for t in targets)})"
    empty = np.zeros(0)
    low = high = mean = std = values = weights = empty
    chol = np.eye(k)
    spec = entry[kind]
    if kind in ("uniform", "corners"):
        low, high = _bounds(spec, targets, what, analysis)
        for t, a, b in zip(targets, low, high, strict=True):
            t.check(np.array([a, b]), what)
    elif kind == "normal":
        mean, std, chol = _normal(spec, targets, what)
    else:
        if k != 1:
            raise ConfigError(f"{what}: discrete takes one parameter")
        values, weights = _discrete(spec, entry.get("weights"), targets[0], what)
    return Dispersion(tuple(targets), kind, low, high, mean, std, chol, values, weights)

"""``ema identify`` on records whose effects no vocabulary names (:mod:`fuzzgen`): it never breaks.

Each record is drawn at random from an independent plant and logger. Whatever it holds, ``ema identify``
exits 0 with strict JSON, its final model is no worse than the reference (output = command) on any
output, and than its baseline and each kept stage than the one before beyond what the stages allow
(:func:`ema_sim.identify.stages.allow`: a twentieth of the output's noise variance, which a refit sharing its
parameters between the outputs may cost one of them while it clears the other).
The default suite runs 30 short records (1.5-2 s, at most one effect added and no escalation to the
physics, so the suite keeps its time budget); ``make test-slow`` runs 300, short and long (8-40 s), with
every stage as ``ema identify`` runs it by default.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import fuzzgen
import pytest

from ema_sim.cli import main
from ema_sim.identify.stages import NO_WORSE, allow

SHORT = range(30)
QUICK = ["--max-effects", "1", "--no-escalate"]
"""The default suite's search: one effect and no escalation to the physics (the slow set runs them all)."""
LONG = range(1000, 1300)


def _identify(seed: int, tmp_path: Path, *, short: bool, quick: bool = False) -> tuple[dict[str, Any], fuzzgen.Fuzz]:
    fuzz, cols = fuzzgen.record(seed, short=short)
    csv = fuzzgen.write(cols, tmp_path / f"fuzz{seed}.csv")
    out = tmp_path / f"fuzz{seed}.json"
    status = main(["identify", str(csv), "--json", str(out), "-q", *(QUICK if quick else [])])
    assert status == 0, f"seed {seed} ({', '.join(fuzz.effects)}): exit {status}"
    text = out.read_text(encoding="utf-8")
    report = json.loads(text, parse_constant=lambda c: pytest.fail(f"seed {seed}: non-strict JSON constant {c}"))
    return report, fuzz


def _no_worse(new: float, old: float) -> bool:
    return new <= old * (1.0 + NO_WORSE) + 1e-12


def _check(report: dict[str, Any], fuzz: fuzzgen.Fuzz) -> None:
    where = f"seed {fuzz.seed} ({', '.join(fuzz.effects) or 'no effect'})"
    final = report["final"]["rms_deg"]
    noise = report["noise_deg"]
    allowed_base = allow(report["baseline"]["rms_deg"], noise)
    for output, value in final.items():
        assert math.isfinite(value), f"{where}: final {output} rms {value}"
        base = allowed_base[output]
        ref = report["reference"]["rms_deg"][output]
        assert _no_worse(value, base), f"{where}: final {output} {value} worse than the baseline's {base} allows"
        assert _no_worse(value, ref), f"{where}: final {output} {value} worse than the reference's {ref}"
    for stage in report["stages"]:
        if stage["status"] != "kept":
            continue
        for output, after in stage["rms_deg_after"].items():
            before = allow(stage["rms_deg_before"], noise)[output]
            assert _no_worse(after, before), (f"{where}: stage {stage['stage']} kept with {output} {after} "
                                              f"worse than {before} before it")
    for failure in report["failures"]:
        assert failure["stage"], f"{where}: a failure without its stage"
        assert failure["error"], f"{where}: stage {failure['stage']} failed without saying why"


@pytest.mark.parametrize("seed", SHORT)
def test_short_fuzz_record(seed: int, tmp_path: Path) -> None:
    """A short record of random, unnamed effects: exit 0, strict JSON, no output worse than before.

    The search is :data:`QUICK` so the suite keeps its budget; the slow set runs every stage in full.
    """
    report, fuzz = _identify(seed, tmp_path, short=True, quick=True)
    _check(report, fuzz)


@pytest.mark.slow
@pytest.mark.parametrize("seed", LONG)
def test_fuzz_record(seed: int, tmp_path: Path) -> None:
    """The same on 300 records, short and long (``make test-slow``)."""
    report, fuzz = _identify(seed, tmp_path, short=seed % 3 != 0)
    _check(report, fuzz)

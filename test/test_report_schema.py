"""The reports' published contract: schemas generated from their TypedDicts, published in the docs, enforced.

Every report any test builds is checked against its schema (``test/conftest.py`` sets ``EMA_STRICT_REPORTS``);
these tests hold the generator, the published files and the check itself.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np
import pytest
from jsonschema import Draft202012Validator

from ema_sim.analysis.contract import analyze_schema
from ema_sim.analysis.pipeline import analyze_record
from ema_sim.analysis.report import to_json
from ema_sim.commands.schema import SCHEMAS, text
from ema_sim.identify.contract import identify_schema
from ema_sim.io.contract import STRICT_ENV, ReportContractError, check, schema_of, violations
from ema_sim.io.measured import MeasuredData

ROOT = Path(__file__).resolve().parents[1]


class _Inner(TypedDict):
    """An inner block."""

    value: float | None
    tags: list[str]


class _Doc(TypedDict):
    """A document."""

    name: str
    count: int
    inner: _Inner
    extra: NotRequired[dict[str, float]]


def test_a_typeddict_becomes_a_closed_schema_with_its_optional_keys():
    schema = schema_of(_Doc, "doc")
    assert schema["required"] == ["count", "inner", "name"]
    assert schema["additionalProperties"] is False
    good = {"name": "a", "count": 1, "inner": {"value": None, "tags": ["x"]}}
    assert violations(good, schema) == []
    assert violations({**good, "extra": {"k": 1.5}}, schema) == []
    wrong = violations({**good, "count": 1.5, "surprise": 1}, schema)
    assert any(w.startswith("count:") for w in wrong)
    assert any("surprise" in w for w in wrong)
    nested = violations({**good, "inner": {"value": "high", "tags": []}}, schema)
    assert nested == ["inner/value: 'high' is not valid under any of the given schemas"]


def test_a_report_that_breaks_its_contract_is_an_error_under_the_strict_switch_and_a_warning_without(monkeypatch):
    schema = schema_of(_Doc, "doc")
    bad = {"name": "a", "count": 1}
    with pytest.raises(ReportContractError, match="inner"):
        check(bad, schema, "test")
    monkeypatch.setenv(STRICT_ENV, "0")
    with pytest.warns(UserWarning, match="does not match its published schema"):
        check(bad, schema, "test")


@pytest.mark.parametrize("report", sorted(SCHEMAS))
def test_the_published_schema_is_the_generated_one(report):
    published = ROOT / "docs" / "schema" / f"{report}.schema.json"
    assert published.read_text(encoding="utf-8") == text(report), (
        f"regenerate it: ema schema {report} --out docs/schema/{report}.schema.json")


def test_the_schemas_are_valid_draft_2020_12():
    for schema in (identify_schema(), analyze_schema()):
        Draft202012Validator.check_schema(schema)


def test_ema_schema_prints_it():
    done = subprocess.run([sys.executable, "-m", "ema_sim.cli", "schema", "identify"], capture_output=True,
                          text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["title"] == "ema identify report"


def test_ema_analyze_writes_a_report_that_matches_its_schema():
    t = np.arange(0.0, 6.0, 0.002)
    command = np.where(np.mod(t, 2.0) < 1.0, 1.0, -1.0)
    position = command + 0.001 * np.random.default_rng(0).standard_normal(t.size)
    data = MeasuredData(time_s=t, command_deg=command, position_deg=position, source="square.csv")
    doc = to_json([analyze_record(data)])
    assert violations(doc, analyze_schema()) == []
    assert doc["records"][0]["data"] == "square.csv"

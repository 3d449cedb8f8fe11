"""The type of a JSON document, for the summaries, manifests and metadata the tools write and read.

Defined once, below every package (it imports nothing), so a model's description, a campaign's summary and an
export's manifest name the same type rather than ``dict[str, Any]``.
"""

from __future__ import annotations

from typing import TypeAlias

JsonValue: TypeAlias = bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"] | None
"""What :func:`json.loads` returns and :func:`json.dumps` writes (no tuple: a tuple is written as a list)."""

JsonObject: TypeAlias = dict[str, JsonValue]
"""A JSON object: a summary, a manifest, a description."""

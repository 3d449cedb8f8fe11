"""Errors that reach the user as one clear line (the CLI maps them to exit status 2)."""

from __future__ import annotations

from collections.abc import Iterable


class EmaError(Exception):
    """Base of every error that is the user's input, not a bug."""


class UnknownNameError(EmaError, KeyError):
    """A model, channel, maneuver or effect name that is not known; lists the known ones."""

    def __init__(self, kind: str, name: str, known: Iterable[str]) -> None:
        self.kind, self.name, self.known = kind, name, sorted(known)
        super().__init__(f"unknown {kind} {name!r}; known: {', '.join(self.known)}")

    def __str__(self) -> str:
        return str(self.args[0])


class SpecError(EmaError, ValueError):
    """A malformed maneuver or load spec; the message names the bad field."""


class DataError(EmaError, ValueError):
    """Measured data (CSV or bag) that breaks the data contract; the message names row and column."""


class ConfigError(EmaError, ValueError):
    """A channel configuration file that is missing or malformed."""

"""A quiet progress bar on stderr that appears only once a run has taken a couple of seconds."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Call with the fraction done; draws after ``delay_s`` and finishes the line on ``close``."""

    def __init__(self, label: str, *, delay_s: float = 2.0, stream: TextIO | None = None, width: int = 30) -> None:
        self.label = label
        self.delay_s = delay_s
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self._start = time.monotonic()
        self._shown = False

    def __call__(self, fraction: float) -> None:
        """Report ``fraction`` of the run done."""
        elapsed = time.monotonic() - self._start
        if elapsed < self.delay_s and not self._shown:
            return
        self._shown = True
        frac = min(max(fraction, 0.0), 1.0)
        filled = round(frac * self.width)
        eta = elapsed * (1.0 - frac) / frac if frac > 0 else float("nan")
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {100 * frac:5.1f}%  {elapsed:5.1f}s elapsed, ~{eta:4.1f}s left")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line (if it was drawn)."""
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()

"""What every suite bag carries: its sides and metadata keys, and the array type its readers return."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
SIDES = ("emac", "fmu")
METADATA_KEYS = ("test", "maneuver", "load", "channel", "model", "profile")
"""Keys every suite bag carries in its metadata (the data contract's minimum)."""

"""Array types of the models' kernels (numpy's typed arrays; numba compiles them as ``float64[:]``...)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
"""Floats: parameter vectors, states, breakpoints, output blocks."""
IntArray = NDArray[np.int64]
"""Integers: held regimes, stop modes, flags."""
UIntArray = NDArray[np.uint64]
"""Unsigned words: the noise generators' states."""

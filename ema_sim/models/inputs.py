"""A model's inputs as its kernels take them: one value or one record per instance, or one for all, all finite.

A record given once for all instances stays one row (a read-only broadcast view) from the caller to the
kernel and back into the record's held inputs, so a batch sharing it holds no copy per instance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ema_sim.errors import DataError, EmaError
from ema_sim.models.arrays import FloatArray, IntArray


def as_batch(value: ArrayLike, n: int, what: str) -> FloatArray:
    """One value per instance (a copy), from a scalar or ``n`` values.

    Parameters
    ----------
    value : array_like
        A scalar, or one value per instance.
    n : int
        Number of instances.
    what : str
        Its name, for the error.

    Returns
    -------
    numpy.ndarray
        ``(n,)``.
    """
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise DataError(f"{what}: expected a scalar or {n} values, got shape {arr.shape}")
    return arr.copy()


def as_record(value: ArrayLike, n: int, m: int, what: str) -> FloatArray:
    """A record's inputs as ``(n, m)``; one row for all instances is a read-only view of it, not a copy.

    Parameters
    ----------
    value : array_like
        ``m`` values for every instance, or ``(n, m)``.
    n : int
        Number of instances.
    m : int
        Number of breakpoints.
    what : str
        Its name, for the error.

    Returns
    -------
    numpy.ndarray
        ``(n, m)``: a broadcast view (stride 0 between instances) when one row was given.
    """
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == m:
        return np.broadcast_to(arr, (n, m))
    if arr.shape != (n, m):
        raise DataError(f"{what}: expected {m} values or shape ({n}, {m}), got shape {arr.shape}")
    return arr


def held_inputs(values: FloatArray, held: IntArray) -> FloatArray:
    """The input in effect at each sample; a record given once for all instances stays one row (a read-only view).

    Parameters
    ----------
    values : numpy.ndarray
        The record's inputs, ``(n, m)`` (:func:`as_record`).
    held : numpy.ndarray
        The breakpoint each sample reads.

    Returns
    -------
    numpy.ndarray
        ``(n, samples)``.
    """
    if values.shape[0] > 1 and values.strides[0] == 0:  # (one instance: a copy of its row costs less than a view)
        return np.broadcast_to(values[0, held], (values.shape[0], held.shape[0]))
    return np.take(values, held, axis=1)


def check_finite(arr: FloatArray, what: str) -> None:
    """Refuse a non-finite value, saying where it is.

    Parameters
    ----------
    arr : numpy.ndarray
        The values.
    what : str
        Their name, for the error.
    """
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise EmaError(f"{what}: non-finite value at index {tuple(int(i) for i in idx)}")

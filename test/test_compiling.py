"""Kernels compiled without reference counting (:mod:`ema_sim.models.compiling`): the same numbers, fewer atomics."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest
from numba.core.errors import TypingError

from ema_sim.models.compiling import ForwardCopiesCompiler, borrowing, unlikely


@nb.njit(inline="always")
def _write(p, x, row, k):
    """An inlined element in the shape of figure 26's output stage: a row view, and an ``or`` of two tests."""
    row[0] = x[k] * p[2]
    row[1] = x[k] + p[1]
    flags = 0
    if x[k] >= p[0] or x[k] <= -p[0]:
        flags |= 1
    if p[1] > 0.0 and not abs(x[k]) < p[1]:
        flags |= 2
    row[2] = flags


def _loop(params, states, out):
    for i in range(params.shape[0]):
        p = params[i]
        x = states[i]
        for k in range(x.shape[0]):
            _write(p, x, out[i, k], k)


def _increfs(dispatcher) -> int:
    return sum(ir.count("NRT_incref") for ir in dispatcher.inspect_llvm().values())


def test_forwarded_copies_give_the_same_numbers_with_fewer_reference_counts():
    plain = nb.njit(_loop)
    forwarded = nb.njit(pipeline_class=ForwardCopiesCompiler)(_loop)
    rng = np.random.default_rng(3)
    params = rng.uniform(0.1, 2.0, (5, 3))
    states = rng.normal(0.0, 2.0, (5, 40))
    a, b = np.empty((5, 40, 3)), np.empty((5, 40, 3))
    plain(params, states, a)
    forwarded(params, states, b)
    assert np.array_equal(a, b)
    assert _increfs(forwarded) < _increfs(plain)


def test_a_borrowing_element_works_in_its_callers_arrays_and_cannot_allocate():
    @borrowing
    def add_into(x, y):
        for k in range(x.shape[0]):
            y[k] += x[k]

    x, y = np.arange(4.0), np.ones(4)
    add_into(x, y)
    assert np.array_equal(y, [1.0, 2.0, 3.0, 4.0])

    @borrowing
    def allocates(x):
        return np.empty_like(x)

    with pytest.raises((TypingError, NotImplementedError, RuntimeError)):
        allocates(x)


def test_unlikely_keeps_the_condition_and_tells_llvm_the_branch_is_rare():
    @nb.njit
    def stick(v, dv, f, fs):
        v_new = v + dv
        if unlikely(v_new * v <= 0.0 and abs(f) <= fs):
            return 0.0
        return v_new

    @nb.njit
    def plain(v, dv, f, fs):
        v_new = v + dv
        if v_new * v <= 0.0 and abs(f) <= fs:
            return 0.0
        return v_new

    cases = [(1.0, -2.0, 0.5, 1.0), (1.0, -2.0, 2.0, 1.0), (1.0, 0.5, 0.1, 1.0), (-1.0, 1.0, 0.0, 0.0)]
    assert [stick(*c) for c in cases] == [plain(*c) for c in cases] == [0.0, -1.0, 1.5, 0.0]
    # llvm.expect is lowered to branch weights marked "expected" (1 : 2000) on the branch it decides
    assert '!"expected", i32 1, i32 2000' in "".join(stick.inspect_llvm().values())
    assert '!"expected"' not in "".join(plain.inspect_llvm().values())

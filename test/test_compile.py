"""Compiled kernels: each factory-made closure caches under a name of its own; the warm-up covers every model.

Numba names a cache file after a function's qualified name. Closures of one factory share it, so two
processes compiling two siblings at once (two test workers, two nodes' first runs) wrote one index and
one data file between them, and one loaded the other's machine code (seen: a HOAC1 run looping in
LOAC's stepper).
"""

from __future__ import annotations

import numpy as np

from ema_sim import warmup
from ema_sim.models.high_order import hoac1
from ema_sim.models.integrate import make_dopri5
from ema_sim.models.registry import model_names
from ema_sim.models.second_order import loac, stage_set
from ema_sim.models.second_order.loada import METHOD_FORWARD_EULER, METHOD_LOADF, kernel


def index_file(dispatcher) -> str:
    return dispatcher._cache._cache_file._index_name


def test_sibling_closures_cache_in_files_of_their_own():
    names = [index_file(kernel(method, on)) for method in (METHOD_FORWARD_EULER, METHOD_LOADF)
             for on in (stage_set.REPORT, stage_set.ALL)]
    names += [index_file(make_dopri5(loac.rhs)), index_file(make_dopri5(hoac1.rhs)), index_file(hoac1.advance)]
    assert len(set(names)) == len(names), names
    # The same closure made twice is one cache entry, not a new file per call.
    assert index_file(make_dopri5(loac.rhs)) == index_file(make_dopri5(loac.rhs))


def test_the_warm_up_compiles_every_model_of_the_registry():
    members = [m for group in warmup.GROUPS if group != "analysis" for m in warmup.TOGETHER.get(group, (group,))]
    assert sorted(members) == sorted(model_names())  # each model in one group, once
    assert "analysis" in warmup.GROUPS
    group, seconds = warmup.warm("sloac")
    assert group == "sloac"
    assert np.isfinite(seconds)
    assert seconds >= 0.0

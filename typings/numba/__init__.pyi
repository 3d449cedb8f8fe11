# Typing stubs for the part of numba ema_sim uses (numba ships none). A compiled function keeps the
# signature of the Python function it compiles, so its annotations are what mypy checks callers against.
from collections.abc import Callable
from typing import Any, Literal, TypeVar, overload

_F = TypeVar("_F", bound=Callable[..., Any])

@overload
def njit(func: _F, /) -> _F: ...
@overload
def njit(
    *,
    cache: bool = ...,
    inline: Literal["always", "never"] = ...,
    error_model: Literal["python", "numpy"] = ...,
    fastmath: bool | set[str] = ...,
    parallel: bool = ...,
    nogil: bool = ...,
    pipeline_class: type = ...,
    _nrt: bool = ...,
) -> Callable[[_F], _F]: ...
def prange(start: int, stop: int = ..., step: int = ..., /) -> range: ...
def get_num_threads() -> int: ...
def set_num_threads(n: int, /) -> None: ...

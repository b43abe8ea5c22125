"""The one place numba is imported: `njit` compiles a function to machine code (nopython
mode, no fastmath: IEEE arithmetic in the order written, so compiled and interpreted maths
agree to the bit) and caches it beside its source (`__pycache__`), so that a later process
loads it instead of compiling it again. Typed for mypy: the decorated function keeps its
signature.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def njit(fn: F) -> F:
    """`numba.njit(cache=True)` with the signature of `fn` kept for the type checker."""
    return cast(F, numba.njit(cache=True)(fn))


_warmed: set[str] = set()
_compile_s = [0.0]


def warm_up(name: str, call: Callable[[], object]) -> None:
    """Run `call` (kernels on sample inputs of their run-time types) once per process: its
    first call compiles the kernels or loads them from the cache, which is timed here rather
    than in the first control step."""
    if name in _warmed:
        return
    _warmed.add(name)
    t0 = time.perf_counter()
    call()
    _compile_s[0] += time.perf_counter() - t0


def compile_time_s() -> float:
    """Seconds this process spent in `warm_up` (compiling or loading kernels)."""
    return _compile_s[0]

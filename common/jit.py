"""The one place numba is imported: `njit` compiles a function to machine code (nopython
mode, no fastmath: IEEE arithmetic in the order written, so compiled and interpreted maths
agree to the bit) and caches it beside its source (`__pycache__`), so that a later process
loads it instead of compiling it again. Typed for mypy: the decorated function keeps its
signature.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def njit(fn: F) -> F:
    """`numba.njit(cache=True)` with the signature of `fn` kept for the type checker."""
    return cast(F, numba.njit(cache=True)(fn))

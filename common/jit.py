"""The one place numba is imported: `njit` compiles a function to machine code (nopython
mode, no fastmath: IEEE arithmetic in the order written, so compiled and interpreted maths
agree to the bit) and caches it on disk, so that a later process loads it instead of
compiling it again. Typed for mypy: the decorated function keeps its signature.
`compiled_for` hands a hot caller a kernel's machine code for fixed argument types, without
numba's type dispatch on each call.

numba checks a cached kernel against its own source file only, while a kernel inlines the
kernels it calls from other modules (the tracker's has the dual-quaternion algebra in it):
an edit of `fcu/control/dualquat.py` would leave a stale tracker in the cache. So the cache lives in
`__pycache__/numba-<hash>` at the project's root, the hash taken over every module that
defines kernels or the constants they freeze (KERNEL_MODULES: the array layouts of
`fcu.control.layouts`, `fcu.estimator.layouts` and `sitl.layouts` too): any edit of one of
them starts a fresh cache.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

from common.blas import load_cython_blas

load_cython_blas()  # before numba's import, which would run all of scipy.linalg for it
import numba  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
KERNEL_MODULES = ("common/jit.py", "common/vehicle_constants.py", "common/layouts.py",
                  "fcu/control/layouts.py", "fcu/estimator/layouts.py", "sitl/layouts.py",
                  "common/quaternion.py", "common/gemm.py",
                  "fcu/control/dualquat.py", "fcu/control/tracker.py", "fcu/control/allocation.py",
                  "fcu/control/core.py", "fcu/control/wrench.py",
                  "fcu/envelope/feasibility.py", "fcu/envelope/excess.py",
                  "fcu/envelope/verdict.py", "fcu/envelope/speed_bound.py",
                  "fcu/reference/approach_kernels.py", "fcu/reference/trajectory.py",
                  "fcu/mission/segments.py", "fcu/mission/verdicts.py", "fcu/mission/stretch.py",
                  "fcu/modes/manual.py", "fcu/safety/actuator_monitor.py",
                  "fcu/control/rate_filter.py",
                  "sitl/plant_kernels.py", "sitl/disturbance.py", "sitl/imu_kernels.py",
                  "fcu/estimator/strapdown.py", "fcu/estimator/update.py",
                  "fcu/estimator/output.py", "fcu/estimator/filter.py",
                  "fcu/estimator/readout.py")


def _sources_hash() -> str:
    digest = hashlib.sha256()
    for name in KERNEL_MODULES:
        digest.update(name.encode())
        digest.update((ROOT / name).read_bytes())
    return digest.hexdigest()[:16]


_config: Any = numba.config
if not _config.CACHE_DIR:  # NUMBA_CACHE_DIR set by the user wins
    _config.CACHE_DIR = str(ROOT / "__pycache__" / f"numba-{_sources_hash()}")

F = TypeVar("F", bound=Callable[..., Any])


def _real_file(fn: F) -> F:
    """`fn` with its code's file name resolved: numba files a cached kernel under its
    source's path, so a module imported through a symlinked folder (a checkout reached by a
    link, `python -m` run from one) finds the kernels cached for the real file instead of
    compiling them all again."""
    code = fn.__code__
    real = str(Path(code.co_filename).resolve())
    if real != code.co_filename:
        fn.__code__ = code.replace(co_filename=real)
    return fn


def njit(fn: F) -> F:
    """`numba.njit(cache=True)` with the signature of `fn` kept for the type checker."""
    return cast(F, numba.njit(cache=True)(_real_file(fn)))


def njit_loops(fn: F) -> F:
    """`njit` with numba's "numpy" error model: a float division by zero gives inf or NaN as
    IEEE 754 says instead of raising ZeroDivisionError. Without that check in its body a
    loop that divides can be vectorised (every value that does not divide by zero is the
    same, to the bit)."""
    return cast(F, numba.njit(cache=True, error_model="numpy")(_real_file(fn)))


def njit_released(fn: F) -> F:
    """`njit_loops` that releases the GIL while it runs: a batch kernel whose calls other
    threads may make at the same time (`fcu.mission.batches`)."""
    return cast(F, numba.njit(cache=True, error_model="numpy", nogil=True)(_real_file(fn)))


def compiled_for(kernel: F, *example_args: object) -> F:
    """`kernel`'s machine code for exactly the numba types of `example_args` (compiled, or
    loaded from the cache, now), called without numba's dispatch: the type fingerprint of
    every argument and the lookup of the matching signature, a few hundred nanoseconds a
    call (with tuple arguments most), some percent of a flight's control period over its
    dozen kernel calls. The arithmetic is the kernel's, to the bit.

    Only for a caller whose argument types are fixed by construction: float64 or int64
    C-contiguous arrays it made itself (their rank as in `example_args`), plain floats, ints
    and bools, tuples of floats. Nothing is checked per call: a tuple of another length, a
    list for a tuple or an argument that is not a number is refused (ValueError, TypeError),
    but a numeric string or bytes would be read as its number and an array of another dtype,
    rank or layout would be misread."""
    dispatcher, typeof = cast(Any, kernel), cast(Any, numba).typeof
    signature = tuple(typeof(a) for a in example_args)
    return cast(F, dispatcher.compile(signature))

"""numba's BLAS without `scipy.linalg`'s package: numba checks at its import that a BLAS is
there by importing `scipy.linalg.cython_blas`, which runs all of `scipy.linalg` first (0.3
to 0.4 s of CPU in every program, the ground station's, the FCU's and the plant's, most
of it scipy's array-API layer) for an extension module that loads alone in 5 ms.
`load_cython_blas` loads that module alone, before numba is imported (`common.jit`).
numba checks for it whether or not a kernel calls BLAS (none of ours does since the
estimator's products use their matrices' structure); a kernel's `np.dot` would take its
function pointers from the module's `__pyx_capi__`: the same module either way.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys

BLAS_MODULE = "scipy.linalg.cython_blas"


def load_cython_blas() -> None:
    """Put `scipy.linalg.cython_blas` in `sys.modules` without running `scipy.linalg`'s
    package; a later `import scipy.linalg` runs it as usual and finds this module there.
    Anything unexpected (no scipy, another layout) leaves it to numba's own import."""
    if BLAS_MODULE in sys.modules or "scipy.linalg" in sys.modules:
        return
    try:
        linalg = importlib.util.find_spec("scipy.linalg")  # imports the `scipy` package alone
        if linalg is None or not linalg.submodule_search_locations:
            return
        spec = importlib.machinery.PathFinder.find_spec(
            BLAS_MODULE, list(linalg.submodule_search_locations))
        if spec is None or spec.loader is None:
            return
        module = importlib.util.module_from_spec(spec)
        sys.modules[BLAS_MODULE] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[BLAS_MODULE]
            raise
    except Exception:  # numba's own import then tries, and says what failed
        return

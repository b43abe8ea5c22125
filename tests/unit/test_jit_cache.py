"""numba files a cached kernel under its source file's path: a kernel module imported through
a symlinked folder (a checkout reached by a link, `python -m` from a folder of links, as the
docs tests run the README) must find the kernels cached for the real file, not compile them
all again (`common.jit`)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from common.jit import njit

KERNEL = """
from common.jit import njit


@njit
def twice(x: float) -> float:
    return 2.0 * x
"""


def test_a_kernel_reached_through_a_link_is_filed_under_its_real_file(tmp_path: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (real / "kernel_mod.py").write_text(KERNEL)
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    spec = importlib.util.spec_from_file_location("kernel_via_link", link / "kernel_mod.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["kernel_via_link"] = module
    try:
        spec.loader.exec_module(module)
        kernel = module.twice
        assert kernel.py_func.__code__.co_filename == str((real / "kernel_mod.py").resolve())
        assert kernel(1.5) == 3.0
    finally:
        del sys.modules["kernel_via_link"]


def test_a_kernel_of_a_real_file_keeps_its_name() -> None:
    def half(x: float) -> float:
        return 0.5 * x

    name = half.__code__.co_filename
    assert njit(half).py_func.__code__.co_filename == str(Path(name).resolve())


def test_every_module_that_compiles_kernels_keys_the_cache() -> None:
    """Every product module that compiles a kernel is in KERNEL_MODULES, whose hash names
    the cache folder and whose stamps `tests.kernels` checks before the suite: one left
    out (the approach's kernels, moved to a module of their own, while the module they
    left stayed listed) could leave a kernel that inlines it stale in the cache."""
    from common.jit import KERNEL_MODULES, ROOT

    compiling = sorted(
        str(path.relative_to(ROOT)) for folder in ("common", "fcu", "sitl", "gcs")
        for path in (ROOT / folder).rglob("*.py")
        if any(mark in path.read_text() for mark in ("@njit", "@jit.njit", "= njit(",
                                                     "@njit_loops")))
    assert [m for m in compiling if m not in KERNEL_MODULES] == []

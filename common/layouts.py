"""Named layouts of the compiled kernels' flat arrays: the mechanism, one table per array.

Each array is a `Layout`: its fields in order, as (name, size). The integer offsets the
kernels index with are module constants taken from those tables where the arrays are
declared (`fcu.control.layouts`, `fcu.estimator.layouts`, `sitl.layouts`): numba freezes a
module's globals when it compiles a kernel, so `x[X_Q + 1]` costs what `x[4]` does, and the
Python code that packs and unpacks the arrays uses the same constants. Frames and units are
those of the field names (world ENU, body FLU, SI).
"""

from __future__ import annotations


class Layout:
    """The fields of a flat array in order: `at(name)` is a field's offset, `size` the
    array's length."""

    def __init__(self, *fields: tuple[str, int]) -> None:
        self.fields = fields
        self._offsets: dict[str, int] = {}
        offset = 0
        for name, size in fields:
            self._offsets[name] = offset
            offset += size
        self.size = offset

    def at(self, name: str) -> int:
        """The offset of field `name`."""
        return self._offsets[name]

    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.fields)

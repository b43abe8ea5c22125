"""Named layouts of the compiled kernels' flat arrays: the mechanism, one table per array.

Each array is a `Layout`: its fields in order, as (name, size). The integer offsets the
kernels index with are module constants taken from those tables where the arrays are
declared (`fcu.control.layouts`, `fcu.estimator.layouts`, `sitl.layouts`): numba freezes a
module's globals when it compiles a kernel, so `x[X_Q + 1]` costs what `x[4]` does. The
Python code that fills, reads and shares the arrays takes a field by name from the same
table (`view`: a view of the field, so that the parts of a fused kernel's buffers are the
buffers of the stages that make it up). Frames and units are those of the field names
(world ENU, body FLU, SI).
"""

from __future__ import annotations

import numpy as np


class Layout:
    """The fields of a flat array in order: `at(name)` is a field's offset, `size` the
    array's length."""

    def __init__(self, *fields: tuple[str, int]) -> None:
        self.fields = fields
        self._offsets: dict[str, int] = {}
        self._sizes = dict(fields)
        offset = 0
        for name, size in fields:
            self._offsets[name] = offset
            offset += size
        self.size = offset

    def at(self, name: str) -> int:
        """The offset of field `name`."""
        return self._offsets[name]

    def span(self, name: str) -> slice:
        """The slice of field `name` in the array."""
        offset = self._offsets[name]
        return slice(offset, offset + self._sizes[name])

    def view(self, array: np.ndarray, name: str) -> np.ndarray:
        """Field `name` of `array` (of this layout's size) as a view: writing it writes the
        array."""
        if array.shape != (self.size,):
            raise ValueError(f"an array of {array.shape} is not of this layout's "
                             f"({self.size},)")
        return array[self.span(name)]

    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.fields)

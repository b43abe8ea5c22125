"""The error of a flight log that cannot be read, apart from the reader (`common.logs.ulog`,
which loads numpy): a program's start-up names it among the errors it reports in one line
(`common.process.program`) without loading the reader."""

from __future__ import annotations


class ULogError(ValueError):
    """A ULog file that cannot be read, or a topic it does not hold."""

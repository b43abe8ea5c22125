"""The link layer's errors: bad input (exit status 2) and a peer that is not there (1)."""

from __future__ import annotations


class LinkError(ValueError):
    """A link URL that cannot be parsed or opened: bad input, exit status 2."""

    exit_code = 2


class LinkUnavailable(LinkError):
    """The other end is not there (a refused TCP connect): a runtime failure, exit status 1."""

    exit_code = 1

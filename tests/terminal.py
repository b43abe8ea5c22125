"""Starting a child as from a terminal, for tests that Ctrl-C it.

pytest-xdist's workers ignore SIGINT, and a child inherits an ignored signal (bash cannot
even reset one ignored at its entry), so a Ctrl-C sent to a program while it imports, before
its own handler is set, would be lost and the program would run on. A terminal starts it
with SIGINT at its default: `Popen(..., preexec_fn=sigint_default)` does the same.
"""

from __future__ import annotations

import signal


def sigint_default() -> None:
    """In the child, before exec: SIGINT at its default action."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)

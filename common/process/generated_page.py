"""A page of docs/ generated from declarations in the code (the parameter table, the config
files' keys): the generator's command line, which writes the page or, with `--check`, exits 1
when the page on disk is not what the declarations give (the tests run the check)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from common.process.diagnostics import say


def page_main(prog: str, description: str | None, page: Path, render: Callable[[], str],
              source: str, argv: list[str] | None = None) -> int:
    """`prog [--check]`: docs/<page> written from `render()`, or checked against it (exit 1
    when stale); `source` names what the page is generated from, for the help."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("--check", action="store_true",
                        help=f"exit 1 if the page differs from {source}, write nothing")
    args = parser.parse_args(argv)
    text = render()
    name = f"docs/{page.name}"
    if args.check:
        current = page.read_text() if page.exists() else ""
        if current != text:
            say(f"{name} is stale: run {prog}")
            return 1
        return 0
    page.write_text(text)
    say(f"wrote {name}")
    return 0

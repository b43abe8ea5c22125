"""What the programs `fcu`, `sitl` and `gcs` write, in two kinds: program output (results,
tables, reports, status lines: `say`, on stdout) and diagnostics (warnings, errors, progress,
debug: the standard `logging` module, one plain line each on stderr).

Every module that writes diagnostics takes its logger from `get_logger`; the loggers of this
project's packages write the bare message to the stderr of the moment, so a line reads the
same whether or not a program set the level. `-q`/`--quiet` keeps warnings and errors alone,
`-v`/`--verbose` adds the debug lines (`add_verbosity_options`, `setup_logging`).
"""

from __future__ import annotations

import argparse
import logging
import sys

PACKAGES = ("common", "fcu", "sitl", "gcs")  # the loggers set up here (and their children)
DEFAULT_LEVEL = logging.INFO


class StderrHandler(logging.Handler):
    """A handler that writes each record's message, one line, to `sys.stderr` as it is when
    the record is written (a test's capture, a redirected stream)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            stream = sys.stderr
            stream.write(self.format(record) + "\n")
            stream.flush()
        except RecursionError:
            raise
        except Exception:
            self.handleError(record)


def _install() -> None:
    """One `StderrHandler` on each package's logger, at the default level (once)."""
    for name in PACKAGES:
        logger = logging.getLogger(name)
        if not any(isinstance(h, StderrHandler) for h in logger.handlers):
            logger.addHandler(StderrHandler())
            logger.setLevel(DEFAULT_LEVEL)
            logger.propagate = False  # a root handler set up elsewhere writes no second copy


def get_logger(name: str) -> logging.Logger:
    """The logger of module `name` (`__name__`), its package's handler installed."""
    _install()
    return logging.getLogger(name)


def add_verbosity_options(parser: argparse.ArgumentParser, *, subcommand: bool = False) -> None:
    """`-v`/`--verbose` (debug lines too) and `-q`/`--quiet` (warnings and errors only) on
    `parser`, exclusive, into `args.log_level`. A subcommand's copy leaves the value given
    before the subcommand in place when it is not given again."""
    default = argparse.SUPPRESS if subcommand else DEFAULT_LEVEL
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-v", "--verbose", dest="log_level", action="store_const",
                       const=logging.DEBUG, default=default,
                       help="also write debug diagnostics (stderr)")
    group.add_argument("-q", "--quiet", dest="log_level", action="store_const",
                       const=logging.WARNING, default=default,
                       help="write only warnings and errors of the diagnostics (stderr)")


def setup_logging(prog: str, args: argparse.Namespace) -> None:
    """Set the diagnostics' level of the program `prog` from its parsed `args`
    (`add_verbosity_options`; the default, info, where it has none)."""
    level = int(getattr(args, "log_level", DEFAULT_LEVEL))
    _install()
    for name in PACKAGES:
        logging.getLogger(name).setLevel(level)
    get_logger(__name__).debug("%s: arguments %s", prog, _arguments(args))


def _arguments(args: argparse.Namespace) -> str:
    """The parsed arguments as `name=value` pairs in name order (a debug line)."""
    return ", ".join(f"{k}={v}" for k, v in sorted(vars(args).items()) if k != "log_level")


def say(text: str, *, end: str = "\n") -> None:
    """Program output: `text` on stdout, flushed (a result, a table, a status line)."""
    print(text, end=end, flush=True)

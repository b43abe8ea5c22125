"""Every ```sh block of README.md and of the pages in docs/ works as written.

Each block is checked statically first: every `gcs`, `fcu` and `sitl` command line is
accepted by the program's own argument parser, every `config/...` path it names exists, every
`make` target is in the Makefile. A block not preceded by `<!-- not-run: REASON -->` is then
run, line by line, as a bash script:

- in a scratch folder that mirrors the repository (symlinks; `.venv` is this suite's venv),
  with HOME in the scratch folder too, and this suite's venv first on PATH;
- in a private network namespace (`unshare -rn`, loopback up), so that the README's own
  ports (14550, 4560, 8765, 7447) are used as written and never meet other processes;
- a long-running command (`sitl`, `fcu`, `gcs router`, `gcs watch`, live `gcs view`,
  `gcs log record` without `--duration`) is started in the background, must still be alive
  when the block's other lines are done, and must exit 0 on Ctrl-C (SIGINT);
- every other line must exit 0, unless its comment says `# exits N`.

`<!-- run-with: HEADING -->` before a block runs the sh block of the section HEADING of the
same page first (its long-running commands in the background): e.g. the vehicle commands
run against the `sitl` and `fcu` started as "Starting the processes by hand" says.

Without network namespaces the blocks are only checked statically (skipped, with reason).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from ..terminal import sigint_default

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("**/*.md"))]
NOT_RUN = re.compile(r"<!--\s*not-run:\s*(.*?)\s*-->")
RUN_WITH = re.compile(r"<!--\s*run-with:\s*(.*?)\s*-->")
EXITS = re.compile(r"#.*\bexits (\d+)\b")
BLOCK_TIMEOUT_S = 110
SETTLE_S = 1.0  # after starting a long-running command, before the next line

pytestmark = pytest.mark.timeout(BLOCK_TIMEOUT_S + 30)


@dataclass
class Block:
    page: str  # the page's path in the repository
    line: int  # of the opening fence, 1-based
    heading: str
    text: str
    not_run: str | None
    run_with: str | None

    @property
    def name(self) -> str:
        where = "" if self.page == "README.md" else f"{self.page} "
        return f"{where}L{self.line} {self.heading[:40]}"


def read_blocks(text: str, page: str = "README.md") -> list[Block]:
    blocks: list[Block] = []
    lines = text.splitlines()
    heading = ""
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("#"):
            heading = line.lstrip("#").strip()
        if line.strip() == "```sh":
            start = i
            body = []
            i += 1
            while i < len(lines) and lines[i].strip() != "```":
                body.append(lines[i])
                i += 1
            before = [lines[j] for j in range(start - 1, max(start - 4, -1), -1)
                      if lines[j].strip()][:2]
            directives = " ".join(before)
            not_run = NOT_RUN.search(directives)
            run_with = RUN_WITH.search(directives)
            blocks.append(Block(page, start + 1, heading, "\n".join(body) + "\n",
                                not_run.group(1) if not_run else None,
                                run_with.group(1) if run_with else None))
        elif line.strip().startswith("```"):  # another language: skip to its end
            i += 1
            while i < len(lines) and not lines[i].strip().startswith("```"):
                i += 1
        i += 1
    return blocks


def commands(block_text: str) -> list[str]:
    """The block's command lines: continuations joined, blank and comment lines dropped."""
    out: list[str] = []
    pending = ""
    for raw in block_text.splitlines():
        line = pending + raw
        if line.rstrip().endswith("\\"):
            pending = line.rstrip()[:-1] + " "
            continue
        pending = ""
        if line.strip() and not line.strip().startswith("#"):
            out.append(line.strip())
    return out


def argvs(command: str) -> list[list[str]]:
    """The simple commands of a line (split at |, &&, ||, ;), comments removed."""
    lexer = shlex.shlex(command, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    out: list[list[str]] = [[]]
    for token in lexer:
        if token in ("|", "||", "&&", ";", "&"):
            out.append([])
        else:
            out[-1].append(token)
    return [a for a in out if a]


SHELL_WORDS = {".", "source", "export", "cd", "set", "unset", "deactivate", "gcs", "fcu",
               "sitl", "zenohd", "mavlogdump.py"}


def program(argv: list[str]) -> str:
    return argv[0].rsplit("/", 1)[-1] if "/" in argv[0] else argv[0]


def long_running(argv: list[str]) -> bool:
    prog, rest = program(argv), argv[1:]
    if prog in ("sitl", "fcu"):
        return True
    if prog != "gcs" or not rest:
        return False
    if rest[0] in ("router", "watch"):
        return "--duration" not in rest
    if rest[0] == "view":  # live, or a replay not at speed 0 (paced by the wall clock)
        if len(rest) < 2 or rest[1].startswith("-"):
            return True
        return "--speed" not in rest or rest[rest.index("--speed") + 1] != "0"
    if rest[:2] == ["log", "record"]:
        return "--duration" not in rest
    return False


# ------------------------------------------------------------------ static checks


def _parser(prog: str):
    if prog == "gcs":
        from gcs.cli.parser import build_parser
    elif prog == "fcu":
        from fcu.edge.node import build_parser
    else:
        from sitl.node import build_parser
    return build_parser()


def _program_problems(command: str, prog: str, argv: list[str]) -> list[str]:
    """`gcs`, `fcu`, `sitl`: the program's own parser accepts the line, its config paths
    exist."""
    problems = []
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            _parser(prog).parse_args(argv[1:])
    except SystemExit as exc:
        if exc.code:
            problems.append(f"{command!r}: {err.getvalue().strip()}")
    for arg in argv[1:]:
        if arg.startswith("config/") and not (ROOT / arg).exists():
            problems.append(f"{command!r}: {arg} does not exist")
    return problems


def _make_problems(command: str, argv: list[str], makefile: str) -> list[str]:
    """`make`: every target is in the Makefile."""
    return [f"{command!r}: no target {target} in the Makefile" for target in argv[1:]
            if "=" not in target and not re.search(rf"^{re.escape(target)}:", makefile, re.M)]


def _argv_problems(command: str, argv: list[str], makefile: str) -> list[str]:
    problems = []
    prog = program(argv)
    notation = [a for a in argv if a.startswith("[") or a.endswith("]") or a == "..."]
    if notation:
        problems.append(f"{command!r}: {' '.join(notation)} is notation, not an "
                        "argument (a reader would type it as it stands)")
    if prog in ("gcs", "fcu", "sitl"):
        problems += _program_problems(command, prog, argv)
    elif prog not in SHELL_WORDS and shutil.which(prog) is None:
        problems.append(f"{command!r}: {prog}: no such command")
    if prog == "make":
        problems += _make_problems(command, argv, makefile)
    return problems


def static_problems(block: Block) -> list[str]:
    makefile = (ROOT / "Makefile").read_text()
    return [problem for command in commands(block.text) for argv in argvs(command)
            for problem in _argv_problems(command, argv, makefile)]


BLOCKS = [block for path in PAGES
          for block in read_blocks(path.read_text(), str(path.relative_to(ROOT)))]


def test_the_readme_has_sh_blocks_and_directives_name_real_sections():
    assert len(BLOCKS) >= 5
    for block in BLOCKS:
        headings = {b.heading for b in BLOCKS if b.page == block.page}
        assert block.not_run is None or block.not_run, f"{block.name}: not-run needs a reason"
        assert block.run_with is None or block.run_with in headings, \
            f"{block.name}: run-with names no section with an sh block: {block.run_with}"


@pytest.mark.parametrize("block", BLOCKS, ids=[b.name for b in BLOCKS])
def test_every_command_line_parses(block):
    """Also for blocks that are not run: arguments the programs accept, files that exist."""
    assert not static_problems(block), "\n".join(static_problems(block))


# ------------------------------------------------------------------ running blocks


def _kill_session(sid: int) -> None:
    """SIGKILL every process of session `sid` (a session this test started)."""
    import signal

    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue  # gone meanwhile
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[3]) == sid:
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(entry.name), signal.SIGKILL)


def _namespaces_work() -> bool:
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return False
    done = subprocess.run(["unshare", "-rn", "ip", "link", "set", "lo", "up"],
                          capture_output=True, check=False)
    return done.returncode == 0


def _script(block: Block, prelude: Block | None, out: Path) -> tuple[str, list[str]]:
    """The bash script for a block (and its run-with prelude); the command of each index."""
    lines = ["set -m", "ip link set lo up", "__bg=()", "__bgi=()"]
    shown: list[str] = []
    parts = ([(c, True) for c in commands(prelude.text)] if prelude else []) + \
        [(c, False) for c in commands(block.text)]
    for command, from_prelude in parts:
        i = len(shown)
        shown.append(command)
        io_ = f'>"{out}/{i}.out" 2>"{out}/{i}.err"'
        if all(long_running(a) for a in argvs(command)):
            lines += [f"{{ {command}\n}} {io_} &", f"__bg+=($!); __bgi+=({i})",
                      f"sleep {SETTLE_S}"]
        elif from_prelude:
            lines += [f"{{ {command}\n}} {io_}", f'echo "@@rc {i} $?"']
        else:
            lines += [f"{{ {command}\n}} {io_} </dev/null", f'echo "@@rc {i} $?"']
    lines += [
        'for k in "${!__bg[@]}"; do',
        '  if kill -0 "${__bg[$k]}" 2>/dev/null; then echo "@@alive ${__bgi[$k]}";',
        '  else echo "@@dead ${__bgi[$k]}"; fi',
        '  kill -INT -- "-${__bg[$k]}" 2>/dev/null',
        "done",
        'for k in "${!__bg[@]}"; do wait "${__bg[$k]}"; echo "@@rc ${__bgi[$k]} $?"; done',
    ]
    return "\n".join(lines) + "\n", shown


def _scratch(tmp_path: Path) -> Path:
    """A folder that looks like the repository after `make demo` (symlinks), nothing of it
    writable through the README's commands except what they create themselves."""
    work = tmp_path / "repo"
    work.mkdir()
    for entry in ROOT.iterdir():
        if entry.name in (".venv", "runs", ".git", ".pytest_cache", ".mypy_cache",
                          ".ruff_cache", "__pycache__"):
            continue
        (work / entry.name).symlink_to(entry)
    (work / ".venv").symlink_to(Path(sys.prefix))
    return work


RUN = [b for b in BLOCKS if b.not_run is None]


@pytest.mark.parametrize("block", RUN, ids=[b.name for b in RUN])
def test_block_runs_as_written(block, tmp_path):
    if not _namespaces_work():
        pytest.skip("needs a private network namespace (unshare -rn) to use the README's "
                    "ports as written; checked statically only")
    prelude = next((b for b in BLOCKS if b.page == block.page and b.heading == block.run_with),
                   None) \
        if block.run_with else None
    work, out, home = _scratch(tmp_path), tmp_path / "out", tmp_path / "home"
    out.mkdir()
    home.mkdir()
    script, shown = _script(block, prelude, out)
    env = {**os.environ, "HOME": str(home),
           "PATH": f"{Path(sys.prefix) / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("VIRTUAL_ENV", None)
    # Its own session: the background jobs (`set -m` gives each its own process group)
    # stay in it, so a block that overruns is stopped whole, none of its processes left.
    proc = subprocess.Popen(["unshare", "-rn", "bash", "-c", script], cwd=work, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=sigint_default)
    try:
        stdout, stderr = proc.communicate(timeout=BLOCK_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        _kill_session(proc.pid)
        stdout, stderr = proc.communicate()
        stdout += "\n@@timeout"
    finally:
        _kill_session(proc.pid)  # what a block left behind (nothing, when it works)
    done = subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
    status = {}
    alive = {}
    for line in done.stdout.splitlines():
        tag, _, rest = line.partition(" ")
        if tag == "@@rc":
            i, rc = rest.split()
            status[int(i)] = int(rc)
        elif tag in ("@@alive", "@@dead"):
            alive[int(rest)] = tag == "@@alive"

    def output(i: int) -> str:
        return "".join((out / f"{i}.{s}").read_text(errors="replace")[-1500:]
                       for s in ("out", "err") if (out / f"{i}.{s}").exists())

    problems = []
    if "@@timeout" in done.stdout:
        problems.append(f"the block did not finish within {BLOCK_TIMEOUT_S} s (stopped)")
    for i, command in enumerate(shown):
        expected = int(m.group(1)) if (m := EXITS.search(command)) else 0
        if alive.get(i) is False:
            problems.append(f"{command!r} ended before the block was done:\n{output(i)}")
        if status.get(i) != expected:
            problems.append(f"{command!r} exited {status.get(i)}, expected {expected}:\n"
                            f"{output(i)}")
    assert not problems, "\n\n".join(problems) + f"\n(bash stderr: {done.stderr[-500:]})"

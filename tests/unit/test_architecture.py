"""The architecture's one-way edges, checked on every module's whole import closure
(docs/architecture.md): the plant and the controller stay independent, the pure packages
load no I/O even through other modules, only the FCU's edge talks to the world, and the
ground station loads the flight code only in the runners that start it."""

from __future__ import annotations

from collections.abc import Iterable
from functools import cache

import pytest

from tools.codemap import (
    ROOT,
    Graph,
    circles,
    closure,
    import_graph,
    loading_graph,
    module_paths,
    modules_per_folder,
    path_to,
)

MODULES = module_paths()  # names only at collection; the graph is parsed when a test asks


@cache
def graph() -> Graph:
    return import_graph(MODULES)


@cache
def loads() -> Graph:
    return loading_graph(graph())  # importing a.b.c also runs a and a.b

# The I/O edges, by package: every other module of common/, fcu/ and sitl/ is pure (no
# MAVLink library, no links, no clocks, no threads, no processes, not even through the
# modules it imports). A new module is pure unless it joins an edge. gcs/ is all edge.
EDGE = (
    "fcu.edge",  # the process, its links, protocols, telemetry and onboard log
    "common.links", "common.process", "common.logs.ulog", "common.logs.px4_topics",
    "common.wire.mavlink", "common.wire.simlink", "common.wire.mission_messages",
    "sitl.node", "sitl.server", "sitl.sensor_feed", "sitl.world", "sitl.truth_log",
    "sitl.firmware.ardupilot_json", "sitl.firmware.px4_hil",
)
IO = {"pymavlink", "zenoh", "serial", "socket", "select", "selectors", "time", "threading",
      "signal", "subprocess", "multiprocessing", "concurrent", "asyncio"}
# The ground station's runners that fly the FCU and the plant in its own process (in-process,
# Table I's and a campaign's workers, the estimator's replay): they alone may load fcu/ and
# sitl/. A run through processes (gcs.run.process_run) starts them as programs and loads
# neither.
RUNNERS = ("gcs.run.inprocess", "gcs.run.table1_run", "gcs.run.replay", "gcs.campaign.worker")


def _under(name: str, prefixes: tuple[str, ...] | str) -> bool:
    prefixes = (prefixes,) if isinstance(prefixes, str) else prefixes
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def pure_modules(modules: Iterable[str]) -> list[str]:
    return sorted(m for m in modules if _under(m, ("common", "fcu", "sitl")) and m != "common"
                  and not _under(m, EDGE) and m not in ("fcu", "sitl"))


def io_loaded(loads: Graph, module: str) -> list[str]:
    """What of the I/O (IO, the edges) `module` loads, directly or through other modules, each
    with one chain that loads it (empty when the module is pure)."""
    found = closure(loads, module)
    bad = sorted({m for m in found if m in IO or _under(m, EDGE)})
    return [" -> ".join(path_to(loads, module, m)) for m in bad]


def forbidden_loads(loads: Graph, module: str, forbidden: tuple[str, ...],
                    through: tuple[str, ...] = ()) -> list[str]:
    """The modules under `forbidden` that `module` loads, each with its chain, not counting
    what it loads through the modules under `through` (whose imports are cut)."""
    cut = {m: (set() if _under(m, through) and m != module else t) for m, t in loads.items()}
    return [" -> ".join(path_to(cut, module, m)) for m in sorted(closure(cut, module))
            if _under(m, forbidden)]


@pytest.mark.parametrize("module", pure_modules(MODULES))
def test_pure_modules_load_no_io(module):
    """Given a module outside every edge, then nothing it loads, directly or through other
    modules, is a MAVLink library, a link, a clock, a thread, a process or an edge module."""
    assert io_loaded(loads(), module) == []


@pytest.mark.parametrize(("package", "forbidden", "why"), [
    ("sitl", ("fcu", "gcs"), "an independent plant makes closed-loop tests mean something"),
    ("fcu", ("sitl", "gcs"), "the controller flies real vehicles without the simulator"),
    ("common", ("fcu", "sitl", "gcs"), "the shared parts are shared, not owned"),
])
def test_package_loads_none_of_the_packages_it_stays_apart_from(package, forbidden, why):
    """Given every module of a package, then its whole import closure holds none of the
    packages it must stay apart from."""
    found = [chain for m in graph() if _under(m, package)
             for chain in forbidden_loads(loads(), m, forbidden)]
    assert found == [], why


def test_only_the_fcu_edge_and_the_runners_load_the_fcu_edge():
    """Given every module, then only fcu/edge itself and the ground station's runners (which
    are the process edge of an FCU they run in-process) load a module of fcu/edge."""
    found = [chain for m in graph() if not _under(m, ("fcu.edge", *RUNNERS, "gcs"))
             for chain in forbidden_loads(loads(), m, ("fcu.edge",))]
    assert found == []


def test_gcs_loads_the_flight_code_only_through_its_runners():
    """Given every module of gcs/, then fcu/ and sitl/ are loaded only through a runner; and
    the reports, which read run folders, load neither even through a runner."""
    found = [chain for m in graph() if _under(m, "gcs") and not _under(m, RUNNERS)
             for chain in forbidden_loads(loads(), m, ("fcu", "sitl"), through=RUNNERS)]
    assert found == []
    reports = [chain for m in graph() if _under(m, "gcs.report")
               for chain in forbidden_loads(loads(), m, ("fcu", "sitl"))]
    assert reports == []


def test_the_rules_see_through_other_modules(tmp_path):
    """Given modules whose I/O or controller is two imports away, or behind a package's
    __init__, then the rules find each with its chain (so the silence above means
    something), and a runner's imports are cut only where the rule says so."""
    graph: Graph = {"common.a": {"common.b"}, "common.b": {"time"},
                    "sitl.p": {"sitl.q"}, "sitl.q": {"common.c"}, "common.c": {"fcu.x"},
                    "fcu.x": set(), "fcu.y.z": set(), "fcu.y": {"socket"},
                    "gcs.cli": {"gcs.run.inprocess"}, "gcs.run.inprocess": {"fcu.x"},
                    "gcs.run": set()}
    loads = loading_graph(graph)
    assert io_loaded(loads, "common.a") == ["common.a -> common.b -> time"]
    assert io_loaded(loads, "fcu.y.z") == ["fcu.y.z -> fcu.y -> socket"]
    assert forbidden_loads(loads, "sitl.p", ("fcu",)) == ["sitl.p -> sitl.q -> common.c -> fcu.x"]
    assert forbidden_loads(loads, "gcs.cli", ("fcu",), through=("gcs.run.inprocess",)) == []
    assert forbidden_loads(loads, "gcs.cli", ("fcu",)) == \
        ["gcs.cli -> gcs.run.inprocess -> fcu.x"]


def test_the_edges_exist_and_the_rule_covers_the_core():
    """Given the edge and runner lists, then each names a module that exists (a renamed edge
    would silently become pure-checked or unchecked), and the core is under the rule."""
    for name in (*EDGE, *RUNNERS):
        assert name in MODULES, f"{name} does not exist"
    pure = pure_modules(MODULES)
    for core in ("fcu.control.tracker", "fcu.control.allocation", "fcu.pipeline",
                 "sitl.plant", "common.frames", "fcu.modes.commander", "fcu.estimator.ekf",
                 "fcu.mission.validation", "common.jit", "common.warm_ups"):
        assert core in pure


def test_circle_finder_finds_hidden_circles(tmp_path):
    """Given modules that import each other only inside a function, under TYPE_CHECKING or
    relatively, then the finder reports each circle (so the next test's silence means
    something), and not a one-way import."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .x import f\n")
    (pkg / "a.py").write_text("def g():\n    from pkg import b\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from pkg.a import g\n")
    (pkg / "sub" / "x.py").write_text("def f():\n    from .. import sub\n")
    (pkg / "c.py").write_text("import pkg.a\nimport time\n")
    graph = import_graph(module_paths(tmp_path, ("pkg",)))
    assert graph["pkg.c"] == {"pkg.a", "time"}
    assert circles({m: t & graph.keys() for m, t in graph.items()}) == \
        [["pkg.a", "pkg.b"], ["pkg.sub", "pkg.sub.x"]]


def test_no_import_circle():
    """Given every import in common, fcu, sitl and gcs, wherever it is written, then no
    module reaches itself through its imports."""
    assert circles({m: t & graph().keys() for m, t in graph().items()}) == []


MAX_LINES = 500  # one job per file: past this a module has several (split it by job)
MAX_MODULES = 15  # a folder past this holds several roles (split it by role)


def test_no_module_over_the_line_limit():
    """Given every module of the four packages, generated ones included, then none is longer
    than MAX_LINES."""
    lengths = {str(path.relative_to(ROOT)): len(path.read_text().splitlines())
               for path in MODULES.values()}
    assert len(lengths) > 50, "the scan found too few modules: it is broken"
    assert {path: n for path, n in lengths.items() if n > MAX_LINES} == {}


def test_no_folder_over_the_module_limit():
    """Given every folder of the four packages, then none holds more than MAX_MODULES
    modules: the tree shows the roles."""
    counts = modules_per_folder()
    assert len(counts) > 10, "the scan found too few folders: it is broken"
    assert {folder: n for folder, n in counts.items() if n > MAX_MODULES} == {}

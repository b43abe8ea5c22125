# Two commands do everything on a fresh machine: `make demo` and `make test`.
# .venv's interpreter: the fastest build of python3's version on the machine (Debian's runs
# the flight stack 6-8 % faster than pyenv's default build; tools/fastest_python.py
# says why); `make PYTHON=/path/to/python3` chooses instead.
PYTHON ?= $(shell python3 tools/fastest_python.py 2>/dev/null || echo python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= runs/demo

.PHONY: venv demo test test-fast test-under-load bench lint clean

# Python caches compiled modules (ours, and pytest's rewritten tests) in __pycache__ folders,
# even where the environment says not to (PYTHONDONTWRITEBYTECODE): the suite starts some
# hundreds of programs, and each would otherwise compile every module it imports again.
export PYTHONDONTWRITEBYTECODE :=

venv: $(STAMP)

$(STAMP): pyproject.toml
	@py="$(PYTHON)"; echo "creating $(VENV) with $$py"; "$$py" -m venv $(VENV)
	@echo "installing into $(VENV) (log: $(VENV)/install.log)"
	@$(PY) -m pip install --upgrade pip > $(VENV)/install.log 2>&1 || (cat $(VENV)/install.log; exit 1)
	@$(PY) -m pip install -e '.[dev]' >> $(VENV)/install.log 2>&1 || (cat $(VENV)/install.log; exit 1)
	touch $(STAMP)

demo: venv
	$(VENV)/bin/gcs run config/scenarios/case1_figure8.toml --out $(OUT) --force

# More pytest workers than a 2-core machine's cores: a test that starts programs spends much
# of its time on wall-clock waits (a heartbeat, a station's re-send, a paced flight) with
# the CPU idle, and the unit tests' links and scripted vehicles wait likewise (with three
# workers the suite kept 1.55 of the two cores busy on average).
WORKERS := -n 4 --dist loadgroup
FAST_WORKERS := -n 4 --dist loadgroup

# The kernels are compiled into numba's cache (tests/kernels.py) beside mypy, before pytest
# starts: on a fresh clone that is a minute of compilation that no test's timeout counts.
test: venv
	$(VENV)/bin/ruff check .
	@$(PY) -m tests.kernels & kernels=$$!; \
	$(PY) -m mypy && $(PY) -m mypy benchmarks tools; types=$$?; \
	wait $$kernels && exit $$types
	$(PY) -m pytest -q $(WORKERS) --durations=20 tests

# tests/unit: tests/sitl and tests/docs start programs (`process`), tests/closed_loop flies
# (`slow`); a test of this tier that starts a process fails (tests/conftest.py).
test-fast: venv
	$(PY) -m pytest -q $(FAST_WORKERS) -m "not slow and not process" tests

# The whole suite twice in a row beside two busy processes at nice 19 (a shared machine).
test-under-load: venv
	$(PY) benchmarks/suite_under_load.py --times 2 --busy 2 -- $(WORKERS) tests

bench: venv
	$(PY) benchmarks/run_all.py

lint: venv
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) runs .pytest_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -prune -exec rm -rf {} +

# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# One thread per process: BLAS/OpenMP oversubscription costs throughput and
# changes floating-point summation order (bit-identical reruns need it fixed).
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export NUMBA_NUM_THREADS ?= 2
export MPLBACKEND := Agg

.PHONY: install test test-slow test-all lock demo bench meshes lint docs clean

# Installs exactly the committed lock (hashes checked), then the project itself
# without resolving anything: a fresh clone gets the versions CI tested.
$(VENV)/.installed: pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --require-hashes --no-deps -r requirements.lock
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m pip check
	touch $@

install: $(VENV)/.installed

# Test processes (pytest-xdist): most tests run on one core, so two processes use both of a 2-core machine.
# Whole test files go to one process (--dist loadfile): a module's fixtures are built once.
TEST_JOBS ?= 2
XDIST := -n $(TEST_JOBS) --dist loadfile

# The default suite: everything but the few end-to-end checks marked `slow` (minutes on 2 cores).
test: install
	$(PY) -m pytest -q $(XDIST) --durations=15 -m "not slow" tests

# Only the end-to-end checks marked `slow` (the slow end-to-end diagnoses and calibrations).
test-slow: install
	$(PY) -m pytest -q $(XDIST) --durations=25 -m slow tests

# Everything: the default suite, then the slow checks, each test run once (what CI runs).
test-all: test test-slow

# Regenerates requirements.lock from pyproject.toml (every extra, hashes, all platforms) with a
# pinned uv in a throwaway venv; tests/packaging/test_packaging.py fails while the two disagree.
UV_VERSION := 0.13.9
LOCK_CMD := uv pip compile pyproject.toml --extra dev --universal --fork-strategy fewest --python-version 3.11 --generate-hashes --index-url https://pypi.org/simple -o requirements.lock
lock:
	$(PYTHON) -m venv .lockenv
	.lockenv/bin/python -m pip install -q uv==$(UV_VERSION)
	.lockenv/bin/$(LOCK_CMD)

demo: install
	$(PY) -m service.cli demo --out demo_output

bench: install
	$(PY) -m benchmarks forward

# Lint and format check (ruff; settings in pyproject.toml).
lint: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# The documentation site (docs/, Sphinx + MyST), offline: every warning is an error, so a broken internal
# reference ({ref}, :ref:, a page missing from the toctree, an unreadable image) fails the build.
docs: install
	$(VENV)/bin/sphinx-build -q -W --keep-going -b html docs docs/_build/html

meshes: install
	$(PY) scripts/make_meshes.py

clean:
	rm -rf $(VENV) .lockenv demo_output .pytest_cache docs/_build docs/_generated

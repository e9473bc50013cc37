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

.PHONY: install test demo bench meshes clean

# Installs exactly the committed lock (hashes checked), then the project itself
# without resolving anything: a fresh clone gets the versions CI tested.
$(VENV)/.installed: pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --require-hashes --no-deps -r requirements.lock
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m pip check
	touch $@

install: $(VENV)/.installed

test: install
	$(PY) -m pytest -q --durations=15 tests

demo: install
	$(PY) -m service.cli demo --out demo_output

bench: install
	$(PY) benchmarks/bench_forward.py

meshes: install
	$(PY) scripts/make_meshes.py

clean:
	rm -rf $(VENV) demo_output .pytest_cache

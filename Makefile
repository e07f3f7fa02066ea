# grfguard: the two commands of the quick start are `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test install lint bench bench-all boundscheck clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# --no-compile: the dependencies' modules are byte-compiled when first imported, not all
# of them at install (about 17 s less install, about 4 s more on the first imports)
$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet --no-compile -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/grfguard demo --out out

# the suite in TEST_JOBS processes (pytest-xdist; CI has two cores): `make test TEST_JOBS=1`
# runs it in one
TEST_JOBS ?= 2

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist worksteal

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

# Speed benchmarks (not part of `make test`): pinned to one core when taskset exists; each
# script rewrites its own BENCHMARKS.md section with machine information and the ratios to
# the plain references timed in the same run. `make bench-all` runs every benchmark.
BENCH_SPEED ?= benchmarks/bench_kernels.py benchmarks/bench_compiled_monitor.py \
	benchmarks/bench_run_cli.py benchmarks/bench_sim.py
PIN := $(shell command -v taskset >/dev/null 2>&1 && echo "taskset -c 1")

bench: $(STAMP)
	@for b in $(BENCH_SPEED); do echo "== $$b"; $(PIN) $(BIN)/python $$b --write || exit 1; done

bench-all: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

# every kernel compiled again with numba's bounds checks and run through its array-size
# paths (about three minutes of CPU, 1 min 49 s wall on two cores; `make test` runs it too:
# tests/test_boundscheck.py)
boundscheck: $(STAMP)
	$(BIN)/python benchmarks/check_bounds.py

clean:
	rm -rf $(VENV) out

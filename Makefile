# Two commands a new user needs: `make figures` and `make test`.
# Both create .venv from the pinned lock files if it is missing (Python 3.11 required):
# requirements.lock (runtime) and requirements-dev.lock (test and lint tools), both generated
# by pip-compile from requirements.in and requirements-dev.in (`make lock`).
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.dtwin-installed

PIP_VERSION := 26.3
PIP_TOOLS_VERSION := 7.6.2

.PHONY: figures test test-fast check fuzz lint report bench clean-results venv lock emps

venv: $(STAMP)

# The last step compiles the EM kernels, the gap diagnoser's force loop, the twin's RK4 loop
# (dtwin/twin/_kernels.py) and the loops that drive an FMU (dtwin/twin/_fmu_kernels.py, about
# 20 s) once into numba's on-disk cache (the __pycache__ beside each file), so no job pays the
# compilation; it reruns when they change.
# Meanwhile compileall byte-compiles the packages on every core (-j 0); pip would do it one file
# at a time (--no-compile: three quarters of pip's CPU time), before the kernels could start.
# It skips the packages' own test folders (-x), which nothing here imports: 3194 of 9053 files,
# 33.0 -> 19.3 CPU s.
$(STAMP): requirements.lock requirements-dev.lock pyproject.toml dtwin/_em_kernels.py dtwin/twin/_force_kernels.py dtwin/twin/_kernels.py dtwin/twin/_fmu_kernels.py dtwin/monitor/_stream_kernels.py
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found; install Python 3.11 or run 'make PYTHON=/path/to/python3.11'"; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet "pip==$(PIP_VERSION)"
	$(BIN)/python -m pip install --quiet --no-compile -r requirements.lock -r requirements-dev.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	$(BIN)/python -c "from dtwin import _em_kernels; from dtwin.twin import _force_kernels, _fmu_kernels, _kernels; from dtwin.monitor import _stream_kernels; _em_kernels.warm_up(); _force_kernels.warm_up(); _kernels.warm_up(); _fmu_kernels.warm_up(); _stream_kernels.warm_up()" & \
	$(BIN)/python -m compileall -q -j 0 -x '/tests?/' "$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" && wait $$!
	touch $(STAMP)

figures: $(STAMP)
	$(BIN)/snakemake --cores 2

# The tests run on PYTEST_WORKERS pytest-xdist workers, each file's tests on one worker in file order
# (tests/conftest.py starts the longest file first); `make test PYTEST_WORKERS=0` runs them in one
# process. By hand: `pytest -n 2 --dist loadfile --no-loadscope-reorder`.
PYTEST_WORKERS ?= 2
PARALLEL = -n $(PYTEST_WORKERS) --dist loadfile --no-loadscope-reorder
# Byte-compiles dtwin/ first (a no-op when current): Python reads __pycache__ even where
# PYTHONDONTWRITEBYTECODE forbids writing it, and would otherwise compile the package from source
# in every worker and every interpreter a test starts (about 1.2 CPU s per worker).
COMPILE = $(BIN)/python -m compileall -q dtwin

# The full suite (CI runs this through .ci/run): `make lint`, then the unit tests, the
# doctests of dtwin/ and the workflow tests that run Snakemake in a subprocess (marked slow).
test: lint
	$(COMPILE)
	$(BIN)/python -m pytest $(PARALLEL)

# For daily work (target: under a minute): `make lint` and the tests without the slow workflow
# tests. `make check` is the same. CI runs `make test`.
test-fast: lint
	$(COMPILE)
	$(BIN)/python -m pytest $(PARALLEL) -m "not slow"

check: test-fast

report: figures
	$(BIN)/snakemake --report paper_figures/report.html

# Every benchmark section, or some: `make bench SECTIONS="dag imports"` (benchmarks/run.py).
bench: $(STAMP)
	$(BIN)/python benchmarks/run.py $(SECTIONS)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/snakemake --lint

# Regenerate the lock files after editing requirements*.in (needs the package registry).
# Existing pins are kept unless the .in files demand otherwise; upgrade on purpose with
# `make lock PIP_COMPILE_ARGS=--upgrade`.
lock:
	test -x .lock-tools/bin/pip-compile || { $(PYTHON) -m venv .lock-tools && .lock-tools/bin/python -m pip install --quiet "pip-tools==$(PIP_TOOLS_VERSION)"; }
	.lock-tools/bin/pip-compile --quiet --no-header --allow-unsafe --strip-extras --no-emit-index-url --no-emit-find-links --no-annotate $(PIP_COMPILE_ARGS) requirements.in -o requirements.lock
	.lock-tools/bin/pip-compile --quiet --no-header --allow-unsafe --strip-extras --no-emit-index-url --no-emit-find-links --no-annotate $(PIP_COMPILE_ARGS) requirements-dev.in -o requirements-dev.lock

# The measured EMPS axis (docs/gap.md §Example: EMPS): fit on the estimation experiment, score on the
# validation experiment with pulses. The data are not in the repository (docs/gap.md says where to get them).
EMPS_DIR ?= ../shared/realdata/emps
emps: $(STAMP)
	@test -f $(EMPS_DIR)/recording_train.csv || { echo "EMPS data not found in $(EMPS_DIR): download it from https://www.nonlinearbenchmark.org (see docs/gap.md, Example: EMPS) or pass EMPS_DIR=..."; exit 1; }
	$(BIN)/dtwin diagnose $(EMPS_DIR)/recording_train.csv --twin $(EMPS_DIR)/twin.yaml --heldout $(EMPS_DIR)/recording_pulses.csv --out results/emps

clean-results:
	rm -rf results logs benchmarks/rules paper_figures/*.png paper_figures/*.pdf paper_figures/*.json

# Property tests with fresh randomness and FUZZ_FACTOR (tests/conftest.py) times the examples.
fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -p no:cacheprovider --hypothesis-show-statistics tests/bad_input/test_malformed_inputs.py tests/bad_input/test_deep_fuzz.py

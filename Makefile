# Two commands do all the set-up (a virtualenv in .venv, installed on first use):
#   make demo   - the demonstration of the whole loop on the built-in robot
#   make test   - the test suite
#   make docs   - build the documentation site into site/ (mkdocs build --strict)
# The virtualenv is installed from requirements.lock: the exact versions (and hashes) of every
# package of the [all] extra that the tests last passed with; the project itself goes in after it
# with --no-deps. After a change to the dependencies in pyproject.toml:
#   make lock   - regenerate requirements.lock (keeps the current pins where it can; to move
#                 everything to the newest allowed versions: make lock LOCK_ARGS=--upgrade)
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

LOCK := requirements.lock
LOCK_ARGS ?=

.PHONY: demo test lint docs bench install lock kernels

# torch in the lock is the CPU build, torch==2.13.0+cpu, from the local wheel in /opt/wheels (the
# --find-links line and the hash in the lock are that file's): any other torch spec pulls several
# GB of CUDA packages. The setuptools of the lock builds the editable install (no build isolation).
$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --require-hashes -r $(LOCK)
	$(BIN)/pip install --quiet --no-deps --no-build-isolation -e .
	$(MAKE) --no-print-directory kernels
	touch $(STAMP)

install: $(STAMP)

# Compile the numba kernels into their cache (__pycache__ beside each module) once, with two short simulations (fused
# attitude with slosh; a noise-free attitude, whose channel fits the encoders' noise propagated), their diagnoses and a
# short arm simulation: otherwise the first run compiles them, in each test worker at once (about 170 s of a cold test
# run on 2 cores). A kernel whose module changes is compiled again on use.
# It runs in the virtualenv's install (a plain `make kernels` needs the virtualenv there already).
kernels:
	@tmp=$$(mktemp -d) && trap 'rm -rf "$$tmp"' EXIT && echo "make: compiling the numba kernels (about 2 minutes)" && \
	$(BIN)/spaceid simulate --duration 8 --attitude fused --hidden-effects slosh --out "$$tmp/log" > /dev/null && \
	$(BIN)/spaceid diagnose --robot paper6 --log "$$tmp/log/log.csv" --params fuel --out "$$tmp/diagnosis" > /dev/null && \
	$(BIN)/spaceid simulate --duration 8 --attitude exact --out "$$tmp/exact" > /dev/null && \
	$(BIN)/spaceid diagnose --robot paper6 --log "$$tmp/exact/log.csv" --params fuel --out "$$tmp/exact-diagnosis" > /dev/null && \
	$(BIN)/spaceid arm simulate --duration 2 --out "$$tmp/arm" > /dev/null

# Python 3.11; the project itself is left out of the lock (--unsafe-package), pip and setuptools are pinned
lock: $(STAMP)
	CUSTOM_COMPILE_COMMAND="make lock" $(BIN)/pip-compile --quiet --extra=all --strip-extras \
	  --generate-hashes --no-allow-unsafe --unsafe-package=spaceid-gym --no-emit-index-url \
	  $(LOCK_ARGS) --output-file=$(LOCK) pyproject.toml
	@! grep -iE '^(nvidia|cuda|triton)' $(LOCK) || { echo "make lock: CUDA packages in $(LOCK)"; exit 1; }
	@grep -q '^torch==2.13.0+cpu ' $(LOCK) || { echo "make lock: torch is not the local CPU build"; exit 1; }

demo: $(STAMP)
	$(BIN)/spaceid demo --out demo-output

# pytest's exit code 5 ("no tests collected") is a failure here
# on every core (pytest-xdist), a test file per worker so that each file's shared fixtures are built once
test: $(STAMP)
	@$(BIN)/python -m pytest -n auto --dist loadfile; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests"; exit 1; fi; exit $$rc

# lint-imports: the import contract of pyproject.toml (layers top -> identification -> core, no cycles; see
# docs/architecture.md); tests/test_import_structure.py checks the rest (no import inside a function)
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports --no-cache --no-logo

# the documentation site (docs/, mkdocs.yml) into site/; --strict: a broken link, anchor or API reference fails
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/env_steps.py
	$(BIN)/python benchmarks/physics_checks.py
	$(BIN)/python benchmarks/objective_throughput.py
	$(BIN)/python benchmarks/fit_time.py

# Two commands do all the set-up (a virtualenv in .venv, installed on first use):
#   make demo   - the demonstration of the whole loop on the built-in robot
#   make test   - the test suite
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench install

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	# the CPU build of torch first: any other torch spec pulls several GB of CUDA packages
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[all]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/spaceid demo --out demo-output

# pytest's exit code 5 ("no tests collected") is a failure here
test: $(STAMP)
	@$(BIN)/python -m pytest; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests"; exit 1; fi; exit $$rc

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)
	$(BIN)/python benchmarks/env_steps.py
	$(BIN)/python benchmarks/physics_checks.py
	$(BIN)/python benchmarks/objective_throughput.py
	$(BIN)/python benchmarks/fit_time.py

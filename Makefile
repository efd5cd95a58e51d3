# mudoe developer and user entry points. Run `make setup` once, then `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
# tiny dense matrices everywhere: BLAS threads only add contention
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: setup test test-repeat test-slow-clock bench identify oed detect report validate clean

setup:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -e ".[test]"

# the layer contract in pyproject.toml ([tool.importlinter]) first, then the tests
test:
	$(BIN)/lint-imports --no-cache
	$(BIN)/python -m pytest -q

# the suite N times in this checkout, one line a run (issue 27); fresh clones, two suites at once and random
# order: python bench/repeat_suite.py --help
N ?= 5
test-repeat:
	$(BIN)/python bench/repeat_suite.py --runs $(N)

# this process's clocks 8x fast: a test whose result depends on the machine's speed fails at once
test-slow-clock:
	MUDOE_TEST_SLOW_CLOCK=8 $(BIN)/python -m pytest -q

bench:
	$(BIN)/python -m bench

# the study commands: thin calls of the CLI on the default study (outputs in results/)
identify:
	$(BIN)/mudoe identify configs/press.toml

oed:
	$(BIN)/mudoe oed configs/press.toml

detect:
	$(BIN)/mudoe detect configs/press.toml

report:
	$(BIN)/mudoe report configs/press.toml

validate:
	$(BIN)/mudoe validate configs/press.toml

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache results

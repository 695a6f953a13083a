# Two commands do all the set-up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3.11
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test lint format bench soak clean venv

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	$(BIN)/hli-server run $(ARGS)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy schemas hli_server/engine
	$(BIN)/lint-imports

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

test: $(STAMP) lint
	$(BIN)/python -m pytest $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/python -m benchmarks $(ARGS)

# The fuzz tests of the suite (marker `fuzz`), long: SOAK_SCALE times their examples, a new seed each
# run unless HLI_FUZZ_SEED is given (docs/reliability.md, "NC programs and configuration").
SOAK_SCALE ?= 100
soak: $(STAMP)
	@seed=$${HLI_FUZZ_SEED:-$$(date +%s)}; echo "soak: HLI_FUZZ_SCALE=$(SOAK_SCALE) HLI_FUZZ_SEED=$$seed"; \
	HLI_FUZZ_SCALE=$(SOAK_SCALE) HLI_FUZZ_SEED=$$seed $(BIN)/python -m pytest -m fuzz -p no:cacheprovider \
		--timeout=0 --durations=0 -q -rP $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache build *.egg-info

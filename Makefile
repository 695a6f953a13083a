# Two commands do all the set-up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3.11
VENV   ?= .venv
BIN    := $(VENV)/bin
RUNTIME_STAMP := $(VENV)/.installed-runtime
TEST_STAMP    := $(VENV)/.installed-test

.PHONY: run test test-fast lint format bench soak clean venv compile node-deps

$(BIN)/python:
	@$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# `make run` needs only the runtime dependencies. The install compiles the engine (setup.py), or copies it
# from the build cache where these engine sources were compiled before (~/.cache/hli-server/engine)
$(RUNTIME_STAMP): pyproject.toml setup.py | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $(RUNTIME_STAMP)

# tests, lint and benchmarks need the test and lint tool chain too: the test extras alone, on top of the
# runtime's install (`pip install -e '.[test]'` would build the package again, issue 37)
TEST_REQUIREMENTS := $(VENV)/test-requirements.txt
$(TEST_STAMP): $(RUNTIME_STAMP)
	$(BIN)/python -c 'import tomllib; print("\n".join(tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["test"]))' > $(TEST_REQUIREMENTS)
	$(BIN)/python -m pip install --quiet -r $(TEST_REQUIREMENTS)
	@touch $(TEST_STAMP)

venv: $(TEST_STAMP)

# Node's ads-client, the second ADS client of tests/interop (H-04): installed with the lock file's versions
# when npm is there; without it the interop tests skip and say why
NODE_DIR   := tests/interop/node
NODE_STAMP := $(NODE_DIR)/node_modules/.package-lock.json
$(NODE_STAMP): $(NODE_DIR)/package-lock.json
	@if command -v npm >/dev/null 2>&1; then \
		(cd $(NODE_DIR) && npm ci --no-audit --no-fund --loglevel=error) \
			|| echo "warning: npm ci in $(NODE_DIR) failed: the ads-client interop tests will be skipped"; \
	else \
		echo "note: npm not found: the ads-client interop tests (tests/interop) will be skipped"; \
	fi

node-deps: $(NODE_STAMP)

# rebuild the compiled engine (and the ADS request path) after editing it (an edited source runs as pure
# Python until then: hli_server/_compiled.py says so once; sources compiled before come from the build
# cache, setup.py); HLI_PURE_PYTHON=1 make compile removes the compiled modules
compile: $(TEST_STAMP)
	find hli_server/engine hli_server/adapters/ads -name '*.so' -delete
	rm -rf build *__mypyc*.so
	$(BIN)/python -m pip install --quiet --no-deps -e .

run: $(RUNTIME_STAMP)
	$(BIN)/hli-server run $(ARGS)

lint: $(TEST_STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports

format: $(TEST_STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# the suite on one worker per core (pytest-xdist): every test binds port 0 and names its own shared
# memory, so workers never meet. (A worker more than cores gave 4 min 0 s - 4 min 40 s on 2 cores instead
# of 5 min 0 s, but the clock's realtime bounds of the attack tests then failed now and then: the cores
# oversubscribed, docs/performance.md.) --maxschedchunk 2: a worker takes two tests at a time, in the order
# tests/conftest.py gives (modules with slow tests first), so the long ones spread over every worker
# (xdist's default hands each worker a quarter of its share at once: one worker got every slow module
# and ran 700 s while the other idled). Bytecode is written even where the environment says not to
# (PYTHONDONTWRITEBYTECODE): else every worker rewrites every test module's assertions (11 s instead of
# 3) and every server a test starts compiles our sources again (1.7 s to its banner instead of 1.1).
PYTEST := PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest
XDIST ?= -n auto --maxschedchunk 2
test: $(TEST_STAMP) node-deps lint
	$(PYTEST) $(XDIST) $(PYTEST_ARGS)

# the edit-test loop: no lint, no test marked `slow` (subprocess servers, xdist, long property runs)
test-fast: $(TEST_STAMP) node-deps
	$(PYTEST) -m "not slow" $(PYTEST_ARGS)

bench: $(TEST_STAMP)
	$(BIN)/python -m benchmarks $(ARGS)

# The fuzz tests of the suite (marker `fuzz`), long: SOAK_SCALE times their examples, a new seed each
# run unless HLI_FUZZ_SEED is given (docs/reliability.md, "NC programs and configuration"); among them the
# slow-client and large-read attacks on a realtime server, SOAK_SCALE x 3 s (at most 5 minutes; issue 27).
SOAK_SCALE ?= 100
soak: $(TEST_STAMP)
	@seed=$${HLI_FUZZ_SEED:-$$(date +%s)}; echo "soak: HLI_FUZZ_SCALE=$(SOAK_SCALE) HLI_FUZZ_SEED=$$seed"; \
	HLI_FUZZ_SCALE=$(SOAK_SCALE) HLI_FUZZ_SEED=$$seed HLI_HYPOTHESIS_PROFILE=explore $(PYTEST) -m fuzz -p no:cacheprovider \
		--timeout=0 --durations=0 -q -rP $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache build *.egg-info *__mypyc*.so
	find hli_server/engine hli_server/adapters/ads -name '*.so' -delete

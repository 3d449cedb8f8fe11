# The two commands of the README: `make demo` and `make test`. Both build .venv/ first.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The packages `make typecheck` (and so `make test`) checks with mypy --strict (config: pyproject.toml).
TYPED  := ema_sim/models ema_sim/signals ema_sim/environment ema_sim/identify ema_sim/io ema_sim/analysis ema_sim/montecarlo

.PHONY: venv test test-slow lint typecheck demo bench clean

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	$(BIN)/python -m ema_sim.warmup
	touch $@

lint: $(STAMP)
	$(BIN)/ruff check .

typecheck: $(STAMP)
	$(BIN)/mypy $(TYPED)

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy $(TYPED)
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup -m "not slow"

# The long end-to-end runs (pytest marker `slow`: identification on HOAD3 records, minutes each).
test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup -m slow

demo: $(STAMP)
	$(BIN)/python -m ema_sim.demo

bench: $(STAMP)
	$(BIN)/ema bench

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache

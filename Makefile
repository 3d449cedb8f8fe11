# The two commands of the README: `make demo` and `make test`. Both build .venv/ first.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The packages `make typecheck` (and so `make test`) checks with mypy --strict (config: pyproject.toml).
TYPED  := ema_sim/models ema_sim/signals ema_sim/environment ema_sim/identify ema_sim/io ema_sim/analysis ema_sim/montecarlo ema_sim/export \
          ema_msgs_py ema_sim/ail ema_sim/commands ema_sim/run.py ema_sim/suite.py ema_sim/launching.py ema_sim/demo.py ema_sim/cli.py \
          ema_sim/nodes ema_sim/emac ema_sim/faults ema_sim/monitor

.PHONY: venv test test-slow lint typecheck demo bench bench-check docs clean

venv: $(STAMP)

# Bytecode is compiled at set-up, the packages' and our own, on every core (pip compiles on one: 47 s against
# 24 + 16 s): where PYTHONDONTWRITEBYTECODE is set (this machine's image), every process the tests start (ROS
# nodes, CLI runs, Dask workers) would otherwise compile from source what it imports (pytest 7:06 → 8:23 measured).
# Left out: what no process here imports (the packages' own test suites, pip, setuptools, mypyc), a third of the
# sources (compileall 26.7 → 16.5 CPU-s measured).
$(STAMP): requirements.txt setup.py setup.cfg
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --no-compile -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	$(BIN)/python -m compileall -q -j 0 -x '/(tests|pip|setuptools|mypyc)/' $(VENV)/lib ema_sim ema_msgs_py
	$(BIN)/python -m ema_sim.warmup
	touch $@

lint: $(STAMP)
	$(BIN)/ruff check .

typecheck: $(STAMP)
	$(BIN)/mypy $(TYPED)

# Two pytest workers fill the two cores, so each runs numba's parallel kernels on one thread: a second
# thread per worker oversubscribes the cores (measured: the fuzz records' tests 55.7 s → 44.4 s).
# mypy runs beside pytest (one process in the gaps the ROS tests leave while they wait); either failing fails.
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy $(TYPED) > $(VENV)/mypy.log 2>&1 & mypy=$$!; \
	NUMBA_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadgroup -m "not slow"; status=$$?; \
	wait $$mypy || { cat $(VENV)/mypy.log; status=1; }; tail -n 1 $(VENV)/mypy.log; exit $$status

# The long end-to-end runs (pytest marker `slow`: identification on HOAD3 records, minutes each).
test-slow: $(STAMP)
	NUMBA_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadgroup -m slow

demo: $(STAMP)
	$(BIN)/python -m ema_sim.demo

bench: $(STAMP)
	$(BIN)/ema bench

# Instruction counts of the kernels under callgrind against bench/baseline.json (fails at +5 %).
bench-check: $(STAMP)
	$(BIN)/python bench/callgrind.py check

# The documentation site (mkdocs.yml, docs/): --strict fails on a broken link or anchor, or a page left out of the nav.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir build/site

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache

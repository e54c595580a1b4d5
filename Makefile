# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
SOURCES := spacecraft_conventions spacecraft_env identifiers controllers spacecraft_lab tests benchmarks examples

PEERS_VENV  ?= .venv-peers
PEERS_STAMP := $(PEERS_VENV)/.installed

.PHONY: demo docs test test-all test-peers lint bench bench-peers results results-short clean

# the demo needs the main dependencies only; the tests add the RL and dev extras
MAIN_STAMP := $(VENV)/.installed-main

$(MAIN_STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip
	$(BIN)/pip install -c constraints.txt -e .
	touch $(MAIN_STAMP)

$(STAMP): $(MAIN_STAMP)
	# torch first and explicitly, so no resolver ever reaches for a CUDA build
	$(BIN)/pip install -c constraints.txt "torch==2.13.0"
	$(BIN)/pip install -c constraints.txt -e ".[rl,dev,docs]"
	touch $(STAMP)

# the peers live in their own environment: they are large and pin their own stacks
$(PEERS_STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(PEERS_VENV)
	$(PEERS_VENV)/bin/pip install --upgrade pip
	$(PEERS_VENV)/bin/pip install -c constraints.txt -e ".[peers]" pytest
	touch $(PEERS_STAMP)

# each stage prints its wall time
demo: $(MAIN_STAMP)
	@start=$$(date +%s); $(BIN)/spacecraft demo --scenario docking --out results/demo; \
	echo "[demo stage: $$(( $$(date +%s) - start )) s]"
	@start=$$(date +%s); \
	$(BIN)/spacecraft control --scenario paddle_rotation --seeds 3 --out results/control; \
	echo "[control stage: $$(( $$(date +%s) - start )) s]"

# the API reference from the numpydoc docstrings (pdoc), into build/api; it needs the main
# install and pdoc only (the RL extras are imported lazily), its landing page is docs/api/
docs: $(MAIN_STAMP)
	$(BIN)/pip install -q -c constraints.txt -e ".[docs]"
	$(BIN)/python -W error -m pdoc -d numpy -t docs/api -o build/api spacecraft_conventions \
	    spacecraft_env identifiers controllers spacecraft_lab

# the suite on every core (pytest-xdist), at most four workers: its own tests start
# process pools of their own
PYTEST_WORKERS := -n auto --maxprocesses=4

test: $(STAMP)
	$(BIN)/ruff check $(SOURCES)
	$(BIN)/pytest -q $(PYTEST_WORKERS)

test-all: $(STAMP)
	$(BIN)/pytest -q -m "" $(PYTEST_WORKERS)

test-peers: $(PEERS_STAMP)
	$(PEERS_VENV)/bin/pytest -q -p no:randomly -m slow tests/identifiers/test_peers.py

bench-peers: $(PEERS_STAMP)
	$(PEERS_VENV)/bin/python benchmarks/bench_peers.py

# the results pages' tables, each written by the command printed above it
# (spacecraft_lab/results_pages.py): `results` runs every command (hours) and writes the
# pages; `results-short` renders them again from the data kept in docs/results/data
results: $(STAMP)
	$(BIN)/python -m spacecraft_lab.results_pages --run

results-short: $(STAMP)
	$(BIN)/python -m spacecraft_lab.results_pages

lint: $(STAMP)
	$(BIN)/ruff check $(SOURCES)

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_env.py
	$(BIN)/python benchmarks/bench_identifiers.py
	$(BIN)/python benchmarks/bench_identifier_parts.py
	$(BIN)/python benchmarks/bench_control.py
	$(BIN)/python benchmarks/bench_scheduled_fit.py
	$(BIN)/python benchmarks/bench_sweep.py
	$(BIN)/python benchmarks/bench_threads.py
	$(BIN)/python benchmarks/bench_workers.py

clean:
	rm -rf $(VENV) $(PEERS_VENV) results build *.egg-info

# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
SOURCES := spacecraft_conventions spacecraft_env identifiers controllers spacecraft_lab tests benchmarks examples

.PHONY: demo test test-all lint bench clean

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip
	# torch first and explicitly, so no resolver ever reaches for a CUDA build
	$(BIN)/pip install -c constraints.txt "torch==2.13.0"
	$(BIN)/pip install -c constraints.txt -e ".[rl,dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/spacecraft demo --scenario docking --out results/demo
	OPENBLAS_NUM_THREADS=1 $(BIN)/spacecraft control --scenario docking --seeds 10 --out results/control

test: $(STAMP)
	$(BIN)/ruff check $(SOURCES)
	$(BIN)/pytest -q

test-all: $(STAMP)
	$(BIN)/pytest -q -m ""

lint: $(STAMP)
	$(BIN)/ruff check $(SOURCES)

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_env.py
	$(BIN)/python benchmarks/bench_identifiers.py
	$(BIN)/python benchmarks/bench_control.py
	$(BIN)/python benchmarks/bench_sweep.py
	$(BIN)/python benchmarks/bench_threads.py

clean:
	rm -rf $(VENV) results build *.egg-info

# kinecal: `make demo` and `make test` set everything up from a fresh clone.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# Python trees checked by ruff (only those present in this checkout).
PYDIRS := $(wildcard src tests benchmarks examples)

.PHONY: demo test test-slow lint bench examples clean format docs

# One BLAS thread per test process: pytest runs one worker per core, and BLAS threads on
# top only oversubscribe them (the suite took 142 s with two, 100 s with one, on 2 cores).
test test-slow: export OPENBLAS_NUM_THREADS ?= 1
# The suite starts ~160 Python processes (the CLI as a user runs it), the benchmarks and
# the demo more: with byte-code caches each imports kinecal 0.13-0.3 s faster, and pytest
# keeps its rewritten test modules (3 s per worker). An empty value turns off a
# PYTHONDONTWRITEBYTECODE set outside (this VM sets it).
demo test test-slow bench examples: export PYTHONDONTWRITEBYTECODE =

# The compiled model kernel is built by the install (setup.py; optional: skipped without a
# C compiler), so a change to its source reinstalls.
$(STAMP): pyproject.toml setup.py src/kinecal/models/_ckernel.c
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "kinecal needs Python >= 3.11"'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[all,dev,reference,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/kinecal demo --out demo-results --force

lint: $(STAMP)
	$(BIN)/ruff check $(PYDIRS)
	$(BIN)/ruff format --check $(PYDIRS)
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -q -n auto -m "not slow" --dist loadgroup

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -n auto -m slow --dist loadgroup

# The documentation site (Sphinx; pages in docs/, the API reference from the docstrings),
# built from scratch with warnings as errors: docs/_build/html/index.html.
docs: $(STAMP)
	rm -rf docs/_build
	$(BIN)/python -m sphinx -b html -W --keep-going -q docs docs/_build/html

bench: $(STAMP)
	$(BIN)/python -m benchmarks --out benchmarks/results.json

examples: $(STAMP)
	$(BIN)/python examples/ur10_mocap.py
	$(BIN)/python examples/franka_fr3_camera.py

format: $(STAMP)
	$(BIN)/ruff format $(PYDIRS)
	$(BIN)/ruff check --fix $(PYDIRS)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache demo-results examples/out docs/_build

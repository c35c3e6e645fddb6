# Two entry points do all set-up on a fresh machine: `make demo` and `make test`.
# Both create .venv on first use and install the project with its dependencies.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
PYTEST  := $(BIN)/python -m pytest

.PHONY: demo test test-all lint bench clean-venv

$(STAMP): pyproject.toml Makefile
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# CPU build of torch that lies on disk; any other spec would download a CUDA build.
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python scripts/demo.py

test: $(STAMP)
	$(PYTEST) -m "not slow" -q

test-all: $(STAMP)
	$(PYTEST) -q

lint: $(STAMP)
	$(BIN)/ruff check afmlearn simulator scripts tests benchmarks

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean-venv:
	rm -rf $(VENV)

# calibctl — two commands on a fresh machine: `make demo` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
PYTEST_WORKERS ?= 2

.DEFAULT_GOAL := help

help: ## list the targets
	@grep -hE '^[a-z][a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP) ## create .venv and install calibctl with its dev tools

demo: $(STAMP) ## render a synthetic board session and run the main job on the embedded SQLite store
	$(VENV)/bin/calibctl demo

test: $(STAMP) ## run the test suite (SQLite and the local PostgreSQL), without the slow marker
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) -m "not slow"

test-slow: $(STAMP) ## run only the slow full-resolution / many-session tests (installs chromium when missing)
	command -v chromium >/dev/null || (apt-get update && apt-get install -y chromium) || \
		(sudo apt-get update && sudo apt-get install -y chromium)
	$(PY) -m pytest -q -m slow

lint: $(STAMP) ## ruff, mypy and the import-layer contract
	$(VENV)/bin/ruff check calibctl tests benchmarks
	$(VENV)/bin/mypy calibctl
	$(VENV)/bin/lint-imports

schemas: $(STAMP) ## regenerate schemas/ from the pydantic artifact models
	$(PY) -m calibctl.artifacts.schema_export schemas

bench: $(STAMP) ## run the benchmarks (writes benchmarks/out/, numbers go into BENCHMARKS.md by hand)
	$(PY) benchmarks/run_all.py

clean: ## remove the virtualenv and caches
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache

.PHONY: help install demo test test-slow lint schemas bench clean

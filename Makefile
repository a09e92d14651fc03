# calibctl — two commands on a fresh machine: `make demo` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
PYTEST_WORKERS ?= 2
FLOOR_VENV ?= .venv-floor
FLOOR_STAMP := $(FLOOR_VENV)/.installed-stamp
# Everything: both extras (PostgreSQL, plots) and the dev tools, at the versions in the lock file.
EXTRAS := .[dev,postgres,plots,bags]

.DEFAULT_GOAL := help

help: ## list the targets
	@grep -hE '^[a-z][a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml constraints/lock.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints/lock.txt -e '$(EXTRAS)'
	touch $(STAMP)

$(FLOOR_STAMP): pyproject.toml constraints/floor.txt
	rm -rf $(FLOOR_VENV)
	$(PYTHON) -m venv $(FLOOR_VENV)
	$(FLOOR_VENV)/bin/python -m pip install --quiet -c constraints/floor.txt -e '$(EXTRAS)'
	touch $(FLOOR_STAMP)

install: $(STAMP) ## create .venv: calibctl, both extras and the dev tools at the versions in constraints/lock.txt

demo: $(STAMP) ## render a synthetic board session and run the main job on the embedded SQLite store
	$(VENV)/bin/calibctl demo

test: $(STAMP) ## run the test suite (SQLite and the local PostgreSQL), without the slow marker
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) -m "not slow"

# What the floor versions (constraints/floor.txt) can break, and only that. A workflow or CLI test above
# these layers reaches numpy, OpenCV, pydantic, SQLAlchemy, PyYAML, typer and rich through the code these
# tests hold, so re-running it on the floor proves little more; the whole fast suite again took 16.8 of CI's
# 54 min on the 2-core host. Kept: the numerics and the detector (tests/core: numpy, OpenCV 4.10), SQL,
# migrations and the chain (tests/store: SQLAlchemy, alembic, psycopg), the documents and their hashes
# (tests/artifacts, tests/test_*.py: pydantic, rfc8785, cryptography, PyYAML), the exports and the parsers
# of what is exported or linted (tests/workflows/exports and lint, the lint/export CLI tests:
# cv2.FileStorage, PyYAML), and the CLI's own machinery (tests/cli/app: registry, help, defaults, plain
# text, start-up imports, extras: typer, rich, pydantic's plugin scan).
FLOOR_TESTS := tests/core tests/store tests/artifacts tests/test_*.py \
	tests/workflows/exports tests/workflows/lint tests/cli/records/test_lint_cli.py \
	tests/cli/records/test_export_lint.py tests/cli/app/test_cli_registry.py tests/cli/app/test_cli_habits.py \
	tests/cli/app/test_cli_defaults.py tests/cli/app/test_plain_text.py tests/cli/app/test_startup_imports.py \
	tests/cli/app/test_extras_cli.py

test-floor: $(FLOOR_STAMP) ## the tests the oldest allowed versions can break, on them (constraints/floor.txt)
	$(FLOOR_VENV)/bin/python -m pytest -q -n $(PYTEST_WORKERS) -m "not slow" -p no:cacheprovider $(FLOOR_TESTS)

# --dist loadscope: one module's tests on one worker, so a module fixture (the wheel's venv) is built once.
test-slow: $(STAMP) ## run only the slow full-resolution / many-session tests (installs chromium when missing)
	command -v chromium >/dev/null || (apt-get update && apt-get install -y chromium) || \
		(sudo apt-get update && sudo apt-get install -y chromium)
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadscope -m slow

CONSUMER_DEBS = python3-camera-calibration-parsers python3-image-geometry python3-mrcal python3-opencv liburdfdom-tools

test-consumers: $(STAMP) ## the robot bundle read by ROS camera_calibration_parsers, image_geometry, mrcal, check_urdf (installs them)
	/usr/bin/python3 -c 'import camera_calibration_parsers, image_geometry, mrcal, cv2' 2>/dev/null && command -v check_urdf >/dev/null || \
		(apt-get update && apt-get install -y $(CONSUMER_DEBS)) || (sudo apt-get update && sudo apt-get install -y $(CONSUMER_DEBS))
	$(PY) -m pytest -q -rs tests/workflows/exports/test_rig_bundle_consumers.py

lint: $(STAMP) ## ruff, mypy and the import-layer contract
	$(VENV)/bin/ruff check calibctl tests benchmarks
	$(VENV)/bin/ruff format --check calibctl tests benchmarks migrations
	$(VENV)/bin/mypy calibctl
	$(VENV)/bin/lint-imports

schemas: $(STAMP) ## regenerate schemas/ from the pydantic artifact models
	$(PY) -m calibctl.artifacts.schema_export schemas

wheel: $(STAMP) ## build dist/calibctl-*.whl (install it with pipx or uv tool install; see README)
	$(PY) -m pip wheel --quiet --no-deps -w dist .

bench: $(STAMP) ## run the benchmarks (writes benchmarks/out/, numbers go into BENCHMARKS.md by hand)
	$(PY) benchmarks/run_all.py

clean: ## remove the virtualenv and caches
	rm -rf $(VENV) $(FLOOR_VENV) .pytest_cache .mypy_cache .ruff_cache

.PHONY: help install demo test test-floor test-slow test-consumers lint schemas wheel bench clean

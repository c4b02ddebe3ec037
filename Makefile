# adaptune — two commands on a fresh machine: `make repro` and `make test`.
VENV ?= .venv
PY := $(VENV)/bin/python
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup test lint bench repro clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	@$(PY) -c "import open3d" >/dev/null 2>&1 || bash .ci/install-system-deps
	@$(PY) -c "import open3d" >/dev/null
	touch $(STAMP)

test: setup
	$(BIN)/pytest -q

lint: setup
	$(BIN)/ruff check pipeline stages schemas tests bench
	$(BIN)/mypy pipeline stages

bench: setup
	$(PY) bench/run.py

# dvc runs the stages' `adaptune ...` commands: the venv's bin must be on PATH
repro: setup
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/dvc repro

clean:
	rm -rf $(VENV) .pytest_cache

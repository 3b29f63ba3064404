# Set-up and entry points. `make reproduce` and `make test` each do the whole set-up on a fresh machine.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup reproduce test lint smoke benchmarks mlflow-ui clean-venv

$(STAMP): requirements.txt pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -r requirements.txt
	$(BIN)/pip install --quiet --no-deps -e .
	touch $(STAMP)

setup: $(STAMP)  ## create .venv and install the pinned dependencies

reproduce: setup  ## run the whole pipeline with params.yaml
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/dvc repro

test: setup  ## unit tests and a smoke run of the whole DAG on tiny params
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python -m pytest -q; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "error: pytest collected no tests (exit code 5)" >&2; fi; exit $$rc

lint: setup
	$(BIN)/ruff check lfdt stages tests benchmarks

benchmarks: setup  ## throughput ratios (numbers go into the README)
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/collect_throughput.py

mlflow-ui: setup  ## browse every run at http://127.0.0.1:5000
	$(BIN)/mlflow ui --backend-store-uri sqlite:///$(CURDIR)/mlflow.db --host 127.0.0.1 --port 5000

clean-venv:
	rm -rf $(VENV)

# Set-up and entry points. `make reproduce` and `make test` each do the whole set-up on a fresh machine.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
UI_PORT ?= 5000

.PHONY: help setup reproduce test lint smoke benchmarks docs cross-cpu mlflow-ui ui-check clean-venv

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed -E 's/:.*## /\t/' | expand -t 14

# pip writes the installed modules' bytecode file by file on one core; compileall writes the same on every core
# (the one file torch keeps for Python 3.12 does not compile under 3.11: pip passes over it in silence)
$(STAMP): requirements.txt pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-compile -r requirements.txt
	$(BIN)/pip install --quiet --no-deps -e .
	$(BIN)/python -m compileall -q -j 0 -x 'py312_intrinsics\.py$$' \
		"$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" >/dev/null
	touch $(STAMP)

setup: $(STAMP)  ## create .venv and install the pinned dependencies

reproduce: setup  ## run the whole pipeline with params.yaml
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/dvc repro

# Two pytest workers, one per core of the project's machine; the smoke project's tests (one xdist_group) run on one,
# the sweep's (another) on the other, and the smoke DAG is built once (tests/conftest.py).
test: setup  ## unit tests and a smoke run of the whole DAG on tiny params (2 workers); installs PostgreSQL if it can
	tools/test_prereqs.sh
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python -m pytest -q -n 2 --dist loadgroup --durations=15; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "error: pytest collected no tests (exit code 5)" >&2; fi; exit $$rc

smoke: setup  ## the whole DAG on tiny params (tests/smoke_params.yaml) in a temporary copy (most of `make test`)
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python -m pytest -q tests/test_pipeline_smoke.py

lint: setup  ## ruff
	$(BIN)/ruff check lfdt stages tests benchmarks tools

benchmarks: setup  ## every speed ratio in benchmarks/ (results in benchmarks/results/, numbers in docs/benchmarks.md)
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/stack_throughput.py
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/pin_cost.py
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python benchmarks/collect_throughput.py
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/training_throughput.py
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/parallel_speedup.py
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python benchmarks/worker_start.py --smoke 1
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python benchmarks/optimizer_start.py
	PATH="$(CURDIR)/$(BIN):$$PATH" MUJOCO_GL=egl $(BIN)/python benchmarks/sweep_vs_repro.py

docs: setup  ## write the numbers of README.md and docs/ from reports/ and benchmarks/results/
	$(BIN)/python -m lfdt.docs

cross-cpu: setup  ## the numeric fingerprint on this CPU and on CPUs emulated by QEMU (needs qemu-user)
	$(BIN)/python tools/cross_cpu.py --models Haswell EPYC Skylake-Client EPYC-Rome

mlflow-ui: setup  ## browse every run at http://127.0.0.1:5000 (UI_PORT=N: another port; prints the URLs of the views first)
	$(BIN)/python -m lfdt.mlflow_views --port-free --ui http://127.0.0.1:$(UI_PORT)
	$(BIN)/mlflow ui --backend-store-uri sqlite:///$(CURDIR)/mlflow.db --host 127.0.0.1 --port $(UI_PORT)

ui-check: setup  ## open the MLflow views in headless Chromium, check what they show, screenshots in docs/mlflow-ui/
	$(BIN)/python tools/mlflow_ui_check.py

clean-venv:
	rm -rf $(VENV)

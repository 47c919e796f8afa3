# Two commands do everything on a machine with only Python 3.11:
#   make demo   create .venv, install, run the main job on the default scene
#   make test   create .venv if missing, install with dev extras, run the tests
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
SCENE := configs/scenes/desk_handover.yaml

.PHONY: demo test setup bench-collision bench-grasps bench-roadmap bench-plan clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

setup: $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev]"

demo: setup
	$(BIN)/regrasp info $(SCENE)
	$(BIN)/regrasp grasps build $(SCENE)
	$(BIN)/regrasp roadmap build $(SCENE)
	$(BIN)/regrasp plan $(SCENE) -o plan.json
	$(BIN)/regrasp validate plan.json

test: setup
	$(BIN)/python -m pytest

bench-collision: setup
	$(BIN)/python scripts/bench_collision.py

bench-grasps: setup
	$(BIN)/python scripts/bench_grasps.py

bench-roadmap: setup
	$(BIN)/python scripts/bench_roadmap.py

bench-plan: setup
	$(BIN)/python scripts/bench_plan.py --out docs/bench_plan.md

clean:
	rm -rf $(VENV) cache .pytest_cache

# Two commands do everything on a machine with only Python 3.11:
#   make demo   create .venv, install, run the main job on the default scene
#   make test   create .venv if missing, install with dev extras, run the tests
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
SCENE := configs/scenes/desk_handover.yaml

.PHONY: demo test setup browser bench-collision bench-grasps bench-roadmap bench bench-hard bench-docs clean

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
	$(BIN)/regrasp show plan.json --html plan.html --png plan_frames

test: setup browser
	$(BIN)/python -m pytest

# Headless Chromium for the browser test (tests/show/test_browser.py), from Debian's
# packages when missing and this is root with apt-get; never fails the build (the test
# is then skipped and says why).
browser:
	@if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  echo "installing chromium and chromium-driver for the browser test"; \
	  (timeout 300 apt-get update -qq && DEBIAN_FRONTEND=noninteractive timeout 600 apt-get install -y -qq chromium chromium-driver) \
	    >/dev/null 2>&1 || echo "note: chromium could not be installed; the browser test will be skipped"; \
	else echo "note: chromium is missing and not installable here (needs root and apt-get); the browser test will be skipped"; fi

bench-collision: setup
	$(BIN)/python scripts/bench_collision.py

bench-grasps: setup
	$(BIN)/python scripts/bench_grasps.py

bench-roadmap: setup
	$(BIN)/python scripts/bench_roadmap.py

# the benchmark suites (configs/bench/): results in bench-results/<suite>/; bench-docs
# copies them into docs/bench/ and rewrites their tables in docs/BENCHMARKS.md
bench: setup
	$(BIN)/regrasp bench configs/bench/default.yaml

bench-hard: setup
	$(BIN)/regrasp bench configs/bench/hard.yaml

bench-docs: setup
	$(BIN)/python scripts/bench_docs.py

clean:
	rm -rf $(VENV) cache .pytest_cache

# transparency_ros: the two commands of the README, plus helpers.
#   make demo   - set up .venv if needed, then run the demonstration (simulated actuator)
#   make test   - set up .venv if needed, then lint and run the whole test suite
# The first run creates .venv and installs the pinned dependencies (requirements/constraints.txt);
# later runs reuse it until a requirements file or setup.py changes.

PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEMO_OUT ?= demo_output
PYTEST_ARGS ?=
FUZZ_SECONDS ?= 60

# Every ROS process started from here stays on loopback, on a domain ID nobody else here uses.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID := $(shell $(PYTHON) transparency_ros/rosenv.py)
# Plots are written to files; never try to open a window.
export MPLBACKEND := Agg

.PHONY: all demo test lint typecheck pytest bench fuzz docs lock clean help
all: test

help:
	@echo "make demo   run the demonstration into $(DEMO_OUT)/"
	@echo "make test   lint, type-check and run the test suite"
	@echo "make bench  run the benchmarks (benchmarks/), results in benchmarks/results/"
	@echo "make docs   regenerate the parameter tables, config/<node>.yaml and the subcommand table"
	@echo "make fuzz   fuzz the bag reader, CAN decoders and CDR reader (FUZZ_SECONDS=$(FUZZ_SECONDS) each)"
	@echo "make lock   re-resolve requirements/*.in into requirements/constraints.txt"
	@echo "make clean  remove .venv and generated output"

$(STAMP): requirements/runtime.in requirements/dev.in requirements/constraints.txt setup.py setup.cfg package.xml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -r requirements/runtime.in -r requirements/dev.in -c requirements/constraints.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/transparency demo --out $(DEMO_OUT)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

pytest: $(STAMP)
	$(BIN)/python -m pytest $(PYTEST_ARGS)

test: lint typecheck pytest

# All benchmarks, one run (about 20 min on 2 cores; the first run also writes a 10M-message bag
# into benchmarks/.cache/). Results: benchmarks/results/*.md, quoted in the README.
bench: $(STAMP)
	$(BIN)/python benchmarks/contact_latency.py
	$(BIN)/python benchmarks/bag_throughput.py
	$(BIN)/python benchmarks/model_sweep.py
	$(BIN)/python benchmarks/discrepancy_scaling.py
	$(BIN)/python benchmarks/driver_loop.py
	$(BIN)/python benchmarks/independent_rig.py
	$(BIN)/python benchmarks/real_injection.py
	$(BIN)/python benchmarks/momentum_observer.py
	$(BIN)/python benchmarks/pendubot_detection.py
	$(BIN)/python benchmarks/pendubot_residual_floor.py
	$(BIN)/python benchmarks/independent_robot.py

# Bounded mutational fuzzing (not part of make test); findings: benchmarks/results/fuzz/, status 1.
fuzz: $(STAMP)
	$(BIN)/python benchmarks/fuzz.py --seconds $(FUZZ_SECONDS)

# The docs' generated parts (parameter tables, subcommands) and config/<node>.yaml, from the code.
docs: $(STAMP)
	$(BIN)/python -m transparency_ros.ros.docgen

# Re-resolve the pins (run by a maintainer, then commit requirements/constraints.txt).
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --report .venv-lock/report.json -r requirements/runtime.in -r requirements/dev.in
	.venv-lock/bin/python requirements/lock.py .venv-lock/report.json requirements/constraints.txt \
		$$(.venv-lock/bin/python -m pip freeze --all | grep -iE "^(setuptools|wheel)==")
	rm -rf .venv-lock

clean:
	rm -rf $(VENV) $(DEMO_OUT) build install log .pytest_cache .mypy_cache .ruff_cache .hypothesis

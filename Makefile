# Thin aliases for the scripts under scripts/ (which work without make, too).
SHELL := bash
.PHONY: setup demo test bench clean

ROS_ENV := ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_DOMAIN_ID=$${ROS_DOMAIN_ID:-$$((RANDOM % 100 + 1))}

setup:
	bash scripts/setup.sh

demo:
	bash scripts/demo.sh

test:
	bash scripts/test.sh

# every benchmark script under bench/ (bench_*.py), in the project virtualenv
bench: setup
	@set -e; ls bench/bench_*.py >/dev/null 2>&1 || { echo "make bench: no bench/bench_*.py yet" >&2; exit 1; }; \
	for f in bench/bench_*.py; do echo "== $$f"; env $(ROS_ENV) .venv/bin/python "$$f"; done

# build products and outputs; keeps .venv (remove it by hand to start over)
clean:
	rm -rf out build install log *.egg-info .pytest_cache .hypothesis
	find . -path ./.venv -prune -o -name __pycache__ -type d -exec rm -rf {} +

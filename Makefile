# splat_tracer: one entry point for set-up, build, demo, tests, packaging and benchmarks.
# Every target sets up what it needs: a virtual environment with the pinned packages
# (.venv) and the native core (splat_tracer/_core.abi3.so).

PYTHON ?= python3
VENV   := .venv
VPY    := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
CORE   := splat_tracer/_core.abi3.so
NATIVE := $(wildcard splat_tracer/native/*.cpp splat_tracer/native/*.h)

.PHONY: all venv build demo test dist docs bench bench-quick clean

all: build

$(STAMP): requirements.txt requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	$(VPY) -m pip install --quiet -r requirements-dev.txt
	touch $@

venv: $(STAMP)

$(CORE): $(STAMP) setup.py $(NATIVE)
	$(VPY) setup.py --quiet build_ext --inplace --force

build: $(CORE)

demo: build
	$(VPY) tools/demo.py --output demo.png

test: build
	$(VPY) -m pytest tests

docs: build
	$(VPY) tools/switch_images.py --output-dir docs/switches
	$(VPY) tools/demo.py --output docs/demo.png --cycles docs/demo_cycles.png | grep "^demo:" | tee docs/demo_times.txt

dist: build
	$(VPY) tools/build_dist.py --output-dir dist

bench-quick: build
	$(VPY) benchmarks/trace_throughput.py --quick
	$(VPY) benchmarks/accuracy.py --quick --output build/bench-quick
	$(VPY) benchmarks/frame_time.py --quick --output build/bench-quick

bench: build
	$(VPY) benchmarks/trace_throughput.py
	$(VPY) benchmarks/accuracy.py --output benchmarks/results
	$(VPY) benchmarks/frame_time.py --output benchmarks/results

clean:
	rm -rf build dist wheels $(CORE) .pytest_cache

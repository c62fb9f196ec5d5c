# splat_tracer: one entry point for set-up, build, demo, tests, packaging and benchmarks.
# Every target sets up what it needs: a virtual environment with the pinned packages
# (.venv) and the native core (splat_tracer/_core.abi3.so). Tools, benchmarks and fuzz
# harnesses run as modules from the root (`python -m tools.demo`), where splat_tracer, tools
# and benchmarks import as packages.

PYTHON ?= python3
VENV   := .venv
VPY    := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
CORE   := splat_tracer/_core.abi3.so
NATIVE := $(shell find splat_tracer/native -name '*.cpp' -o -name '*.h')

.PHONY: all venv build native demo test test-release test-matrix test-windows test-sanitize sanitize-tree fuzz \
        dist docs bench bench-quick clean

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

# The shipped cores, for linux-x64 (glibc 2.28), windows-x64, macos-arm64 and macos-x64,
# cross-compiled with Zig (the ziglang package) into build/native/<platform>/. `make build`
# (gcc, in place) stays the development build: the sanitizer build and the tests use it.
native: $(STAMP)
	$(VPY) -m tools.build_native

demo: build
	$(VPY) -m tools.demo --output demo.png

# The everyday loop: every test that needs no cross build and no other Blender release, that
# is all but tests/release/: the Blender-free tests (pipeline/, render/; `-m "not blender"`
# runs only those) and the ones in bpy 5.0.1 (blender/).
test: build
	$(VPY) -m pytest tests --ignore=tests/release

# The release checks, which CI runs after `make test`: the shipped cores cross-built for the
# four platforms (tests/release/test_portable.py: about 10 minutes on 2 cores when Zig's
# cache is cold) and the Linux zip installed into bpy 5.0.1 (test_dist.py), the version
# matrix, the Windows build run under Wine, the core under the sanitizers and a short fuzz run.
test-release: build test-matrix test-windows test-sanitize fuzz
	$(VPY) -m pytest tests/release/test_portable.py tests/release/test_dist.py

# The version matrix: the linux-x64 zip (`make dist`'s) installed from the command line into
# each Blender the manifest claims, as the bpy module, each in its own venv with the Python
# and numpy that release ships (build/matrix/bpy-<series>/, made on first use: a ~370 MB
# download and ~1 GB on disk each; 5.1 and 5.2 need a python3.13, from PATH or pyenv),
# clouds of every format imported and one rendered and checked
# (tests/release/test_blender_versions.py). MATRIX picks series (the keys of its table).
MATRIX ?= 4.2.13 4.2 4.3 4.4 4.5 5.0 5.1 5.2

test-matrix: $(STAMP)
	cd tests && ../$(VPY) -m pytest -q -p no:cacheprovider --durations=0 release/test_blender_versions.py \
		$(MATRIX:%=--bpy %)

# The Windows build loaded and run under Wine (tests/release/test_windows.py): the Windows
# core in Windows Python 3.11 and 3.13 against the Linux core on the same inputs, and the
# windows_x64 zip installed into the Windows bpy 5.0.1, importing and rendering like Linux.
# tools/wine.py sets up what it needs in build/windows/ (about 1.8 GB): Wine from Debian's
# packages when missing (apt-get, as root), a Wine prefix, the Windows Pythons and wheels
# from PyPI. Skipped, with the reason, only where Wine cannot be installed.
test-windows: build
	$(VPY) -m pytest -q -rs -p no:cacheprovider --durations=0 tests/release/test_windows.py

# --- Sanitizers -------------------------------------------------------------------------
# The native core built with AddressSanitizer + UndefinedBehaviorSanitizer (setup.py,
# SPLAT_SANITIZE=1) into build/sanitize/, next to a copy of the Python package and the
# tests: the in-place binary of `make build` is never replaced. Only the core's test files
# run there: bpy does not load into a process with the ASan runtime. The runtime has to be
# preloaded into Python (which is not built with it), with libstdc++ (else ASan cannot find
# the real __cxa_throw and every C++ exception aborts). Leak detection is off: CPython keeps
# interned objects and module state until exit by design, so every run would "leak".
# Reports go to build/sanitize/logs/ (pytest's output capture would hide them); any report,
# even from a subprocess whose test tolerated its failure, fails the target.
SAN      := build/sanitize
SAN_LIBS  = $(shell gcc -print-file-name=libasan.so) $(shell gcc -print-file-name=libstdc++.so)
SAN_ENV   = LD_PRELOAD="$(SAN_LIBS)" \
            ASAN_OPTIONS=detect_leaks=0:log_path=$(abspath $(SAN))/logs/asan \
            UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1:log_path=$(abspath $(SAN))/logs/ubsan
SAN_TESTS = render/test_splats.py render/test_hostile_inputs.py render/test_method.py render/test_invariants.py \
            render/test_scene.py render/test_native_buffers.py render/test_scene_concurrency.py \
            pipeline/test_neighbours.py pipeline/test_graph.py

sanitize-tree: $(STAMP)
	SPLAT_SANITIZE=1 $(VPY) setup.py --quiet build_ext --build-lib $(SAN)/lib --build-temp $(SAN)/tmp
	rm -rf $(SAN)/tree $(SAN)/logs
	mkdir -p $(SAN)/tree/splat_tracer $(SAN)/logs
	tar -C splat_tracer --exclude=native --exclude='_core*' --exclude=__pycache__ -cf - . \
	    | tar -C $(SAN)/tree/splat_tracer -xf -  # the package tree, without the sources and the in-place core
	cp $(SAN)/lib/splat_tracer/_core.abi3.so $(SAN)/tree/splat_tracer/
	cp -r tests tools fuzz $(SAN)/tree/
	ldd $(SAN)/tree/splat_tracer/_core.abi3.so | grep -q libasan  # really the sanitized build

test-sanitize: sanitize-tree
	cd $(SAN)/tree/tests && $(SAN_ENV) $(abspath $(VPY)) -m pytest -q -p no:cacheprovider $(SAN_TESTS) \
		|| { cat $(abspath $(SAN))/logs/* 2>/dev/null; exit 1; }
	@if ls $(SAN)/logs/* >/dev/null 2>&1; then cat $(SAN)/logs/*; echo "sanitizer reports above"; exit 1; fi
	@echo "test-sanitize: no AddressSanitizer or UndefinedBehaviorSanitizer report"

# --- Fuzzing ----------------------------------------------------------------------------
# atheris harnesses in fuzz/ (the PLY, LAS/LAZ, E57, text and PCD readers, the import
# preparation, the native entry points), each for FUZZ_SECONDS / 7 from its seed corpus
# fuzz/corpus/<harness>/; the native harness's corpus is then replayed against the
# sanitizer build (see fuzz/run.py). 120 s: 17 s a harness, 4,000-15,000 files a reader.
FUZZ_SECONDS ?= 120

fuzz: build sanitize-tree
	$(VPY) -m fuzz.run --seconds $(FUZZ_SECONDS) --sanitized $(SAN)/tree

docs: build
	$(VPY) -m tools.switch_images --output-dir docs/switches
	$(VPY) -m tools.viewport_images --output-dir docs/viewport
	$(VPY) -m tools.demo --output docs/demo.png --cycles docs/demo_cycles.png | grep "^demo:" | tee docs/demo_times.txt
	$(VPY) -m tools.composite_images --output docs/composite.png --cycles docs/composite_cycles.png | grep "^composite:" | tee docs/composite_times.txt

# One zip per platform (tools/build_dist.py says why), each with its own core and wheels.
dist: $(STAMP)
	$(VPY) -m tools.build_dist --output-dir dist

bench-quick: build
	$(VPY) -m benchmarks.trace_throughput --quick
	$(VPY) -m benchmarks.scale --quick
	$(VPY) -m benchmarks.accuracy --quick --output build/bench-quick
	$(VPY) -m benchmarks.frame_time --quick --output build/bench-quick
	$(VPY) -m benchmarks.viewport_latency --quick
	$(VPY) -m benchmarks.import_speed --quick --output build/bench-quick
	$(VPY) -m benchmarks.real_scans --quick --output build/bench-quick
	$(VPY) -m benchmarks.time_to_clean --quick --output build/bench-quick

# Open3D for the import benchmark's comparison rows, in its own environment (its wheel
# brings dependencies the add-on's environment must not get); it needs libusb at load
# time, installed from Debian's packages when missing and possible. A failure here only
# skips those rows (the benchmark says why).
O3D := build/o3d
$(O3D)/.installed-stamp:
	-{ ldconfig -p | grep -q libusb-1.0 || { apt-get update -qq && apt-get install -y -qq libusb-1.0-0; }; } \
	  && $(PYTHON) -m venv $(O3D) && $(O3D)/bin/pip install --quiet numpy==1.26.4 open3d-cpu==0.20.0 \
	  && touch $@

bench: build $(O3D)/.installed-stamp
	$(VPY) -m benchmarks.trace_throughput
	$(VPY) -m benchmarks.scale
	$(VPY) -m benchmarks.accuracy --output benchmarks/results
	$(VPY) -m benchmarks.frame_time --output benchmarks/results
	$(VPY) -m benchmarks.viewport_latency --output benchmarks/results/viewport_latency.md
	$(VPY) -m benchmarks.import_speed --repeat 3 --output benchmarks/results
	$(VPY) -m benchmarks.real_scans --output benchmarks/results
	$(VPY) -m benchmarks.time_to_clean --output benchmarks/results

clean:
	rm -rf build dist wheels $(CORE) .pytest_cache

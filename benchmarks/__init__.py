"""Benchmarks (`make bench`, `make bench-quick`). Run as modules from the repository root,
e.g. `python -m benchmarks.accuracy --quick`, so that splat_tracer, tools and benchmarks
import as packages."""

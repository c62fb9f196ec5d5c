"""atheris fuzz harnesses (`make fuzz`). Run as modules from the root of the tree whose
splat_tracer is to be fuzzed, e.g. `python -m fuzz.run --seconds 60`."""

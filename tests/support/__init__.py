"""Helpers shared by the tests and by the tools that render through Blender. The tests
import them by module name (`from geometry import fibonacci_sphere`: pytest.ini's
pythonpath has this folder); tools and benchmarks run from the root import them as
tests.support.<module>."""

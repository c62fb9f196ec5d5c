"""Development tools: the builds, the demo, the README's images, loading the extension from
source. Run as modules from the repository root, e.g. `python -m tools.demo`, so that
splat_tracer, tools and the tests' support helpers import as packages."""

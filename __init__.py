# SPDX-License-Identifier: GPL-3.0-or-later
"""Splat Tracer: render point-cloud scans as splats with a native ray tracer.

Layout: `splat_tracer/` holds the renderer (native core, engine, export, properties,
readers), `operators/` the importer, `ui/` the panels. Each package has register().
"""
from . import operators, ui
from . import splat_tracer as renderer

_packages = (renderer, operators, ui)


def register():
    for package in _packages:
        package.register()


def unregister():
    for package in reversed(_packages):
        package.unregister()

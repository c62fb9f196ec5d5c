# SPDX-License-Identifier: GPL-3.0-or-later
"""Splat Tracer: render point-cloud scans as splats with a native ray tracer.

Layout (docs/architecture.md): `splat_tracer/` holds the renderer in layers (blender/ over
the Blender-free pointcloud/ and render/, over util/ and the native core), `operators/` the
importer and the A/B operators, `ui/` the panels. Each package has register().
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

"""The settings audit (issue 26, item 5): every setting an artist can change for a render,
enumerated from Blender's RNA (not a hand list), is honoured (the image or a pass changes),
said in the render report (a line said, or no longer said; that the line names the setting
is checked case by case in test_unhonoured_settings.py), or listed in settings_not_rendered.py
with its reason -- which docs/settings.md shows. A setting a new Blender adds is in none of
these and fails here instead of going unsaid.

The scene is tiny (24 x 24 pixels, 1 sample): a splat-cloud sphere on a mesh floor (one
material, partly transmissive and transparent), a point lamp, a grey world with mist, the
camera and the cloud moving through the frame (for motion blur). Each setting is changed
alone from the scene's value
(settings_not_rendered.VALUES where the generic change would show nothing in this scene, and
CONTEXT where it acts only in another mode, e.g. a spot lamp's cone), the frame is rendered
through the session (the engine's own export and render, passes included) and compared with
the frame before the change; then the value is put back. "Honoured" here means "changes the
render" -- whether it changes it as Cycles does is the side-by-side tests' job.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import settings_not_rendered as lists
import settings_walk
from blender_helpers import add_camera, extension_module
from test_scene_export import cloud_sphere, lamp, plane, principled

W = H = 24
DOCS = Path(__file__).resolve().parents[2] / "docs" / "settings.md"


class Audit:
    """The small scene and its frames."""

    def __init__(self, bpy):
        self.bpy = bpy
        bpy.ops.wm.read_homefile(use_empty=True)
        scene = self.scene = bpy.context.scene
        scene.render.engine = "SPLAT_TRACER"
        material = principled(bpy, "Grey", specular=0.5, roughness=0.4)
        # Some light through and past the surfaces: the transmission and transparency settings act.
        shader = material.node_tree.nodes["Principled BSDF"]
        shader.inputs["Transmission Weight"].default_value = 0.3
        shader.inputs["Alpha"].default_value = 0.8
        self.mesh = plane(bpy, "Floor", 6.0, (0, 0, 0), material)
        self.cloud = cloud_sphere(bpy, "Scan", 600, 0.8, (0, 0, 0.8), material)
        self.lamp = lamp(bpy, "POINT", location=(1.5, -1.5, 3.0), energy=300.0)
        camera = add_camera(bpy, scene, (0, -5, 3), (math.radians(62), 0, 0))
        # The camera moves through the frame (at rest at it, in the same place as without the
        # keys), so that motion blur, when rendered, changes the image.
        for frame, dx in ((0, -0.1), (1, 0.0), (2, 0.1)):
            camera.location.x = dx
            camera.keyframe_insert("location", index=0, frame=frame)
        # The cloud moves and turns too, along Blender's default (Bezier, not linear) keys, so
        # that its own Motion Blur switch and Motion Steps (more steps follow the curve more
        # closely) change the image; at frame 1 it is where it was without the keys.
        x0 = self.cloud.location.x
        for frame, d in ((0, -1.0), (1, 0.0), (2, 1.0)):
            self.cloud.location.x, self.cloud.rotation_euler.z = x0 + 0.4 * d, 0.5 * d
            self.cloud.keyframe_insert("location", index=0, frame=frame)
            self.cloud.keyframe_insert("rotation_euler", index=2, frame=frame)
        # A shape key (its Basis alone: the floor's shape is unchanged) makes the floor an
        # object that may deform, whose Deformation motion blur the report says.
        self.mesh.shape_key_add(name="Basis")
        scene.frame_set(1)
        scene.world = bpy.data.worlds.new("Grey")
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.3, 0.3, 1)
        scene.world.mist_settings.start, scene.world.mist_settings.depth = 2.0, 6.0
        r = scene.render
        r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
        c = scene.cycles
        c.samples, c.use_denoising, c.use_adaptive_sampling = 1, False, False
        layer = scene.view_layers[0]
        for prop, *_ in extension_module("blender.engine")._PASSES:
            owner, _, name = prop.rpartition(".")
            setattr(getattr(layer, owner) if owner else layer, name, True)
        self.session = extension_module("blender.session")
        self.engine = extension_module("blender.engine")

    def owners(self, name: str) -> list:
        """The structs an owner name stands for (an object setting is tried on the cloud and
        on the mesh: honoured on either counts)."""
        return settings_walk.owner_structs(self.scene, [self.cloud, self.mesh], self.lamp)[name]

    def frame(self) -> tuple:
        """(passes, report lines) of the scene as it is, rendered by F12 (bpy.ops.render.render:
        Blender's render depsgraph, the engine's own passes). Headless, Blender's Render Result
        holds no pixels: the session's frame is taken as the engine gets it."""
        frames, render_frame = [], self.session.render_frame

        def keep(*args, **kwargs):
            frames.append(render_frame(*args, **kwargs))
            return frames[-1]

        self.session.render_frame = keep
        try:
            self.bpy.ops.render.render()
        finally:
            self.session.render_frame = render_frame
        assert len(frames) == 1, "one view layer, one frame"
        frame = frames[0]
        # A stereo or multi-view frame: every view's passes (a setting may change one eye only).
        passes = {f"{view}/{name}": pixels for view, views in frame.views.items() for name, pixels in views.items()}
        return passes or frame.passes, list(frame.report.lines)


def _enum_items(owner, prop) -> list:
    """The items an enum takes now: a dynamic enum's (colour management's, Cycles' device)
    differ from its RNA's static list, and setting a wrong one lists them in the error."""
    try:
        setattr(owner, prop.identifier, "\x01" if not prop.is_enum_flag else {"\x01"})
    except TypeError as e:
        return re.findall(r"'([^']+)'", str(e).partition(" not found in ")[2])
    return [i.identifier for i in prop.enum_items]


def _number(prop, v):
    lo, hi = prop.soft_min, prop.soft_max
    for c in (v * 2, v + 1, v * 0.5, v - 1, lo, hi):
        c = int(round(c)) if prop.type == "INT" else float(c)
        if lo <= c <= hi and c != v:
            return c
    return v


def changed_value(owner, prop, value):
    """A value other than `value`, the generic way: a switch flipped, another enum item, a
    number doubled (or moved within its soft range), a name."""
    if prop.type == "BOOLEAN":
        return [not v for v in value] if prop.is_array else not value
    if prop.type == "STRING":
        return value + "Audit"
    if prop.type == "ENUM":
        items = _enum_items(owner, prop)
        if prop.is_enum_flag:
            return set() if value else {items[0]}
        return next((i for i in items if i != value), value)
    if prop.is_array:
        flat = list(np.asarray(value, dtype=float).ravel())
        new = [_number(prop, v) for v in flat]
        return np.asarray(new).reshape(np.shape(value)).tolist() if np.ndim(value) > 1 else new
    return _number(prop, value)


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(a[k].shape == b[k].shape and np.array_equal(a[k], b[k], equal_nan=True)
                                        for k in a)


def _value(owner, prop):
    v = getattr(owner, prop.identifier)
    if getattr(prop, "is_array", False):
        try:
            return [list(row) for row in v] if np.ndim(v) > 1 else list(v)
        except TypeError:
            return list(v)
    return v


def _apply(audit, settings: dict) -> list:
    """Sets {"owner.prop": value} on every struct of each owner; returns the undo."""
    undo = []
    for key, value in settings.items():
        owner_name, _, prop = key.rpartition(".")
        for owner in audit.owners(owner_name):
            undo.append((owner, prop, getattr(owner, prop)))
            setattr(owner, prop, value)
    return undo


def _undo(undo: list) -> None:
    for owner, prop, value in reversed(undo):
        setattr(owner, prop, value)


def walk(audit, only=None) -> dict:
    """{'owner.prop': 'honoured' | 'reported' | 'listed' | what went wrong} for every value
    setting of every owner; `only`: those keys, each rendered even when listed."""
    outcome = {}
    version = tuple(audit.bpy.app.version)
    for owner_name, key, structs, prop in settings_walk.settings(audit.bpy, audit.owners, audit.lamp):
        if only is not None and key not in only:
            continue
        if only is None and lists.listed(key, version):
            outcome[key] = "listed"
            continue
        undo = _apply(audit, lists.CONTEXT.get(key, {}))
        try:
            outcome[key] = "unchanged"
            for owner in structs:
                # The frame before, each time: a value put back may differ in its last bit
                # (an object's dimensions), and the scene must not drift under the walk.
                before, said = audit.frame()
                value = _value(owner, prop)
                new = lists.VALUES.get(key, None)
                new = changed_value(owner, prop, value) if new is None else new
                setattr(owner, prop.identifier, new)
                try:
                    passes, lines = audit.frame()
                finally:
                    setattr(owner, prop.identifier, value)
                fresh = sorted(set(lines) ^ set(said))  # a line said, or no longer said
                if not _same(before, passes):
                    outcome[key] = "honoured"
                    break
                if fresh:
                    outcome[key] = f"reported: {fresh}"
                    break
        except Exception as e:  # noqa: BLE001 - every setting is walked; the failures are listed
            outcome[key] = f"error: {type(e).__name__}: {e}"
        finally:
            _undo(undo)
    return outcome


@pytest.fixture(scope="module")
def audit_outcome(blender):
    audit = Audit(blender)
    first, second = audit.frame(), audit.frame()
    assert _same(first[0], second[0]), "the small scene must render the same twice"
    return walk(audit)


def test_every_setting_is_honoured_reported_or_listed(audit_outcome):
    bad = {k: v for k, v in audit_outcome.items()
           if v not in ("honoured", "listed") and not v.startswith("reported")}
    assert not bad, "\n".join(f"{k}: {v}" for k, v in sorted(bad.items()))


def test_a_listed_setting_exists(blender, audit_outcome):
    """Each entry of the lists for this Blender names settings it has (no stale entry); an
    entry for other versions only is checked by the version matrix in those."""
    assert not settings_walk.stale(list(audit_outcome), tuple(blender.app.version))


def test_the_docs_show_the_lists():
    assert DOCS.read_text() == lists.markdown(), "run: python tests/blender/settings_not_rendered.py > docs/settings.md"

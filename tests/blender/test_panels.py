"""Panels as an artist expects (issue 26, item 6): one Light panel, Blender's generic panels
opened only from the engine's include list (ui.GENERIC_PANELS, as Cycles' add-on keeps one),
and no panel showing a setting the engine neither honours nor says (the settings audit's
"not rendered" list, settings_not_rendered.py).

What a panel shows is recorded by drawing it, headless, into a layout that notes each
`prop()` (panels are Python: their draw() is the truth of what they show), with a context
holding the audit's objects.
"""
from __future__ import annotations

import fnmatch
import inspect
import math
import types
from types import SimpleNamespace

import pytest

import settings_not_rendered as lists
import test_settings_audit
from blender_helpers import add_camera, extension_module
from test_scene_export import cloud_sphere, lamp, plane, principled

ENGINE = "SPLAT_TRACER"
CONTEXTS = ("render", "output", "view_layer", "object", "data", "material", "world")


class Layout:
    """A UILayout that records (struct, property) of every prop() drawn."""

    def __init__(self, drawn: list):
        self._drawn = drawn

    def prop(self, data, prop, *args, **kwargs):
        self._drawn.append((data, prop))

    prop_enum = prop_menu_enum = prop_tabs_enum = prop_with_popover = prop_with_menu = prop_decorator = prop

    def props_enum(self, data, prop):
        self._drawn.append((data, prop))

    def prop_search(self, data, prop, *args, **kwargs):
        self._drawn.append((data, prop))

    def panel(self, *args, **kwargs):
        return self, self

    panel_prop = panel

    def __getattr__(self, name):
        # row(), column(), box(), split(), label(), operator(), template_*(), ...: more of the
        # same layout (an operator's properties set on it are ignored).
        return lambda *args, **kwargs: self


def _opened_panels(bpy):
    """Blender's panels (not the engine's own) opened for the engine."""
    return [p for p in bpy.types.Panel.__subclasses__() if not p.__name__.startswith("SPLAT_TRACER_")
            and isinstance(getattr(p, "COMPAT_ENGINES", None), set) and ENGINE in p.COMPAT_ENGINES]


def _all_panels(bpy):
    own = [getattr(bpy.types, cls.__name__) for cls in extension_module("ui").classes]
    return own + _opened_panels(bpy)


def test_generic_panels_come_from_the_include_list(blender):
    bpy = blender
    ui = extension_module("ui")
    opened = [p.__name__ for p in _opened_panels(bpy)]
    assert opened and all(ui.generic_panel_included(name) for name in opened)
    # Each entry opens something (no stale name), and the light panels left out stay out.
    names = [p.__name__ for p in bpy.types.Panel.__subclasses__()]
    assert all(any(fnmatch.fnmatchcase(n, pattern) for n in names) for pattern in ui.GENERIC_PANELS)
    for left_out in ("DATA_PT_light", "DATA_PT_spot", "DATA_PT_preview", "MATERIAL_PT_preview",
                     "RENDER_PT_freestyle", "OBJECT_PT_shading"):
        assert left_out not in opened
    # Blender's engine-agnostic panels that show for its own BLENDER_RENDER were all opened before
    # (297 of them); the include list opens fewer.
    print(f"{len(opened)} of Blender's panels opened")


def _struct_owner(bpy, data, prop: str):
    """The settings audit's key ('owner.prop') for a drawn property, or None for a struct the
    audit does not walk."""
    t = bpy.types
    simple = {t.RenderSettings: "render", t.ColorManagedViewSettings: "view_settings",
              t.ColorManagedDisplaySettings: "display_settings", t.ViewLayer: "view_layer", t.Object: "object",
              t.World: "world", t.WorldLighting: "world.light_settings", t.WorldMistSettings: "world.mist_settings",
              t.Material: "material", t.Camera: "camera", t.CameraDOFSettings: "camera.dof",
              t.CameraStereoData: "camera.stereo"}
    for cls, owner in simple.items():
        if isinstance(data, cls):
            return f"{owner}.{prop}"
    if isinstance(data, t.Light):
        point = {p.identifier for p in t.PointLight.bl_rna.properties}
        return f"light.{prop}" if prop in point else f"{data.type.lower()}_light.{prop}"
    cycles = {"CyclesRenderSettings": "cycles", "CyclesRenderLayerSettings": "view_layer.cycles",
              "CyclesObjectSettings": "object.cycles", "CyclesLightSettings": "light.cycles",
              "CyclesWorldSettings": "world.cycles", "CyclesVisibilitySettings": "world.cycles_visibility",
              "CyclesMaterialSettings": "material.cycles"}
    owner = cycles.get(type(data).__name__)
    return f"{owner}.{prop}" if owner else None


@pytest.fixture
def scene_objects(blender):
    bpy = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = ENGINE
    material = principled(bpy, "Grey")
    floor = plane(bpy, "Floor", 6.0, (0, 0, 0), material)
    cloud = cloud_sphere(bpy, "Scan", 200, 0.8, (0, 0, 0.8), material)
    lamp_obj = lamp(bpy, "SPOT", location=(1, -1, 3))
    cam = add_camera(bpy, scene, (0, -5, 3), (math.radians(62), 0, 0))
    cam.data.dof.use_dof = True
    scene.render.use_multiview = True  # the camera's Stereoscopy panel shows with it
    scene.world = bpy.data.worlds.new("World")
    return scene, [floor, cloud, lamp_obj, cam], material


class _Self:
    """Stands for a panel instance (bpy makes those only while drawing a real editor): the
    recording layout, and the panel class's attributes and methods (mixins' helpers)."""

    def __init__(self, panel, layout):
        self._panel, self.layout = panel, layout

    def __getattr__(self, name):
        attr = getattr(self._panel, name)
        static = isinstance(inspect.getattr_static(self._panel, name, None), staticmethod)
        return types.MethodType(attr, self) if inspect.isfunction(attr) and not static else attr


def _draw(bpy, panel, ctx) -> list:
    drawn = []
    me = _Self(panel, Layout(drawn))
    for method in ("draw_header", "draw"):
        fn = getattr(panel, method, None)
        if fn is not None:
            fn(me, ctx)
    return drawn


def _draw_if_can(bpy, panel, ctx) -> list:
    """What a panel draws; a generic panel that needs more of a real context than _context
    gives (custom properties' path_resolve) draws nothing here."""
    try:
        return _draw(bpy, panel, ctx)
    except AttributeError:
        if panel.__name__.startswith("SPLAT_TRACER_"):
            raise
        return []


def _context(bpy, scene, obj, material, bl_context):
    """What a Properties editor's tab gives its panels, for `obj` active."""
    ctx = SimpleNamespace(engine=ENGINE, scene=scene, view_layer=scene.view_layers[0], object=obj, active_object=obj,
                          material=material, world=scene.world, bl_context=bl_context, light=None, camera=None,
                          mesh=None, pointcloud=None, curves=None, speaker=None, lightprobe=None, volume=None,
                          texture=None, particle_system=None, collection=scene.collection,
                          space_data=SimpleNamespace(pin_id=None, context=bl_context.upper()),
                          preferences=bpy.context.preferences, texture_user=None, brush=None, line_style=None)
    kinds = {"LIGHT": "light", "CAMERA": "camera", "MESH": "mesh", "POINTCLOUD": "pointcloud"}
    setattr(ctx, kinds.get(obj.type, "mesh"), obj.data)
    return ctx


def _contexts(bpy, scene, objects, material):
    for obj in objects:
        for kind in ("POINT", "SPOT", "AREA", "SUN") if obj.type == "LIGHT" else (None,):
            if kind:
                obj.data.type = kind
            for bl_context in CONTEXTS:
                yield f"{obj.name}{'/' + kind if kind else ''}", _context(bpy, scene, obj, material, bl_context)


def test_no_panel_shows_a_setting_the_engine_does_not_render(blender, scene_objects):
    """Every property the engine's panels and the generic panels it opens show, in every
    context of the audit's objects (a lamp of each type), is honoured, said, or not a render
    setting -- none the audit lists as not rendered. The engine's own panels must draw."""
    bpy = blender
    scene, objects, material = scene_objects
    shown, failures = {}, []
    for name, ctx in _contexts(bpy, scene, objects, material):
        for panel in _all_panels(bpy):
            if (getattr(panel, "bl_space_type", "") != "PROPERTIES"
                    or getattr(panel, "bl_context", "") not in (ctx.bl_context, "")):
                continue
            try:
                if hasattr(panel, "poll") and not panel.poll(ctx):
                    continue
                drawn = _draw(bpy, panel, ctx)
            except Exception as e:  # noqa: BLE001 - a generic panel may need more of a real context
                if panel.__name__.startswith("SPLAT_TRACER_"):
                    failures.append(f"{panel.__name__} ({name}): {type(e).__name__}: {e}")
                continue
            for data, prop in drawn:
                key = _struct_owner(bpy, data, prop)
                if key:
                    shown.setdefault(key, set()).add(panel.__name__)
    assert not failures, failures
    shown_keys = set(shown)
    unsupported = {key: sorted(panels) for key, panels in shown.items()
                   if (entry := lists.listed(key, bpy.app.version)) is not None and entry.kind == "unsupported"}
    if unsupported:
        # A setting listed as not rendered that a change since made the engine honour or say
        # may be shown: the audit's walk decides, for those alone.
        outcome = test_settings_audit.walk(test_settings_audit.Audit(bpy), only=set(unsupported))
        unsupported = {k: v for k, v in unsupported.items() if outcome.get(k) not in ("honoured", "reported")
                       and not str(outcome.get(k)).startswith("reported")}
    assert not unsupported, unsupported
    # The walk saw the engine's settings (a draw recorder that records nothing would pass).
    assert {"cycles.samples", "light.temperature", "light.exposure", "camera.dof.aperture_fstop",
            "object.is_shadow_catcher", "render.resolution_x", "camera.stereo.interocular_distance",
            "view_layer.use_pass_diffuse_direct", "view_layer.use_pass_ambient_occlusion",
            "world.light_settings.distance", "object.lightgroup", "world.lightgroup",
            "view_layer.pass_cryptomatte_depth",
            # the engine's Motion Blur panels (Render, Object)
            "render.use_motion_blur", "render.motion_blur_shutter", "cycles.rolling_shutter_type",
            "object.cycles.use_motion_blur", "object.cycles.motion_steps", "view_layer.use_motion_blur"} <= shown_keys, sorted(shown_keys)


def test_one_light_panel_with_one_type_selector(blender, scene_objects):
    """Among the panels shown for a lamp in the Light data tab, one is labelled Light, and the
    lamp's type is drawn once; Temperature and Exposure, which the engine renders, are shown."""
    bpy = blender
    scene, objects, material = scene_objects
    lamp_obj = objects[2]
    for kind in ("POINT", "SPOT", "AREA", "SUN"):
        lamp_obj.data.type = kind
        ctx = _context(bpy, scene, lamp_obj, material, "data")
        shown = [p for p in _all_panels(bpy) if getattr(p, "bl_context", "") == "data"
                 and getattr(p, "bl_space_type", "") == "PROPERTIES" and p.poll(ctx)]
        assert [p.bl_label for p in shown].count("Light") == 1, [p.__name__ for p in shown]
        drawn = [prop for p in shown for data, prop in _draw_if_can(bpy, p, ctx) if data == lamp_obj.data]
        assert drawn.count("type") == 1, (kind, drawn)
        assert {"use_temperature", "temperature", "exposure", "energy", "color"} <= set(drawn), (kind, drawn)

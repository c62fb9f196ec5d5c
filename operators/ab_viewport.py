"""The viewport's live A/B comparison: flip between A and B, copy settings between the scene
and a slot, and drag the split wipe. The settings live in scene.splat_tracer.ab
(blender/properties.py); what the viewport draws of them is splat_tracer/render/ab.py."""
from __future__ import annotations

import bpy

from ..splat_tracer.render import ab

FLIP_KEY = dict(type="B", value="PRESS", shift=True, alt=True)  # Shift+Alt+B in the 3D View


class SPLAT_TRACER_OT_ab_flip(bpy.types.Operator):
    """Show the other of A and B in the Rendered viewport (from Off or Split: A)"""

    bl_idname = "splat_tracer.ab_flip"
    bl_label = "Flip A/B"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        props = context.scene.splat_tracer.ab
        props.mode = {"A": "B", "B": "A"}.get(props.mode, "A")
        return {"FINISHED"}


class SPLAT_TRACER_OT_ab_copy(bpy.types.Operator):
    """Copy the visibility settings (switches, epsilon, kernel, radius factor) between the scene and A or B"""

    bl_idname = "splat_tracer.ab_copy"
    bl_label = "Copy A/B Settings"
    bl_options = {"REGISTER", "UNDO"}

    slot: bpy.props.EnumProperty(name="Slot", items=(("A", "A", "Settings A"), ("B", "B", "Settings B")))
    direction: bpy.props.EnumProperty(
        name="Direction", default="FROM_SCENE",
        items=(("FROM_SCENE", "From Scene", "Set the slot to the scene's current settings"),
               ("TO_SCENE", "To Scene", "Set the scene's settings (what F12 renders) to the slot's")))

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        settings = context.scene.splat_tracer
        slot = getattr(settings.ab, self.slot.lower())
        source, target = (settings, slot) if self.direction == "FROM_SCENE" else (slot, settings)
        target.copy_visibility(source)
        settings.ab.initialised = True
        return {"FINISHED"}


class SPLAT_TRACER_OT_ab_split_drag(bpy.types.Operator):
    """Drag the A/B wipe across the viewport (click or Enter to keep it, right-click or Esc to cancel)"""

    bl_idname = "splat_tracer.ab_split_drag"
    bl_label = "Drag A/B Split"
    bl_options = {"REGISTER", "UNDO", "GRAB_CURSOR", "BLOCKING"}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.area is not None and context.area.type == "VIEW_3D"

    def _region(self, context):
        return next((r for r in context.area.regions if r.type == "WINDOW"), None)

    def invoke(self, context, event):
        props = context.scene.splat_tracer.ab
        self._initial = (props.mode, props.split)
        props.mode = "SPLIT"
        context.window_manager.modal_handler_add(self)
        context.area.header_text_set("A/B split: move the mouse, click to keep, Esc to cancel")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        props = context.scene.splat_tracer.ab
        region = self._region(context)
        if event.type == "MOUSEMOVE" and region is not None:
            props.split = ab.split_at(event.mouse_x, region.x, region.width)
        elif event.type in {"LEFTMOUSE", "RET", "NUMPAD_ENTER"} and event.value == "PRESS":
            context.area.header_text_set(None)
            return {"FINISHED"}
        elif event.type in {"RIGHTMOUSE", "ESC"} and event.value == "PRESS":
            props.mode, props.split = self._initial
            context.area.header_text_set(None)
            return {"CANCELLED"}
        context.area.tag_redraw()
        return {"RUNNING_MODAL"}


classes = (SPLAT_TRACER_OT_ab_flip, SPLAT_TRACER_OT_ab_copy, SPLAT_TRACER_OT_ab_split_drag)
_keymaps = []


def register_keymap():
    """Shift+Alt+B flips A/B in the 3D View (Preferences > Keymap can rebind it). Blender
    has no add-on key configuration in some builds: then there is no shortcut, only the
    buttons."""
    keyconfig = bpy.context.window_manager.keyconfigs.addon
    if keyconfig is None:
        return
    keymap = keyconfig.keymaps.new(name="3D View", space_type="VIEW_3D")
    _keymaps.append((keymap, keymap.keymap_items.new(SPLAT_TRACER_OT_ab_flip.bl_idname, **FLIP_KEY)))


def unregister_keymap():
    for keymap, item in _keymaps:
        keymap.keymap_items.remove(item)
    _keymaps.clear()

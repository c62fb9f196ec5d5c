"""Which settings the settings audit (test_settings_audit.py) walks: the value settings Blender's
RNA gives each owner of settings_not_rendered.OWNERS. One place for the audit, which renders
each, and for the version matrix (tests/release/test_blender_versions.py), which runs this file
in each Blender series' bpy without pytest or the extension:

    python tests/blender/settings_walk.py                      # JSON: this bpy's version and keys
    python tests/blender/settings_walk.py --against keys.json  # JSON: what this bpy has that the
                                                               # audit's bpy (keys.json) had not
                                                               # walked, and is not listed

A setting the audited bpy walks was classified there (the audit requires it honoured or said, or
it is listed); a setting only another series has must be listed (with its versions) or its
series fails the matrix instead of being a silent gap.
"""
from __future__ import annotations

import json
import sys

import settings_not_rendered as lists

# RNA types an artist sets a value of; pointers and collections are structure (the audit walks
# the structs they lead to, each an owner of lists.OWNERS).
VALUE_TYPES = {"BOOLEAN", "INT", "FLOAT", "ENUM", "STRING"}
# The owners walked on the lamp turned into each type (their own RNA classes' settings).
LAMP_KINDS = {"spot_light": "SPOT", "area_light": "AREA", "sun_light": "SUN"}


def owner_structs(scene, objects: list, lamp) -> dict:
    """Owner name (lists.OWNERS) -> the structs it stands for in a scene, `lamp` the lamp object
    (its data's RNA class follows its type). An object setting is tried on every one of
    `objects`."""
    world, cam = scene.world, scene.camera.data
    layer = scene.view_layers[0]
    material = next(o.active_material for o in objects if o.active_material)
    return {
        "render": [scene.render], "cycles": [scene.cycles], "view_settings": [scene.view_settings],
        "display_settings": [scene.display_settings], "view_layer": [layer], "view_layer.cycles": [layer.cycles],
        "object": objects, "object.cycles": [o.cycles for o in objects],
        "light": [lamp.data], "light.cycles": [lamp.data.cycles],
        "spot_light": [lamp.data], "area_light": [lamp.data], "sun_light": [lamp.data],
        "world": [world], "world.cycles": [world.cycles], "world.light_settings": [world.light_settings],
        "world.mist_settings": [world.mist_settings], "world.cycles_visibility": [world.cycles_visibility],
        "material": [material], "material.cycles": [material.cycles],
        "camera": [cam], "camera.dof": [cam.dof], "camera.stereo": [cam.stereo],
    }


def settings(bpy, owners, lamp):
    """(owner name, 'owner.prop', the owner's structs, the RNA property) for every value setting
    of every owner, `owners(name)` giving the structs. The lamp is of each type in turn while
    that type's owner is walked (POINT again after)."""
    point = {p.identifier for p in bpy.types.PointLight.bl_rna.properties}
    for owner_name in lists.OWNERS:
        kind = LAMP_KINDS.get(owner_name)
        if kind:
            lamp.data.type = kind  # a lamp of each type has its own settings (a new RNA class)
        try:
            structs = owners(owner_name)
            base = point if kind else set()
            for prop in list(structs[0].bl_rna.properties):
                if (prop.identifier == "rna_type" or prop.is_readonly or prop.type not in VALUE_TYPES
                        or prop.identifier in base):
                    continue
                yield owner_name, f"{owner_name}.{prop.identifier}", structs, prop
        finally:
            if kind:
                lamp.data.type = "POINT"


def keys(bpy) -> list:
    """The keys the audit walks in this bpy, from an empty file with one of each owner (no
    extension needed: the RNA classes are Blender's and Cycles')."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    if not hasattr(scene, "cycles"):  # Cycles is enabled in a factory bpy; say so if not
        raise RuntimeError("Cycles' add-on is not enabled in this bpy: its settings cannot be listed")
    mesh = bpy.data.objects.new("Mesh", bpy.data.meshes.new("Mesh"))
    mesh.data.materials.append(bpy.data.materials.new("Material"))
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    for obj in (mesh, lamp, camera):
        scene.collection.objects.link(obj)
    scene.camera, scene.world = camera, bpy.data.worlds.new("World")
    # Asked anew for each owner: the lamp's data is of another RNA class once its type changed.
    return sorted(key for _, key, _, _ in settings(bpy, lambda name: owner_structs(scene, [mesh], lamp)[name], lamp))


def unaudited(found: list, version: tuple, audited: list) -> list:
    """The keys of a bpy of `version` neither walked by the audit's bpy (`audited`) nor
    listed for that version."""
    walked = set(audited)
    return [k for k in found if k not in walked and not lists.listed(k, version)]


def stale(found: list, version: tuple) -> list:
    """The list's patterns that match none of a bpy's keys though their entry claims its
    version."""
    return [f"{e.owner}.{pattern}" for e in lists.ENTRIES if lists.applies(e, version) for pattern in e.names
            if not any(lists.fnmatch.fnmatchcase(k, f"{e.owner}.{pattern}") for k in found)]


def main(argv: list) -> None:
    import bpy

    version = tuple(bpy.app.version)
    found = keys(bpy)
    out = {"version": list(version), "keys": found}
    if argv[:1] == ["--against"]:
        with open(argv[1]) as f:
            audited = json.load(f)
        out = {"version": list(version), "audited_version": audited["version"], "keys": len(found),
               "unaudited": unaudited(found, version, audited["keys"]), "stale": stale(found, version)}
    print("SETTINGS_WALK " + json.dumps(out))  # one marked line: Blender may print its own


if __name__ == "__main__":
    main(sys.argv[1:])

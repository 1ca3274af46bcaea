"""One-off check that Blender imports a leafsim .glb with its drying animation (not run in CI).

Blender as a Python module is large, so it is not a project dependency; use a throwaway venv:

    python3 -m venv /tmp/bpy && /tmp/bpy/bin/pip install bpy
    /tmp/bpy/bin/python tools/blender_check.py FILE.glb

Prints, per mesh object, its vertex/face counts, shape keys (one per morph target) and the
frame range of the action that drives them.
"""

import sys

import bpy

path = sys.argv[1]
bpy.ops.wm.read_factory_settings(use_empty=True)
print("import:", bpy.ops.import_scene.gltf(filepath=path))
for ob in bpy.data.objects:
    if ob.type != "MESH":
        continue
    me = ob.data
    keys = me.shape_keys
    names = [k.name for k in keys.key_blocks] if keys else []
    action = keys.animation_data.action if keys and keys.animation_data else None
    print(f"mesh {ob.name}: {len(me.vertices)} vertices, {len(me.polygons)} faces, {len(names)} shape keys "
          f"{names[:3]}{'…' if len(names) > 3 else ''}, materials {[m.name for m in me.materials]}, "
          f"colour attributes {[a.name for a in me.color_attributes]}, "
          f"action {action.name if action else None} frames {tuple(action.frame_range) if action else None}")
print("blender", bpy.app.version_string, "fps", bpy.context.scene.render.fps)

# play the animation to its last key: the evaluated mesh must be the last key frame's shape
scene = bpy.context.scene
for ob in bpy.data.objects:
    keys = ob.data.shape_keys if ob.type == "MESH" else None
    if not keys or not keys.animation_data:
        continue
    end = int(round(keys.animation_data.action.frame_range[1]))
    scene.frame_set(end)
    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    last = keys.key_blocks[-1].data
    basis = keys.key_blocks[0].data
    moved = max((ev.vertices[i].co - basis[i].co).length for i in range(len(basis)))
    err = max((ev.vertices[i].co - last[i].co).length for i in range(len(basis)))
    print(f"{ob.name} at frame {end}: max displacement from the first key {moved:.4g} m, from the last key {err:.3g} m")
    ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()

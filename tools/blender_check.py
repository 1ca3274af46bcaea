"""Render a leafsim glTF (or OBJ) in Blender at the first and last frame of its drying, imported
with the add-on (leafsim/export/blender_import.py), with Cycles on the CPU:

    python3.11 -m venv /tmp/bpyenv && /tmp/bpyenv/bin/pip install bpy==4.2.0
    /tmp/bpyenv/bin/python tools/blender_check.py [--plain] maple.glb OUT_DIR

writes OUT_DIR/first.png and OUT_DIR/last.png and prints what Blender imported (objects,
vertex counts, colour attributes, shape keys, frame range).  bpy is Blender as a Python module
(PyPI); it is not a leafsim dependency.
"""

import importlib.util
import math
import sys
from pathlib import Path

import bpy
from mathutils import Vector

ADDON = Path(__file__).resolve().parent.parent / "leafsim" / "export" / "blender_import.py"
GLB, OUT = sys.argv[-2], Path(sys.argv[-1])
PLAIN = "--plain" in sys.argv  # Blender's own importer alone (the colour morphs are dropped)
OUT.mkdir(parents=True, exist_ok=True)
spec = importlib.util.spec_from_file_location("blender_import", ADDON)
bi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bi)
bpy.ops.wm.read_factory_settings(use_empty=True)
if PLAIN and GLB.lower().endswith(".obj"):  # Blender's OBJ importer alone (normal map as sRGB, vertex colours unused)
    bpy.ops.wm.obj_import(filepath=GLB)
    objs = list(bpy.data.objects)
elif PLAIN:
    bpy.ops.import_scene.gltf(filepath=GLB)
    objs = list(bpy.data.objects)
    for o in objs:
        act = o.data.shape_keys.animation_data.action if o.type == "MESH" and o.data.shape_keys else None
        if act is not None:
            bpy.context.scene.frame_start = math.floor(act.frame_range[0])
            bpy.context.scene.frame_end = math.ceil(act.frame_range[1] - 1e-6)
else:
    objs = bi.import_leafsim(GLB)
sc = bpy.context.scene
print("objects", [(o.name, o.type, len(o.data.vertices) if o.type == "MESH" else None) for o in objs])
print("frame range", sc.frame_start, sc.frame_end)
for o in objs:
    if o.type == "MESH":
        print(o.name, "attrs", [a.name for a in o.data.color_attributes][:5], "keys", len(o.data.shape_keys.key_blocks) if o.data.shape_keys else 0)
# camera + light
mins = Vector((1e9,)*3); maxs = Vector((-1e9,)*3)
for f in (sc.frame_start, sc.frame_end):  # the shapes as drawn at both frames (shape keys applied)
    sc.frame_set(f)
    dg = bpy.context.evaluated_depsgraph_get()
    for o in objs:
        if o.type == "MESH":
            for v in o.evaluated_get(dg).data.vertices:
                w = o.matrix_world @ v.co
                mins = Vector(map(min, mins, w)); maxs = Vector(map(max, maxs, w))
c = (mins + maxs) / 2; size = (maxs - mins).length
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam")); sc.collection.objects.link(cam)
cam.location = c + Vector((0, -0.9 * size, 1.1 * size))
cam.rotation_euler = (c - cam.location).to_track_quat('-Z', 'Y').to_euler()
sc.camera = cam
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN")); sc.collection.objects.link(sun)
sun.rotation_euler = (math.radians(35), math.radians(10), 0); sun.data.energy = 3.0
world = bpy.data.worlds.new("w"); sc.world = world; world.use_nodes = True
world.node_tree.nodes["Background"].inputs[1].default_value = 0.6
sc.render.engine = "CYCLES"; sc.cycles.samples = 16; sc.cycles.device = "CPU"
sc.render.resolution_x, sc.render.resolution_y = 480, 360
for f, name in ((sc.frame_start, "first"), (sc.frame_end, "last")):
    sc.frame_set(f)
    sc.render.filepath = str(OUT / f"{name}.png")
    bpy.ops.render.render(write_still=True)
    print("rendered", f, name)

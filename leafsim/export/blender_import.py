"""Blender add-on: import a leafsim glTF with its drying colour.

A leafsim ``.glb`` / ``.gltf`` stores the drying as morph targets with ``POSITION``, ``NORMAL``
and ``COLOR_0`` deltas and one animation keying their weights.  Blender's glTF importer turns
the position deltas into shape keys driven by the animation but drops the colour deltas, so
the leaf curls yet stays summer-green.  This add-on imports the file with Blender's own
importer, then adds the colour deltas as colour attributes (``leafsim_dk``) and rebuilds the
material's base colour as glTF defines it::

    colour = COLOR_0 + Σ_k weight_k · ΔCOLOR_0_k

with each weight_k driven by the shape key the importer made for target k, so colour and
shape change together on the same animation.  A ``--texture photo`` export carries instead the
factor the ageing multiplies the photo by, as ``_AGEING`` with its own morph deltas (COLOR_0
must stay within 0-1, the factor does not; one exported state has the factor alone); the base
colour is then the photo times it.  It also sets the scene's frame range to the
drying action's.

An OBJ exported with ``--texture baked`` carries the crinkle's normal map as the MTL's
``map_Bump``, which Blender's own OBJ importer wires as a normal map but reads as sRGB colour,
and its vertex colours, which that importer keeps but leaves unused; this add-on imports an
``.obj`` with Blender's importer, marks those images as data and draws the vertex colours.

Install: Blender → Edit → Preferences → Add-ons → Install from Disk… → this file (its path:
``leafsim export … --json`` reports it as ``blender_addon``); then File → Import → "leafsim
glTF (drying colour)".  Without the add-on: ``import_leafsim(path)`` from Blender's Python.

This module imports ``bpy`` only inside the functions that need Blender; :func:`colour_morphs`
reads the file with the standard library alone (tests use it outside Blender).
"""

from __future__ import annotations

import json
import math
import re
import struct
import urllib.parse
from array import array
from pathlib import Path

bl_info = {
    "name": "leafsim glTF import (drying colour)",
    "author": "leafsim",
    "version": (1, 0, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > leafsim glTF (drying colour)",
    "description": "Import a leafsim .glb/.gltf with its colour morph targets as animated vertex colours",
    "category": "Import-Export",
}

_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _load(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    if data[:4] == b"glTF":
        n = struct.unpack("<I", data[12:16])[0]
        doc = json.loads(data[20:20 + n])
        off = 20 + n
        blob = data[off + 8: off + 8 + struct.unpack("<I", data[off:off + 4])[0]] if off < len(data) else b""
        return doc, blob
    doc = json.loads(data)
    uri = doc["buffers"][0].get("uri")
    # (a URI: "my leaf.gltf" has its buffer at "my%20leaf.bin")
    return doc, (path.parent / urllib.parse.unquote(uri)).read_bytes() if uri else b""


def _floats(doc: dict, blob: bytes, index: int) -> list[tuple[float, ...]]:
    """A float accessor as a list of tuples (leafsim writes tightly packed float32)."""
    acc = doc["accessors"][index]
    if acc["componentType"] != 5126:
        raise ValueError(f"accessor {index}: expected float32 data")
    view = doc["bufferViews"][acc["bufferView"]]
    k = _COMPONENTS[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    a = array("f")
    a.frombytes(blob[start:start + 4 * k * acc["count"]])
    if struct.pack("=I", 1) != struct.pack("<I", 1):
        a.byteswap()
    return [tuple(a[i * k:(i + 1) * k]) for i in range(acc["count"])]


def colour_morphs(path) -> dict:
    """``{mesh name: {"colours": [(r, g, b), …], "deltas": [[(dr, dg, db), …] per target],
    "targets": [shape key names], "times": [s], "photo_factor": bool}}`` for every mesh of a
    leafsim glTF that has colour morph targets: ``COLOR_0`` (linear RGB, as stored), or with
    the photo as texture ``_AGEING``, the factor the ageing multiplies the photo by
    (``photo_factor`` True) — also for one state, without targets (``deltas`` empty)."""
    doc, blob = _load(Path(path))
    times = []
    for anim in doc.get("animations", []):
        times = [t[0] for t in _floats(doc, blob, anim["samplers"][0]["input"])]
    out = {}
    for mesh in doc.get("meshes", []):
        prim = mesh["primitives"][0]
        targets = prim.get("targets") or []
        key = next((k for k in ("COLOR_0", "_AGEING") if k in prim["attributes"] and targets and k in targets[0]), None)
        if key is None and "_AGEING" in prim["attributes"] and not targets:
            # one state with the photo as texture: the factor without deltas (Blender's importer
            # keeps no custom attribute, so a dried leaf came in with the fresh photo's green)
            key = "_AGEING"
        if key is None:  # (a static COLOR_0 Blender's importer draws itself)
            continue
        names = (mesh.get("extras") or {}).get("targetNames") or [f"target_{k}" for k in range(len(targets))]
        out[mesh["name"]] = {"colours": [c[:3] for c in _floats(doc, blob, prim["attributes"][key])],
                             "deltas": [[c[:3] for c in _floats(doc, blob, t[key])] for t in targets],
                             "targets": list(names), "times": times, "photo_factor": key == "_AGEING"}
    return out


# ---------------------------------------------------------------------------------- in Blender
def _colour_attribute(mesh, name: str, values) -> None:
    attr = mesh.color_attributes.get(name) or mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    flat = []
    for r, g, b in values:
        flat += (r, g, b, 1.0)
    attr.data.foreach_set("color", flat)


def _drive(socket, key, shape_name: str) -> None:
    """``socket.default_value`` follows the value of shape key ``shape_name`` of ``key``."""
    fc = socket.driver_add("default_value")
    drv = fc.driver
    drv.type = "AVERAGE"
    var = drv.variables.new()
    var.name = "w"
    var.type = "SINGLE_PROP"
    var.targets[0].id_type = "KEY"
    var.targets[0].id = key
    var.targets[0].data_path = f'key_blocks["{shape_name}"].value'


def _wire_material(obj, morph: dict) -> None:
    """Base colour = Σ as in the module docstring, into every Principled BSDF of ``obj``."""
    key = obj.data.shape_keys
    names = [kb.name for kb in key.key_blocks][1:] if key is not None else []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or not mat.use_nodes:
            continue
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
        if bsdf is None:
            continue
        base = nodes.new("ShaderNodeAttribute")
        base.attribute_name = "leafsim_colour"
        acc = base.outputs["Vector"]
        for k, shape in enumerate(morph["targets"]):
            if shape not in names:
                continue
            delta = nodes.new("ShaderNodeAttribute")
            delta.attribute_name = f"leafsim_d{k}"
            weight = nodes.new("ShaderNodeValue")
            weight.label = f"weight of {shape}"
            _drive(weight.outputs[0], key, shape)
            mix = nodes.new("ShaderNodeVectorMath")
            mix.operation = "MULTIPLY_ADD"
            links.new(delta.outputs["Vector"], mix.inputs[0])
            links.new(weight.outputs[0], mix.inputs[1])
            links.new(acc, mix.inputs[2])
            acc = mix.outputs["Vector"]
        image = next((n for n in nodes if n.type == "TEX_IMAGE"), None)
        if morph.get("photo_factor") and image is not None:  # the photo times the ageing factor
            mul = nodes.new("ShaderNodeVectorMath")
            mul.operation = "MULTIPLY"
            links.new(image.outputs["Color"], mul.inputs[0])
            links.new(acc, mul.inputs[1])
            acc = mul.outputs["Vector"]
        for link in list(bsdf.inputs["Base Color"].links):
            links.remove(link)
        links.new(acc, bsdf.inputs["Base Color"])


def _finish_obj(objects) -> None:
    """What Blender's OBJ importer leaves undone on a leafsim OBJ.  It reads an MTL's ``map_Bump``
    as a tangent-space normal map but leaves its image in the sRGB colour space, which bends
    every normal (a flat texel 128 reads as 0.22): the images feeding a Normal Map node are
    data, Non-Color.  It reads the ``v x y z r g b`` vertex colours as a colour attribute but
    leaves the material a plain grey: a mesh without a texture (the veins over a drawn leaf,
    every mesh of a ``--texture colours`` export) takes its base colour from the attribute."""
    for obj in objects:
        if obj.type != "MESH":
            continue
        attrs = obj.data.color_attributes
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None or not mat.use_nodes:
                continue
            nodes, links = mat.node_tree.nodes, mat.node_tree.links
            for node in nodes:
                if node.type == "NORMAL_MAP":
                    for link in node.inputs["Color"].links:
                        image = getattr(link.from_node, "image", None)
                        if image is not None:
                            image.colorspace_settings.name = "Non-Color"
            bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
            if bsdf is not None and len(attrs) and not bsdf.inputs["Base Color"].links:
                col = nodes.new("ShaderNodeVertexColor")
                col.layer_name = attrs[0].name
                links.new(col.outputs["Color"], bsdf.inputs["Base Color"])


def morph_of(morphs: dict, *names: str):
    """The colour morphs (:func:`colour_morphs`) of the file's mesh an imported object stands
    for, looked up by the object's mesh name, then its own: Blender names a second leaf's
    meshes ``blade.001``, ``veins.001`` ... where the file says ``blade``, ``veins`` (the second
    leaf imported into one scene stayed green); None for a mesh without morphs."""
    for name in names:
        for key in (name, re.sub(r"\.\d{3,}$", "", name)):
            if key in morphs:
                return morphs[key]
    return None


def scene_leaves(placement) -> list:
    """The leaves of a ``leafsim scene`` output as ``(name, mesh file, 4 × 4 matrix)``, read from
    its ``placement.json`` (standard library only): each leaf's mesh (``leaves/NAME/leaf.glb``,
    ``.gltf`` or ``.obj``; None when its group wrote none) and its placement p' = R p + t as a
    row-major matrix.  The placement
    is in leafsim's z-up frame, which is Blender's (the glTF and OBJ importers turn the files'
    y-up into it), so the matrix applies to the imported leaf as it stands."""
    placement = Path(placement)
    if placement.is_dir():
        placement = placement / "placement.json"
    doc = json.loads(placement.read_text())
    out = []
    for leaf in doc.get("leaves", []):
        folder = placement.parent / "leaves" / leaf["name"]
        found = [folder / f"leaf.{ext}" for ext in ("glb", "gltf", "obj") if (folder / f"leaf.{ext}").is_file()]
        (r0, r1, r2), t = leaf["rotation"], leaf["translation"]
        m = [[r0[0], r0[1], r0[2], t[0]], [r1[0], r1[1], r1[2], t[1]], [r2[0], r2[1], r2[2], t[2]], [0.0, 0.0, 0.0, 1.0]]
        out.append((leaf["name"], found[0] if found else None, m))  # None: its group wrote no mesh (output.mesh)
    return out


def import_leafsim(path) -> list:
    """Import a leafsim glTF into the current Blender scene with its drying colour, a leafsim
    OBJ with its baked crinkle's normal map and vertex colours wired up (:func:`_finish_obj`), or
    a whole scene (its ``placement.json``, or its output folder): every leaf imported so and
    placed as the scene placed it (:func:`scene_leaves`).  Returns the imported objects."""
    if Path(path).is_dir() or Path(path).suffix.lower() == ".json":
        return _import_scene(path)
    objects = _import_one(path)
    _frame_range(objects)
    return objects


def _import_scene(path) -> list:
    from mathutils import Matrix

    objects = []
    for _name, mesh, m in scene_leaves(path):
        if mesh is None:  # (a group without output.mesh: nothing to import)
            continue
        new = _import_one(mesh)
        place = Matrix(m)
        for obj in new:
            if obj.parent is None:  # the leaf's root node (a glTF's), or each object of an OBJ
                obj.matrix_world = place @ obj.matrix_world
        objects += new
    _frame_range(objects)
    return objects


def _import_one(path) -> list:
    """One leafsim file imported (:func:`import_leafsim`), the frame range left alone."""
    import bpy

    before = set(bpy.data.objects)
    if Path(path).suffix.lower() == ".obj":
        bpy.ops.wm.obj_import(filepath=str(path))
        objects = [o for o in bpy.data.objects if o not in before]
        _finish_obj(objects)
        return objects
    bpy.ops.import_scene.gltf(filepath=str(path))
    objects = [o for o in bpy.data.objects if o not in before]
    morphs = colour_morphs(path)
    for obj in objects:
        morph = morph_of(morphs, obj.data.name, obj.name) if obj.type == "MESH" else None
        if morph is None:
            continue
        mesh = obj.data
        if len(mesh.vertices) != len(morph["colours"]):
            raise RuntimeError(f"{obj.name}: {len(mesh.vertices)} vertices in Blender, {len(morph['colours'])} in the file "
                               "(import without merging vertices)")
        _colour_attribute(mesh, "leafsim_colour", morph["colours"])
        for k, d in enumerate(morph["deltas"]):
            _colour_attribute(mesh, f"leafsim_d{k}", d)
        _wire_material(obj, morph)
    return objects


def _frame_range(objects) -> None:
    """The scene's frame range set to the drying actions of ``objects``, when they have one."""
    import bpy

    scene = bpy.context.scene
    ranges = [o.data.shape_keys.animation_data.action.frame_range for o in objects
              if o.type == "MESH" and o.data.shape_keys and o.data.shape_keys.animation_data
              and o.data.shape_keys.animation_data.action]
    if ranges:
        # the key times are seconds × fps, rarely whole frames: the range reaches the last key
        # (the dried leaf; the shape holds there), not the frame before it
        scene.frame_start = math.floor(min(r[0] for r in ranges))
        scene.frame_end = math.ceil(max(r[1] for r in ranges) - 1e-6)


def _operator():
    import bpy
    from bpy_extras.io_utils import ImportHelper

    class ImportLeafsim(bpy.types.Operator, ImportHelper):
        """Import a leafsim glTF with its drying colour, a leafsim OBJ with its normal map, or a
        whole leafsim scene (its placement.json)"""

        bl_idname = "import_scene.leafsim_gltf"
        bl_label = "Import leafsim glTF"
        filename_ext = ".glb"
        filter_glob: bpy.props.StringProperty(default="*.glb;*.gltf;*.obj;placement.json", options={"HIDDEN"})

        def execute(self, context):
            try:
                import_leafsim(self.filepath)
            except Exception as e:  # shown in Blender's status bar, not a traceback
                self.report({"ERROR"}, f"leafsim import: {e}")
                return {"CANCELLED"}
            return {"FINISHED"}

    return ImportLeafsim


_classes: list = []


def _menu(self, context):
    self.layout.operator("import_scene.leafsim_gltf", text="leafsim glTF (drying colour)")


def register():
    import bpy

    cls = _operator()
    _classes.append(cls)
    bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(_menu)


def unregister():
    import bpy

    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    while _classes:
        bpy.utils.unregister_class(_classes.pop())

"""A small glTF 2.0 writer for :mod:`leafsim.export.mesh` (binary .glb, or .gltf JSON + .bin).

One node and one mesh per exported surface (blade, stalk, veins), the children of one root node named
after the leaf (with what it is as ``extras``), a double-sided metallic-roughness material each (baked pigment colours as ``COLOR_0``, or the photo as ``baseColorTexture``).
Several frames: the base mesh is the **last** key frame (the state the export was asked for, so
a viewer that does not play morph animations, such as trimesh or a still in an engine, shows
it), each earlier key frame a morph target with ``POSITION``, ``NORMAL`` and ``COLOR_0`` deltas
against it, default weights 0, and one animation whose sampler keys the weights one-hot at the
earlier frames' times and all zero at the last (LINEAR interpolation between two keys is the
linear blend of two consecutive frames).  The output depends only on the data (no timestamps), so it is
reproducible byte for byte.
"""

from __future__ import annotations

import json
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np

from leafsim import __version__
from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes

FLOAT, UINT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


class GltfBuilder:
    """Collects buffer views, accessors, meshes and nodes; :meth:`glb` / :meth:`gltf` serialise."""

    def __init__(self):
        self.bin = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": f"leafsim {__version__}"},
                    "scene": 0, "scenes": [{"name": "leaf", "nodes": []}], "nodes": [], "meshes": [],
                    "materials": [], "accessors": [], "bufferViews": []}

    def view(self, data: bytes, target: int | None = None) -> int:
        self.bin += b"\0" * (-len(self.bin) % 4)
        bv = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target is not None:
            bv["target"] = target
        self.bin += data
        self.doc["bufferViews"].append(bv)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, arr: np.ndarray, target: int | None = ARRAY_BUFFER, bounds: bool = False) -> int:
        """An accessor of float32 data (n, k) / (n,), or uint32 indices when ``target`` is the
        element array buffer; ``bounds`` adds min/max (required for positions and times)."""
        index = target == ELEMENT_ARRAY_BUFFER
        a = np.ascontiguousarray(arr, np.uint32 if index else np.float32)
        comps = 1 if a.ndim == 1 else a.shape[1]
        acc = {"bufferView": self.view(a.tobytes(), target), "componentType": UINT if index else FLOAT,
               "count": int(a.size if index else a.shape[0]), "type": "SCALAR" if index else _TYPES[comps]}
        if bounds:
            a2 = a.reshape(len(a), -1)
            acc["min"] = [float(x) for x in a2.min(0)]
            acc["max"] = [float(x) for x in a2.max(0)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def material(self, name: str, texture: int | None, normal: int | None = None) -> int:
        pbr = {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.75}
        if texture is not None:
            pbr["baseColorTexture"] = {"index": texture}
        mat = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": True}
        if normal is not None:
            mat["normalTexture"] = {"index": normal}
        self.doc["materials"].append(mat)
        return len(self.doc["materials"]) - 1

    def texture(self, png: bytes, name: str = "photo") -> int:
        """A texture of the PNG ``png`` (mipmapped; returns its index).  Its sampler repeats it
        mirrored: within [0, 1], where every upper face's coordinate lies, that reads as clamping
        at the edges (the mirror's first texel is the edge's), and a shell's lower face under a
        normal map reads the same texels at the negated coordinates (:meth:`mesh`)."""
        d = self.doc
        d.setdefault("images", []).append({"bufferView": self.view(png), "mimeType": "image/png", "name": name})
        d["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33648, "wrapT": 33648}]
        d.setdefault("textures", []).append({"sampler": 0, "source": len(d["images"]) - 1})
        return len(d["textures"]) - 1

    def mesh(self, name: str, frames: list, material: int, target_names: list[str] | None = None) -> int:
        """A node + mesh from one :class:`~leafsim.export.mesh.Surface` per frame (the last is the
        base, the earlier ones morph targets against it: module docstring).  A material with a
        normal map gets the surface's tangents (:func:`tangents`) with it."""
        s0 = frames[-1]
        mapped = s0.uv is not None and "normalTexture" in self.doc["materials"][material]
        if mapped and len(frames) > 1:
            raise ValueError("glTF: a normal map on an animated mesh would need its tangents morphed too")
        if mapped and s0.lower is not None:
            s0 = _lower_face_turned(s0)
        attrs = {"POSITION": self.accessor(s0.positions, bounds=True), "NORMAL": self.accessor(s0.normals)}
        if s0.uv is not None:
            attrs["TEXCOORD_0"] = self.accessor(s0.uv)
            if mapped:
                attrs["TANGENT"] = self.accessor(tangents(s0.positions, s0.normals, s0.uv, s0.triangles))
        if s0.colours is not None:
            attrs["COLOR_0"] = self.accessor(s0.colours)
        if s0.thickness is not None:
            attrs["_THICKNESS"] = self.accessor(s0.thickness)
        if s0.ageing is not None:
            attrs["_AGEING"] = self.accessor(s0.ageing)
        prim = {"attributes": attrs, "indices": self.accessor(s0.triangles.ravel(), ELEMENT_ARRAY_BUFFER),
                "material": material, "mode": 4}
        mesh = {"name": name, "primitives": [prim]}
        if len(frames) > 1:
            prim["targets"] = [self._target(s0, s) for s in frames[:-1]]
            mesh["weights"] = [0.0] * (len(frames) - 1)
            if target_names:
                mesh["extras"] = {"targetNames": list(target_names)}
        self.doc["meshes"].append(mesh)
        self.doc["nodes"].append({"name": name, "mesh": len(self.doc["meshes"]) - 1})
        node = len(self.doc["nodes"]) - 1
        self.doc["scenes"][0]["nodes"].append(node)
        return node

    def counts(self) -> dict:
        """{mesh name: {"vertices", "triangles"}} as the file holds them."""
        acc = self.doc["accessors"]
        return {m["name"]: {"vertices": int(acc[m["primitives"][0]["attributes"]["POSITION"]]["count"]),
                            "triangles": int(acc[m["primitives"][0]["indices"]]["count"]) // 3}
                for m in self.doc["meshes"]}

    def _target(self, s0, s) -> dict:
        t = {"POSITION": self.accessor(s.positions - s0.positions, bounds=True),
             "NORMAL": self.accessor(s.normals - s0.normals)}
        if s0.colours is not None:
            t["COLOR_0"] = self.accessor(s.colours - s0.colours)
        if s0.ageing is not None:
            t["_AGEING"] = self.accessor(s.ageing - s0.ageing)
        return t

    def animation(self, nodes: list[int], times: list[float]) -> None:
        """Weights of every node's morph targets keyed at ``times``: one-hot on target i at key
        frame i, all zero at the last key frame (the base mesh)."""
        k = len(times) - 1
        t = np.asarray(times, np.float64) - times[0]
        if (np.diff(t) <= 0).any():
            raise LeafsimError("export: key frame times must increase strictly")
        w = np.zeros((k + 1, k), np.float32)
        w[np.arange(k), np.arange(k)] = 1.0
        sampler = {"input": self.accessor(t, None, bounds=True), "output": self.accessor(w.ravel(), None),
                   "interpolation": "LINEAR"}
        channels = [{"sampler": 0, "target": {"node": n, "path": "weights"}} for n in nodes]
        self.doc["animations"] = [{"name": "drying", "samplers": [sampler], "channels": channels}]

    def _json(self, uri: str | None) -> bytes:
        buf = {"byteLength": len(self.bin)}
        if uri is not None:
            buf["uri"] = uri
        self.doc["buffers"] = [buf]
        return json.dumps(self.doc, separators=(",", ":")).encode()

    def glb(self) -> bytes:
        js = self._json(None)
        js += b" " * (-len(js) % 4)
        bn = bytes(self.bin) + b"\0" * (-len(self.bin) % 4)
        total = 12 + 8 + len(js) + 8 + len(bn)
        return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
                + struct.pack("<I4s", len(bn), b"BIN\0") + bn)

    def gltf(self, bin_name: str) -> tuple[bytes, bytes]:
        """(the JSON, the binary buffer) of a .gltf whose buffer is the file ``bin_name`` beside
        it; the name goes in as a URI, percent-encoded (a space or a '#' in it would be read as
        the end of the URI or a fragment)."""
        from urllib.parse import quote

        return self._json(quote(bin_name)), bytes(self.bin)


def _lower_face_turned(s):
    """The shell ``s`` (a :class:`~leafsim.export.mesh.Surface` with ``lower`` set) for a normal
    map: its lower face (normal −n) reads the map in a frame turned by 180° about its normal, so
    the map tilts each lower normal against its upper twin's, the same relief seen from below.
    Its texture coordinates are the upper face's negated, which the mirrored-repeat sampler
    (:meth:`GltfBuilder.texture`) reads at the same texels, so a client that makes its own
    tangents from the coordinates (Blender: MikkTSpace) gets that frame too, not a mirror of the
    relief.  The rim's triangles, which join the two faces, get their own copies of their
    vertices with the upper face's coordinates: on the shared vertices they would span the
    texture from (u, v) to (−u, −v), draw a smear of it on the rim and turn the tangents a client
    averages over the margin's vertices."""
    low = np.asarray(s.lower, bool)
    tri = np.asarray(s.triangles, np.int64)
    k = low[tri].sum(axis=1)
    rim = (k > 0) & (k < 3)
    used = np.unique(tri[rim])
    new = np.full(len(low), -1, np.int64)
    new[used] = len(low) + np.arange(len(used))
    tri = tri.copy()
    tri[rim] = new[tri[rim]]
    more = lambda a: None if a is None else np.concatenate([a, np.asarray(a)[used]])  # noqa: E731
    uv = more(s.uv).astype(np.float32)
    uv[:len(low)][low] = -uv[:len(low)][low]
    return replace(s, positions=more(s.positions), normals=more(s.normals), triangles=tri.astype(np.uint32),
                   uv=uv, colours=more(s.colours), thickness=more(s.thickness), ageing=more(s.ageing),
                   lower=np.concatenate([low, np.zeros(len(used), bool)]))


def tangents(positions: np.ndarray, normals: np.ndarray, uv: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n, 4) float32 glTF TANGENT of a surface: xyz the direction of increasing u (the sum over
    each vertex's triangles of ∂P/∂u, made orthogonal to the vertex normal, unit), w the sign
    that makes cross(normal, tangent) · w point up the image (decreasing v, v = 0 the top row),
    the normal map's +y (the bake's frame, :func:`leafsim.export.bake.bake_normals`): the frame
    a client derives from the texture coordinates itself.  A vertex of no usable triangle gets
    any unit vector across its normal and w = 1."""
    P = np.asarray(positions, np.float64)
    N = np.asarray(normals, np.float64)
    U = np.asarray(uv, np.float64)
    tri = np.asarray(triangles, np.int64)
    dP = np.stack([P[tri[:, 1]] - P[tri[:, 0]], P[tri[:, 2]] - P[tri[:, 0]]], 2)  # (m, 3, 2)
    dU = np.stack([U[tri[:, 1]] - U[tri[:, 0]], U[tri[:, 2]] - U[tri[:, 0]]], 2)  # (m, 2, 2)
    det = dU[:, 0, 0] * dU[:, 1, 1] - dU[:, 0, 1] * dU[:, 1, 0]
    ok = np.abs(det) > 1e-14
    D = np.zeros((len(tri), 3, 2))
    D[ok] = dP[ok] @ np.linalg.inv(dU[ok])  # [∂P/∂u, ∂P/∂v]
    t = np.zeros_like(P)
    b = np.zeros_like(P)
    for k in range(3):
        np.add.at(t, tri[:, k], D[:, :, 0])
        np.add.at(b, tri[:, k], D[:, :, 1])
    t -= N * np.sum(N * t, axis=1, keepdims=True)
    norm = np.linalg.norm(t, axis=1)
    bad = norm < 1e-12
    if bad.any():  # any direction across the normal
        alt = np.where(np.abs(N[bad, 0:1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
        t[bad] = alt - N[bad] * np.sum(N[bad] * alt, axis=1, keepdims=True)
        norm[bad] = np.linalg.norm(t[bad], axis=1)
    t /= norm[:, None]
    w = np.where(np.sum(np.cross(N, t) * -b, axis=1) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], 1).astype(np.float32)


def build_gltf(frames: list[dict], times: list[float], photo_png: bytes | None = None,
               image_name: str = "photo", normal_png: bytes | None = None, name: str = "leaf",
               extras: dict | None = None) -> GltfBuilder:
    """A :class:`GltfBuilder` holding every surface of ``frames`` (one dict name → Surface per
    key frame), animated over ``times`` when there is more than one frame; the texture
    ``photo_png`` goes on every surface with texture coordinates, the normal map ``normal_png``
    (the blade's crinkle, in the same texture space) on the blade's.  The surfaces' nodes are the
    children of one node called ``name`` carrying ``extras`` (what leaf this is), so leaves
    imported side by side stay apart by name (their surfaces all called blade, stalk and veins)."""
    g = GltfBuilder()
    tex = g.texture(photo_png, image_name) if photo_png is not None else None
    nrm = g.texture(normal_png, "crinkle") if normal_png is not None else None
    names = [f"t = {t - times[0]:.4g} s" for t in times[:-1]]  # the morph targets: every key frame but the last

    def material(name):
        uv = frames[0][name].uv is not None
        return g.material(name, tex if uv else None, nrm if uv and name == "blade" else None)

    nodes = [g.mesh(s, [f[s] for f in frames], material(s), names) for s in frames[0]]
    root = {"name": str(name), "children": nodes}
    if extras:
        root["extras"] = extras
    g.doc["nodes"].append(root)
    g.doc["scenes"][0]["nodes"] = [len(g.doc["nodes"]) - 1]
    if len(frames) > 1:
        g.animation(nodes, times)
    return g


def write_gltf(path: Path, frames: list[dict], times: list[float], photo_png: bytes | None = None,
               binary: bool = True, image_name: str = "photo", normal_png: bytes | None = None,
               name: str = "leaf", extras: dict | None = None, counts: dict | None = None) -> list[Path]:
    """Write ``frames`` as ``path`` (.glb, or .gltf + a .bin beside it); returns the files.
    ``counts``, when given, receives each mesh's vertices and triangles as written (the blade of
    a normal-mapped glTF has its rim's vertices twice: :func:`_lower_face_turned`)."""
    g = build_gltf(frames, times, photo_png, image_name, normal_png, name, extras)
    if counts is not None:
        counts.update(g.counts())
    if binary:
        return [atomic_write_bytes(path, g.glb(), "glTF binary")]
    bin_path = path.with_suffix(".bin")
    js, bn = g.gltf(bin_path.name)
    return [atomic_write_bytes(bin_path, bn, "glTF buffer"), atomic_write_bytes(path, js, "glTF")]

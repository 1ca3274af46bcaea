"""Mesh export checked by real clients: the Khronos glTF-Validator and trimesh (SPEC §17)."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from helpers.gltf import assert_clean
from helpers.paths import HANG_S
from leafsim.appearance.photo import load_photo_rgba
from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError
from leafsim.config.species import get_species
from leafsim.base.geometry import boundary_edges
from leafsim.export.mesh import MeshSource, export_mesh
from leafsim.pipeline import build_leaf
from leafsim.sim.model import LAYER_T
from leafsim.sim.simulator import Simulator


def _drying(key: str):
    """Species ``key`` on a tiny mesh, ageing fast: (species, model, params, simulator, states at
    frames 0, 40, 80)."""
    sp = get_species(key)
    params = sp.params.with_overrides({"mesh.spacing": 0.08, "colour.age_rate": 5.0})
    _, _, model = build_leaf(sp, params, 0)
    sim = Simulator(model, params, seed=0)
    st = sim.state()
    states = [st.copy()]
    for _ in range(2):
        for _ in range(40):
            sim.step(st)
        states.append(st.copy())
    return sp, model, params, sim, states


@pytest.fixture(scope="module")
def leaf():
    """Oak on a tiny mesh, its photo, and states at frames 0, 40, 80."""
    sp, model, params, _, states = _drying("oak")
    return model, params, LeafView(model, load_photo_rgba(sp.image)), states


def _counts(model):
    T = model.particle_layer == LAYER_T
    n, m = int(T.sum()), len(model.tri_T)
    return n, m, len(boundary_edges(model.tri_T))


def _vein_counts(model):
    """(vertices, triangles) of the vein ribbons: 2 per point and per segment on each face."""
    lines = [i for i, _, _ in model.vein_polylines() if len(i) >= 2]
    return 4 * sum(len(i) for i in lines), 4 * sum(len(i) - 1 for i in lines)


def test_animated_glb_is_valid_and_loads_with_expected_counts(leaf, tmp_path):
    model, params, view, states = leaf
    path = tmp_path / "oak.glb"
    rep = export_mesh(model, states, path, params=params, view=view, veins=True)
    val = assert_clean(path)
    info = val["info"]
    n, m, b = _counts(model)
    vn, vt = _vein_counts(model)
    assert info["animationCount"] == 1 and info["hasMorphTargets"] and info["materialCount"] == 2
    assert info["totalVertexCount"] == 2 * n + vn and info["totalTriangleCount"] == 2 * m + 2 * b + vt
    assert rep["meshes"]["blade"] == {"vertices": 2 * n, "triangles": 2 * m + 2 * b}
    scene = trimesh.load(path, process=False)
    blade, veins = scene.geometry["blade"], scene.geometry["veins"]
    assert (len(blade.vertices), len(blade.faces)) == (2 * n, 2 * m + 2 * b)
    assert blade.is_watertight and blade.is_winding_consistent and blade.volume > 0  # a closed shell, outward
    assert (len(veins.vertices), len(veins.faces)) == _vein_counts(model)
    # the ribbons on both faces, as the window draws the veins from either side: the second half
    # is the first mirrored through the blade, a thickness and two lifts below it, facing down
    half = len(veins.vertices) // 2
    up, down = np.asarray(veins.vertices[:half]), np.asarray(veins.vertices[half:])
    nu, nd = np.asarray(veins.vertex_normals[:half]), np.asarray(veins.vertex_normals[half:])
    gap = np.sum((up - down) * nu, axis=1)
    assert np.all(gap > 0.5 * model.thickness) and np.all(gap < 2 * model.thickness)  # (h shrinks as it dries)
    assert np.median(np.sum(nu * nd, axis=1)) < -0.99
    # the morph targets and the animation: one target per key frame after the first, keyed one-hot
    doc = _glb_json(path)
    prim = doc["meshes"][0]["primitives"][0]
    assert len(prim["targets"]) == 2 and set(prim["targets"][0]) == {"POSITION", "NORMAL", "COLOR_0"}
    anim = doc["animations"][0]
    times = doc["accessors"][anim["samplers"][0]["input"]]
    assert times["count"] == 3 and times["max"][0] == pytest.approx(states[-1].time - states[0].time, rel=1e-6)
    assert doc["materials"][0]["doubleSided"] and "pbrMetallicRoughness" in doc["materials"][0]
    # the base mesh is the last key frame (the state asked for), so a viewer that plays no morph
    # animation shows it (trimesh; before, the base was frame 0: the fresh leaf); the targets
    # bring back the earlier frames: base + target 0 = frame 0
    assert [m["weights"] for m in doc["meshes"]] == [[0.0, 0.0], [0.0, 0.0]]
    first, last = tmp_path / "first.glb", tmp_path / "last.glb"
    export_mesh(model, states[0], first, params=params, view=view, veins=True)
    export_mesh(model, states[-1], last, params=params, view=view, veins=True)
    alone = {k: trimesh.load(f, process=False).geometry["blade"].vertices for k, f in (("first", first), ("last", last))}
    assert np.abs(blade.vertices - alone["last"]).max() < 1e-6 and np.abs(alone["first"] - alone["last"]).max() > 1e-5
    base = _accessor(path, prim["attributes"]["POSITION"])
    back = base + _accessor(path, prim["targets"][0]["POSITION"])
    assert np.abs(back - _accessor(first, _glb_json(first)["meshes"][0]["primitives"][0]["attributes"]["POSITION"])).max() < 1e-6
    w = _accessor(path, anim["samplers"][0]["output"], 1).reshape(3, 2)  # keys × targets
    assert w.tolist() == [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]


def _accessor(path, index: int, width: int = 3) -> np.ndarray:
    """The float data of accessor ``index`` of a .glb file, ``width`` components each (read as
    the Blender add-on reads it)."""
    from leafsim.export.blender_import import _floats, _load

    doc, blob = _load(path)
    return np.asarray(_floats(doc, blob, index), float).reshape(-1, width)


def _winding_against_normals(vertices, faces, normals) -> tuple[int, int]:
    """(faces wound against their vertex normals, faces checked): a face counts where its
    geometric normal and its vertices' mean normal are within 60° of parallel or antiparallel
    (the blade's edge strips stand at 90° to their vertex normals and are checked by volume)."""
    v = np.asarray(vertices, float)[np.asarray(faces)]
    g = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    g /= np.maximum(np.linalg.norm(g, axis=1), 1e-30)[:, None]
    nm = np.asarray(normals, float)[np.asarray(faces)].mean(1)
    nm /= np.maximum(np.linalg.norm(nm, axis=1), 1e-30)[:, None]
    c = (g * nm).sum(1)
    checked = np.abs(c) > 0.5
    return int((c[checked] < 0).sum()), int(checked.sum())


@pytest.mark.parametrize("fmt", ["glb", "obj", "ply"])
def test_every_face_is_wound_with_its_normals(leaf, tmp_path, fmt):
    """Clients shade a face by its winding: a vein ribbon wound against its stored normals
    rendered black in Blender.  Every blade and vein face, in every format, turns
    counter-clockwise about its vertices' normals."""
    model, params, view, states = leaf
    path = tmp_path / f"oak.{fmt}"
    export_mesh(model, states[-1], path, params=params, view=view, veins=True)
    if fmt == "ply":  # one merged mesh: normals straight from the file
        raw = trimesh.load(path, process=False).metadata["_ply_raw"]
        vx = raw["vertex"]["data"]
        geoms = {"all": (np.column_stack([vx["x"], vx["y"], vx["z"]]),
                         raw["face"]["data"]["vertex_indices"]["f1"].astype(np.int64), np.column_stack([vx["nx"], vx["ny"], vx["nz"]]))}
    else:
        scene = trimesh.load(path, process=False, group_material=False)
        geoms = {k: (g.vertices, g.faces, g.vertex_normals) for k, g in scene.geometry.items()}
    assert len(geoms) == (1 if fmt == "ply" else 2)
    for name, (v, f, n) in geoms.items():
        wrong, checked = _winding_against_normals(v, f, n)
        assert checked > 0.5 * len(f), name
        assert wrong == 0, f"{name}: {wrong} of {checked} faces wound against their normals"


def test_the_blender_addon_reads_the_colour_morphs(leaf, tmp_path):
    """The Blender add-on's reader (standard library only, as in Blender) gets back exactly
    the base colours and per-key-frame colour deltas the export wrote, with the shape keys'
    names and the key times."""
    from leafsim.export.blender_import import colour_morphs

    model, params, view, states = leaf
    for fmt in ("glb", "gltf"):
        path = tmp_path / f"oak.{fmt}"
        export_mesh(model, states, path, params=params, view=view, veins=True)
        m = colour_morphs(path)
        assert set(m) == {"blade", "veins"}
        doc = _glb_json(path) if fmt == "glb" else json.loads(path.read_text())
        blade = m["blade"]
        assert blade["targets"] == doc["meshes"][0]["extras"]["targetNames"] and len(blade["deltas"]) == 2
        assert blade["times"] == pytest.approx([s.time - states[0].time for s in states], rel=1e-6)
        scene = trimesh.load(path, process=False)
        c0 = np.asarray(blade["colours"])
        assert c0.shape == (len(scene.geometry["blade"].vertices), 3) and (c0 > 0).all() and (c0 <= 1).all()
        # base + delta of the last key = the last state's colours: the leaf ends autumn-coloured
        last = c0 + np.asarray(blade["deltas"][-1])
        assert np.abs(last - c0).max() > 0.05 and (last >= -1e-6).all() and (last <= 1 + 1e-6).all()


def test_a_photo_export_carries_the_ageing(tmp_path):
    """--texture photo in glTF: the factor the ageing multiplies the photo by (the app's photo
    albedo), rgb(now)/rgb(young), travels as the custom attribute _AGEING with morph deltas (it
    exceeds 1, which COLOR_0 may not): 1 on the fresh leaf, the view's factor at the last key;
    the file passes the validator and the Blender add-on's reader gets it back."""
    from leafsim.export.blender_import import colour_morphs

    sp, model, params, sim, states = _drying("grapevine")
    view = LeafView(model, load_photo_rgba(sp.image), sim.state().pigments, photo_colour=sp.photo_colour)
    path = tmp_path / "vine.glb"
    export_mesh(model, states, path, params=params, view=view, texture="photo", veins=True)
    assert_clean(path)
    m = colour_morphs(path)
    assert set(m) == {"blade", "veins"} and m["blade"]["photo_factor"]
    last = np.asarray(m["blade"]["colours"])  # the base mesh is the last key frame
    c0 = last + np.asarray(m["blade"]["deltas"][0])  # target 0 brings back frame 0
    assert np.allclose(c0, 1.0, atol=1e-5)  # the fresh leaf is the photo itself
    _, tint = view.colours(states[-1], params)
    n = len(tint)
    assert np.allclose(last[:n], tint, rtol=1e-4, atol=1e-4) and np.allclose(last[n:], tint, rtol=1e-4, atol=1e-4)
    assert last.max() > 1.2  # above what COLOR_0 could hold
    # one state (the dried leaf alone): the factor without targets reaches the add-on too (it
    # read only primitives with morph targets, so a static photo export came into Blender green)
    one = tmp_path / "vine_dried.glb"
    export_mesh(model, states[-1:], one, params=params, view=view, texture="photo", veins=True)
    assert_clean(one)
    m1 = colour_morphs(one)
    assert m1["blade"]["photo_factor"] and m1["blade"]["deltas"] == [] and m1["blade"]["targets"] == []
    assert np.allclose(np.asarray(m1["blade"]["colours"]), last, rtol=1e-5, atol=1e-5)


def _glb_json(path) -> dict:
    data = path.read_bytes()
    magic, version, total = struct.unpack("<4sII", data[:12])
    assert magic == b"glTF" and version == 2 and total == len(data)
    n, kind = struct.unpack("<I4s", data[12:20])
    assert kind == b"JSON"
    return json.loads(data[20:20 + n])


def test_gltf_mid_surface_with_thickness_and_photo(leaf, tmp_path):
    model, params, view, states = leaf
    path = tmp_path / "oak.gltf"
    rep = export_mesh(model, states, path, params=params, view=view, layers="mid", texture="photo")
    assert sorted(rep["files"]) == sorted([str(tmp_path / "oak.bin"), str(path)])
    assert_clean(path)
    n, m, _ = _counts(model)
    doc = json.loads(path.read_text())
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    assert "_THICKNESS" in attrs and "COLOR_0" not in attrs and doc["images"][0]["mimeType"] == "image/png"
    thick = doc["accessors"][attrs["_THICKNESS"]]
    assert thick["count"] == n
    g = trimesh.load(path, process=False).geometry["blade"]
    assert (len(g.vertices), len(g.faces)) == (n, m)


def test_static_obj_and_ply_load_in_trimesh(leaf, tmp_path):
    model, params, view, states = leaf
    n, m, b = _counts(model)
    export_mesh(model, states[-1], tmp_path / "oak.obj", params=params, view=view, veins=True)
    assert (tmp_path / "oak.mtl").exists()
    obj = trimesh.load(tmp_path / "oak.obj", process=False, group_material=False)
    got = sorted((len(g.vertices), len(g.faces)) for g in obj.geometry.values())
    assert got == sorted([(2 * n, 2 * m + 2 * b), _vein_counts(model)])
    # each untextured mesh's Kd is its vertex colours' mean (linear), so a reader that draws no
    # vertex colours shows that, not grey; the gloss is the glTF material's in Blender's mapping
    # (roughness 1 − √(Ns / 1000) = 0.75)
    surf = MeshSource(model, params, view, "shell", True, "colours").surfaces(states[-1])
    mtl = {m.split()[0]: m.splitlines() for m in (tmp_path / "oak.mtl").read_text().split("newmtl ")[1:]}
    assert set(mtl) == {"blade", "veins"}
    for name, lines in mtl.items():
        kd = np.array([float(v) for v in next(ln for ln in lines if ln.startswith("Kd ")).split()[1:]])
        assert np.allclose(kd, surf[name].colours.mean(axis=0), atol=1e-4) and kd.std() > 0.01, (name, kd)
        ns = float(next(ln for ln in lines if ln.startswith("Ns ")).split()[1])
        assert abs((1.0 - np.sqrt(ns / 1000.0)) - 0.75) < 1e-9
    export_mesh(model, states[-1], tmp_path / "oak.ply", params=params, view=view, layers="mid")
    ply = trimesh.load(tmp_path / "oak.ply", process=False)
    assert (len(ply.vertices), len(ply.faces)) == (n, m)
    raw = ply.metadata["_ply_raw"]["vertex"]["data"]
    c = np.column_stack([raw["red"], raw["green"], raw["blue"]]).astype(int)
    assert np.asarray(raw["thickness"]).min() > 0
    assert c.std(0).max() > 0 and (c.mean(0) > 10).all()  # real pigment colours, not a constant
    # y up: the leaf's length (y in leafsim) is along −z of the file
    assert np.ptp(ply.vertices[:, 2]) > 5 * np.ptp(ply.vertices[:, 1])


def test_export_is_deterministic_and_bad_requests_write_nothing(leaf, tmp_path):
    model, params, view, states = leaf
    a, b = tmp_path / "a.glb", tmp_path / "b.glb"
    export_mesh(model, states, a, params=params, view=view, veins=True)
    export_mesh(model, states, b, params=params, view=view, veins=True)
    assert a.read_bytes() == b.read_bytes()
    with pytest.raises(LeafsimError, match="one static shape"):
        export_mesh(model, states, tmp_path / "x.obj", params=params)
    with pytest.raises(LeafsimError, match="does not exist"):
        export_mesh(model, states, tmp_path / "missing" / "x.glb", params=params)
    with pytest.raises(LeafsimError, match="unknown mesh format"):
        export_mesh(model, states, tmp_path / "x.stl", params=params)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.glb", "b.glb"]


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "leafsim", *args], capture_output=True, text=True, timeout=HANG_S)


@pytest.mark.slow
def test_cli_export_animation_and_bad_input(tmp_path):
    out = tmp_path / "chestnut.glb"
    r = _cli("export", "--species", "chestnut", "--frames", "40", "--every", "20", "--format", "glb", "--out", str(out),
             "--set", "mesh.spacing=0.08", "--veins", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["targets"] == 2 and rep["frames"] == 40 and set(rep["meshes"]) == {"blade", "veins"}
    assert rep["texture"] == "colours"  # the default for an animation: vertex colours with their morphs
    assert_clean(out)
    still = tmp_path / "still.glb"
    r = _cli("export", "--species", "chestnut", "--frames", "40", "--out", str(still), "--set", "mesh.spacing=0.08", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["texture"] == "baked", r.stderr  # a still: as the window draws it
    assert_clean(still)
    for args, msg in [(["--every", "5", "--out", str(tmp_path / "x.obj")], "--every needs"),
                      (["--out", str(tmp_path / "nope" / "x.glb")], "does not exist"),
                      (["--texture", "photo", "--out", str(tmp_path / "x.glb")], "has no photo"),
                      (["--texture", "baked", "--frames", "4", "--every", "2", "--out", str(tmp_path / "x.glb")],
                       "--texture baked holds one state"),
                      (["--texture", "baked", "--out", str(tmp_path / "x.ply")], "PLY carries vertex colours")]:
        r = _cli("export", "--species", "chestnut", *args)
        assert r.returncode == 2 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    r = _cli("export", "--species", "nosuch", "--out", str(tmp_path / "x.glb"))
    assert r.returncode == 2 and "unknown species" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chestnut.glb", "still.glb"]


@pytest.mark.parametrize("key, frames", [("oak", 0), ("oak", 80), ("maple", 80)])
def test_an_exported_glb_renders_like_the_app(tmp_path, key, frames):
    """The exported glb drawn as glTF viewers draw it (double-sided, back faces lit with the
    flipped normal) against the app's own renderer on the same state, both from above: the
    same colour (mean chromaticity within 0.01, young and aged) and the same silhouette; the
    veins never render darker than the blade under them (a vein wound against its normals
    rendered black in Blender); they carry the vein tissue's own colour, paler than the lamina
    (a photo leaf's: its photo's colour there, changed as vein tissue differs from the lamina)."""
    from helpers.gltf_render import render_top
    from leafsim.render.camera import OrbitCamera
    from leafsim.render.offscreen import OffscreenRenderer
    from leafsim.render.options import RenderOptions

    sp = get_species(key)
    params = sp.params.with_overrides({"mesh.spacing": 0.06, "colour.age_rate": 5.0})
    _, _, model = build_leaf(sp, params, 0)
    sim = Simulator(model, params, seed=0)
    st = sim.state()
    for _ in range(frames):
        sim.step(st)
    photo = load_photo_rgba(sp.image) if sp.image is not None else None
    view = LeafView(model, photo, sim.state().pigments, photo_tint=False, photo_colour=sp.photo_colour)
    path = tmp_path / f"{key}.glb"
    export_mesh(model, st, path, params=params, view=view, veins=True)
    glb, blade_only = render_top(path), render_top(path, only={"blade"})
    mesh = view.mesh(st, params)
    cam = OrbitCamera(yaw=-90.0, pitch=90.0, ortho=True)
    cam.frame_bounds(mesh.positions, aspect=1.0)
    with OffscreenRenderer(400, 400, samples=0) as r:
        app = r.render_array(mesh, camera=cam, options=RenderOptions(albedo="colours", ground=False, shadows=False,
                                                                      veins=False, background=(0.0, 0.0, 0.0)))

    def chroma(img):
        c = img[img.astype(int).sum(-1) > 30].astype(float)
        return (c / c.sum(1, keepdims=True)).mean(0), len(c) / (img.shape[0] * img.shape[1])

    (cg, ag), (ca, aa) = chroma(blade_only), chroma(app)
    assert np.abs(cg - ca).max() < 0.01, (cg, ca)
    assert abs(ag - aa) < 0.25 * aa  # the same leaf fills about the same share of the picture
    darker = (blade_only.astype(int) - glb).sum(-1) > 6
    assert darker.sum() < 0.001 * darker.size, darker.sum()  # never black
    vein = np.abs(glb.astype(int) - blade_only).sum(-1) > 6
    assert vein.sum() > 300
    assert glb[vein].astype(float).mean() > blade_only[vein].astype(float).mean()  # paler than the lamina


def test_the_exported_photo_has_no_background_at_or_past_the_margin(leaf, tmp_path):
    """The photo a mesh export ships is the renderer's clean texture: past the leaf's mask (where
    a viewer's filtering and mipmaps reach at the margin) and over its outermost texels, the
    colour of the blade further in, never the photo's paper or background."""
    import cv2
    from scipy.ndimage import distance_transform_edt

    from leafsim.appearance.texture import FRINGE_PX, clean_texture
    from leafsim.export.mesh import TEXTURE_MAX

    model, params, view, states = leaf
    export_mesh(model, states[-1], tmp_path / "oak.obj", params=params, view=view, texture="photo")
    png = cv2.cvtColor(cv2.imread(str(tmp_path / "oak_photo.png")), cv2.COLOR_BGR2RGB)
    photo = np.asarray(view.photo_rgba)
    want = clean_texture(photo)[..., :3]
    if max(photo.shape[:2]) > TEXTURE_MAX:
        f = TEXTURE_MAX / max(photo.shape[:2])
        want = cv2.resize(want, (round(photo.shape[1] * f), round(photo.shape[0] * f)), interpolation=cv2.INTER_AREA)
        photo = cv2.resize(photo, want.shape[1::-1], interpolation=cv2.INTER_NEAREST)
    assert png.shape == want.shape and np.abs(png.astype(int) - want).max() <= 1
    leafy = photo[..., 3] >= 128
    deep = distance_transform_edt(leafy) >= FRINGE_PX + 2
    blade = np.median(photo[deep, :3], axis=0)
    outside = ~leafy
    # the background (the raw photo's pixels there) differs from the blade; the export does not
    assert np.abs(np.median(photo[outside, :3], axis=0) - blade).sum() > 60
    assert np.abs(np.median(png[outside], axis=0) - blade).sum() < 40


def test_a_gltf_named_with_a_space_and_a_hash_points_at_its_buffer(leaf, tmp_path):
    """The .bin's name is a URI in the .gltf: percent-encoded, so a space or '#' is not read as
    the URI's end or a fragment (the validator warned NON_RELATIVE_URI; web loaders asked for
    'my leaf' without '#1.bin')."""
    model, params, view, states = leaf
    path = tmp_path / "my leaf#1.gltf"
    export_mesh(model, states[-1], path, params=params, view=view)
    assert (tmp_path / "my leaf#1.bin").is_file()
    assert json.loads(path.read_text())["buffers"][0]["uri"] == "my%20leaf%231.bin"
    assert_clean(path)


def test_the_blender_addon_finds_a_second_leaf_s_morphs():
    """Blender names the meshes of a second leaf imported into one scene blade.001, veins.001:
    the add-on looked them up by that name and left the second leaf green (checked in Blender
    4.2 with two oaks); it strips the suffix Blender adds."""
    from leafsim.export.blender_import import morph_of

    morphs = {"blade": "B", "veins": "V"}
    assert morph_of(morphs, "blade.001", "blade.001") == "B" and morph_of(morphs, "veins.012", "x") == "V"
    assert morph_of(morphs, "blade", "blade") == "B" and morph_of(morphs, "stalk.001", "stalk") is None
    assert morph_of({"leaf.2": "L"}, "leaf.2") == "L"  # a name of the file's own with a dot is taken as it is


def test_the_blender_addon_reads_a_gltf_whose_buffer_name_is_percent_encoded(leaf, tmp_path):
    from leafsim.export.blender_import import colour_morphs

    model, params, view, states = leaf
    path = tmp_path / "my leaf#1.gltf"
    export_mesh(model, states, path, params=params, view=view)
    assert set(colour_morphs(path)) == {"blade"}


def test_an_obj_export_removes_the_side_files_an_earlier_export_left(leaf, tmp_path):
    """Re-exporting an OBJ under the same name removes the textures the earlier export's MTL named
    and this one does not write (a fresh leaf writes no normal map; a baked export no photo): the
    new MTL no longer names them, yet a folder zipped for a client shipped them.  Nothing else:
    not a file of such a name no leafsim MTL named (a user's leaf_photo.png, which a name rule
    removed), not one of ``keep`` (the species' photo), not a link."""
    model, params, view, states = leaf
    out = tmp_path / "oak.obj"
    stale = [tmp_path / n for n in ("oak_baked_normal.png", "oak_baked_normal_lower.png")]
    for p in stale:
        p.write_bytes(b"an earlier export's")
    photo = tmp_path / "oak_photo.png"  # the user's own, never named by a leafsim MTL
    photo.write_bytes(b"the user's photo")
    other = tmp_path / "oak_notes.png"
    other.write_bytes(b"the user's")
    mtl = out.with_suffix(".mtl")
    mtl.write_text("# leafsim materials\nnewmtl blade\nmap_Kd oak_baked.png\nmap_Bump -bm 1 oak_baked_normal.png\n"
                   "newmtl blade_lower\nmap_Kd oak_baked_lower.png\nmap_Bump -bm 1 oak_baked_normal_lower.png\n"
                   "newmtl x\nmap_Kd oak_notes.png\n")
    rep = export_mesh(model, states[:1], out, params=params, view=view, texture="baked")
    assert str(tmp_path / "oak_baked_normal.png") not in rep["files"]  # the fresh leaf: no crinkle, no map
    assert sorted(rep["removed"]) == sorted(str(p) for p in stale) and not any(p.exists() for p in stale)
    assert photo.read_bytes() == b"the user's photo" and other.read_bytes() == b"the user's"  # (not leafsim's names / not named)
    assert all(Path(f).is_file() for f in rep["files"])
    # an MTL that is not leafsim's names nothing leafsim removes; keep= protects an input
    for p in stale:
        p.write_bytes(b"again")
    mtl.write_text("# someone else's\nmap_Kd oak_baked_normal.png\n")
    out.unlink()
    assert export_mesh(model, states[:1], out, params=params, view=view, texture="baked")["removed"] == []
    mtl.write_text("# leafsim materials\nmap_Kd oak_baked_normal.png\nmap_Kd oak_baked_normal_lower.png\n")
    rep = export_mesh(model, states[:1], out, params=params, view=view, texture="baked", keep=(stale[0],))
    assert rep["removed"] == [str(stale[1])] and stale[0].read_bytes() == b"again"
    assert export_mesh(model, states[:1], tmp_path / "oak.glb", params=params, view=view, texture="baked")["removed"] == []

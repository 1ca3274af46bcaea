"""The baked texture (``export --texture baked``): the window's albedo, sub-grid mottle and photo
detail included, computed on the CPU per texel; checked against the renderer itself (the
top-down scanner picture of the same flat leaf, whose blade facing up is drawn in exactly its
albedo), against the GL sampling conventions, and in the files a client opens."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial import Delaunay

from helpers.gltf import assert_clean
from leafsim.appearance.photo import load_photo_rgba
from leafsim.appearance.reflectance import linear_to_srgb
from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError
from leafsim.config.species import get_species
from leafsim.export.bake import _raster, bake_albedo, bake_png, bilinear
from leafsim.export.mesh import MeshSource, export_mesh
from leafsim.pipeline import build_leaf
from leafsim.sim.simulator import Simulator


def _locate(pts, tri, W, H, dtype=np.float64):
    tri_id = np.full((H, W), -1, np.int32)
    bary = np.zeros((H, W, 2), dtype)
    _raster(np.asarray(pts, np.float64), np.asarray(tri, np.int64), tri_id, bary)
    return tri_id, bary


@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-9), (np.float32, 1e-4)])
def test_every_texel_of_a_triangulated_square_is_located_once_at_its_centre(dtype, tol):
    """A Delaunay triangulation of random points covering [0, W] × [0, H]: every texel centre is
    found in a triangle (none lost on the shared edges) and its barycentric weights give back
    the centre (float32 weights, as the bake keeps them, to a ten-thousandth of a texel)."""
    rng = np.random.default_rng(3)
    W, H = 37, 23
    pts = np.concatenate([[[0, 0], [W, 0], [0, H], [W, H]], rng.uniform(0, 1, (40, 2)) * [W, H]])
    tri = Delaunay(pts).simplices
    tri_id, bary = _locate(pts, tri, W, H, dtype)
    assert (tri_id >= 0).all()
    y, x = np.mgrid[0:H, 0:W]
    t = tri[tri_id]
    s, r = bary[..., 0:1].astype(float), bary[..., 1:2].astype(float)
    back = pts[t[..., 0]] * (1 - s - r) + pts[t[..., 1]] * s + pts[t[..., 2]] * r
    assert np.abs(back - np.stack([x + 0.5, y + 0.5], -1)).max() < tol
    assert (bary >= -tol).all() and (bary.sum(-1) <= 1 + tol).all()


def test_a_triangle_covers_its_area_and_nothing_outside_it():
    tri = np.array([[0, 1, 2]])
    pts = np.array([[3.2, 4.1], [50.7, 10.3], [20.4, 38.9]])
    tri_id, _ = _locate(pts, tri, 64, 48)
    (ax, ay), (bx, by) = pts[1] - pts[0], pts[2] - pts[0]
    area = 0.5 * abs(ax * by - ay * bx)
    perimeter = sum(np.linalg.norm(pts[(i + 1) % 3] - pts[i]) for i in range(3))
    assert abs((tri_id == 0).sum() - area) < 0.5 * perimeter


def test_bilinear_samples_as_a_gl_linear_sampler():
    """Texel centres at (i + ½)/W: a linear ramp is reproduced exactly inside, the edge clamps
    and the wrap-around (repeat) blends the last column with the first."""
    H, W = 8, 10
    y, x = np.mgrid[0:H, 0:W].astype(float)
    img = 2.0 * x + 3.0 * y
    u, v = np.array([0.23, 0.51, 0.77]), np.array([0.31, 0.5, 0.66])
    assert np.allclose(bilinear(img, u, v, wrap=False), 2.0 * (u * W - 0.5) + 3.0 * (v * H - 0.5))
    assert np.isclose(bilinear(img, np.array([0.0]), np.array([0.5]), wrap=True)[0], 0.5 * (img[3, 0] + img[3, -1]) * 0.5
                      + 0.5 * (img[4, 0] + img[4, -1]) * 0.5)
    assert np.isclose(bilinear(img, np.array([0.0]), np.array([0.5]), wrap=False)[0], 0.5 * (img[3, 0] + img[4, 0]))
    rgb = np.stack([img, 2 * img, -img], -1)
    assert np.allclose(bilinear(rgb, u, v, wrap=True), np.stack([bilinear(img, u, v, True) * k for k in (1, 2, -1)], -1))


def _turning(key: str, mottle: float = 0.7, photo_tint: bool = False):
    """(model, params, view) of species ``key`` on a coarse mesh, and a state lying flat at rest
    whose every reaction is half-way (the mottle's strongest), as the window would draw it
    (``photo_tint``: the view of the window's "photo" albedo, the photo tinted)."""
    sp = get_species(key)
    params = sp.params.with_overrides({"mesh.spacing": 0.04, "colour.mottle": mottle})
    _, _, model = build_leaf(sp, params, 0)
    sim = Simulator(model, params, seed=0)
    st = sim.state()
    pig0 = st.pigments.copy()
    st.particle_q[:] = model.particle_rest
    p = st.pigments
    p.chlorophyll[:], p.carotenoid[:], p.browning[:], p.necrosis[:] = 0.45, 0.8, 0.4, 0.15
    photo = load_photo_rgba(sp.image) if sp.image is not None else None
    view = LeafView(model, photo, pig0, photo_tint=photo_tint, photo_colour=sp.photo_colour)
    return model, params, view, st


def _srgb8(lin):
    return np.clip(np.round(linear_to_srgb(np.clip(lin, 0, 1)).astype(float) * 255.0), 0, 255)


def _window_pixels(model, view, src, st, params, options: dict, faces=None, weights=False) -> tuple:
    """The renderer's top-down picture of the flat leaf (``options`` over the scanner's) and, for
    every pixel well inside its blade: (rows, columns, blade triangle, texture coordinates, the
    picture's colour there).  The triangle indexes ``view.remap[model.blade_tri_T]`` (or
    ``view.remap[faces]``, T triangles of the model)."""
    from leafsim.compare.metrics import Frame
    from leafsim.render.topdown import TopDown

    xy = model.particle_rest[view.T][:, :2]
    scale = 2500.0 / np.ptp(xy, axis=0).max()
    lo, hi = xy.min(0) - 0.002, xy.max(0) + 0.002
    fr = Frame(scale, float(lo[0]), float(hi[1]), int((hi[0] - lo[0]) * scale) + 1, int((hi[1] - lo[1]) * scale) + 1)
    td = TopDown(fr, supersample=1)
    try:
        rgb, mask = td.render(view.mesh(st, params), options)
    finally:
        td.release()
    tri = view.remap[model.blade_tri_T if faces is None else faces].astype(np.int64)
    tri_id, bary = _locate(fr.to_px(xy), tri, fr.width, fr.height)
    ok = (tri_id >= 0) & cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    y, x = np.nonzero(ok)
    k = tri_id[y, x]
    t = tri[k]
    s, r = bary[y, x, 0:1], bary[y, x, 1:2]
    uv = src.uv[t[:, 0]] * (1 - s - r) + src.uv[t[:, 1]] * s + src.uv[t[:, 2]] * r
    if weights:  # each pixel's barycentric weights of its triangle's three vertices
        return y, x, k, uv, rgb, np.concatenate([1 - s - r, s, r], 1)
    return y, x, k, uv, rgb


@pytest.mark.parametrize("key, albedo", [("maple", "colours"), ("oak", "detail"), ("oak", "texture")])
def test_the_bake_is_what_the_window_draws(key, albedo):
    """The texture sampled where each pixel of the renderer's top-down picture of the same flat
    leaf lies (that pixel's texture coordinates): the same colour within a level on average, a
    few at worst (a texel is resampled once more than a window pixel), with the mottle's flecks
    and, on oak, the photo: with its detail under the pigment colour (the window's default
    albedo) or tinted by the pigment change (its "photo" albedo).  Fails when the bake leaves out
    the mottle (its flecks are 7-9 levels of RMS here) or the photo."""
    model, params, view, st = _turning(key, photo_tint=albedo == "texture")
    src = MeshSource(model, params, view, "shell", False, "baked", albedo)
    alb, inside = bake_albedo(src, st)
    y, x, _, uv, rgb = _window_pixels(model, view, src, st, params, {"albedo": albedo, "veins": False})
    baked = _srgb8(bilinear(alb, uv[:, 0], uv[:, 1], wrap=False))
    window = rgb[y, x].astype(float)
    d = np.abs(baked - window)
    assert len(y) > 20000
    assert d.mean() < 1.0 and np.percentile(d, 99) <= 6, (d.mean(), np.percentile(d, 99))
    # the flecks are in the bake: its picture minus its blur over a few flecks, at least half
    # the window's (and on maple, whose palette colour is smooth, nothing else makes them)
    img = np.full(rgb.shape, 255.0, np.float32)
    img[y, x] = baked
    blur = lambda a: cv2.GaussianBlur(a, (0, 0), 4.0)[y, x]  # noqa: E731
    fine_bake, fine_window = (baked - blur(img)).std(), (window - blur(rgb.astype(np.float32))).std()
    assert fine_bake > 4.0 and fine_bake > 0.8 * fine_window, (fine_bake, fine_window)


def test_a_fresh_leaf_bakes_its_vertex_colours_and_the_mottle_adds_flecks_only_when_turning():
    """Fresh tissue is uniform under the mottle (p = 0): the bake is the interpolated pigment
    colour, the same with colour.mottle 0; a turning leaf's bake with the mottle carries several
    times the fine structure of one without, and the same mean colour (the mottle moves the
    pigments about their mean)."""
    model, params, view, st = _turning("maple")
    _, params0, view0, _ = _turning("maple", mottle=0.0)
    fresh = Simulator(model, params, seed=0).state()
    a, inside = bake_albedo(MeshSource(model, params, view, "shell", False, "baked"), fresh)
    b, _ = bake_albedo(MeshSource(model, params0, view0, "shell", False, "baked"), fresh)
    assert np.abs(a - b)[inside].max() < 1e-6
    m, _ = bake_albedo(MeshSource(model, params, view, "shell", False, "baked"), st)
    s, _ = bake_albedo(MeshSource(model, params0, view0, "shell", False, "baked"), st)
    inner = cv2.erode(inside.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)

    def fine(img):
        img = _srgb8(img).astype(np.float32)
        return (img - cv2.GaussianBlur(img, (0, 0), 3.0))[inner].std()

    assert fine(m) > 10.0 * fine(s) and fine(m) > 1.5, (fine(m), fine(s))
    assert np.abs(_srgb8(m)[inner].mean(0) - _srgb8(s)[inner].mean(0)).max() < 2.0


def _glb_json(path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    n, kind = struct.unpack("<I4s", data[12:20])
    assert kind == b"JSON"
    doc = json.loads(data[20:20 + n])
    m = struct.unpack("<I", data[20 + n:24 + n])[0]
    return doc, data[28 + n:28 + n + m]


def _png_at(png: bytes, uv: np.ndarray) -> np.ndarray:
    """The PNG's sRGB levels sampled bilinearly at glTF texture coordinates ``uv`` (v down)."""
    img = cv2.cvtColor(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return bilinear(img.astype(np.float64), uv[:, 0], uv[:, 1], wrap=False)


def _accessor(doc, blob, index) -> np.ndarray:
    acc = doc["accessors"][index]
    bv = doc["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    dtype = np.uint32 if acc["componentType"] == 5125 else np.float32
    return np.frombuffer(blob, dtype, acc["count"] * width, bv["byteOffset"] + acc.get("byteOffset", 0)).reshape(-1, width)


def test_a_fresh_leaf_s_baked_texture_in_the_file_is_its_vertex_colours(tmp_path):
    """The file as a client reads it: the PNG embedded in the glb, sampled at each blade
    vertex's TEXCOORD_0, is that vertex's COLOR_0 of the same leaf exported with vertex
    colours (a fresh leaf: the mottle moves nothing).  Catches a flipped v, swapped channels or
    a shifted texel grid in the file, which the bake's own sampler would not."""
    model, params, view, _ = _turning("maple")
    fresh = Simulator(model, params, seed=0).state()
    a, b = tmp_path / "baked.glb", tmp_path / "colours.glb"
    export_mesh(model, fresh, a, params=params, view=view, texture="baked")
    export_mesh(model, fresh, b, params=params, view=view, texture="colours")
    doc_a, blob_a = _glb_json(a)
    doc_b, blob_b = _glb_json(b)
    attrs_a, attrs_b = doc_a["meshes"][0]["primitives"][0]["attributes"], doc_b["meshes"][0]["primitives"][0]["attributes"]
    uv = _accessor(doc_a, blob_a, attrs_a["TEXCOORD_0"]).astype(np.float64)
    bv = doc_a["bufferViews"][doc_a["images"][0]["bufferView"]]
    got = _png_at(blob_a[bv["byteOffset"]:bv["byteOffset"] + bv["byteLength"]], uv)
    want = _srgb8(_accessor(doc_b, blob_b, attrs_b["COLOR_0"]))
    # the baked blade keeps the vertices of the faces off the stalk, in their order (the stalk is
    # a mesh of its own: test_the_stalk_of_a_baked_export_is_what_the_window_draws_there)
    tri = _accessor(doc_b, blob_b, doc_b["meshes"][0]["primitives"][0]["indices"]).reshape(-1, 3)
    stalk = np.concatenate([~model.blade_particles[view.T]] * 2)  # the shell's two layers
    blade = np.unique(tri[~stalk[tri].any(axis=1)])
    assert len(blade) == len(got) and not stalk[blade].any()
    d = np.abs(got - want[blade])
    assert d.mean() < 0.5 and d.max() <= 3.0, (d.mean(), d.max())


@pytest.mark.parametrize("key", ["maple", "aspen"])
def test_the_stalk_of_a_baked_export_is_what_the_window_draws_there(tmp_path, key):
    """The stalk's texture coordinates lie on the blade's midrib (a photo's petiole pixels are
    not the stalk's), whose texels the blade's own colour fills.  A baked export gives the stalk
    a mesh of its own carrying the window's albedo per vertex: with the stalk turned brown and
    the blade still half green, the renderer's top-down picture of the flat leaf over the stalk
    is the stalk mesh's colours interpolated, within a few levels (the photo's detail varies
    between the vertices on aspen), where the blade's texels there are tens of levels off (the
    file before: the stalk took the texture).  Without the mottle, whose sub-grid flecks a vertex
    colour cannot hold.  The glb holds the mesh (vertex colours, no texture coordinates) and
    passes the validator."""
    from scipy.spatial import cKDTree

    model, params, view, st = _turning(key, mottle=0.0)
    stalk_p = ~model.blade_particles
    p = st.pigments
    p.chlorophyll[stalk_p], p.carotenoid[stalk_p], p.browning[stalk_p], p.necrosis[stalk_p] = 0.02, 0.3, 0.9, 0.3
    src = MeshSource(model, params, view, "shell", False, "baked")
    surf = src.surfaces(st)
    assert set(surf) == {"blade", "stalk"}
    stalk = surf["stalk"]
    assert stalk.uv is None and stalk.colours is not None
    # each view vertex's colour on the stalk mesh's upper face, found by position
    full = MeshSource(model, params, view, "shell", False, "colours").surfaces(st)["blade"]
    nT = len(view.T)
    dist, at = cKDTree(stalk.positions.astype(np.float64)).query(full.positions[nT:].astype(np.float64))
    faces = model.tri_T[~model.blade_particles[model.tri_T].all(axis=1)]
    on = np.zeros(nT, bool)
    on[view.remap[faces].ravel()] = True
    assert dist[on].max() < 1e-9
    options = {"veins": False, **({"albedo": "detail"} if view.photo_rgba is not None else {})}  # the window's default
    y, x, k, uv, rgb, w = _window_pixels(model, view, src, st, params, options, faces, weights=True)
    assert len(y) > 300
    t = view.remap[faces].astype(np.int64)[k]
    window = rgb[y, x].astype(float)
    col = stalk.colours[at].astype(np.float64)  # (nT, 3): meaningful on the stalk's vertices
    exported = _srgb8((col[t] * w[:, :, None]).sum(1))
    d = np.abs(exported - window)
    assert d.mean() < 5.0 and np.percentile(d, 99) <= 20, (d.mean(), np.percentile(d, 99))
    alb, _ = bake_albedo(src, st)  # the blade's texels under the stalk: what the stalk showed before
    before = np.abs(_srgb8(bilinear(alb, uv[:, 0], uv[:, 1], wrap=False)) - window)
    assert before.mean() > 15.0 and before.mean() > 3 * d.mean(), (before.mean(), d.mean())
    path = tmp_path / f"{key}.glb"
    export_mesh(model, st, path, params=params, view=view, texture="baked")
    assert_clean(path)
    doc, blob = _glb_json(path)
    mesh = {m["name"]: m["primitives"][0] for m in doc["meshes"]}
    assert set(mesh["stalk"]["attributes"]) >= {"POSITION", "NORMAL", "COLOR_0"}
    assert "TEXCOORD_0" not in mesh["stalk"]["attributes"]
    assert np.allclose(_accessor(doc, blob, mesh["stalk"]["attributes"]["COLOR_0"])[:, :3], stalk.colours, atol=1e-6)


@pytest.mark.parametrize("key", ["maple", "oak"])
def test_a_baked_export_opens_as_a_textured_glb_and_obj(tmp_path, key):
    """glb: valid, the blade textured by the bake (no vertex colours); the veins in their own
    colour per vertex (maple), or over a photo textured like the blade, as the window draws them
    there (oak); byte for byte reproducible.  OBJ: the texture beside it, mapped on the textured
    meshes only.  An animation, a PLY or an unknown albedo is refused in one line, and nothing
    is written."""
    model, params, view, st = _turning(key)
    photo = key == "oak"
    path = tmp_path / f"{key}.glb"
    rep = export_mesh(model, st, path, params=params, view=view, veins=True, texture="baked")
    assert_clean(path)
    doc, blob = _glb_json(path)
    prims = {m["name"]: m["primitives"][0] for m in doc["meshes"]}
    # the report counts what the file holds: the normal-mapped blade's rim has its own vertices
    acc = doc["accessors"]
    assert rep["meshes"] == {k: {"vertices": acc[p["attributes"]["POSITION"]]["count"],
                                 "triangles": acc[p["indices"]]["count"] // 3} for k, p in prims.items()}
    assert "COLOR_0" not in prims["blade"]["attributes"] and "TEXCOORD_0" in prims["blade"]["attributes"]
    assert ("COLOR_0" in prims["veins"]["attributes"]) != photo and ("TEXCOORD_0" in prims["veins"]["attributes"]) == photo
    mats = doc["materials"]
    assert mats[prims["blade"]["material"]]["pbrMetallicRoughness"]["baseColorTexture"] == {"index": 0}
    assert ("baseColorTexture" in mats[prims["veins"]["material"]]["pbrMetallicRoughness"]) == photo
    assert doc["images"][0]["name"] == "baked"
    bv = doc["bufferViews"][doc["images"][0]["bufferView"]]
    png = blob[bv["byteOffset"]:bv["byteOffset"] + bv["byteLength"]]
    assert png == bake_png(MeshSource(model, params, view, "shell", True, "baked"), st)
    if photo:  # the texture is the photo's grid
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        h, w = view.photo_rgba.shape[:2]
        assert img.shape[0] % h == 0 and img.shape[1] % w == 0 and img.shape[0] // h == img.shape[1] // w
    again = tmp_path / "again.glb"
    export_mesh(model, st, again, params=params, view=view, veins=True, texture="baked")
    assert again.read_bytes() == path.read_bytes()

    files = export_mesh(model, st, tmp_path / f"{key}.obj", params=params, view=view, veins=True, texture="baked")["files"]
    assert sorted(p.rsplit("/", 1)[-1] for p in files) == sorted([f"{key}.mtl", f"{key}.obj", f"{key}_baked.png"])
    mtl = (tmp_path / f"{key}.mtl").read_text().split("newmtl ")
    assert [m.split()[0] for m in mtl if f"map_Kd {key}_baked.png" in m] == (["blade", "veins"] if photo else ["blade"])
    # a textured material's Kd is white: a reader that multiplies map_Kd by Kd keeps the texture's colour
    assert [m.split()[0] for m in mtl if "Kd 1.0000 1.0000 1.0000" in m] == (["blade", "veins"] if photo else ["blade"])

    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(LeafsimError, match="one state"):
        export_mesh(model, [st, st], tmp_path / "anim.glb", params=params, view=view, texture="baked", times=[0.0, 1.0])
    with pytest.raises(LeafsimError, match="PLY carries vertex colours"):
        export_mesh(model, st, tmp_path / "x.ply", params=params, view=view, texture="baked")
    with pytest.raises(LeafsimError, match="albedo 'shiny'"):
        export_mesh(model, st, tmp_path / "y.glb", params=params, view=view, texture="baked", albedo="shiny")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_texels_outside_the_blade_take_the_nearest_blade_colour():
    """No background colour anywhere in the texture (a mipmapping viewer averages the margin
    with what lies past it, at every level): every outside texel is its nearest blade texel's."""
    from scipy.ndimage import distance_transform_edt

    model, params, view, st = _turning("maple")
    alb, inside = bake_albedo(MeshSource(model, params, view, "shell", False, "baked"), st)
    assert 0.2 < inside.mean() < 0.9
    _, (iy, ix) = distance_transform_edt(~inside, return_indices=True)
    assert np.array_equal(alb, alb[iy, ix]) and (alb[~inside].min(axis=1) > 0.01).all()


def test_texture_sizes_follow_the_mottle_and_the_photo_within_the_cap():
    """A texel spans at most a third of the mottle's length on the blade; over a photo the
    texture is the photo's grid times an integer, never above BAKE_MAX; a photo larger than the
    cap is shrunk as the renderer's upload shrinks it (area averaging, to 4096 a side)."""
    from leafsim.export.bake import BAKE_MAX, photo_texels, texture_size

    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    xy = uv * [0.1, 0.06]  # 10 cm by 6 cm of blade over the texture space
    tri = np.array([[0, 1, 2]])
    assert texture_size(uv, xy, tri, 6e-4) == (500, 300)
    assert texture_size(uv, xy * 0.1, tri, 6e-4) == (256, 256)  # BAKE_MIN
    assert texture_size(uv, xy, tri, 6e-4, photo_size=(300, 200)) == (600, 400)  # 2 × the photo
    assert texture_size(uv, xy, tri, 6e-4, photo_size=(800, 500)) == (800, 500)
    assert texture_size(uv, xy, tri, 1e-5, photo_size=(3000, 1000)) == (3000, 1000)  # × 2 would pass the cap
    assert max(texture_size(uv, xy, tri, 1e-5)) == BAKE_MAX
    big = np.zeros((2500, 5000, 4), np.uint8)
    big[..., :3], big[..., 3] = 200, 255
    big[:, ::2, 0] = 100  # a stripe pattern the area average halves
    t = photo_texels(big)
    assert t.shape == (2048, 4096, 3)
    want = ((150 / 255 + 0.055) / 1.055) ** 2.4  # the average of 100 and 200, decoded
    assert abs(float(np.median(t[..., 0])) - want) < 0.01


def _client_frames(P: np.ndarray, uv: np.ndarray, tri: np.ndarray, flip_v: bool = False, flip_u: bool = False) -> tuple:
    """Per triangle, the tangent frame a glTF client lays over texture coordinates: x along
    ∂P/∂u, y "up" in the image (−∂P/∂v, v = 0 the top row), both unit; (``flip_v``, ``flip_u``:
    wrong conventions, y along +∂P/∂v or x along −∂P/∂u, which the test must tell apart)."""
    dP = np.stack([P[tri[:, 1]] - P[tri[:, 0]], P[tri[:, 2]] - P[tri[:, 0]]], 2)       # (m, 3, 2)
    dU = np.stack([uv[tri[:, 1]] - uv[tri[:, 0]], uv[tri[:, 2]] - uv[tri[:, 0]]], 2)   # (m, 2, 2)
    D = dP @ np.linalg.pinv(dU)                                                          # [∂P/∂u, ∂P/∂v]
    with np.errstate(invalid="ignore", divide="ignore"):  # (a rim triangle of the shell has no texture area: NaN)
        t = (-1.0 if flip_u else 1.0) * D[:, :, 0] / np.linalg.norm(D[:, :, 0], axis=1, keepdims=True)
        b = (1.0 if flip_v else -1.0) * D[:, :, 1] / np.linalg.norm(D[:, :, 1], axis=1, keepdims=True)
    return t, b


@pytest.mark.parametrize("key,way", [("maple", "both"), ("oak", "both"), ("maple", 30.0), ("oak", 160.0)])
def test_the_crinkle_s_normal_map_is_what_the_window_draws(tmp_path, key, way):
    """A flat leaf whose lamina is held 2 % short of its rest lengths (a crinkle of about 0.2
    rad RMS slope; ``way`` an angle: 3 % short along the line at that angle only, a one-way
    crinkle of wrinkles across it; 160° lies where the shader's orientations wrap) lit at 45° from the side (and 45° to both texture axes), drawn by the renderer top-down: every pixel's
    brightness is what a glTF client computes from the baked albedo and the baked normal map
    decoded in its tangent frame (x along increasing u, y up the image), within a couple of
    levels on average; decoded with u's or v's direction the other way it is not.  The glb carries the
    map as the blade's normalTexture (not the veins'), passes the validator, and a leaf without
    a crinkle (fresh, or render.crinkle 0) carries none."""
    from leafsim.export.bake import bake_normals

    model, params, view, st = _turning(key, mottle=0.0)
    params = params.with_overrides({"dynamics.path": "own", "render.crinkle_size": 0.002})
    if way == "both":
        st.spring_rest[:] = 1.02 * model.spring_rest0
    else:  # rest lengths as if the leaf were 1/0.97 longer along d: the flat leaf is 3 % short that way only
        d = np.array([np.cos(np.radians(way)), np.sin(np.radians(way)), 0.0])
        e = st.particle_q[model.spring_ij[:, 1]] - st.particle_q[model.spring_ij[:, 0]]
        st.spring_rest[:] = np.linalg.norm(e + (1.0 / 0.97 - 1.0) * (e @ d)[:, None] * d, axis=1)
    src = MeshSource(model, params, view, "shell", False, "baked", "colours")
    alb, inside = bake_albedo(src, st)
    nmap = bake_normals(src, st, (alb.shape[1], alb.shape[0]))
    assert nmap is not None and nmap.shape == alb.shape and nmap.dtype == np.uint8
    s45 = np.sqrt(0.5)
    L = np.array([0.5, 0.5, s45])  # from the side, at 45° to both texture axes: a flip of either shows
    light = dict(light_dir=tuple(L), light_colour=(1.0, 1.0, 1.0), sky_colour=(0.0, 0.0, 0.0))
    y, x, k, uv, rgb = _window_pixels(model, view, src, st, params, {"albedo": "colours", "veins": False, **light})
    xy = model.particle_rest[view.T][:, :2]
    tri = view.remap[model.blade_tri_T].astype(np.int64)
    albedo = bilinear(alb, uv[:, 0], uv[:, 1], wrap=False)
    n_ts = bilinear(nmap.astype(np.float64), uv[:, 0], uv[:, 1], wrap=False) / 127.5 - 1.0
    P = np.concatenate([xy, np.zeros((len(xy), 1))], 1)
    window = rgb[y, x].astype(float)
    errors = {}
    for flip in ("none", "v", "u"):
        tx, by = _client_frames(P, src.uv, tri, flip_v=flip == "v", flip_u=flip == "u")
        N = tx[k] * n_ts[:, 0:1] + by[k] * n_ts[:, 1:2] + np.array([0.0, 0.0, 1.0]) * n_ts[:, 2:3]
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        ndl = np.maximum(N @ L, 0.0)
        errors[flip] = np.abs(_srgb8(albedo * ndl[:, None]) - window)
    flat = _srgb8(albedo * s45)
    assert (window - flat).std() > 3.0  # the crinkle is drawn: several levels of shading (0 without it)
    right = errors["none"]
    assert right.mean() < 2.0 and np.percentile(right, 90) <= 5, (right.mean(), np.percentile(right, 90))
    for wrong in ("u", "v"):  # (a one-way crinkle tilts the normals in one plane: a flip shows less)
        margin = 2.0 if way == "both" else 1.0
        assert errors[wrong].mean() > 2.0 * right.mean() + margin, (wrong, errors[wrong].mean(), right.mean())

    path = tmp_path / f"{key}.glb"
    rep = export_mesh(model, st, path, params=params, view=view, veins=True, texture="baked", albedo="colours")
    assert_clean(path)
    doc, blob = _glb_json(path)
    prims = {m["name"]: m["primitives"][0] for m in doc["meshes"]}
    # the report counts the rim's own vertices (the shell's without them, plus one per rim corner)
    shell = src.surfaces(st)["blade"]
    assert len(shell.positions) < rep["meshes"]["blade"]["vertices"] == _accessor(doc, blob, prims["blade"]["attributes"]["POSITION"]).shape[0]
    assert rep["meshes"]["blade"]["triangles"] == len(shell.triangles)
    mats = doc["materials"]
    blade = mats[prims["blade"]["material"]]
    assert "normalTexture" not in mats[prims["veins"]["material"]]
    img = doc["images"][doc["textures"][blade["normalTexture"]["index"]]["source"]]
    assert img["name"] == "crinkle"
    bv = doc["bufferViews"][img["bufferView"]]
    got = cv2.cvtColor(cv2.imdecode(np.frombuffer(blob[bv["byteOffset"]:bv["byteOffset"] + bv["byteLength"]], np.uint8),
                                    cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert np.array_equal(got, nmap)
    # the tangents in the file: x along increasing u, cross(normal, tangent) × w up the image, as
    # the client frames of the file's own positions and texture coordinates, on both faces: a
    # client that makes its tangents from the coordinates (Blender) reads the map as the file's
    # tangents say.  The lower face (normal −n) has the upper face's coordinates negated (the
    # mirrored-repeat sampler reads the same texels there), so its frame is turned by 180° about
    # the normal: each lower vertex's whole frame (x, y, normal) is its upper twin's negated and
    # the map tilts it against the upper face's, as the same relief seen from below
    attrs = prims["blade"]["attributes"]
    Pf, Nf, Uf, Tf = (_accessor(doc, blob, attrs[a]).astype(np.float64) for a in ("POSITION", "NORMAL", "TEXCOORD_0", "TANGENT"))
    trif = _accessor(doc, blob, prims["blade"]["indices"]).reshape(-1, 3).astype(np.int64)
    tx, by = _client_frames(Pf, Uf, trif)
    fn = np.cross(Pf[trif[:, 1]] - Pf[trif[:, 0]], Pf[trif[:, 2]] - Pf[trif[:, 0]])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
    face = np.abs(np.sum(fn * Nf[trif[:, 0]], axis=1)) > 0.99  # the leaf's faces, not the shell's rim
    first = np.full(len(Pf), -1)
    first[trif[face, 0]] = np.flatnonzero(face)  # one face triangle of each vertex
    v = np.flatnonzero(first >= 0)
    assert np.all(np.abs(np.linalg.norm(Tf[:, :3], axis=1) - 1) < 1e-5) and set(np.unique(Tf[:, 3])) <= {-1.0, 1.0}
    up = np.cross(Nf[v], Tf[v, :3]) * Tf[v, 3:4]
    nT = len(shell.positions) // 2  # the shell (its faces off the stalk): the lower face's vertices, the upper
    # face's twins, the rim's own copies
    assert len(Pf) > 2 * nT and np.all(Uf[2 * nT:] >= 0.0)  # the rim reads the texture at the upper face's coordinates
    assert np.all(trif[~face] >= 2 * nT) and np.all(trif[face] < 2 * nT)  # no rim triangle shares a face's vertex
    v = v[v < 2 * nT]
    top = v >= nT
    assert 0.4 < top.mean() < 0.6 and np.all(Nf[v[top], 1] > 0.99)  # the flat leaf's upper face faces up (+y)
    along = np.sum(Tf[v, :3] * tx[first[v]], axis=1)
    upward = np.sum(up * by[first[v]], axis=1)
    assert np.median(along[top]) > 0.99 and np.median(upward[top]) > 0.99
    assert np.median(along[~top]) > 0.99 and np.median(upward[~top]) > 0.99
    frame = lambda i: np.stack([Tf[i, :3], np.cross(Nf[i], Tf[i, :3]) * Tf[i, 3:4], Nf[i]], 1)  # noqa: E731
    low = np.arange(nT)
    assert np.allclose(Uf[low], -Uf[low + nT]) and np.median(np.abs(frame(low) + frame(low + nT)).max(axis=(1, 2))) < 1e-3
    assert all(smp["wrapS"] == smp["wrapT"] == 33648 for smp in doc["samplers"])  # MIRRORED_REPEAT
    # OBJ: the same map beside it, on the blade's material as map_Bump (Blender's normal map),
    # and the frame a reader derives from the file's vt (x along increasing u, y along increasing
    # vt, i.e. up the image) is the glTF's
    obj = tmp_path / f"{key}.obj"
    files = export_mesh(model, st, obj, params=params, view=view, veins=True, texture="baked", albedo="colours")["files"]
    normal = tmp_path / f"{key}_baked_normal.png"
    assert str(normal) in files
    assert np.array_equal(cv2.cvtColor(cv2.imread(str(normal), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB), nmap)
    mtl = {m.split()[0]: m for m in (tmp_path / f"{key}.mtl").read_text().split("newmtl ")[1:]}
    assert f"map_Bump -bm 1 {normal.name}" in mtl["blade"] and "map_Bump" not in mtl["veins"]
    lines = obj.read_text().splitlines()
    blade_end = lines.index("o stalk")  # (the stalk's own mesh comes next, then the veins)
    vt = np.array([[float(a) for a in ln.split()[1:3]] for ln in lines[:blade_end] if ln.startswith("vt ")])
    upper = np.c_[np.abs(Uf[:2 * nT, 0]), 1.0 - np.abs(Uf[:2 * nT, 1])]  # the upper face's coordinates, as OBJ vt
    assert len(vt) == 3 * nT and np.allclose(vt[:2 * nT], upper, atol=1e-6)  # every vertex's, then the lower face's own
    assert np.allclose(vt[2 * nT:], 1.0 - upper[:nT], atol=1e-6)  # (1 − u, 1 − v): the texel the upper face reads, turned
    # the lower face (and only it) is drawn with blade_lower: the turned copies of the texture and the map
    assert f"map_Kd {key}_baked_lower.png" in mtl["blade_lower"] and f"map_Bump -bm 1 {key}_baked_normal_lower.png" in mtl["blade_lower"]
    turned = {n: cv2.cvtColor(cv2.imread(str(tmp_path / f"{key}_{n}.png"), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
              for n in ("baked", "baked_lower", "baked_normal_lower")}
    assert str(tmp_path / f"{key}_baked_lower.png") in files and str(tmp_path / f"{key}_baked_normal_lower.png") in files
    assert np.array_equal(turned["baked_normal_lower"], nmap[::-1, ::-1]) and np.array_equal(turned["baked_lower"], turned["baked"][::-1, ::-1])
    faces, mats, cur = [], [], None
    for ln in lines[:blade_end]:
        if ln.startswith("usemtl "):
            cur = ln.split()[1]
        elif ln.startswith("f "):
            faces.append([[int(x) - 1 for x in c.split("/")] for c in ln.split()[1:]])
            mats.append(cur)
    faces, mats = np.array(faces), np.array(mats)
    fv, ft = faces[:, :, 0], faces[:, :, 1]
    on_lower = mats == "blade_lower"
    assert np.array_equal(on_lower, (fv < nT).all(axis=1))  # the lower face's triangles, no rim one
    assert np.all(ft[on_lower] >= 2 * nT) and np.all(ft[~on_lower] < 2 * nT) and np.all(ft[on_lower] - 2 * nT == fv[on_lower])
    h, w = nmap.shape[:2]
    for img, ref_img in ((turned["baked_normal_lower"], nmap), (turned["baked_lower"], turned["baked"])):
        read_low = bilinear(img.astype(float), vt[2 * nT:, 0], 1.0 - vt[2 * nT:, 1], wrap=False)
        read_up = bilinear(ref_img.astype(float), vt[nT:2 * nT, 0], 1.0 - vt[nT:2 * nT, 1], wrap=False)
        assert np.abs(read_low - read_up).max() < 0.01  # the same texels under a lower vertex and its twin (vt: 7 digits)
    # the frames a reader derives from the file's vt (x along increasing u, y along increasing vt,
    # i.e. up the image) are the glTF's on both faces: the lower face's turned by 180°
    vt_of_glb = np.concatenate([vt[2 * nT:], vt[nT:2 * nT], np.c_[Uf[2 * nT:, 0], 1.0 - Uf[2 * nT:, 1]]])
    tx_o, vt_dir = _client_frames(Pf, vt_of_glb, trif, flip_v=True)  # y along +∂P/∂vt: OBJ's vt grows up the image
    for side in (top, ~top):
        assert np.median(np.sum(Tf[v, :3] * tx_o[first[v]], axis=1)[side]) > 0.99
        assert np.median(np.sum(up * vt_dir[first[v]], axis=1)[side]) > 0.99
    for quiet in (Simulator(model, params, seed=0).state(), None):
        p = params if quiet is not None else params.with_overrides({"render.crinkle": 0.0})
        plain = tmp_path / "plain.glb"
        export_mesh(model, quiet if quiet is not None else st, plain, params=p, view=view, texture="baked")
        doc, _ = _glb_json(plain)
        assert all("normalTexture" not in m for m in doc["materials"]) and len(doc["images"]) == 1
        plain_obj = tmp_path / "plain.obj"
        written = export_mesh(model, quiet if quiet is not None else st, plain_obj, params=p, view=view, texture="baked")["files"]
        assert "map_Bump" not in (tmp_path / "plain.mtl").read_text() and not any("normal" in Path(f).name for f in written)

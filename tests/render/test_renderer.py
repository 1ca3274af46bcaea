"""Renderer on a real EGL context with pixel assertions (synthetic ellipse leaf)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial import Delaunay

from helpers.unwritable import unwritable_folder
from leafsim.appearance.mesh import isotropic_crinkle
from leafsim.base.errors import LeafsimError
from leafsim.render import OrbitCamera, RenderMesh, RenderOptions

W, H = 320, 240
A, B = 0.03, 0.05  # ellipse half axes (x, y); base at the origin, apex at y = 2B
GREEN = (0.10, 0.32, 0.05)
BROWN = (0.28, 0.13, 0.04)


def synthetic_leaf(spacing: float = 0.0025, texture: np.ndarray | None = None) -> RenderMesh:
    """Ellipse leaf in z = 0 with a midrib (order 0) and four laterals (order 1).

    ``texture``: optional (H, W, 4) uint8; the ellipse's bounding box maps onto it (apex at
    the top row)."""
    xs = np.arange(-A, A + 1e-9, spacing)
    ys = np.arange(0.0, 2 * B + 1e-9, spacing * math.sqrt(3) / 2)
    gx, gy = np.meshgrid(xs, ys)
    gx = gx + (np.arange(len(ys))[:, None] % 2) * 0.0  # keep x = 0 columns for the midrib
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    inside = (pts[:, 0] / A) ** 2 + ((pts[:, 1] - B) / B) ** 2 < 0.97
    pts = pts[inside]
    t = np.linspace(0, 2 * math.pi, int(2 * math.pi * B / spacing), endpoint=False)
    rim = np.stack([A * np.sin(t), B - B * np.cos(t)], 1)
    pts = np.concatenate([pts, rim])
    tri = Delaunay(pts).simplices.astype(np.int32)
    n = len(pts)
    pos = np.zeros((n, 3), np.float32)
    pos[:, :2] = pts
    # midrib: vertices with x == 0 (grid column and the two rim points), base to apex
    mid = np.flatnonzero(np.abs(pts[:, 0]) < 1e-9)
    mid = mid[np.argsort(pts[mid, 1])]
    wmid = np.interp(pts[mid, 1], [0, 2 * B], [1.6e-3, 0.4e-3])
    lines = [(mid, wmid, 0)]
    for y0, side in ((0.035, 1), (0.035, -1), (0.06, 1), (0.06, -1)):
        # lateral: nearest vertices along a straight line towards the margin
        d = np.array([side * 0.8, 0.6])
        steps = np.arange(0, 0.03, spacing)
        target = np.array([0.0, y0]) + steps[:, None] * d
        keep = (target[:, 0] / A) ** 2 + ((target[:, 1] - B) / B) ** 2 < 0.9
        idx = np.argmin(((pts[None, :, :] - target[keep][:, None, :]) ** 2).sum(-1), axis=1)
        idx = idx[np.concatenate([[True], idx[1:] != idx[:-1]])]
        lines.append((idx, np.linspace(0.7e-3, 0.25e-3, len(idx)), 1))
    uv = np.stack([(pts[:, 0] + A) / (2 * A), 1.0 - pts[:, 1] / (2 * B)], 1).astype(np.float32)
    colours = np.tile(np.array(GREEN, np.float32), (n, 1))
    r = np.sqrt((pts[:, 0] / A) ** 2 + ((pts[:, 1] - B) / B) ** 2)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    edges = np.unique(np.sort(edges, 1), axis=0)
    top = pos[: n // 2].copy()
    top[:, 2] += 0.001
    links = np.stack([np.arange(n // 2), n + np.arange(n // 2)], 1)
    springs = np.concatenate([edges, links]).astype(np.int32)
    kind = np.concatenate([np.zeros(len(edges)), np.full(len(links), 2)]).astype(np.int8)
    kind[: len(edges)][np.isin(edges, mid).all(1)] = 3
    return RenderMesh(positions=pos, triangles=tri, texcoords=uv, colours=colours, texture_rgba=texture,
                      vein_lines=lines, springs=springs, spring_kind=kind, top_positions=top,
                      scalars={"mass": (1.0 - r).astype(np.float32), "water": (pts[:, 1] / (2 * B)).astype(np.float32)})


def top_camera() -> OrbitCamera:
    return OrbitCamera(yaw=-90.0, pitch=90.0, distance=0.3, target=np.array([0.0, B, 0.0]), fov=30.0)


@pytest.fixture(scope="module")
def off():
    from leafsim.render import OffscreenRenderer

    r = OffscreenRenderer(W, H)
    yield r
    r.release()


@pytest.fixture(scope="module")
def leaf():
    return synthetic_leaf()


def leaf_mask(img: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """Pixels that differ clearly from the ground/background colour at the image corner."""
    return np.abs(img.astype(int) - bg.astype(int)).sum(-1) > 40


def render(off, mesh, **opts):
    return off.render_array(mesh, top_camera(), RenderOptions(**opts))


def test_leaf_at_centre_background_elsewhere(off, leaf):
    img = render(off, leaf)
    c = img[H // 2, W // 2].astype(int)
    assert c[1] > c[0] + 20 and c[1] > c[2] + 20, c  # green
    corner = img[5, 5].astype(int)
    assert abs(corner[0] - corner[2]) < 40 and corner.sum() > 300, corner  # grey ground/background
    assert not (corner[1] > corner[0] + 20)


def test_silhouette_area_matches_projection(off, leaf):
    img = render(off, leaf, veins=False, shadows=False, ground=False)
    mask = leaf_mask(img, img[2, 2])
    cam = top_camera()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    expected = math.pi * A * B * px_per_m ** 2
    assert abs(mask.sum() / expected - 1) < 0.08, (mask.sum(), expected)


def test_colour_change_moves_mean_colour(off, leaf):
    img0 = render(off, leaf, veins=False)
    mask = leaf_mask(img0, img0[2, 2])
    off.render_array({"positions": leaf.positions, "colours": np.tile(np.float32(BROWN), (leaf.vertex_count, 1))},
                     top_camera(), RenderOptions(veins=False))
    img1 = off.render_array(None, top_camera(), RenderOptions(veins=False))
    m0, m1 = img0[mask].mean(0), img1[mask].mean(0)
    assert m1[0] > m0[0] + 20 and m1[1] < m0[1] - 10, (m0, m1)
    off.render_array({"positions": leaf.positions, "colours": leaf.colours}, top_camera())


def test_bending_changes_silhouette(off, leaf):
    flat = render(off, leaf, veins=False, ground=False, shadows=False)
    bent = leaf.positions.copy()
    bent[:, 2] = 0.5 * (bent[:, 1] - B) ** 2 / B + 40.0 * bent[:, 0] ** 2  # curl up
    img = off.render_array({"positions": bent}, OrbitCamera(yaw=-90, pitch=15, distance=0.3,
                                                            target=np.array([0, B, 0.0])),
                           RenderOptions(veins=False, ground=False, shadows=False))
    off.render_array({"positions": leaf.positions}, top_camera())
    flat_side = off.render_array(None, OrbitCamera(yaw=-90, pitch=15, distance=0.3, target=np.array([0, B, 0.0])),
                                 RenderOptions(veins=False, ground=False, shadows=False))
    m_flat = leaf_mask(flat_side, flat_side[2, 2])
    m_bent = leaf_mask(img, img[2, 2])
    assert (m_flat ^ m_bent).sum() > 0.2 * m_flat.sum()
    assert m_bent.sum() > m_flat.sum() * 1.2  # curled up: seen more from the side
    assert leaf_mask(flat, flat[2, 2]).sum() > 0


def test_debug_views_differ(off, leaf):
    imgs = {v: render(off, leaf, view=v).astype(int) for v in ("shaded", "particles", "springs", "mass", "water")}
    names = list(imgs)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            diff = np.abs(imgs[a] - imgs[b]).sum(-1) > 30
            assert diff.mean() > 0.02, (a, b, diff.mean())
    # heat map spans the colour map: the centre (mass high) differs from near the margin
    mass = imgs["mass"]
    assert np.abs(mass[H // 2, W // 2] - mass[H // 2, W // 2 + 30]).sum() > 40


def test_renders_into_the_bound_framebuffer(off, leaf):
    """On screen the GUI binds its framebuffer and calls render() without naming one."""
    expected = render(off, leaf)
    with off.ctx:  # the GUI's context is current; emulate that
        off.fbo.use()
        off.renderer.render(top_camera(), W, H, RenderOptions())
        off.ctx.copy_framebuffer(off.resolve, off.fbo)
        got = np.frombuffer(off.resolve.read(components=3, alignment=1), np.uint8).reshape(H, W, 3)[::-1]
    assert np.abs(got.astype(int) - expected.astype(int)).max() <= 2


def test_unknown_view_and_option_raise(off, leaf):
    with pytest.raises(LeafsimError, match="nosuch"):
        render(off, leaf, view="nosuch")
    with pytest.raises(LeafsimError, match="bogus"):
        RenderOptions.coerce({"bogus": 1})


def test_non_finite_colours_are_refused_in_one_line(off, leaf):
    """A NaN colour or tint (a diverged pigment state) is refused naming the field, at
    populate and at update, instead of drawing black or white blotches."""
    bad = np.array(leaf.colours if leaf.colours is not None else np.zeros((leaf.vertex_count, 3)), np.float32)
    bad[3, 1] = np.nan
    with pytest.raises(LeafsimError, match="colours must be finite"):
        off.render_array(RenderMesh(**{**leaf.__dict__, "colours": bad}), top_camera())
    off.render_array(leaf, top_camera())
    with pytest.raises(LeafsimError, match="tint must be finite"):
        off.render_array({"positions": leaf.positions, "tint": np.full_like(bad, np.inf)}, top_camera())
    with pytest.raises(LeafsimError, match="colours must be finite"):
        off.render_array({"positions": leaf.positions, "colours": bad}, top_camera())


def test_texture_path_shows_texture(off):
    tex = np.zeros((64, 64, 4), np.uint8)
    tex[:, :32] = (230, 30, 30, 255)  # left half red
    tex[:, 32:] = (30, 30, 230, 255)  # right half blue
    mesh = synthetic_leaf(texture=tex)
    img = off.render_array(mesh, top_camera(), RenderOptions(veins=False, albedo="texture"))
    left, right = img[H // 2, W // 2 - 25].astype(int), img[H // 2, W // 2 + 25].astype(int)
    assert left[0] > left[2] + 60 and right[2] > right[0] + 60, (left, right)
    # tint darkens / shifts the photo while it keeps its two halves
    tint = np.tile(np.float32([0.5, 0.5, 0.5]), (mesh.vertex_count, 1))
    img2 = off.render_array({"positions": mesh.positions, "tint": tint}, top_camera(),
                            RenderOptions(veins=False, albedo="texture"))
    l2 = img2[H // 2, W // 2 - 25].astype(int)
    assert l2[0] < left[0] - 20 and l2[0] > l2[2] + 30


def test_veins_visible_along_midrib(off, leaf):
    """Veins with their own (paler) tissue colour show along the midrib and nowhere else; veins
    without one take the blade's colour under them (a photo's own veins), so a thin vein adds
    no second line."""
    import dataclasses

    pale = dataclasses.replace(leaf, vein_colours=np.asarray(leaf.colours) * np.float32([1.6, 1.4, 1.2]))
    with_v = render(off, pale, shadows=False).astype(int)
    plain = render(off, leaf, shadows=False).astype(int)
    without = render(off, leaf, veins=False, shadows=False).astype(int)
    cam = top_camera()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    col = W // 2
    rows = [int(H / 2 - (y - B) * px_per_m) for y in np.linspace(0.02, 0.08, 12)]
    d_mid = np.mean([np.abs(with_v[r, col - 1:col + 2] - without[r, col - 1:col + 2]).sum(-1).max() for r in rows])
    d_off = np.mean([np.abs(with_v[r, col + 12] - without[r, col + 12]).sum() for r in rows])
    d_plain = np.mean([np.abs(plain[r, col - 1:col + 2] - without[r, col - 1:col + 2]).sum(-1).max() for r in rows])
    assert d_mid > 25 and d_off < 10 and d_plain < 10, (d_mid, d_off, d_plain)


def test_vein_opacity_fades_the_veins_toward_the_blade(off, leaf):
    """render.vein_alpha is the veins' opacity (it only switched them on and off): along the
    midrib the half-opaque veins lie between the opaque ones and none, and the parameters set the
    same options in the window and in rendered frames (RenderOptions.of_params)."""
    import dataclasses

    from leafsim.config.params import ParamSet

    pale = dataclasses.replace(leaf, vein_colours=np.asarray(leaf.colours) * np.float32([1.6, 1.4, 1.2]))
    full = render(off, pale, shadows=False).astype(int)
    half = render(off, pale, shadows=False, vein_opacity=0.5).astype(int)
    none = render(off, pale, veins=False, shadows=False).astype(int)
    cam = top_camera()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    rows = [int(H / 2 - (y - B) * px_per_m) for y in np.linspace(0.02, 0.08, 12)]
    col = W // 2
    d_full = np.mean([np.abs(full[r, col - 1:col + 2] - none[r, col - 1:col + 2]).sum(-1).max() for r in rows])
    d_half = np.mean([np.abs(half[r, col - 1:col + 2] - none[r, col - 1:col + 2]).sum(-1).max() for r in rows])
    assert d_full > 25 and 0.3 * d_full < d_half < 0.7 * d_full, (d_full, d_half)
    p = ParamSet({"render.vein_alpha": 0.3, "render.specular": 0.6, "render.translucency": 0.7})
    o = RenderOptions.of_params(p, view="shaded")
    assert o.vein_opacity == 0.3 and o.veins and o.specular == 0.6 and abs(o.translucency - 1.3) < 1e-9
    d = RenderOptions.of_params(ParamSet({}))
    assert abs(d.translucency - RenderOptions().translucency) < 1e-12 and d.vein_opacity == 1.0
    assert not RenderOptions.of_params(ParamSet({"render.vein_alpha": 0.0})).veins


def test_png_atomic_and_unwritable(off, leaf, tmp_path):
    out = tmp_path / "leaf.png"
    off.render_png(leaf, out, top_camera())
    import cv2

    img = cv2.imread(str(out))
    assert img.shape == (H, W, 3)
    assert [p.name for p in tmp_path.iterdir()] == ["leaf.png"]  # no temp files left
    with pytest.raises(LeafsimError, match="missing"):
        off.render_png(leaf, tmp_path / "missing" / "x.png", top_camera())
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(LeafsimError, match="x.png"):
        off.render_png(leaf, blocker / "x.png", top_camera())
    with unwritable_folder(tmp_path) as ro:  # as root too (helpers.unwritable)
        with pytest.raises(LeafsimError, match=re.escape(str(ro / "x.png")) + ".*cannot write"):
            off.render_png(leaf, ro / "x.png", top_camera())
        assert list(ro.iterdir()) == []  # no temp file left
    assert {"file", "leaf.png"} <= {p.name for p in tmp_path.iterdir()} <= {"file", "leaf.png", "ro"}


def test_vertex_normals_of_a_flat_leaf():
    """Unit normals on a maple-sized flat mesh (its cost is a benchmark's business, not a
    test's: the suite runs on busy machines)."""
    from leafsim.render.geom import vertex_normals

    mesh = synthetic_leaf(spacing=0.00085)
    assert 5000 < mesh.vertex_count < 8000
    out = np.empty_like(mesh.positions)
    vertex_normals(mesh.positions, mesh.triangles, out)
    assert np.allclose(np.abs(out[:, 2]), 1.0, atol=1e-5)


def test_orbit_camera_frames_and_moves():
    pts = synthetic_leaf(0.005).positions
    cam = OrbitCamera()
    cam.frame_bounds(pts)
    clip = (cam.proj(W / H) @ cam.view() @ np.c_[pts, np.ones(len(pts))].T).T
    ndc = clip[:, :3] / clip[:, 3:]
    assert np.all(np.abs(ndc[:, :2]) < 1.0) and np.all(clip[:, 3] > 0)
    eye0, d0, t0 = cam.eye.copy(), cam.distance, cam.target.copy()
    cam.drag(40, -20)
    assert not np.allclose(cam.eye, eye0) and -89 <= cam.pitch <= 89
    cam.zoom(2)
    assert cam.distance < d0
    cam.pan(30, 10)
    assert not np.allclose(cam.target, t0)
    cam.drag(0, 1e4)
    assert cam.pitch == 89.0
    v = cam.view()
    assert np.allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-9)


def test_colormap_matches_heat_map(off, leaf):
    from leafsim.appearance.colormaps import colormap

    img = render(off, leaf, view="mass", ground=False)
    t = np.array([0.0, 0.5, 1.0])
    c = colormap("turbo", t)
    assert c.shape == (3, 3) and np.all((0 <= c) & (c <= 1))
    centre = img[H // 2 - 2:H // 2 + 3, W // 2 - 2:W // 2 + 3].reshape(-1, 3).mean(0) / 255.0
    # centre = mass maximum = top of the map (dark red), lit by 0.55..1 in linear space
    assert centre[0] > centre[1] + 0.2 and centre[0] > centre[2] + 0.2
    assert np.abs(centre - c[2]).max() < 0.2


def test_two_offscreen_renderers_coexist(off, leaf):
    from leafsim.render import OffscreenRenderer

    first = off.render_array(leaf, top_camera())
    other = OffscreenRenderer(120, 90, samples=0)
    try:
        small = other.render_array(leaf, top_camera())
        assert small.shape == (90, 120, 3)
        again = off.render_array(None, top_camera())  # switches back to its own context
        assert np.abs(first.astype(int) - again).max() <= 2
    finally:
        other.release()
    assert np.abs(first.astype(int) - off.render_array(None, top_camera())).max() <= 2


def test_winding_made_consistent_even_for_a_folded_leaf():
    from leafsim.render.geom import _consistent, orient_up, vertex_normals

    leaf = synthetic_leaf(0.004)
    rng = np.random.default_rng(1)
    tri = leaf.triangles.copy()
    flip = rng.random(len(tri)) < 0.5
    tri[flip] = tri[flip][:, [0, 2, 1]]  # scrambled winding
    flat = orient_up(leaf.positions, tri)
    assert _consistent(flat)
    assert np.all(vertex_normals(leaf.positions, flat)[:, 2] > 0.99)
    # fold the right half over the midrib: per-triangle "z up" would now be inconsistent
    folded = leaf.positions.copy()
    right = folded[:, 0] > 0
    folded[right, 2] = 0.002
    folded[right, 0] = -folded[right, 0]
    o = orient_up(folded, tri)
    assert _consistent(o)


def test_ground_shadow_falls_away_from_the_sun(off):
    """A leaf held h = 2 cm above the ground casts a soft shadow displaced along -L by
    h · L_x / L_z (the ground-shadow mask projects along the sun direction); none without
    shadows."""
    h, lz = 0.02, 0.8
    lifted = synthetic_leaf()
    lifted.positions[:, 2] += h
    lifted.top_positions[:, 2] += h
    cam = top_camera()  # looks straight down on x = 0 from z = 0.3
    for lx, side in ((0.6, -1), (-0.6, 1)):
        opts = dict(veins=False, ground_z=0.0, light_dir=(lx, 0.0, lz), self_shadow=False)
        lit = off.render_array(lifted, cam, RenderOptions(shadows=False, **opts)).astype(int)
        shaded = off.render_array(lifted, cam, RenderOptions(shadows=True, **opts)).astype(int)
        bg = lit[2, 2]
        leaf_cols = np.flatnonzero(leaf_mask(lit, bg).any(0))
        ppm_ground = (leaf_cols[-1] - leaf_cols[0] + 1) / (2 * A) * (cam.distance - h) / cam.distance
        diff = lit.sum(-1) - shaded.sum(-1)
        dark = diff > 30  # ground pixels the shadow darkens
        assert dark.mean() > 0.01, f"no visible shadow (light x {lx})"
        assert (((diff > 4) & ~dark).sum()) > 0.01 * dark.sum()  # a soft edge, not a hard step
        cols = np.flatnonzero(dark.any(0))
        reach = ((W / 2 - cols[0]) if side < 0 else (cols[-1] + 1 - W / 2)) / ppm_ground
        assert reach == pytest.approx(A + h * abs(lx) / lz, rel=0.1), (lx, reach)
        # the shadow only reaches out on the side away from the sun
        other = ((cols[-1] + 1 - W / 2) if side < 0 else (W / 2 - cols[0])) / ppm_ground
        assert other < A


def test_heat_range_of_a_uniform_field_is_its_full_scale(off):
    """A field the same everywhere (a fresh leaf's water, a pigment not made yet) is drawn on
    its full scale, not fitted to itself: that range was (c, c + 1e-12), which drew the whole
    leaf in the lowest colour (a fresh leaf black) under a bar whose every tick read c."""
    leaf = synthetic_leaf()
    n = len(leaf.positions)
    for view, value, want in (("water", 1.0, (0.0, 1.0)), ("anthocyanin", 0.0, (0.0, 1.0)),
                              ("water", 0.5 + 1e-9 * np.arange(n), (0.0, 1.0)), ("mass", 0.2, (0.1, 0.3))):
        leaf.scalars[view] = np.broadcast_to(np.asarray(value, np.float32), (n,)).copy()
        off.render_array(leaf, top_camera(), RenderOptions(view=view, ground=False))
        lo, hi = off.renderer.scalar_range(RenderOptions(view=view))
        assert (lo, hi) == pytest.approx(want, rel=1e-6), view
    # the fresh leaf's water is drawn in the bar's top colour, not its bottom one
    from leafsim.appearance.colormaps import colormap

    leaf.scalars["water"] = np.ones(n, np.float32)
    img = off.render_array(leaf, top_camera(), RenderOptions(view="water", ground=False)).astype(float)
    colours = img[leaf_mask(img.astype(np.uint8), img[2, 2].astype(np.uint8))]
    top, bottom = (colormap("turbo", np.array([v]))[0] for v in (1.0, 0.0))
    mean = colours.mean(0) / max(colours.mean(0).max(), 1e-6)
    assert np.abs(mean - top / top.max()).max() < np.abs(mean - bottom / bottom.max()).max()


def test_heat_range_ignores_outliers_and_the_bar_matches(off):
    """Fitted heat-map range = 2nd..98th percentile (a few dry margin particles no longer
    paint the rest of the leaf one colour); pixels at the range's ends take the colour bar's
    end colours."""
    from leafsim.appearance.colormaps import colormap

    leaf = synthetic_leaf()
    n = len(leaf.positions)
    water = np.full(n, 0.8, np.float32)
    water[: n // 2] = 0.6  # one half drier than the other
    water[:3] = 0.0  # three almost dry outliers
    leaf.scalars["water"] = water
    off.render_array(leaf, top_camera(), RenderOptions(view="water", ground=False))
    lo, hi = off.renderer.scalar_range(RenderOptions(view="water"))
    assert lo == pytest.approx(0.6) and hi == pytest.approx(0.8)
    assert off.renderer.scalar_range(RenderOptions(view="water", scalar_range=(0.0, 1.0))) == (0.0, 1.0)
    img = off.render_array(None, top_camera(), RenderOptions(view="water", ground=False)).astype(float) / 255
    mask = leaf_mask((img * 255).astype(np.uint8), (img[2, 2] * 255).astype(np.uint8))
    colours = img[mask]
    # both ends of the bar appear on the leaf (blue-ish low end, red-ish high end), lit 0.55..1
    ends = colormap("turbo", np.array([0.0, 1.0]))
    for end in ends:
        d = np.abs(colours / np.maximum(colours.max(1, keepdims=True), 1e-6) - end / end.max()).max(1)
        assert (d < 0.25).mean() > 0.1


def _srgb8(lin) -> np.ndarray:
    return np.clip(255.0 * np.power(np.asarray(lin, float), 1 / 2.2) + 0.5, 0, 255).astype(np.uint8)


def test_detail_albedo_lays_the_photos_own_hues_on_living_tissue(off):
    """The "detail" albedo: the vertex colour (here one blurred mean for the whole leaf) times
    the texel's luminance detail and, weighted by ``chroma``'s living share, the texel's own
    chromaticity over the vertex's: stripes of two hues finer than nothing the mesh resolves
    come back at weight 1, and at weight 0 (dead tissue; no chroma given) only their
    brightness does."""
    a, b = np.array([0.20, 0.30, 0.02]), np.array([0.04, 0.30, 0.16])
    w = np.array([0.2126, 0.7152, 0.0722])
    tex = np.zeros((64, 64, 4), np.uint8)
    tex[..., 3] = 255
    for k in range(8):
        tex[:, 8 * k:8 * k + 8, :3] = _srgb8(a if k % 2 == 0 else b)
    mean = 0.5 * (a + b)
    mesh = synthetic_leaf(texture=tex)
    n = mesh.vertex_count
    mesh.colours = np.tile(mean.astype(np.float32), (n, 1))
    chroma = np.tile(np.float32([*(mean / (mean @ w)), 1.0]), (n, 1))
    cam = top_camera()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    cols = [int(W / 2 + (-A + (k + 0.5) / 8 * 2 * A) * px_per_m) for k in (2, 3, 4, 5)]

    def stripes(m):
        img = off.render_array(m, cam, RenderOptions(veins=False, shadows=False, albedo="detail")).astype(float)
        px = img[H // 2 - 3:H // 2 + 4, cols].mean(axis=0)  # (4, 3): stripes a, b, a, b
        return px[:, 0] - px[:, 2]  # red minus blue: high on a, low on b

    mesh.chroma = chroma
    live = stripes(mesh)
    assert min(live[0], live[2]) > max(live[1], live[3]) + 40, live
    # at weight 1, with the vertex colour the texture's mean, the detail albedo is the texel
    # itself: the same pixels as the photo drawn as albedo
    detail = off.render_array(mesh, cam, RenderOptions(veins=False, shadows=False, albedo="detail")).astype(int)
    photo = off.render_array(mesh, cam, RenderOptions(veins=False, shadows=False, albedo="texture")).astype(int)
    rows = slice(H // 2 - 3, H // 2 + 4)
    assert np.abs(detail[rows, cols] - photo[rows, cols]).max() <= 6, (detail[rows, cols], photo[rows, cols])
    # on a vertex whose colour has left the young one (a red leaf that still holds chlorophyll)
    # the photo's hues move its hue, not its brightness: the stripes' luminance ratio is the
    # texels' (1.10), not 2.0 as a plain per-channel factor gives; and the hue does move
    red = RenderMesh(**{**mesh.__dict__, "colours": np.tile(np.float32([0.4, 0.1, 0.05]), (n, 1))})
    img = off.render_array(red, cam, RenderOptions(veins=False, shadows=False, albedo="detail"))
    c = img[rows, cols].astype(float).mean(axis=0) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4) @ w
    assert abs((lin[0] + lin[2]) / (lin[1] + lin[3]) / ((a @ w) / (b @ w)) - 1.0) < 0.03, lin
    rb = img[rows, cols].astype(float).mean(axis=0)
    rb = rb[:, 0] - rb[:, 2]  # red minus blue: the yellower stripes a redder than the bluer b
    assert min(rb[0], rb[2]) > max(rb[1], rb[3]) + 30, rb
    # the veins take the same detail: along the midrib (x = 0, the boundary of stripes 3 and 4)
    # weight 1 and weight 0 draw it differently
    with_v = off.render_array(mesh, cam, RenderOptions(shadows=False, albedo="detail")).astype(int)
    no_ch = off.render_array(RenderMesh(**{**mesh.__dict__, "chroma": None}), cam,
                             RenderOptions(shadows=False, albedo="detail")).astype(int)
    mid = [int(H / 2 - (y - B) * px_per_m) for y in np.linspace(0.03, 0.07, 9)]
    assert np.mean([np.abs(with_v[r, W // 2] - no_ch[r, W // 2]).sum() for r in mid]) > 10
    dead = chroma.copy()
    dead[:, 3] = 0.0
    gone = stripes(RenderMesh(**{**mesh.__dict__, "chroma": dead}))
    assert np.ptp(gone) < 6, gone
    assert np.ptp(stripes(RenderMesh(**{**mesh.__dict__, "chroma": None}))) < 6
    with pytest.raises(LeafsimError, match="chroma"):
        off.render_array({"positions": mesh.positions, "chroma": chroma[:, :3]}, cam, RenderOptions(albedo="detail"))
    with pytest.raises(LeafsimError, match="chroma"):
        off.render_array({"positions": mesh.positions, "chroma": np.full_like(chroma, np.nan)}, cam, RenderOptions(albedo="detail"))


def test_texture_fringe_takes_the_colour_further_in():
    """The photo's outermost leaf texels mix the leaf with its background (here a pink ring):
    the texture the renderer uploads gives them the colour of the clean leaf further in (here
    a radial gradient: the colour just inside the fringe), keeps the mask, and leaves every
    texel ``FRINGE_PX`` or more inside untouched."""
    from leafsim.appearance.texture import FRINGE_PX, clean_texture

    tex = np.zeros((40, 40, 4), np.uint8)
    yy, xx = np.mgrid[:40, :40]
    r = np.hypot(yy - 19.5, xx - 19.5)
    inside = r < 15
    tex[inside, 3] = 255
    tex[..., 1] = np.clip(60 + 8 * r, 0, 255).astype(np.uint8)  # green rises outwards
    tex[..., 0], tex[..., 2] = 40, 30
    ring = inside & (r >= 14)
    tex[ring, :3] = (230, 150, 160)
    out = clean_texture(tex)
    assert np.array_equal(out[..., 3], tex[..., 3])
    from scipy.ndimage import distance_transform_edt

    depth = distance_transform_edt(inside)
    deep = depth >= FRINGE_PX
    assert np.array_equal(out[deep], tex[deep])  # no erosion past the fringe
    fringe = inside & ~deep
    assert fringe.sum() > ring.sum()  # the fringe is wider than the pink ring, and none of it is left
    assert not (out[fringe, 0] > 100).any() and not (out[~inside, 0] > 100).any()
    # a fringe texel takes a clean texel's colour from just inside it (green 60 + 8 r, r ≈ 12–13)
    assert np.abs(out[ring, 1].astype(int) - int(60 + 8 * 12.5)).max() <= 12


def test_a_blurred_photo_margin_is_cleaned_as_far_as_the_blur_reaches():
    """A scan's optics blur the paper's lightness several texels into the leaf (the
    aspen_senescent photo: 52 levels lighter at the edge, still 8 at 4-5 px), which the detail
    albedo drew as a lime rim round the whole leaf.  The fringe is measured per photo: a sharp
    margin keeps ``FRINGE_PX``, a blurred one is cleaned until its bands stop changing.  Here
    the outer 5 px are 23.6 levels lighter than the blade before cleaning, 11.1 after the fixed
    2.5 px fringe, 3.2 now."""
    import cv2
    from scipy.ndimage import distance_transform_edt

    from leafsim.appearance.texture import FRINGE_PX, MAX_FRINGE_PX, clean_texture, fringe_width

    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[:240, :240]
    inside = np.hypot(yy - 119.5, xx - 119.5) < 90
    leaf = np.clip(np.array([50.0, 110.0, 40.0]) + rng.normal(0, 4, (240, 240, 3)), 0, 255)
    paper = np.array([235.0, 235.0, 225.0])
    sharp = np.where(inside[..., None], leaf, paper)
    blurred = cv2.GaussianBlur(sharp, (0, 0), 2.0)
    depth = distance_transform_edt(inside)
    lum = np.array([0.2126, 0.7152, 0.0722])
    for img, wide in ((sharp, False), (blurred, True)):
        tex = np.dstack([np.clip(img, 0, 255), np.where(inside, 255, 0)]).astype(np.uint8)
        w = fringe_width(tex)
        assert (FRINGE_PX + 1 < w <= MAX_FRINGE_PX) if wide else w == FRINGE_PX, (wide, w)
        raw = tex[..., :3].astype(float) @ lum
        out = clean_texture(tex)[..., :3].astype(float) @ lum
        blade = float(np.median(out[depth > 20]))
        rim = inside & (depth <= 5)
        before, after = raw[rim].mean() - blade, out[rim].mean() - blade
        assert abs(after) < (6.0 if wide else 3.0) and (not wide or after < 0.25 * before), (wide, before, after)


@pytest.mark.parametrize("albedo", ["texture", "detail"])
def test_over_a_photo_the_veins_draw_no_second_pattern(off, albedo):
    """The photo shows its veins in their own light: over it a drawn vein is lit as the blade
    (a rounded rod drew a darker outline on each side, "inked"), sampled smoothly along its
    line (the centre line's texels came out as bands across it), and the finer, grown orders
    are not drawn at all (they crossed the photo's areoles as pale hairlines)."""
    import dataclasses

    rng = np.random.default_rng(4)
    tex = np.zeros((96, 96, 4), np.uint8)
    tex[..., :3] = np.clip(rng.normal([70, 120, 50], 12, (96, 96, 3)), 0, 255)
    tex[..., 3] = 255
    mesh = synthetic_leaf(texture=tex)
    cam = dataclasses.replace(top_camera(), distance=0.06)  # close: the midrib is ~10 px wide
    opts = dict(shadows=False, albedo=albedo)
    bare = off.render_array(mesh, cam, RenderOptions(veins=False, **opts)).astype(int)
    drawn = off.render_array(mesh, cam, RenderOptions(**opts)).astype(int)
    d = (drawn - bare).sum(-1)
    on = d != 0
    assert on.sum() > 2000  # the traced orders are drawn (their blurred sample) ...
    # ... as the blade under them: with the rounded rod, |difference| 25-29 on average and
    # 1200-1400 pixels darker by more than 30 (the inked edges); now 6-7 and at most 39
    assert np.abs(d[on]).mean() < 12 and (d < -30).sum() < 0.02 * on.sum(), (np.abs(d[on]).mean(), (d < -30).sum())
    fine = dataclasses.replace(mesh, vein_lines=[(i, w, 2) for i, w, _ in mesh.vein_lines])
    assert np.array_equal(off.render_array(fine, cam, RenderOptions(**opts)).astype(int), bare)
    # lit from behind (the leaf glows through): the vein transmits as the blade does (with the
    # vein's own, lower translucency it drew 31-38 levels darker on average)
    back = dict(opts, light_dir=(0.35, -0.45, -0.82))
    bare = off.render_array(mesh, cam, RenderOptions(veins=False, **back)).astype(int)
    d = (off.render_array(mesh, cam, RenderOptions(**back)).astype(int) - bare).sum(-1)
    assert abs(d[d != 0].mean()) < 12 and (d < -30).sum() < 0.02 * (d != 0).sum(), (d[d != 0].mean(), (d < -30).sum())


def test_a_ribbon_over_a_photo_samples_it_smoothly_along_its_line(off):
    """Without the blade's rest positions a ribbon carries its centre line's texture coordinate
    on both sides, so the GPU sees no change across it and samples the photo sharper than on the
    blade: the texel rows along the midrib came out as bands across the vein.  The vein then
    samples 1.5 mip levels coarser.  Here the photo alternates light and dark pairs of texel
    rows across the midrib: along the drawn midrib they vary less than on the bare blade under
    it (std 2.8 against 8.5; 16.9 without the coarser sample).  With the rest positions each
    side samples where it lies, as the blade does, and the drawn midrib shows the photo under
    it (within 3 levels of the bare blade)."""
    import dataclasses

    tex = np.zeros((256, 256, 4), np.uint8)
    tex[..., 3] = 255
    tex[..., :3] = np.where(((np.arange(256) // 2) % 2 == 0)[:, None, None], [90, 150, 60], [40, 90, 30])
    mesh = synthetic_leaf(texture=tex)
    mesh = dataclasses.replace(mesh, vein_lines=[mesh.vein_lines[0]])  # the midrib only
    cam = top_camera()
    opts = dict(shadows=False, albedo="texture")
    bare = off.render_array(mesh, cam, RenderOptions(veins=False, **opts)).astype(float)
    drawn = off.render_array(mesh, cam, RenderOptions(**opts)).astype(float)
    rows, col = slice(H // 2 - 60, H // 2 + 60), W // 2  # the midrib (x = 0) runs up the middle
    along_bare, along_vein = np.std(bare[rows, col, 1]), np.std(drawn[rows, col, 1])
    assert along_bare > 4 and along_vein < 0.6 * along_bare, (along_vein, along_bare)
    # with the blade's rest positions the sides sample the photo where they lie, as the blade
    # does: along the midrib the drawn vein shows the photo's rows as the bare blade does
    rest = np.asarray(mesh.positions, np.float32)[:, :2]
    uv = np.column_stack([rest[:, 0] * 3.0 + 0.5, rest[:, 1] * 3.0 + 0.2]).astype(np.float32)
    mesh = dataclasses.replace(mesh, texcoords=uv, mottle_rest=rest)
    bare = off.render_array(mesh, cam, RenderOptions(veins=False, **opts)).astype(float)
    drawn = off.render_array(mesh, cam, RenderOptions(**opts)).astype(float)
    near = np.abs(drawn[rows, col - 2:col + 3] - bare[rows, col - 2:col + 3]).mean()
    assert np.std(bare[rows, col, 1]) > 4 and near < 3.0, near


def test_veins_seen_edge_on_stay_whole_lines(off, leaf):
    """A vein is a rod: seen edge-on (the blade from its side, as a stalk lying on the ground
    is seen from a low camera) it is as wide as seen from above and drawn whole.  The ribbon
    used to lie in the blade's tangent plane, so it vanished edge-on and broke into dots."""
    cam = OrbitCamera(yaw=0.0, pitch=1.0, distance=0.3, target=np.array([0.0, B, 0.0]), fov=30.0)
    opts = dict(shadows=False, ground=False)
    with_v = off.render_array(leaf, cam, RenderOptions(**opts)).astype(int)
    without = off.render_array(leaf, cam, RenderOptions(veins=False, **opts)).astype(int)
    diff = np.abs(with_v - without).sum(-1)
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    cols = [int(W / 2 + s * (y - B) * px_per_m) for y in np.linspace(0.01, 0.09, 40) for s in (1,)]
    seen = [diff[:, c].max() for c in cols]
    assert min(seen) > 40, seen  # every column along the midrib shows the vein
    # twisted, so the blade's normal swings across the view along the midrib: the ribbon stays
    # whole there too (a side flipped to follow the normal twisted a segment into a bow-tie and
    # halved the line over 8 columns)
    import dataclasses

    pos = np.asarray(leaf.positions).copy()
    pos[:, 2] = 3.0 * pos[:, 0] * (pos[:, 1] - B)
    tw = dataclasses.replace(leaf, positions=pos, vein_lines=[leaf.vein_lines[0]],
                             vein_colours=np.tile(np.float32([0.6, 0.05, 0.05]), (leaf.vertex_count, 1)))
    cam = OrbitCamera(yaw=0.0, pitch=0.0, distance=0.06, target=np.array([0.0, B, 0.0]), fov=30.0)
    d = np.abs(off.render_array(tw, cam, RenderOptions(**opts)).astype(int)
               - off.render_array(tw, cam, RenderOptions(veins=False, **opts)).astype(int)).sum(-1)
    per = np.array([d[:, c].sum() for c in range(W // 2 - 12, W // 2 + 13)])
    assert per.min() > 0.75 * np.median(per), per


def test_veins_drawn_in_the_vein_colours_the_mesh_carries(off, leaf):
    """``vein_colours`` colour the ribbons (the vein tissue's own albedo), not the blade."""
    import dataclasses

    red = dataclasses.replace(leaf, vein_colours=np.tile(np.float32([0.6, 0.05, 0.05]), (leaf.vertex_count, 1)))
    img = render(off, red, shadows=False).astype(int)
    plain = render(off, leaf, shadows=False).astype(int)
    cam = top_camera()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    rows = [int(H / 2 - (y - B) * px_per_m) for y in np.linspace(0.02, 0.08, 12)]
    mid = np.array([img[r, W // 2] for r in rows])
    was = np.array([plain[r, W // 2] for r in rows])
    assert (was[:, 1] > was[:, 0]).all(), was  # the blade's colour under the vein: green
    assert (mid[:, 0] - mid[:, 1] > was[:, 0] - was[:, 1] + 40).all(), mid  # red veins (thinner to the apex)
    assert (mid[:6, 0] > mid[:6, 1] + 40).all(), mid  # fully red where the midrib is a few pixels wide
    changed = (img != plain).any(-1)
    assert 0 < changed.mean() < 0.03  # only the veins' pixels: the blade keeps its colour
    assert (img[changed][:, 0] - img[changed][:, 1] > plain[changed][:, 0] - plain[changed][:, 1]).mean() > 0.95
    # an update carries them too
    off.render_array(leaf, cam, RenderOptions(shadows=False))
    upd = off.render_array({"positions": leaf.positions, "vein_colours": red.vein_colours}, cam, RenderOptions(shadows=False))
    assert np.array_equal(upd, plain)  # a mesh populated without vein colours keeps the blade's


def test_veins_stay_hidden_under_a_leaf_lying_on_them(off, leaf):
    """The ribbons' depth is pulled toward the eye only by half their width and at most
    VEIN_PULL_MAX beyond (enough for a lobe's sag between two vein points): a second leaf lying
    2 mm above still hides them, from near and far (a pull of several pixels let them show
    through leaves stacked millimetres apart in a small picture)."""
    import dataclasses

    n = leaf.vertex_count
    red = np.tile(np.float32([0.6, 0.05, 0.05]), (n, 1))
    up = np.asarray(leaf.positions).copy()
    up[:, 2] += 2e-3
    stack = RenderMesh(positions=np.concatenate([leaf.positions, up]), triangles=np.concatenate([leaf.triangles, leaf.triangles + n]),
                       colours=np.concatenate([leaf.colours, leaf.colours]), vein_colours=np.concatenate([red, leaf.colours]),
                       vein_lines=list(leaf.vein_lines))
    for dist in (0.3, 1.0):
        cam = OrbitCamera(yaw=-90.0, pitch=90.0, distance=dist, target=np.array([0.0, B, 0.0]), fov=30.0)
        opts = RenderOptions(shadows=False, ground=False)
        img = off.render_array(stack, cam, opts).astype(int)
        bare = off.render_array(dataclasses.replace(stack, vein_lines=[]), cam, opts).astype(int)
        shows = ((img[..., 0] - img[..., 1]) - (bare[..., 0] - bare[..., 1]) > 30).sum()
        assert shows == 0, (dist, shows)
        # the same veins on top are drawn
        top = dataclasses.replace(stack, vein_colours=np.concatenate([leaf.colours, red]),
                                  vein_lines=[(i + n, w, o) for i, w, o in leaf.vein_lines])
        img = off.render_array(top, cam, opts).astype(int)
        assert ((img[..., 0] - img[..., 1]) - (bare[..., 0] - bare[..., 1]) > 30).sum() > 20



def _mottled(mesh, chlorophyll: float, size: float = 0.003, rest=None):
    """(``mesh`` coloured by pigments with ``chlorophyll`` left, half the way to browning, and
    the sub-grid mottle's rows at colour.mottle's default; the pigments; the parameters).
    ``rest``: where every vertex samples the field (default: its position)."""
    from leafsim.appearance.reflectance import mottle_pigments, pigments_to_rgb
    from leafsim.config.params import ParamSet
    from leafsim.sim.pigments import init_pigments

    p = ParamSet()
    pig = init_pigments(mesh.vertex_count, p, seed=0)
    pig.chlorophyll[:] = chlorophyll
    pig.browning[:] = 0.5 * (1.0 - chlorophyll)
    rest = np.asarray(mesh.positions[:, :2], np.float32) if rest is None else rest
    m = RenderMesh(**{**mesh.__dict__, "colours": pigments_to_rgb(pig, p), "mottle": mottle_pigments(pig, p),
                      "mottle_rest": rest, "mottle_size": size, "mottle_amount": float(p["colour.mottle"])})
    return m, pig, p


def test_mottle_flecks_turning_tissue_only_and_moves_with_it(off, leaf):
    """The sub-grid mottle (colour.mottle): a half-turned blade of one colour at every vertex is
    drawn flecked (the pixels' spread), a fresh one exactly as without it, and the flecks are
    fixed to the tissue: the leaf moved by 8 px draws the same flecks 8 px on."""
    opts = RenderOptions(veins=False, shadows=False, ground=False)
    cam = top_camera()
    box = (slice(H // 2 - 40, H // 2 + 40), slice(W // 2 - 25, W // 2 + 25))  # inside the blade
    fresh = _mottled(leaf, 1.0)[0]
    plain = RenderMesh(**{**fresh.__dict__, "mottle": None, "mottle_rest": None})
    assert np.array_equal(off.render_array(fresh, cam, opts), off.render_array(plain, cam, opts))
    half = _mottled(leaf, 0.4)[0]
    flecked = off.render_array(half, cam, opts)[box].astype(float)
    smooth = off.render_array(RenderMesh(**{**half.__dict__, "mottle_size": 0.0}), cam, opts)[box].astype(float)
    assert smooth.std(axis=(0, 1)).max() < 1.0  # one colour, evenly lit
    red_green = flecked[..., 0] - flecked[..., 1]  # yellower flecks beside greener ones
    assert red_green.std() > 6.0, red_green.std()
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    moved = RenderMesh(**{**half.__dict__, "positions": (half.positions + np.float32([8 / px_per_m, 0, 0])).astype(np.float32)})
    shifted = off.render_array(moved, cam, opts)[box[0], slice(W // 2 - 17, W // 2 + 33)].astype(float)
    assert np.abs(shifted - flecked).mean() < 0.15 * np.abs(flecked - flecked.mean(axis=(0, 1))).mean() + 1.0
    with pytest.raises(LeafsimError, match="mottle"):
        off.render_array({"positions": half.positions, "mottle": half.mottle[:, :4]}, cam, opts)
    with pytest.raises(LeafsimError, match="mottle_size"):
        off.render_array({"positions": half.positions, "mottle_size": -1.0}, cam, opts)
    with pytest.raises(LeafsimError, match="mottle_rest"):
        off.render_array(RenderMesh(**{**half.__dict__, "mottle_rest": None}), cam, opts)


@pytest.mark.parametrize("albedo", ["colours", "texture", "detail"])
def test_mottle_draws_the_moved_pigments(off, leaf, albedo):
    """Every vertex samples the field at one texel's centre (its largest value, then its
    smallest): the blade must draw exactly the colour of the pigments moved by ±a·p(1 − p), as a
    plain mesh coloured with those pigments draws it, under every albedo; over the photo albedos
    the vein ribbons, which redraw the blade under them, too."""
    from leafsim.appearance.mottle import FIELD_SIZE, mottle_field, mottle_scale
    from leafsim.appearance.reflectance import pigments_to_rgb

    f = mottle_field()
    tex = np.zeros((32, 32, 4), np.uint8)
    tex[..., :3], tex[..., 3] = (120, 150, 60), 255
    base = RenderMesh(**{**leaf.__dict__, "texture_rgba": tex})
    # (with vertex colours a vein ribbon is the vein tissue's own colour, not the blade under it,
    # and is not mottled: drawn without them)
    opts = RenderOptions(veins=albedo != "colours", shadows=False, ground=False, albedo=albedo)
    cam = top_camera()
    rows = slice(H // 2 - 40, H // 2 + 40)
    for pick in (np.argmax, np.argmin):
        iy, ix = np.unravel_index(pick(f), f.shape)
        n = float(f[iy, ix])
        assert abs(n) == 255 / 256
        scale = mottle_scale(0.003)
        at = np.tile(np.float32([(ix + 0.5) / FIELD_SIZE / scale, (iy + 0.5) / FIELD_SIZE / scale]), (leaf.vertex_count, 1))
        mottled, pig, p = _mottled(base, 0.4, rest=at)
        a = float(p["colour.mottle"])
        c, b = pig.chlorophyll.astype(np.float64), pig.browning.astype(np.float64)
        moved = pig.copy()
        moved.chlorophyll = (c - a * n * c * (1 - c)).astype(np.float32)
        moved.browning = (b + a * n * b * (1 - b)).astype(np.float32)
        want = RenderMesh(**{**mottled.__dict__, "mottle": None, "mottle_rest": None,
                             "colours": pigments_to_rgb(moved, p),
                             "tint": pigments_to_rgb(moved, p) / pigments_to_rgb(pig, p) if albedo == "texture" else None})
        if albedo == "texture":  # the photo albedo multiplies the photo by the tint: the plain mesh's tint moves
            mottled = RenderMesh(**{**mottled.__dict__, "tint": np.ones((leaf.vertex_count, 3), np.float32)})
        got = off.render_array(mottled, cam, opts)[rows].astype(int)
        ref = off.render_array(want, cam, opts)[rows].astype(int)
        smooth = off.render_array(RenderMesh(**{**mottled.__dict__, "mottle_size": 0.0}), cam, opts)[rows].astype(int)
        assert np.abs(got - ref).max() <= 2, (albedo, n, np.abs(got - ref).max())
        assert np.abs(smooth - ref).max() >= 8, (albedo, n, np.abs(smooth - ref).max())


def test_mottle_switched_on_and_off_by_update(off, leaf):
    """A mesh populated without the mottle, then updated with it (the window's slider from 0):
    the flecks appear; updated with mottle_size 0 it draws exactly as the plain mesh."""
    opts = RenderOptions(veins=False, shadows=False, ground=False)
    cam = top_camera()
    box = (slice(H // 2 - 40, H // 2 + 40), slice(W // 2 - 25, W // 2 + 25))
    half = _mottled(leaf, 0.4)[0]
    plain = RenderMesh(**{**half.__dict__, "mottle_size": 0.0, "mottle_amount": 0.0})
    before = off.render_array(plain, cam, opts)
    on = off.render_array({"positions": half.positions, "mottle": half.mottle, "mottle_size": half.mottle_size,
                           "mottle_amount": half.mottle_amount}, cam, opts)
    assert (on[box][..., 0].astype(float) - on[box][..., 1]).std() > 6.0
    again = off.render_array({"positions": half.positions, "mottle_size": 0.0}, cam, opts)
    assert np.array_equal(again, before)
    # a mesh populated without where to sample the field refuses the mottle in one line
    bare = RenderMesh(**{**half.__dict__, "mottle": None, "mottle_rest": None, "mottle_size": 0.0})
    off.render_array(bare, cam, opts)
    with pytest.raises(LeafsimError, match="mottle_rest"):
        off.render_array({"positions": half.positions, "mottle": half.mottle, "mottle_size": 0.003}, cam, opts)


def test_vein_ribbon_samples_the_mottle_across_its_width():
    """A ribbon's two sides sample the mottle field half the vein's width either side of its
    centre line, across the line in the rest plane (one sample stretched across a stalk drew
    bars along it)."""
    from leafsim.render.geom import VeinRibbons

    rest = np.array([[0.0, 0.0], [0.001, 0.002], [0.002, 0.004], [0.003, 0.006]], np.float32)
    width = np.array([0.002, 0.0016, 0.0012, 0.0008])
    rib = VeinRibbons([(np.arange(4), width, 0)], 4)
    mottle = np.arange(40, dtype=np.float32).reshape(4, 10)
    rows = rib.mottle_rows(mottle, rest).reshape(4, 2, 12)
    np.testing.assert_array_equal(rows[:, 0, :10], mottle)
    np.testing.assert_array_equal(rows[:, 1, :10], mottle)
    np.testing.assert_allclose(0.5 * (rows[:, 0, 10:] + rows[:, 1, 10:]), rest, atol=1e-7)
    half = 0.5 * (rows[:, 1, 10:] - rows[:, 0, 10:])
    np.testing.assert_allclose(np.linalg.norm(half, axis=1), width / 2, rtol=1e-5)
    np.testing.assert_allclose(half @ np.array([1.0, 2.0]) / np.sqrt(5), 0.0, atol=1e-7)  # across the line


def test_vein_ribbon_samples_the_photo_across_its_width():
    """Over a photo, a ribbon's sides carry the texture coordinates of where they lie, half the
    vein's width across the line in the rest plane, through the rest -> uv map (affine on a
    photo leaf): the photo's vein is drawn at its own width, not stretched to the ribbon's (a
    3 px midrib became an 8 px band).  Coordinates that are no affine map keep the centre's."""
    from leafsim.render.geom import VeinRibbons

    rest = np.array([[0.0, 0.0], [0.001, 0.002], [0.002, 0.004], [0.003, 0.006], [0.004, -0.002]], np.float32)
    A = np.array([[40.0, 5.0], [-3.0, 60.0]])  # uv = rest @ A + b (metres to texture units)
    uv = rest @ A + np.array([0.3, 0.2])
    width = np.array([0.002, 0.0016, 0.0012, 0.0008])
    rib = VeinRibbons([(np.arange(4), width, 0)], 5, uv, rest)
    st = rib.static.reshape(4, 2, 5)
    centre = 0.5 * (st[:, 0, 2:4] + st[:, 1, 2:4])
    np.testing.assert_allclose(centre, uv[:4], atol=1e-6)
    half = 0.5 * (st[:, 1, 2:4] - st[:, 0, 2:4])
    back = np.linalg.solve(A.T, half.T).T  # the rest-plane offset each side stands for
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), width / 2, rtol=1e-4)
    np.testing.assert_allclose(back @ np.array([1.0, 2.0]) / np.sqrt(5), 0.0, atol=1e-7)  # across the line
    st = VeinRibbons([(np.arange(4), width, 0)], 5, uv).static.reshape(4, 2, 5)  # no rest positions
    np.testing.assert_array_equal(st[:, 0, 2:4], st[:, 1, 2:4])
    # a blade on the map and a stalk placed otherwise (as a photo leaf's): the stalk's ribbon
    # keeps its centre's coordinate; no affine map at all: every ribbon keeps it
    g = np.random.default_rng(1)
    pts = g.random((40, 2)) * 0.05
    tex = pts @ A + 0.1
    tex[:4] += 0.3  # the stalk's four vertices
    line = [(np.array([0, 1, 2, 3, 10, 11, 12]), np.full(7, 0.001), 0)]
    st = VeinRibbons(line, 40, tex, pts).static.reshape(7, 2, 5)
    same = np.all(st[:, 0, 2:4] == st[:, 1, 2:4], axis=1)
    assert same[:4].all() and not same[4:].any()
    bent = np.column_stack([np.sin(40 * pts[:, 0]), pts[:, 1] ** 2 * 90])
    st = VeinRibbons(line, 40, bent, pts).static.reshape(7, 2, 5)
    np.testing.assert_array_equal(st[:, 0, 2:4], st[:, 1, 2:4])


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def test_crinkle_tilts_the_normals_by_the_slope_asked_for(off, leaf):
    """The sub-grid crinkle (render.crinkle): a flat blade lit at 45° from the side shades as
    N·L, so to first order the pixels' linear brightness spreads by albedo × sun × sin 45° × the
    RMS slope along the light's direction.  The drawn spread must give back the slope each vertex
    asks for (0.1 rad) within a fifth; the mean brightness stays; without a slope (or with a
    size of 0) the blade is drawn exactly as a mesh that has no crinkle; the crinkle stays on
    the tissue (moving the leaf moves the pattern); bad slopes get a one-line error."""
    s45 = math.sqrt(0.5)
    opts = RenderOptions(veins=False, shadows=False, ground=False, specular=0.0, translucency=0.0,
                         light_dir=(s45, 0.0, s45), light_colour=(1.0, 1.0, 1.0), sky_colour=(0.0, 0.0, 0.0))
    cam = top_camera()
    box = (slice(H // 2 - 50, H // 2 + 50), slice(W // 2 - 22, W // 2 + 22))  # inside the blade
    n = leaf.vertex_count
    rest = leaf.positions[:, :2].astype(np.float32)
    plain = RenderMesh(**{**leaf.__dict__, "mottle_rest": rest})
    slope = 0.1
    crinkled = RenderMesh(**{**plain.__dict__, "crinkle": isotropic_crinkle(np.full(n, slope)), "crinkle_size": 0.003})
    flat = off.render_array(plain, cam, opts)[box]
    got = off.render_array(crinkled, cam, opts)[box]
    g = _srgb_to_linear(got[..., 1])
    g0 = _srgb_to_linear(flat[..., 1])
    assert g0.std() < 0.002 * g0.mean()  # evenly lit without it
    albedo_sun = g0.mean() / s45  # N·L = sin 45° on the flat blade
    measured = g.std() / (albedo_sun * s45)
    assert 0.8 * slope < measured < 1.2 * slope, measured
    assert abs(g.mean() - g0.mean()) < 0.03 * g0.mean()
    # no slope, or no size: exactly the plain blade (the program without the crinkle)
    for off_mesh in (RenderMesh(**{**crinkled.__dict__, "crinkle": np.zeros((n, 3), np.float32)}),
                     RenderMesh(**{**crinkled.__dict__, "crinkle_size": 0.0})):
        assert np.array_equal(off.render_array(off_mesh, cam, opts)[box], flat)
    # the pattern rides with the tissue: the leaf moved by 10 px draws it 10 px on
    px_per_m = H / (2 * cam.distance * math.tan(math.radians(cam.fov) / 2))
    moved = RenderMesh(**{**crinkled.__dict__, "positions": (crinkled.positions + np.float32([10 / px_per_m, 0, 0])).astype(np.float32)})
    shifted = off.render_array(moved, cam, opts)[box[0], slice(W // 2 - 12, W // 2 + 32)].astype(float)
    assert np.abs(shifted - got).mean() < 0.2 * np.abs(got - got.mean()).mean() + 1.0
    with pytest.raises(LeafsimError, match="crinkle"):
        off.render_array(RenderMesh(**{**crinkled.__dict__, "crinkle": np.tile(np.float32([0.01, 0.02, 0.01]), (n, 1))}),
                         cam, opts)  # not positive semi-definite
    with pytest.raises(LeafsimError, match="crinkle"):
        off.render_array(RenderMesh(**{**crinkled.__dict__, "crinkle": np.full(n, 0.1, np.float32)}), cam, opts)
    with pytest.raises(LeafsimError, match="crinkle"):
        off.render_array(RenderMesh(**{**crinkled.__dict__, "mottle_rest": None}), cam, opts)


@pytest.mark.parametrize("deg", [0.0, 30.0, 90.0, 160.0])
def test_a_one_way_crinkle_wrinkles_across_its_compression(off, leaf, deg):
    """A slope tensor with all of its slope along one direction d (a lamina compressed one way,
    stretched the other): lit along d the blade's brightness gives back the slope asked for,
    lit across it (along the crests) it hardly varies; and the pattern's crests run across d,
    so the picture changes along d several times faster than along the crests.  (160°: the
    orientations the shader mixes wrap from 135° to 0°.)  A blade populated smooth and given
    the tensors by ``update`` draws the same."""
    s45 = math.sqrt(0.5)
    cam = top_camera()
    box = (slice(H // 2 - 50, H // 2 + 50), slice(W // 2 - 22, W // 2 + 22))  # inside the blade
    n = leaf.vertex_count
    rest = leaf.positions[:, :2].astype(np.float32)
    slope, a = 0.1, math.radians(deg)
    d = np.array([math.cos(a), math.sin(a)])
    S = slope * slope * np.array([d[0] * d[0], d[0] * d[1], d[1] * d[1]])
    mesh = RenderMesh(**{**leaf.__dict__, "mottle_rest": rest, "crinkle": np.tile(S.astype(np.float32), (n, 1)),
                         "crinkle_size": 0.003})
    got = {}
    for name, u in (("along", d), ("across", np.array([-d[1], d[0]]))):
        opts = RenderOptions(veins=False, shadows=False, ground=False, specular=0.0, translucency=0.0,
                             light_dir=(s45 * u[0], s45 * u[1], s45), light_colour=(1.0, 1.0, 1.0), sky_colour=(0.0, 0.0, 0.0))
        flat = _srgb_to_linear(off.render_array(RenderMesh(**{**mesh.__dict__, "crinkle": None}), cam, opts)[box][..., 1])
        g = _srgb_to_linear(off.render_array(mesh, cam, opts)[box][..., 1])
        got[name] = g
        got[name + "_slope"] = g.std() / flat.mean()  # N·L = sin 45° flat: the spread ÷ (albedo × sun × sin 45°)
    assert 0.8 * slope < got["along_slope"] < 1.2 * slope, got["along_slope"]
    assert got["across_slope"] < 0.15 * got["along_slope"], got["across_slope"]
    plain = RenderMesh(**{**mesh.__dict__, "crinkle": None})
    off.render_array(plain, cam, opts)
    updated = off.render_array({"positions": plain.positions, "crinkle": mesh.crinkle, "crinkle_size": 0.003}, cam, opts)
    assert np.array_equal(updated, off.render_array(mesh, cam, opts))
    zeros = off.render_array({"positions": plain.positions, "crinkle": np.zeros((n, 3), np.float32), "crinkle_size": 0.003},
                             cam, opts)
    assert np.array_equal(zeros, off.render_array(plain, cam, opts))
    if deg in (0.0, 90.0):  # the picture's rows are one axis, its columns the other
        g = got["along"]
        dx = np.abs(np.diff(g, axis=1)).mean()
        dy = np.abs(np.diff(g, axis=0)).mean()
        along_d, along_crest = (dx, dy) if deg == 0.0 else (dy, dx)
        assert along_d > 1.8 * along_crest, (along_d, along_crest)


def test_the_shader_s_crinkle_constants_are_the_bake_s():
    """The blade shader spells out the crinkle's crest stretch and its oriented fields'
    directions; the bake (leafsim.appearance.mottle) must read the field alike."""
    from leafsim.appearance import mottle
    from leafsim.base.resources import shader_dir

    src = (shader_dir() / "blade.frag").read_text()
    crest = float(re.search(r"const float CRINKLE_CREST = ([0-9.]+);", src).group(1))
    step = float(re.search(r"const float CRINKLE_STEP = ([0-9.]+);", src).group(1))
    dirs = re.search(r"const vec2 CRINKLE_DIRS\[4\] = vec2\[4\]\((.*?)\);", src, re.S).group(1)
    dirs = np.array([[float(x) for x in v.split(",")] for v in re.findall(r"vec2\(([^)]*)\)", dirs)])
    assert crest == mottle.CRINKLE_CREST and mottle.CRINKLE_ORIENTATIONS == 4 and "& 3" in src
    assert step == pytest.approx(np.pi / mottle.CRINKLE_ORIENTATIONS, abs=1e-10)
    k = np.arange(4) * np.pi / 4
    assert np.allclose(dirs, np.stack([np.cos(k), np.sin(k)], 1), atol=1e-8)
    assert len(mottle.CRINKLE_ORIENTED_OFFSETS) == 4

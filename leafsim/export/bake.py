"""One state's blade colour baked into a texture (``export --texture baked``; core: no OpenGL).

The window draws the blade's albedo per pixel: the pigment colour interpolated over each
triangle, the photo's own detail on a photo species ("detail" albedo), and the sub-grid mottle
(``colour.mottle``, :mod:`leafsim.appearance.mottle`), which moves every reaction's progress
per pixel and so lives below the vertices.  Per-vertex colours cannot carry it: a glTF or OBJ
of a turning leaf was smooth where the window is flecked.  This module computes the same
albedo on the CPU at every texel of the blade's texture space (the particles' texture
coordinates, the photo's for a photo species) and returns it as an 8-bit sRGB image:

* every texel centre is located in a blade triangle of the texture space (:func:`_raster`:
  barycentric coordinates, first triangle wins on shared edges);
* the vertex attributes the fragment shader interpolates (colour, the photo detail's young
  chromaticity and living weight, the mottle's pigment rows and rest positions) are
  interpolated with the same barycentric weights;
* the photo is sampled bilinearly after the exact sRGB decode (what the GL sampler does),
  the mottle field bilinearly with wrap-around, and ``photo_detail`` and ``mottle_ratio``
  are the shader's formulas (:mod:`leafsim.appearance.reflectance` holds the mottle's CPU twin);
* every texel outside the blade takes the nearest blade texel's colour (a viewer that filters
  or mipmaps across the margin finds no background colour there, at any mip level).

A texel is at most a third of the mottle's correlation length on the blade (sharper flecks
than the window at any zoom a user would draw the leaf), within :data:`BAKE_MIN` and
:data:`BAKE_MAX` texels a side; over a photo the texture is the photo's size, or an integer
multiple of it where the mottle asks for more (texel centres on the photo's pixels' grid, so
its detail is not resampled at fractional offsets).  The stalk's texture coordinates lie on the
blade's midrib near the base, where the blade's triangles are baked (first triangle wins): an
export gives the stalk a mesh of its own with the window's albedo per vertex
(:func:`vertex_albedo`).  A state is a still: an animation's texture could not
change with its key frames, so animations carry vertex colours (:func:`leafsim.export.mesh.export_mesh`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from leafsim.base.cache import configure_numba_cache

configure_numba_cache()

#: texels per correlation length of the mottle on the blade (at least)
TEXELS_PER_MOTTLE = 3.0
#: largest and smallest side of a baked texture, texels
BAKE_MAX = 4096
BAKE_MIN = 256
#: texels computed per chunk (bounds the memory of the interpolated attributes)
CHUNK = 1 << 18
#: the crinkle's largest slope [rad] below which a bake makes no normal map: half a level of
#: the 8-bit map (a fresh leaf's round-off excess, 1e-8 rad, would otherwise add a flat one)
MIN_SLOPE = 0.5 / 127.5
#: the fragment shader's "no photo detail" chromaticity and weight
NO_CHROMA = np.array([1.0, 1.0, 1.0, 0.0])
_W = np.array([0.2126, 0.7152, 0.0722])


@njit(cache=True, nogil=True)
def _raster(uv_px, tri, tri_id, bary):  # pragma: no cover - compiled
    """Locate every texel centre (x + ½, y + ½) in the triangles ``tri`` (m, 3) of vertex
    positions ``uv_px`` (n, 2) in texels: ``tri_id`` (H, W) int32 (−1 outside; filled by the
    caller) gets the triangle, ``bary`` (H, W, 2) the weights of its second and third vertex."""
    H, W = tri_id.shape
    for t in range(tri.shape[0]):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        ax, ay = uv_px[a, 0], uv_px[a, 1]
        bx, by = uv_px[b, 0] - ax, uv_px[b, 1] - ay
        cx, cy = uv_px[c, 0] - ax, uv_px[c, 1] - ay
        det = bx * cy - by * cx
        if abs(det) < 1e-12:
            continue
        x0 = max(int(np.floor(min(ax, ax + bx, ax + cx) - 0.5)), 0)
        x1 = min(int(np.ceil(max(ax, ax + bx, ax + cx) - 0.5)), W - 1)
        y0 = max(int(np.floor(min(ay, ay + by, ay + cy) - 0.5)), 0)
        y1 = min(int(np.ceil(max(ay, ay + by, ay + cy) - 0.5)), H - 1)
        eps = -1e-9
        for y in range(y0, y1 + 1):
            py = y + 0.5 - ay
            for x in range(x0, x1 + 1):
                if tri_id[y, x] >= 0:
                    continue
                px = x + 0.5 - ax
                s = (px * cy - py * cx) / det
                r = (bx * py - by * px) / det
                if s >= eps and r >= eps and s + r <= 1.0 - eps:
                    tri_id[y, x] = t
                    bary[y, x, 0] = s
                    bary[y, x, 1] = r


def srgb_decode(x: np.ndarray) -> np.ndarray:
    """The exact sRGB transfer curve's inverse (what an sRGB texture sampler applies), float64."""
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


#: :func:`srgb_decode` of the 256 8-bit levels (float32): a photo decodes by lookup
SRGB_LEVELS = srgb_decode(np.arange(256) / 255.0).astype(np.float32)


def bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray, wrap: bool) -> np.ndarray:
    """``img`` (H, W[, C]) sampled at texture coordinates ``u``, ``v`` (0..1 across the image,
    texel centres at (i + ½)/W) as a GL linear sampler does: wrapped (repeat) or clamped to
    the edge."""
    H, W = img.shape[:2]
    x = np.asarray(u, np.float64) * W - 0.5
    y = np.asarray(v, np.float64) * H - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    if wrap:
        xa, xb, ya, yb = x0 % W, (x0 + 1) % W, y0 % H, (y0 + 1) % H
    else:
        xa, xb = np.clip(x0, 0, W - 1), np.clip(x0 + 1, 0, W - 1)
        ya, yb = np.clip(y0, 0, H - 1), np.clip(y0 + 1, 0, H - 1)
    if img.ndim == 3:
        fx, fy = fx[:, None], fy[:, None]
    f = lambda a, b: np.asarray(img[a, b], np.float64)  # noqa: E731
    return (f(ya, xa) * (1 - fx) + f(ya, xb) * fx) * (1 - fy) + (f(yb, xa) * (1 - fx) + f(yb, xb) * fx) * fy


def photo_detail(base: np.ndarray, t: np.ndarray, tex_mean, chroma: np.ndarray) -> np.ndarray:
    """The fragment shader's ``photo_detail`` (shaders/common.glsl): the pigment colour ``base``
    with the photo texel ``t``'s brightness over the photo's mean and, weighted by the living
    tissue, its chromaticity over the young one (all linear RGB, (k, 3); ``chroma`` (k, 4))."""
    lum = t @ _W
    f = np.clip(lum / max(float(np.asarray(tex_mean, np.float64) @ _W), 1e-4), 0.0, 3.0)
    ratio = np.clip((t / np.maximum(lum, 1e-4)[:, None]) / np.maximum(chroma[:, :3], 1e-4), 0.25, 4.0)
    b = np.maximum(base, 0.0)
    c = b * ratio ** np.clip(chroma[:, 3:4], 0.0, 1.0)
    return f[:, None] * c * ((b @ _W) / np.maximum(c @ _W, 1e-6))[:, None]


def photo_texels(photo: np.ndarray) -> np.ndarray:
    """(h, w, 3) float32 linear RGB of the photo as the renderer holds it: the clean texture
    (:func:`~leafsim.appearance.texture.clean_texture`: the blade's colour carried past its
    mask), shrunk with area averaging to at most :data:`BAKE_MAX` texels a side as the
    renderer's upload is (its limit), then the exact sRGB decode of its sampler."""
    import cv2

    from leafsim.appearance.texture import clean_texture

    rgba = clean_texture(np.asarray(photo))
    h, w = rgba.shape[:2]
    if max(h, w) > BAKE_MAX:
        f = BAKE_MAX / max(h, w)
        rgba = cv2.resize(rgba, (max(1, int(w * f)), max(1, int(h * f))), interpolation=cv2.INTER_AREA)
    return SRGB_LEVELS[rgba[:, :, :3]]


def texture_size(uv: np.ndarray, xy: np.ndarray, tri: np.ndarray, mottle_size: float,
                 photo_size: tuple[int, int] | None = None) -> tuple[int, int]:
    """(width, height) in texels of the texture space [0, 1]² so that a texel spans at most
    1/:data:`TEXELS_PER_MOTTLE` of the mottle's correlation length on the blade (rest
    positions ``xy`` [m] against texture coordinates ``uv`` over the triangles ``tri``),
    clamped to [:data:`BAKE_MIN`, :data:`BAKE_MAX`].  With a photo (``photo_size`` (W, H), at
    most :data:`BAKE_MAX` a side: :func:`photo_texels`; the texture space is the photo) the
    photo's size times the integer the mottle asks for, as far as the cap allows."""
    e1u, e2u = uv[tri[:, 1]] - uv[tri[:, 0]], uv[tri[:, 2]] - uv[tri[:, 0]]
    e1x, e2x = xy[tri[:, 1]] - xy[tri[:, 0]], xy[tri[:, 2]] - xy[tri[:, 0]]
    det = e1u[:, 0] * e2u[:, 1] - e1u[:, 1] * e2u[:, 0]
    ok = np.abs(det) > 1e-14
    # the Jacobian ∂x/∂(u, v) of each triangle's affine map; its column norms are metres per unit of u and v
    X = np.stack([e1x[ok], e2x[ok]], 2)  # (m, 2 coords, 2 edges)
    J = X @ np.linalg.inv(np.stack([e1u[ok], e2u[ok]], 2))  # (m, 2, 2): d(x, y)/d(u, v)
    per_u = float(np.median(np.linalg.norm(J[:, :, 0], axis=1))) if ok.any() else 0.1
    per_v = float(np.median(np.linalg.norm(J[:, :, 1], axis=1))) if ok.any() else 0.1
    texel = max(float(mottle_size), 1e-5) / TEXELS_PER_MOTTLE
    if photo_size is not None:  # the photo's grid, times the integer the mottle asks for (if the cap allows)
        pw, ph = (int(x) for x in photo_size)
        if max(pw, ph) > BAKE_MAX:
            raise ValueError(f"texture_size: a photo grid of {pw} x {ph} is above BAKE_MAX (shrink it: photo_texels)")
        k = max(1, int(np.ceil(max(per_u / texel / pw, per_v / texel / ph) - 1e-9)))
        k = max(1, min(k, BAKE_MAX // max(pw, ph)))
        return pw * k, ph * k
    side = lambda metres: int(np.clip(np.ceil(metres / texel - 1e-9), BAKE_MIN, BAKE_MAX))  # noqa: E731
    return side(per_u), side(per_v)


def _fill_outside(rgb: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """``rgb`` with every texel outside ``inside`` given its nearest inside texel's colour."""
    from scipy.ndimage import distance_transform_edt

    if inside.all() or not inside.any():
        return rgb
    iy, ix = distance_transform_edt(~inside, return_distances=False, return_indices=True)
    return rgb[iy, ix]


def _bake_triangles(source) -> np.ndarray:
    """(m, 3) int64 the T triangles in the view's vertex numbering, the blade's own first:
    where the stalk's thin strip of texture space overlaps the blade's (a photo's petiole on the
    blade), the blade's texels are kept."""
    model = source.model
    stalk_tri = ~model.blade_particles[model.tri_T].all(axis=1)
    return source.view.remap[model.tri_T[np.argsort(stalk_tri, kind="stable")]].astype(np.int64)


def _tangent_frames(uv: np.ndarray, xy: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(m, 2, 2): per triangle, the unit directions in the rest plane of glTF's tangent-space
    x (increasing u) and y ("up" in the image: decreasing v, v = 0 the top row), as a client
    that derives its tangents from the texture coordinates (MikkTSpace) lays them on the
    surface; rows 0 and 1.  Degenerate triangles get the rest axes."""
    e1u, e2u = uv[tri[:, 1]] - uv[tri[:, 0]], uv[tri[:, 2]] - uv[tri[:, 0]]
    e1x, e2x = xy[tri[:, 1]] - xy[tri[:, 0]], xy[tri[:, 2]] - xy[tri[:, 0]]
    det = e1u[:, 0] * e2u[:, 1] - e1u[:, 1] * e2u[:, 0]
    ok = np.abs(det) > 1e-14
    out = np.tile(np.array([[1.0, 0.0], [0.0, 1.0]]), (len(tri), 1, 1))
    J = np.stack([e1x[ok], e2x[ok]], 2) @ np.linalg.inv(np.stack([e1u[ok], e2u[ok]], 2))  # d(x, y)/d(u, v)
    t, b = J[:, :, 0], -J[:, :, 1]
    nt, nb = np.linalg.norm(t, axis=1), np.linalg.norm(b, axis=1)
    good = (nt > 0) & (nb > 0)
    idx = np.flatnonzero(ok)[good]
    out[idx, 0] = t[good] / nt[good, None]
    out[idx, 1] = b[good] / nb[good, None]
    return out


def bake_normals(source, state, size: tuple[int, int]) -> np.ndarray | None:
    """(H, W, 3) uint8 tangent-space normal map of the blade's sub-grid crinkle
    (``render.crinkle``, :mod:`leafsim.sim.crinkle`) over the texture space of ``size`` (W, H)
    (the albedo's), as glTF's ``normalTexture`` holds it (x right along increasing u, y up,
    z out; RGB = (n + 1) / 2), or None when the blade has no crinkle.  Each texel takes the
    fragment shader's height gradient at its rest position (the vertices' slopes and rest
    positions interpolated as the shader has them, the field's central differences
    (:func:`~leafsim.appearance.mottle.crinkle_gradient`, in half floats as the renderer's
    texture) sampled bilinearly with wrap-around, oriented as the compression asks:
    :func:`~leafsim.appearance.mottle.crinkle_height_gradient`) and tilts the normal against it along the triangle's
    tangent-space directions (:func:`_tangent_frames`).  Outside the blade: flat (0, 0, 1)
    carried from the nearest blade texel.  None too when no slope reaches :data:`MIN_SLOPE`."""
    from leafsim.appearance.mottle import crinkle_gradient, crinkle_gradient_rms, crinkle_height_gradient, mottle_scale

    view, params, model = source.view, source.params, source.model
    slopes, csize = view.crinkle(state, params)
    if slopes is None or csize <= 0.0:
        return None
    from leafsim.sim.crinkle import principal

    if float(np.sqrt(np.max(principal(slopes)[0], initial=0.0))) < MIN_SLOPE:  # the steepest direction's RMS slope
        return None
    tri = _bake_triangles(source)
    uv = np.asarray(source.uv, np.float64)
    rest = np.asarray(view.mottle_rest(state), np.float64)
    frames = _tangent_frames(uv, model.particle_rest[view.T][:, :2].astype(np.float64), tri)
    W, H = int(size[0]), int(size[1])
    tri_id = np.full((H, W), -1, np.int32)
    bary = np.zeros((H, W, 2), np.float32)
    _raster(uv * np.array([W, H], np.float64), tri, tri_id, bary)
    inside = tri_id >= 0
    attr = np.concatenate([np.asarray(slopes, np.float64), rest], 1)
    grad_field = crinkle_gradient().astype(np.float16)  # as the renderer's half-float texture holds it
    scale, norm = mottle_scale(csize), 1.0 / crinkle_gradient_rms()
    out = np.zeros((H, W, 3), np.float32)
    ys, xs = np.nonzero(inside)
    for lo in range(0, len(ys), CHUNK):
        y, x = ys[lo:lo + CHUNK], xs[lo:lo + CHUNK]
        k = tri_id[y, x]
        t = tri[k]
        s, r = bary[y, x, 0:1].astype(np.float64), bary[y, x, 1:2].astype(np.float64)
        a = attr[t[:, 0]] * (1.0 - s - r) + attr[t[:, 1]] * s + attr[t[:, 2]] * r
        grad = crinkle_height_gradient(a[:, 0:3], a[:, 3:5], scale,
                                       lambda u, v: norm * bilinear(grad_field, u, v, wrap=True))  # dh/d(rest x, y)
        ht = np.einsum("ij,ij->i", grad, frames[k, 0])
        hb = np.einsum("ij,ij->i", grad, frames[k, 1])
        nrm = np.stack([-ht, -hb, np.ones_like(ht)], 1)
        out[y, x] = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    out[~inside] = (0.0, 0.0, 1.0)
    out = _fill_outside(out, inside)
    return np.clip(np.rint((out + 1.0) * 127.5), 0, 255).astype(np.uint8)


#: the window's albedos a bake reproduces (render options' names)
ALBEDOS = ("detail", "texture", "colours")


class _Shading:
    """What the fragment shader needs to draw the blade's albedo of ``source`` in ``state`` at a
    point: the per-vertex attributes it interpolates (:attr:`attr`, rows of the view's vertices)
    and the photo and mottle it samples (:meth:`shade`)."""

    def __init__(self, source, state):
        from leafsim.appearance.mottle import mottle_levels, mottle_scale

        view, params = source.view, source.params
        col, tint = view.colours(state, params)
        col = np.asarray(col, np.float64)
        mottle, self.msize, self.amount = view.mottle(state, params)
        rest = np.asarray(view.mottle_rest(state), np.float64)
        self.mode = getattr(source, "albedo", "detail")
        self.photo = view.photo_rgba if view.use_texture(params) and self.mode != "colours" else None
        if self.photo is not None:
            if self.mode == "texture":
                col = np.ones_like(col) if tint is None else np.asarray(tint, np.float64)  # the photo × the tint
            self.tex = photo_texels(self.photo)
            mask = np.asarray(self.photo)[:, :, 3] >= 128
            lin = (np.asarray(self.photo)[:, :, :3][mask].astype(np.float64) / 255.0) ** 2.2  # the renderer's mean (u_tex_mean)
            self.tex_mean = lin.mean(axis=0) if lin.size else np.array([0.2, 0.3, 0.1])
        chroma = view.chroma(state, params) if self.photo is not None and self.mode == "detail" else None
        self.chroma = chroma is not None
        cols = [col]
        if chroma is not None:
            cols.append(np.asarray(chroma, np.float64))
        self.use_mottle = mottle is not None and self.msize > 0 and self.amount > 0
        if self.use_mottle:
            cols += [np.asarray(mottle, np.float64), rest]
            self.noise = mottle_levels()
            self.scale = mottle_scale(self.msize)
        self.attr = np.concatenate(cols, 1)

    def shade(self, a: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(k, 3) linear albedo of points with interpolated attributes ``a`` (k, :attr:`attr`'s
        columns) at texture coordinates ``u``, ``v`` (k,) (where the photo is sampled)."""
        from leafsim.appearance.reflectance import mottle_ratio

        albedo = a[:, :3]
        k = 3
        if self.photo is not None:
            texel = bilinear(self.tex, u, v, wrap=False)
            if self.mode == "texture":
                albedo = texel * albedo
            else:
                ch = a[:, k:k + 4] if self.chroma else np.tile(NO_CHROMA, (len(a), 1))
                k += 4 if self.chroma else 0
                albedo = photo_detail(albedo, texel, self.tex_mean, ch)
        if self.use_mottle:
            rows, pos = a[:, k:k + 10], a[:, k + 10:k + 12]
            lev = bilinear(self.noise, pos[:, 0] * self.scale, pos[:, 1] * self.scale, wrap=True) / 255.0
            n = lev * (255.0 / 128.0) - (255.0 / 256.0)  # the shader's mottle_n
            albedo = albedo * mottle_ratio(rows, n, self.amount)
        return albedo


def bake_albedo(source, state, size: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(albedo (H, W, 3) float32 linear RGB, blade (H, W) bool) of ``source``'s blade in
    ``state`` over the texture space (``source``: a :class:`~leafsim.export.mesh.MeshSource`;
    ``size`` (W, H) default :func:`texture_size`).  The albedo is ``source.albedo``'s where the
    species has a photo (and ``render.texture`` is on): "detail" (the pigment colour with the
    photo's detail, the window's default), "texture" (the photo times the view's tint) or
    "colours"; the pigment colour otherwise.  Outside the blade the nearest blade texel's colour."""
    view, model = source.view, source.model
    tri = _bake_triangles(source)
    uv = np.asarray(source.uv, np.float64)
    sh = _Shading(source, state)
    if size is None:
        size = texture_size(uv, model.particle_rest[view.T][:, :2], tri, sh.msize if sh.msize > 0 else 6e-4,
                            None if sh.photo is None else (sh.tex.shape[1], sh.tex.shape[0]))
    W, H = int(size[0]), int(size[1])
    tri_id = np.full((H, W), -1, np.int32)
    bary = np.zeros((H, W, 2), np.float32)
    _raster(uv * np.array([W, H], np.float64), tri, tri_id, bary)
    inside = tri_id >= 0
    attr = sh.attr
    out = np.zeros((H, W, 3), np.float32)
    ys, xs = np.nonzero(inside)
    for lo in range(0, len(ys), CHUNK):
        y, x = ys[lo:lo + CHUNK], xs[lo:lo + CHUNK]
        t = tri[tri_id[y, x]]
        s, r = bary[y, x, 0:1].astype(np.float64), bary[y, x, 1:2].astype(np.float64)
        a = attr[t[:, 0]] * (1.0 - s - r) + attr[t[:, 1]] * s + attr[t[:, 2]] * r
        out[y, x] = sh.shade(a, (x + 0.5) / W, (y + 0.5) / H)
    return _fill_outside(out, inside), inside


def vertex_albedo(source, state, vertices: np.ndarray) -> np.ndarray:
    """(k, 3) linear albedo the window draws at the view's vertices ``vertices`` (k,) of
    ``source``'s leaf in ``state``: the fragment shader's colour at the vertex (pigments, the
    photo's detail at its texture coordinates, the mottle at its rest position).  What the
    stalk carries per vertex in a baked export: its texture coordinates lie on the blade's
    midrib, whose texels the blade's own colour fills (:func:`bake_albedo`)."""
    vertices = np.asarray(vertices, np.int64)
    sh = _Shading(source, state)
    uv = np.asarray(source.uv, np.float64)[vertices]
    return sh.shade(sh.attr[vertices], uv[:, 0], uv[:, 1]).astype(np.float32)


def bake_png(source, state) -> bytes:
    """:func:`bake_albedo` as PNG bytes (8-bit sRGB, what glTF's baseColorTexture holds)."""
    return bake_pngs(source, state, normals=False)[0]


def bake_pngs(source, state, normals: bool = True) -> tuple[bytes, bytes | None]:
    """(:func:`bake_png`, the crinkle's normal map of the same size as PNG bytes
    (:func:`bake_normals`; glTF's normalTexture, linear RGB) or None without a crinkle or with
    ``normals`` False)."""
    import cv2

    from leafsim.appearance.reflectance import linear_to_srgb
    from leafsim.base.errors import LeafsimError

    albedo, inside = bake_albedo(source, state)
    if not inside.any():
        raise LeafsimError("export: the blade covers no texel of its texture space (texture coordinates all outside "
                           "[0, 1] or degenerate): nothing to bake")
    srgb = np.clip(np.rint(linear_to_srgb(albedo) * np.float32(255.0)), 0, 255).astype(np.uint8)  # float32 throughout
    ok, buf = cv2.imencode(".png", cv2.cvtColor(srgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise LeafsimError("export: cannot encode the baked texture as PNG")
    nmap = bake_normals(source, state, (albedo.shape[1], albedo.shape[0])) if normals else None
    if nmap is None:
        return buf.tobytes(), None
    ok, nbuf = cv2.imencode(".png", cv2.cvtColor(nmap, cv2.COLOR_RGB2BGR))
    if not ok:
        raise LeafsimError("export: cannot encode the crinkle's normal map as PNG")
    return buf.tobytes(), nbuf.tobytes()

"""CPU geometry for the renderer: vertex normals and vein ribbons. numpy + numba, no OpenGL."""

from __future__ import annotations

import numpy as np

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency, keep a slow path anyway
    njit = None
from leafsim.base.cache import configure_numba_cache

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources


def _normals_numpy(pos: np.ndarray, tri: np.ndarray, out: np.ndarray) -> None:
    fn = np.cross(pos[tri[:, 1]] - pos[tri[:, 0]], pos[tri[:, 2]] - pos[tri[:, 0]])
    n = pos.shape[0]
    for k in range(3):
        out[:, k] = (np.bincount(tri[:, 0], fn[:, k], n) + np.bincount(tri[:, 1], fn[:, k], n)
                     + np.bincount(tri[:, 2], fn[:, k], n))
    ln = np.linalg.norm(out, axis=1)
    bad = ln < 1e-30
    out[~bad] /= ln[~bad, None]
    out[bad] = (0.0, 0.0, 1.0)


if njit is not None:

    @njit(cache=True, fastmath=True)
    def _normals_nb(pos, tri, out):  # pragma: no cover - compiled
        n = pos.shape[0]
        for i in range(n):
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
        for t in range(tri.shape[0]):
            a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
            ux = pos[b, 0] - pos[a, 0]
            uy = pos[b, 1] - pos[a, 1]
            uz = pos[b, 2] - pos[a, 2]
            vx = pos[c, 0] - pos[a, 0]
            vy = pos[c, 1] - pos[a, 1]
            vz = pos[c, 2] - pos[a, 2]
            nx = uy * vz - uz * vy
            ny = uz * vx - ux * vz
            nz = ux * vy - uy * vx
            for v in (a, b, c):
                out[v, 0] += nx
                out[v, 1] += ny
                out[v, 2] += nz
        for i in range(n):
            ln = np.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
            if ln > 1e-30:
                out[i, 0] /= ln
                out[i, 1] /= ln
                out[i, 2] /= ln
            else:
                out[i, 0] = 0.0
                out[i, 1] = 0.0
                out[i, 2] = 1.0


def vertex_normals(pos: np.ndarray, tri: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Area-weighted unit vertex normals.

    Parameters
    ----------
    pos : (n, 3) float32
    tri : (m, 3) int32, consistently wound
    out : (n, 3) float32, optional output buffer

    Returns
    -------
    (n, 3) float32
    """
    if out is None:
        out = np.empty(pos.shape, dtype=np.float32)
    if njit is not None:
        _normals_nb(pos, tri, out)
    else:
        _normals_numpy(pos, tri, out)
    return out


def _consistent(tri: np.ndarray) -> bool:
    """True if no directed edge occurs twice (neighbouring triangles wound alike)."""
    t = tri.astype(np.int64)
    a = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    b = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    key = a * (int(t.max()) + 1) + b
    return np.unique(key).size == key.size


def _propagate(tri: np.ndarray, nz: np.ndarray) -> np.ndarray:
    """Make winding consistent across shared edges (breadth-first from the triangle facing
    most clearly up in each connected piece). Non-manifold edges are left as they come."""
    from collections import defaultdict, deque

    tri = tri.copy()
    edge_tris = defaultdict(list)
    for t, (a, b, c) in enumerate(tri.tolist()):
        for u, v in ((a, b), (b, c), (c, a)):
            edge_tris[(min(u, v), max(u, v))].append(t)
    seen = np.zeros(len(tri), bool)
    for seed in np.argsort(-np.abs(nz)):
        if seen[seed]:
            continue
        if nz[seed] < 0:
            tri[seed, [1, 2]] = tri[seed, [2, 1]]
        seen[seed] = True
        queue = deque([seed])
        while queue:
            t = queue.popleft()
            a, b, c = tri[t]
            for u, v in ((a, b), (b, c), (c, a)):
                for o in edge_tris[(min(u, v), max(u, v))]:
                    if seen[o]:
                        continue
                    oa, ob, oc = tri[o]
                    # a consistent neighbour runs the shared edge the other way (v -> u)
                    if (oa, ob) == (u, v) or (ob, oc) == (u, v) or (oc, oa) == (u, v):
                        tri[o, [1, 2]] = tri[o, [2, 1]]
                    seen[o] = True
                    queue.append(o)
    return tri


def orient_up(pos: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Copy of ``tri`` wound consistently, with normals towards +z where the leaf is flat.

    Each triangle is first wound so that its normal has z >= 0 (right for the flat rest
    shape). If that leaves neighbours wound differently (a curled or folded state was
    given), the given winding is kept when it is consistent (flipped as a whole if it faces
    down on average), else the winding is propagated across shared edges.
    """
    tri = np.array(tri, dtype=np.int32, copy=True)
    p = np.asarray(pos, dtype=np.float64)
    nz = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])[:, 2]
    up = tri.copy()
    flip = nz < 0
    up[flip, 1], up[flip, 2] = tri[flip, 2], tri[flip, 1]
    if _consistent(up):
        return up
    if _consistent(tri):
        if nz.sum() < 0:
            tri[:, [1, 2]] = tri[:, [2, 1]]
        return tri
    return _propagate(tri, nz)


def unique_edges(tri: np.ndarray) -> np.ndarray:
    """(e, 2) int32 undirected edges of a triangle list."""
    tri = np.asarray(tri, dtype=np.int64)
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    m = int(hi.max()) + 1
    key = np.unique(lo * m + hi)
    return np.stack([key // m, key % m], 1).astype(np.int32)


def bounds(pos: np.ndarray):
    """(lo (3,), hi (3,)) float64 of ``pos (n, 3)``."""
    if njit is not None:
        return _bounds_nb(pos)
    p = np.where(np.isfinite(pos), pos, np.nan)
    return np.nanmin(p, axis=0).astype(np.float64), np.nanmax(p, axis=0).astype(np.float64)


if njit is not None:

    @njit(cache=True)
    def _bounds_nb(pos):  # pragma: no cover - compiled
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for i in range(pos.shape[0]):
            for k in range(3):
                v = pos[i, k]
                if not np.isfinite(v):
                    continue
                if v < lo[k]:
                    lo[k] = v
                if v > hi[k]:
                    hi[k] = v
        return lo, hi


class VeinRibbons:
    """Static topology of the vein ribbons; :meth:`frame` fills the per-frame vertex data.

    Every polyline point becomes two ribbon vertices (left ``v = -1``, right ``v = +1``);
    consecutive points of one polyline form a quad.
    """

    def __init__(self, vein_lines, n_vertices: int, texcoords=None, rest=None):
        idx, width, order, prev, nxt, quads = [], [], [], [], [], []
        start = 0
        for line in vein_lines or []:
            li, lw, lo = line
            li = np.asarray(li, dtype=np.int64).ravel()
            lw = np.asarray(lw, dtype=np.float64).ravel()
            p = li.size
            if p < 2:
                continue
            g = start + np.arange(p)
            idx.append(li)
            width.append(lw)
            order.append(np.full(p, int(lo)))
            prev.append(np.maximum(g - 1, start))
            nxt.append(np.minimum(g + 1, start + p - 1))
            s = g[:-1]
            quads.append(np.stack([2 * s, 2 * s + 1, 2 * s + 2, 2 * s + 1, 2 * s + 3, 2 * s + 2], 1))
            start += p
        self.count = start
        self.across_uv = False
        if start == 0:
            return
        self.idx = np.concatenate(idx)
        self.prev = np.concatenate(prev)
        self.next = np.concatenate(nxt)
        self.indices = np.concatenate(quads).astype(np.int32).ravel()
        hw = 0.5 * np.concatenate(width)
        self.hw = hw  # half widths, metres (the mottle's sample positions across the ribbon)
        order = np.concatenate(order).astype(np.float32)
        uv = (np.zeros((start, 2)) if texcoords is None
              else np.asarray(texcoords, dtype=np.float64)[self.idx])
        static = np.empty((start, 2, 5), dtype=np.float32)  # hw, v, uv(2), order
        static[:, :, 0] = hw[:, None]
        static[:, 0, 1], static[:, 1, 1] = -1.0, 1.0
        static[:, :, 2:4] = uv[:, None, :]
        duv = None if texcoords is None or rest is None else self._across_uv(texcoords, rest, hw)
        self.across_uv = duv is not None  # the sides sample the photo where they lie
        if duv is not None:
            # each side samples the photo where it lies, half the vein's width across it: the
            # ribbon shows the photo's own vein at its own width.  With the centre line's
            # coordinate on both sides, a photo vein 3 px wide was drawn as a band of the
            # ribbon's width (8 px on hornbeam's midrib) in the vein's darkest colour
            static[:, 0, 2:4] = uv - duv
            static[:, 1, 2:4] = uv + duv
        static[:, :, 4] = order[:, None]
        self.static = static.reshape(-1, 5)
        self.dynamic = np.empty((start, 2, 9), dtype=np.float32)  # centre, side, normal
        self.base = np.empty((start, 2, 13), dtype=np.float32)

    def _across_uv(self, texcoords, rest, hw) -> np.ndarray | None:
        """(p, 2) the texture-coordinate step from a ribbon's centre line to its v = +1 side:
        half the vein's width across the vein in the rest plane (as :meth:`mottle_rows` moves
        the mottle's samples), through the affine map from rest positions to texture
        coordinates that a photo leaf's blade follows (fitted on the vertices that follow one
        map: a stalk's are placed otherwise, and their ribbon keeps its centre's coordinate).
        None where no affine map holds for most vertices (residual over 10⁻⁴) or without rest
        positions."""
        uvs = np.asarray(texcoords, np.float64)
        xy = np.asarray(rest, np.float64)[:, :2]
        if len(xy) != len(uvs) or len(xy) < 3 or not np.ptp(xy, axis=0).all():
            return None
        X = np.column_stack([xy, np.ones(len(xy))])
        fit = np.ones(len(xy), bool)
        for _ in range(3):  # refit on the vertices the map holds for (hornbeam: 1203 of 1224, its stalk's out)
            A, *_ = np.linalg.lstsq(X[fit], uvs[fit], rcond=None)
            if not np.isfinite(A).all():
                return None
            res = np.abs(X @ A - uvs).max(1)
            fit = res <= max(1e-4, float(np.percentile(res, 80)))
        held = res <= 1e-4
        if held.sum() < 0.5 * len(xy):
            return None
        t = xy[self.idx[self.next]] - xy[self.idx[self.prev]]
        ln = np.linalg.norm(t, axis=1, keepdims=True)
        perp = np.where(ln > 1e-12, np.stack([-t[:, 1], t[:, 0]], 1) / np.maximum(ln, 1e-12), np.array([1.0, 0.0]))
        return np.where(held[self.idx][:, None], (perp * hw[:, None]) @ A[:2], 0.0)

    def frame(self, pos: np.ndarray, nrm: np.ndarray) -> np.ndarray:
        """(2p, 9) float32: centre, side, normal per ribbon vertex."""
        c = pos[self.idx]
        n = nrm[self.idx]
        t = pos[self.idx[self.next]] - pos[self.idx[self.prev]]
        side = np.cross(n, t)
        ln = np.linalg.norm(side, axis=1, keepdims=True)
        side = np.where(ln > 1e-20, side / np.maximum(ln, 1e-20), np.array([1.0, 0.0, 0.0], np.float32))
        d = self.dynamic
        d[:, :, 0:3] = c[:, None, :]
        d[:, :, 3:6] = side[:, None, :]
        d[:, :, 6:9] = n[:, None, :]
        return d.reshape(-1, 9)

    def mottle_rows(self, mottle: np.ndarray, rest: np.ndarray) -> np.ndarray:
        """(2p, k + 2) float32 per ribbon vertex: the blade's sub-grid mottle pigments at the
        centre line's vertex (k columns, :func:`leafsim.appearance.reflectance.mottle_pigments`)
        and where the tissue samples the mottle field: the vertex's rest position moved half the
        vein's width across the vein in the rest plane, to the side the vertex spreads to, so a
        ribbon (which redraws the blade under it with the photo albedos) shows the field across
        its width as the blade does, not one sample stretched across it in bars."""
        rest = np.asarray(rest, np.float64)
        c = rest[self.idx]
        t = rest[self.idx[self.next]] - rest[self.idx[self.prev]]
        ln = np.linalg.norm(t, axis=1, keepdims=True)
        perp = np.where(ln > 1e-12, np.stack([-t[:, 1], t[:, 0]], 1) / np.maximum(ln, 1e-12), np.array([1.0, 0.0]))
        off = perp * self.hw[:, None]
        m = np.asarray(mottle, np.float32)[self.idx]
        out = np.empty((self.count, 2, m.shape[1] + 2), np.float32)
        out[:, :, :-2] = m[:, None, :]
        out[:, 0, -2:] = c - off   # v = -1
        out[:, 1, -2:] = c + off   # v = +1
        return out.reshape(-1, m.shape[1] + 2)

    def base_colours(self, colours: np.ndarray, tint: np.ndarray, chroma: np.ndarray,
                     vein: np.ndarray | None = None) -> np.ndarray:
        """(2p, 13) float32 per ribbon vertex: the blade's colour x tint, tint (linear), the
        detail albedo's chromaticity and weight (:class:`~leafsim.appearance.mesh.RenderMesh`),
        and the vein tissue's own colour x tint (``vein``; the blade's when None), which the
        vertex-colour albedo draws (the photo albedos draw the photo's veins under them)."""
        self.base[:, :, 0:3] = (colours[self.idx] * tint[self.idx])[:, None, :]
        self.base[:, :, 3:6] = tint[self.idx][:, None, :]
        self.base[:, :, 6:10] = chroma[self.idx][:, None, :]
        self.base[:, :, 10:13] = ((colours if vein is None else vein)[self.idx] * tint[self.idx])[:, None, :]
        return self.base.reshape(-1, 13)

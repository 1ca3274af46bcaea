"""What a botanist sees in a dried leaf, as numbers: how far the margins roll, how much the blade
wrinkles between the veins and at what wavelength, and how far it folds along the midrib.

All in the leaf's own rigid frame (:func:`leafsim.sim.shape.leaf_frame`: the best rigid fit of
the blade onto its rest shape), over the rest shape's parameters, so they do not depend on
where the leaf lies or on the mesh:

* **margin roll** — the angle between the surface normal at each margin particle and the
  blade's mean normal, averaged over the margin (0° flat, 90° an upright margin, beyond 90° a
  margin rolled back over the blade); also its 90th percentile.
* **wrinkles** — the height field of the blade (z in the leaf frame, sampled on a grid over the
  rest outline) minus its smooth part (a Gaussian of σ = ``SMOOTH`` × L, normalised inside the
  blade: a local quadratic fit, so a bowl's or a saddle's curvature leaves no residual): the RMS of the rest over L (amplitude) and its dominant wavelength over L (the peak of
  the radially averaged power spectrum).  Below ``FLAT`` × L RMS the blade counts as smooth and
  has no wavelength.
* **midrib fold** — the V angle across the midrib: at ten stations over the middle 70 % of the
  midrib's length, the angle between the mean normals of the blade strips on either side of it
  (within ``FOLD_BAND`` × L of the midrib at rest, L the leaf's length from base to apex), seen
  along the midrib (their components along the deformed midrib's direction there left out: a
  twist about the midrib is no fold), averaged with the strips' areas as weights;
  0° flat, 90° a right-angled V, positive when the halves rise (a valley along the midrib, the
  upper faces turned towards each other), negative for a ridge.  Local along the midrib, so a
  blade bent end to end (a boat) or curled along its length has no fold unless it is also
  V-shaped across the midrib.  (Until 7 December it was the angle between the best-fit planes
  of the two whole halves: for a half curled along its length that plane is ill-defined, and
  chestnut's boat read 67–115° where its V is 12°.)

Guo et al. 2025 (arXiv:2507.01813) class dried shapes as C-curl, S-curl and fold with wavy edges;
these three numbers tell them apart (roll without fold, fold with wavy margin, …).
"""

from __future__ import annotations

import math

import numpy as np

from leafsim.sim.model import Model, State
from leafsim.sim.shape import leaf_frame

#: the smooth part of the height field: Gaussian σ, × leaf length
SMOOTH = 0.06
#: grid cells across the leaf length for the height field
GRID = 160
#: below this RMS (× L; 0.1 mm on a 10 cm leaf) the residual is no wrinkle
FLAT = 1e-3
#: the midrib fold's strips: the blade within this distance of the midrib (× L), either side
FOLD_BAND = 0.1
#: the midrib fold's stations: this many, over this share of the midrib's length (its middle)
FOLD_STATIONS, FOLD_SPAN = 10, (0.15, 0.85)


def _normals(q: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Area-weighted (unnormalised) triangle normals, orientation of the rest shape (CCW = +z)."""
    return 0.5 * np.cross(q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]])


def margin_roll(model: Model, q: np.ndarray) -> dict:
    """Mean and 90th percentile of the margin particles' normal angle to the mean normal [deg]."""
    tri = model.blade_tri_T
    nt = _normals(q, tri)
    mean = nt.sum(0)
    mean /= max(float(np.linalg.norm(mean)), 1e-300)
    n = np.zeros_like(q)
    for k in range(3):
        np.add.at(n, tri[:, k], nt)
    idx = model.contour_particles
    ni = n[idx]
    ni /= np.maximum(np.linalg.norm(ni, axis=1, keepdims=True), 1e-300)
    ang = np.degrees(np.arccos(np.clip(ni @ mean, -1.0, 1.0)))
    return {"margin_roll_deg": round(float(ang.mean()), 2), "margin_roll_p90_deg": round(float(np.percentile(ang, 90)), 2)}


def _midrib_rest(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """(k, 2) the midrib at rest, base to apex, and its (k,) particles: of the first-order
    veins of the blade (not the stalk's) that start at the base, the one that reaches furthest
    towards the apex (+y); the base–apex axis (no particles) if there is none."""
    r = model.particle_rest
    base = r[model.base_particle, :2]
    stalk = model.particle_petiole
    best, reach = None, -np.inf
    for idx, _, order in model.vein_polylines():
        p = r[idx, :2]
        if order != 0 or len(p) < 2 or (stalk is not None and bool(np.asarray(stalk)[idx].any())):
            continue
        if np.linalg.norm(p[0] - base) <= 0.05 * model.length and p[-1, 1] > reach:
            best, reach = idx, p[-1, 1]
    if best is None:
        y = r[model.blade_T, 1]
        return np.array([[0.0, float(y.min())], [0.0, float(y.max())]]), np.zeros(0, np.int64)
    return r[best, :2], np.asarray(best, np.int64)


def _blade_length(model: Model) -> float:
    return float(np.ptp(model.particle_rest[model.blade_T, 1])) or 1.0  # the blade's, not the stalk's


def _arc_length(poly: np.ndarray) -> np.ndarray:
    """(k,) the arc length of each point of the polyline from its first."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])


def _along_midrib(poly: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(s, d, length): the arc length of each point's nearest point on the polyline and its
    signed distance from it (+ on the left, looking from the base to the apex)."""
    from scipy.spatial import cKDTree

    cum = _arc_length(poly)
    total = float(cum[-1])
    seg = np.diff(poly, axis=0)
    seg_len = np.diff(cum)
    keep = seg_len > 0
    if total <= 0.0:
        return np.zeros(len(pts)), np.zeros(len(pts)), 0.0
    start, seg, seg_len = cum[:-1][keep], seg[keep], seg_len[keep]
    base = poly[:-1][keep]
    # resampled finely (4000 points over the midrib), the nearest sample is the foot within L/8000
    s_samp = np.linspace(0.0, total, 4000)
    k = np.clip(np.searchsorted(start, s_samp, side="right") - 1, 0, len(seg) - 1)
    samp = base[k] + ((s_samp - start[k]) / seg_len[k])[:, None] * seg[k]
    tang = seg[k] / seg_len[k][:, None]
    dist, j = cKDTree(samp).query(pts)
    rel = pts - samp[j]
    side = np.sign(tang[j, 0] * rel[:, 1] - tang[j, 1] * rel[:, 0])
    return s_samp[j], side * dist, total


def _direction(q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The direction (unnormalised) of the line fitted through the points ``q`` against their
    parameter ``s`` (least squares)."""
    ds = s - s.mean()
    return ((q - q.mean(0)) * ds[:, None]).sum(0)


def midrib_fold(model: Model, q: np.ndarray) -> float:
    """The V angle across the midrib [deg] (module docstring): + the halves rise, − a ridge."""
    tri = model.blade_tri_T
    poly, mid = _midrib_rest(model)
    s, d, total = _along_midrib(poly, model.particle_rest[tri].mean(1)[:, :2])
    if len(tri) == 0 or total <= 0.0:
        return 0.0
    s_mid = _arc_length(poly)
    n = _normals(q, tri)
    band = FOLD_BAND * model.length
    edges = np.linspace(FOLD_SPAN[0] * total, FOLD_SPAN[1] * total, FOLD_STATIONS + 1)
    half = 0.5 * (edges[1] - edges[0])
    num = den = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        at = (s >= a) & (s < b) & (np.abs(d) <= band)
        left, right = at & (d > 0), at & (d < 0)
        if not (left.any() and right.any()):
            continue
        nl, nr = n[left].sum(0), n[right].sum(0)  # area-weighted (the normals' lengths are areas)
        w = min(float(np.linalg.norm(nl)), float(np.linalg.norm(nr)))
        # seen along the midrib: the normals' components along the deformed midrib's direction
        # here are left out (a twist of the blade about the midrib turns them that way)
        on = (s_mid >= a - half) & (s_mid <= b + half)
        if len(mid) and on.sum() >= 2:
            t = _direction(q[mid[on]], s_mid[on])
        else:  # no midrib particles (the fallback axis): the strips' centroids against s
            t = _direction(q[tri[at]].mean(1), s[at])
        tn = float(np.linalg.norm(t))
        if w <= 0.0 or tn <= 0.0:
            continue
        t /= tn
        nl, nr = nl - (nl @ t) * t, nr - (nr @ t) * t
        al, ar = float(np.linalg.norm(nl)), float(np.linalg.norm(nr))
        if min(al, ar) <= 0.0:
            continue
        nl, nr = nl / al, nr / ar
        angle = math.degrees(math.acos(min(1.0, max(-1.0, float(nl @ nr)))))
        # a valley (the halves rise): the left strip's normal leans towards the right strip
        across = q[tri[right]].mean((0, 1)) - q[tri[left]].mean((0, 1))
        sign = 1.0 if float((nl - nr) @ across) >= 0.0 else -1.0
        num += sign * angle * w
        den += w
    return num / den if den > 0 else 0.0


def height_field(model: Model, q: np.ndarray, grid: int = GRID) -> tuple[np.ndarray, np.ndarray, float]:
    """(z on a regular grid over the rest outline (NaN outside), inside mask, cell size [m]):
    the blade's height in the leaf frame, linearly interpolated over the rest triangles."""
    from scipy.interpolate import LinearNDInterpolator

    T = model.blade_T
    rest = model.particle_rest[T, :2]
    L = _blade_length(model)
    h = L / grid
    lo, hi = rest.min(0), rest.max(0)
    xs = np.arange(lo[0], hi[0] + h, h)
    ys = np.arange(lo[1], hi[1] + h, h)
    X, Y = np.meshgrid(xs, ys)
    remap = np.full(model.particle_count, -1)
    remap[np.flatnonzero(T)] = np.arange(int(T.sum()))
    from scipy.spatial import Delaunay

    tri = Delaunay(rest)  # the interpolant's own triangulation of the rest points
    f = LinearNDInterpolator(tri, q[T, 2])
    Z = f(X, Y)
    # only inside the blade's own triangles (not the convex hull across sinuses)
    inside = _inside_mesh(rest, remap[model.blade_tri_T], X, Y)
    Z[~inside] = np.nan
    return Z, inside, h


def _inside_mesh(rest: np.ndarray, tri: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Grid points inside any of the rest triangles ``tri`` (indices into ``rest``)."""
    import cv2

    h = float(X[0, 1] - X[0, 0]) if X.shape[1] > 1 else 1.0
    x0, y0 = float(X[0, 0]), float(Y[0, 0])
    img = np.zeros(X.shape, np.uint8)
    pts = np.round(((rest - [x0, y0]) / h) * 16).astype(np.int32)
    for t in tri:
        cv2.fillConvexPoly(img, pts[t].reshape(-1, 1, 2), 1, cv2.LINE_8, shift=4)
    return img > 0


def _local_quadratic(z: np.ndarray, m: np.ndarray, sigma: float) -> np.ndarray:
    """The value at every grid point of the quadratic fitted to the blade's heights (mask ``m``)
    around it with Gaussian weights of ``sigma`` cells: exact for any bowl, saddle or tilt."""
    import cv2

    ny, nx = z.shape
    v, u = np.mgrid[0:ny, 0:nx].astype(np.float64)
    u, v = (u - nx / 2) / max(nx, ny), (v - ny / 2) / max(nx, ny)
    basis = [np.ones_like(u), u, v, u * u, u * v, v * v]

    def G(f):
        return cv2.GaussianBlur(f * m, (0, 0), sigma)

    A = np.empty((ny, nx, 6, 6))
    b = np.empty((ny, nx, 6))
    for i in range(6):
        b[..., i] = G(z * basis[i])
        for j in range(i, 6):
            A[..., i, j] = A[..., j, i] = G(basis[i] * basis[j])
    A += 1e-12 * np.eye(6)
    coef = np.linalg.solve(A.reshape(-1, 6, 6), b.reshape(-1, 6, 1)).reshape(ny, nx, 6)
    return sum(coef[..., i] * basis[i] for i in range(6))


def wrinkles(model: Model, q: np.ndarray, grid: int = GRID) -> dict:
    """RMS amplitude and dominant wavelength of the height field minus its smooth part, × L."""
    import cv2

    Z, inside, h = height_field(model, q, grid)
    inside = inside & np.isfinite(Z)
    L = _blade_length(model)
    z = np.where(inside, Z, 0.0).astype(np.float64)
    m = inside.astype(np.float64)
    s = SMOOTH * L / h
    smooth = _local_quadratic(z, m, s)
    # the edge band of one σ is left out: there the smooth part sees only one side
    core = inside & (cv2.erode(inside.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=max(1, int(s))) > 0)
    if not core.any():
        return {"wrinkle_rms_L": 0.0, "wrinkle_wavelength_L": None}
    r = z - smooth
    r = np.where(core, r - r[core].mean(), 0.0)
    rms = float(np.sqrt((r[core] ** 2).mean())) / L
    if rms < FLAT:
        return {"wrinkle_rms_L": round(rms, 6), "wrinkle_wavelength_L": None}
    ny, nx = r.shape
    P = np.abs(np.fft.rfft2(r * np.outer(np.hanning(ny), np.hanning(nx)))) ** 2
    ky = np.fft.fftfreq(ny, d=h)[:, None]
    kx = np.fft.rfftfreq(nx, d=h)[None, :]
    k = np.hypot(kx, ky)
    dk = 1.0 / (max(nx, ny) * h)
    kmin = 1.0 / (2.0 * SMOOTH * L * math.pi)  # longer waves are the smooth part's
    bins = np.arange(kmin, k.max(), dk)
    if len(bins) < 2:
        return {"wrinkle_rms_L": round(rms, 6), "wrinkle_wavelength_L": None}
    which = np.digitize(k.ravel(), bins)
    power = np.bincount(which, weights=P.ravel(), minlength=len(bins) + 1)[1:len(bins)]
    count = np.bincount(which, minlength=len(bins) + 1)[1:len(bins)]
    spec = power / np.maximum(count, 1)
    j = int(np.argmax(spec))
    kpk = 0.5 * (bins[j] + bins[j + 1])
    return {"wrinkle_rms_L": round(rms, 6), "wrinkle_wavelength_L": round(1.0 / (kpk * L), 4)}


def dried_shape(model: Model, state: State) -> dict:
    """Every measure of the module docstring for ``state`` (in the leaf's own frame)."""
    q = leaf_frame(model, state)
    out = margin_roll(model, q)
    out["midrib_fold_deg"] = round(midrib_fold(model, q), 2)
    out.update(wrinkles(model, q))
    return out

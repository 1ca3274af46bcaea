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
* **midrib fold** — the angle between the best-fit planes of the two halves of the blade (left
  and right of the base–apex axis at rest): 0° flat, 90° a right-angled V.

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


def midrib_fold(model: Model, q: np.ndarray) -> float:
    """Angle between the best-fit planes of the two halves of the blade [deg]."""
    T = np.flatnonzero(model.blade_T)
    x = model.particle_rest[T, 0]
    area = model.particle_area[T]
    normals = []
    for half in (x < 0, x > 0):
        P, w = q[T[half]], area[half]
        if len(P) < 3:
            return 0.0
        c = (P * w[:, None]).sum(0) / w.sum()
        _, _, vt = np.linalg.svd((P - c) * np.sqrt(w)[:, None], full_matrices=False)
        nrm = vt[2]
        normals.append(nrm)
    # orient both like the blade's mean normal (the plane normal's sign is arbitrary)
    mean = _normals(q, model.blade_tri_T).sum(0)
    a, b = (n if n @ mean >= 0 else -n for n in normals)
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def height_field(model: Model, q: np.ndarray, grid: int = GRID) -> tuple[np.ndarray, np.ndarray, float]:
    """(z on a regular grid over the rest outline (NaN outside), inside mask, cell size [m]):
    the blade's height in the leaf frame, linearly interpolated over the rest triangles."""
    from scipy.interpolate import LinearNDInterpolator

    T = model.blade_T
    rest = model.particle_rest[T, :2]
    L = float(np.ptp(model.particle_rest[model.blade_T, 1])) or 1.0  # the blade's, not the stalk's
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
    L = float(np.ptp(model.particle_rest[model.blade_T, 1])) or 1.0  # the blade's, not the stalk's
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

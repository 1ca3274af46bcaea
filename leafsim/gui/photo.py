"""The species photo in the model's orientation (numpy only; the app draws the quads).

The blade's texture coordinates are an exact affine image of the rest positions
(``uv = A · [x, y, 1]``, fitted here by least squares), so the photo's corners have model
coordinates, and from there the same screen positions as the model under any camera.  The
side panel shows the photo undistorted but turned (and mirrored, if the camera mirrors) as the
leaf appears on screen -- base to apex as shown, whichever way the photo was taken -- and the
3-D view can overlay it on the leaf, projected by the camera.
"""

from __future__ import annotations

import numpy as np

UV_CORNERS = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def texcoord_affine(xy: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(2, 3) A with uv ≈ A @ [x, y, 1] (least squares over the blade's vertices)."""
    X = np.c_[np.asarray(xy, np.float64), np.ones(len(xy))]
    A, *_ = np.linalg.lstsq(X, np.asarray(uv, np.float64), rcond=None)
    return A.T


def uv_to_model(A: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Model xy of texture coordinates ``uv`` (..., 2) under the affine ``A``."""
    M, t = A[:, :2], A[:, 2]
    return (np.asarray(uv, np.float64) - t) @ np.linalg.inv(M).T


def project(points: np.ndarray, view_proj: np.ndarray, rect) -> np.ndarray:
    """Screen pixels (y down) of world points (..., 3) in the viewport ``rect = (x, y, w, h)``."""
    p = np.asarray(points, np.float64)
    h = np.c_[p.reshape(-1, 3), np.ones(p.size // 3)] @ view_proj.T
    w = np.where(np.abs(h[:, 3]) < 1e-12, 1e-12, h[:, 3])
    ndc = h[:, :2] / w[:, None]
    x0, y0, rw, rh = rect
    out = np.c_[x0 + (ndc[:, 0] + 1) * 0.5 * rw, y0 + (1 - ndc[:, 1]) * 0.5 * rh]
    return out.reshape(p.shape[:-1] + (2,))


def leaf_axes(rest: np.ndarray, now: np.ndarray) -> np.ndarray:
    """(3, 2) where the leaf's rest x and y axes point now: the rotation that best carries the
    rest positions onto the current ones (Kabsch), applied to x̂ and ŷ.  A hanging leaf hangs
    with its rest xy plane turned upright, and its photo is turned with it."""
    a = np.asarray(rest, np.float64)
    b = np.asarray(now, np.float64)
    ok = np.isfinite(b).all(axis=1)
    a, b = a[ok], b[ok]
    if len(a) < 3:
        return np.eye(3)[:, :2]
    H = (a - a.mean(0)).T @ (b - b.mean(0))
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R[:, :2]


def screen_rotation(view_proj: np.ndarray, rect, centre: np.ndarray, scale: float,
                    axes: np.ndarray | None = None) -> np.ndarray:
    """The orthogonal 2x2 nearest to the camera's model-xy → screen map at ``centre`` (the
    leaf seen from the camera, without the foreshortening): polar part of the Jacobian.
    ``axes`` (3, 2): where the model's x and y point in the world now (:func:`leaf_axes`;
    default: where they rest)."""
    c = np.asarray(centre, np.float64)
    ax = np.eye(3)[:, :2] if axes is None else np.asarray(axes, np.float64)
    pts = np.stack([c, c + scale * ax[:, 0], c + scale * ax[:, 1]])
    s = project(pts, view_proj, rect)
    J = np.stack([s[1] - s[0], s[2] - s[0]], axis=1) / scale
    U, _, Vt = np.linalg.svd(J)
    return U @ Vt


def panel_quad(A: np.ndarray, R: np.ndarray, box) -> tuple[np.ndarray, float]:
    """Screen corners (4, 2) of the photo (its UV_CORNERS, in order) turned by ``R`` and
    fitted into ``box = (x, y, w, h)``; returns (corners, pixels per metre)."""
    m = uv_to_model(A, UV_CORNERS)
    p = (m - m.mean(axis=0)) @ R.T
    lo, hi = p.min(axis=0), p.max(axis=0)
    x, y, w, h = box
    k = min(w / max(hi[0] - lo[0], 1e-12), h / max(hi[1] - lo[1], 1e-12))
    centre = np.array([x + w / 2, y + h / 2]) - k * (lo + hi) / 2
    return centre + k * p, float(k)


def overlay_grid(A: np.ndarray, z: float, view_proj: np.ndarray, rect, n: int = 8):
    """The photo as an n×n grid of screen quads (perspective-correct enough for imgui's
    affine per-triangle mapping): (screen (n+1, n+1, 2), uv (n+1, n+1, 2))."""
    t = np.linspace(0.0, 1.0, n + 1)
    uv = np.stack(np.meshgrid(t, t, indexing="xy"), axis=-1)
    xy = uv_to_model(A, uv.reshape(-1, 2))
    pts = np.c_[xy, np.full(len(xy), float(z))]
    return project(pts, view_proj, rect).reshape(n + 1, n + 1, 2), uv

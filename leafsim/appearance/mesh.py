"""What the renderer draws: a plain, OpenGL-free description of one leaf.

The simulation side fills a :class:`RenderMesh` once (topology, texture, veins, springs) and
afterwards only passes new per-vertex arrays to ``Renderer.update``. Importing this module
imports no OpenGL.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from leafsim.base.errors import LeafsimError

#: A vertex's ``chroma`` without colour detail: the "detail" albedo takes the photo's luminance only.
NO_CHROMA = np.array([1.0, 1.0, 1.0, 0.0], dtype=np.float32)

#: Spring kinds used by the "springs" debug view.
SPRING_SURFACE_T, SPRING_SURFACE_V, SPRING_LINK, SPRING_VEIN = 0, 1, 2, 3


@dataclass
class RenderMesh:
    """One leaf as the renderer sees it (duck typing: any object with these attributes works).

    Parameters
    ----------
    positions : (n, 3) float32
        Blade vertices in metres; z up, the rest leaf lies in z ~ 0, base (petiole) at the
        origin, apex towards +y.
    triangles : (m, 3) int32
        Blade triangles (the bottom layer). Winding need not be consistent: ``populate``
        orients every triangle so that its normal points to +z in the *given* positions, so
        populate with the flat rest shape.
    texcoords : (n, 2) float32 or None
        Photo coordinates in [0, 1]: ``u = x_px / width``, ``v = y_px / height`` in image
        convention (``v = 0`` is the top row of ``texture_rgba``).
    colours : (n, 3) float32 or None
        Linear RGB albedo per vertex (0..1). None means a default summer green.
    texture_rgba : (H, W, 4) uint8 or None
        The species photo (sRGB) with alpha = leaf mask.
    tint : (n, 3) float32 or None
        Linear multiplier applied to the albedo (photo or colours), e.g. to age the photo.
    chroma : (n, 4) float32 or None
        For the "detail" albedo (vertex colour × the photo's own detail): the young photo's
        colour at the vertex (blurred as the vertex colour is) over its luminance, and the
        weight, 0..1, with which a texel's own chromaticity replaces it (the living share of
        the tissue). None: luminance detail only (:data:`NO_CHROMA` everywhere).
    vein_colours : (n, 3) float32 or None
        Linear RGB albedo of the vein tissue at each vertex, which the drawn veins show (the
        pigment model's pure vein tissue). None: the veins take the blade's albedo under them.
    vein_lines : list of (indices (p,) int, widths (p,) float metres, order int)
        Vein polylines through blade vertices; ``order`` 0 = main, 1 = lateral,
        2 = sublateral, 3+ = tertiary.
    springs : (s, 2) int32 or None
        Spring end points, indices into ``positions`` followed by ``top_positions``
        (top-layer index ``j`` is ``n + j``).
    spring_kind : (s,) int8 or None
        0 surface T, 1 surface V, 2 link, 3 vein.
    top_positions : (k, 3) float32 or None
        Second (top) layer particles, drawn by the "particles" debug view.
    scalars : dict str -> (n,) float32
        Per-vertex fields for heat-map views, e.g. ``"mass"``, ``"water"``.
    mottle : (n, 10) float32 or None
        The sub-grid mottle (``colour.mottle``): each vertex's pigment concentrations and
        reaction states (:func:`leafsim.appearance.reflectance.mottle_pigments`). None: no mottle.
    mottle_rest : (n, 2) float32 or None
        Where each vertex samples the mottle field (metres: rest position plus the leaf's
        offset); required with ``mottle``.
    mottle_size : float
        The field's correlation length in metres; 0 = no mottle.
    mottle_amount : float
        ``colour.mottle`` a, 0..1; 0 = no mottle.
    crinkle : (n, 3) float32 or None
        Slope tensor S of the sub-grid crinkle at each vertex over the rest plane (xx, xy, yy,
        rad²: along a direction u its mean squared slope is uᵀSu; ``render.crinkle``² × 2K of
        :func:`leafsim.sim.crinkle.crinkle_slopes`), drawn over the same rest positions as the
        mottle (``mottle_rest``, required with it). None or all 0: a smooth blade.
        :func:`isotropic_crinkle` makes one of RMS slope s along every direction.
    crinkle_size : float
        The crinkle field's correlation length in metres (``render.crinkle_size``).
    """

    positions: np.ndarray
    triangles: np.ndarray
    texcoords: np.ndarray | None = None
    colours: np.ndarray | None = None
    texture_rgba: np.ndarray | None = None
    tint: np.ndarray | None = None
    chroma: np.ndarray | None = None
    vein_colours: np.ndarray | None = None
    vein_lines: list = field(default_factory=list)
    springs: np.ndarray | None = None
    spring_kind: np.ndarray | None = None
    top_positions: np.ndarray | None = None
    scalars: dict = field(default_factory=dict)
    mottle: np.ndarray | None = None
    mottle_rest: np.ndarray | None = None
    mottle_size: float = 0.0
    mottle_amount: float = 0.0
    crinkle: np.ndarray | None = None
    crinkle_size: float = 0.0

    @property
    def vertex_count(self) -> int:
        return int(np.asarray(self.positions).shape[0])


def isotropic_crinkle(slope) -> np.ndarray:
    """(n, 3) float32 slope tensors s² I of an isotropic crinkle of RMS slope ``slope`` (n,)
    [rad] along every direction."""
    s2 = np.square(np.asarray(slope, np.float32))
    return np.stack([s2, np.zeros_like(s2), s2], 1).astype(np.float32)


def slope_tensors_ok(tensors) -> bool:
    """(n, 3) rows xx, xy, yy are positive semi-definite (to float32 rounding)."""
    T = np.asarray(tensors, np.float64)
    xx, xy, yy = T[:, 0], T[:, 1], T[:, 2]
    tol = 1e-6 * (np.abs(xx) + np.abs(yy)) + 1e-12
    return bool(np.all(xx >= -tol) and np.all(yy >= -tol) and np.all(xx * yy - xy * xy >= -tol * (np.abs(xx) + np.abs(yy))))


def validate_mesh(mesh) -> None:
    """Raise :class:`LeafsimError` naming the first malformed field of a render mesh."""
    pos = np.asarray(mesh.positions)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 3:
        raise LeafsimError(f"render mesh: positions must be (n>=3, 3), got {pos.shape}")
    n = pos.shape[0]
    tri = np.asarray(mesh.triangles)
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] < 1:
        raise LeafsimError(f"render mesh: triangles must be (m>=1, 3), got {tri.shape}")
    if tri.min() < 0 or tri.max() >= n:
        raise LeafsimError(f"render mesh: triangle index out of range [0, {n})")

    def _check(name, shape_tail):
        a = getattr(mesh, name, None)
        if a is None:
            return
        a = np.asarray(a)
        if a.shape != (n, *shape_tail):
            raise LeafsimError(f"render mesh: {name} must be {(n, *shape_tail)}, got {a.shape}")

    _check("texcoords", (2,))
    _check("colours", (3,))
    _check("tint", (3,))
    _check("chroma", (4,))
    _check("vein_colours", (3,))
    _check("mottle", (10,))
    _check("mottle_rest", (2,))
    _check("crinkle", (3,))
    if getattr(mesh, "crinkle", None) is not None and getattr(mesh, "mottle_rest", None) is None:
        raise LeafsimError("render mesh: crinkle needs mottle_rest (where each vertex samples the crinkle field)")
    csize = float(getattr(mesh, "crinkle_size", 0.0) or 0.0)
    if not (np.isfinite(csize) and csize >= 0.0):
        raise LeafsimError(f"render mesh: crinkle_size must be a finite length >= 0 m, got {csize}")
    if getattr(mesh, "mottle", None) is not None and getattr(mesh, "mottle_rest", None) is None:
        raise LeafsimError("render mesh: mottle needs mottle_rest (where each vertex samples the mottle field)")
    size = float(getattr(mesh, "mottle_size", 0.0) or 0.0)
    if not (np.isfinite(size) and size >= 0.0):
        raise LeafsimError(f"render mesh: mottle_size must be a finite length >= 0 m, got {size}")
    amount = float(getattr(mesh, "mottle_amount", 0.0) or 0.0)
    if not (np.isfinite(amount) and 0.0 <= amount <= 1.0):
        raise LeafsimError(f"render mesh: mottle_amount must be in [0, 1], got {amount}")
    for name in ("colours", "tint", "chroma", "vein_colours", "mottle", "mottle_rest", "crinkle"):
        a = getattr(mesh, name, None)
        if a is not None and not np.all(np.isfinite(np.asarray(a, dtype=np.float64))):
            raise LeafsimError(f"render mesh: {name} must be finite")
    crinkle = getattr(mesh, "crinkle", None)
    if crinkle is not None and not slope_tensors_ok(crinkle):
        raise LeafsimError("render mesh: crinkle slope tensors (xx, xy, yy) must be positive semi-definite")
    for name, arr in (getattr(mesh, "scalars", None) or {}).items():
        if np.asarray(arr).shape != (n,):
            raise LeafsimError(f"render mesh: scalar field {name!r} must be ({n},)")
    tex = getattr(mesh, "texture_rgba", None)
    if tex is not None:
        tex = np.asarray(tex)
        if tex.ndim != 3 or tex.shape[2] != 4 or tex.dtype != np.uint8:
            raise LeafsimError(f"render mesh: texture_rgba must be (H, W, 4) uint8, got {tex.shape} {tex.dtype}")
    top = getattr(mesh, "top_positions", None)
    k = 0 if top is None else np.asarray(top).shape[0]
    springs = getattr(mesh, "springs", None)
    if springs is not None:
        s = np.asarray(springs)
        if s.ndim != 2 or s.shape[1] != 2:
            raise LeafsimError(f"render mesh: springs must be (s, 2), got {s.shape}")
        if s.size and (s.min() < 0 or s.max() >= n + k):
            raise LeafsimError(f"render mesh: spring index out of range [0, {n + k})")
        kind = getattr(mesh, "spring_kind", None)
        if kind is not None and np.asarray(kind).shape != (s.shape[0],):
            raise LeafsimError("render mesh: spring_kind must have one entry per spring")
    for i, line in enumerate(getattr(mesh, "vein_lines", None) or []):
        idx, width, _order = line
        idx = np.asarray(idx)
        if idx.ndim != 1 or np.asarray(width).shape != idx.shape:
            raise LeafsimError(f"render mesh: vein line {i}: indices and widths must be equal-length 1-D")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise LeafsimError(f"render mesh: vein line {i}: index out of range [0, {n})")

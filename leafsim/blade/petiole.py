"""Stage 3c′: the petiole — a short rod from the base, meshed into layer T as a three-row strip.

The petiole is the leaf stalk: a rod of diameter ``petiole.diameter`` and length
``petiole.length`` [m] that leaves the blade at the base, pointing away from the apex (turned
by the least angle that keeps it off the blade when basal lobes lie in the way).  It is meshed
as a strip of sections k = 0 … N: section 0 is the base particle and its two neighbours on the
contour (so the strip's first triangles share the blade's margin edges, and hinges across
them carry bending moments from stalk to blade), each later section a centre particle with
one particle ±d/2 to either side.  The centre row is a vein of order 0 of width d: its springs
are rods (cross-section πd²/4) and it adds the rod's mass, lumped as a half on the centre and a
quarter on either side particle, so each section has the rod's mass M and its polar moment of
inertia M d²/8 (all of it on the centre row left the side particles thousands of times lighter
than the centre, held by the rod's stiff hinges: on meshes finer than the default the stalk
went unstable within 30 frames of drying).  The strip's hinges
across the stalk (the two crosswise edges of every section) share the rod's bending stiffness
I/ℓ = (πd⁴/64)/s; the hinges along the centre row keep the strip from folding along its axis
with the same weight, and so do its diagonals (else the strip folds along them); none of them
takes the blade's bilayer curl.  The V layer, the
thickness volumes, osmosis and colour treat the strip as blade tissue of the petiole's
projected area d × length.

Everything that measures the *blade* (areas kept, the curl and wrinkle measures, the
silhouette against the photo) leaves the petiole out: :attr:`Model.particle_petiole`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from leafsim.base.geometry import LeafShape, points_in_region
from leafsim.blade.sample import Points
from leafsim.config.params import ParamSet
from leafsim.sim.model import KIND_PETIOLE

#: largest turn [deg] away from straight down the midrib axis tried to keep the stalk off the blade
MAX_TURN = 80.0
#: a section of the strip that would overlap the blade narrows by SHRINK at a time, down to
#: MIN_HALF_WIDTH of the stalk's d/2 (:func:`_strip_half_widths`)
SHRINK, MIN_HALF_WIDTH = 0.8, 0.2


@dataclass
class Petiole:
    """The petiole's place in the T mesh (final particle numbering)."""

    chain: np.ndarray        # (N+1,) centre particles from the tip to the base particle
    sections: np.ndarray     # (N+1, 3) [left, centre, right] per section, section 0 at the base
    cross_rod: float         # I/ℓ share [m³] of each crosswise / axial hinge
    diameter: float          # [m]
    direction: np.ndarray    # (2,) unit vector base → tip at rest
    first: int               # index of the first petiole particle (they are the last ones)
    lead: float = 0.0        # [m] the first segment's extra length (sections start past the junction)

    @property
    def tip(self) -> np.ndarray:
        """The tip section's three particles (pinned in the hanging scene)."""
        return self.sections[-1]


def petiole_direction(shape: LeafShape, length: float, diameter: float) -> np.ndarray:
    """Unit vector from the base along which the stalk lies at rest: away from the apex, turned
    by the least angle (steps of 5°, up to ±MAX_TURN) for which it clears the blade; straight
    down when no angle does (it then lies across the basal lobes, as a folded stalk does)."""
    base = np.asarray(shape.base, float)
    d0 = base - np.asarray(shape.apex, float)
    d0 /= max(float(np.linalg.norm(d0)), 1e-300)
    t = np.linspace(0.1, 1.0, 24)[:, None] * length
    for turn in np.r_[0.0, np.repeat(np.arange(5.0, MAX_TURN + 1, 5.0), 2) * np.tile([1, -1], int(MAX_TURN // 5))]:
        a = math.radians(turn)
        d = np.array([d0[0] * math.cos(a) - d0[1] * math.sin(a), d0[0] * math.sin(a) + d0[1] * math.cos(a)])
        nrm = np.array([-d[1], d[0]])
        pts = np.vstack([base + t * d + s * 0.5 * diameter * nrm for s in (-1.0, 0.0, 1.0)])
        if not points_in_region(pts, shape.contour, shape.holes).any():
            return d
    return d0


def add_petiole(P: Points, tri: np.ndarray, remap: np.ndarray, base: int, shape: LeafShape,
                params: ParamSet, r: float, vp: list, vw: list, vo: list):
    """Append the petiole's particles and triangles to layer T (their indices follow the
    blade's), and its centre row to the vein chains.  Returns (points, triangles, vein chains,
    widths, orders, :class:`Petiole`), or the inputs and None when ``petiole.length`` is 0."""
    length, diam = float(params["petiole.length"]), float(params["petiole.diameter"])
    if length <= 0.0:
        return P, tri, vp, vw, vo, None
    d = petiole_direction(shape, length, diam)
    nrm = np.array([-d[1], d[0]])  # left of the stalk
    n_sec = max(2, int(math.ceil(length / r)))
    junction, ahead = _junction(P, remap, base, d, nrm, r, length)
    root_xy = P.pts[junction[1]]
    s = (length - ahead) / n_sec  # the first section just past the junction's outline particles
    first = len(P.pts)
    new = []
    sections = [junction]
    centres = root_xy + (ahead + np.arange(1, n_sec + 1)[:, None] * s) * d
    half = _strip_half_widths(P, remap, junction, centres, nrm, 0.5 * diam)
    for k in range(1, n_sec + 1):
        row = []
        for side in (1.0, 0.0, -1.0):
            row.append(first + len(new))
            new.append(centres[k - 1] + side * half[k - 1] * nrm)
        sections.append(row)
    sections = np.array(sections, np.int64)
    pts = np.vstack([P.pts, np.array(new)])
    kinds = np.concatenate([P.kinds, np.full(len(new), KIND_PETIOLE, np.int8)])
    vord = np.concatenate([P.vorders, np.full(len(new), -1, np.int8)])
    vord[sections[1:, 1]] = 0
    ptri = []
    for (l0, c0, r0), (l1, c1, r1) in zip(sections[:-1], sections[1:]):
        ptri += [(l0, c0, c1), (l0, c1, l1), (c0, r0, r1), (c0, r1, c1)]
    ptri = np.array([t for t in ptri if len(set(t)) == 3], np.int64)
    a, b, c = pts[ptri[:, 0]], pts[ptri[:, 1]], pts[ptri[:, 2]]
    ar = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ptri[ar < 0] = ptri[ar < 0][:, [0, 2, 1]]
    chain = sections[::-1, 1].copy()
    points = Points(pts, kinds, vord, P.vein_lists, P.vein_ord, P.vein_wid, P.n_contour)
    info = Petiole(chain, sections, math.pi * diam ** 4 / 64.0 / s / 2.0, diam, d, first, ahead)
    return (points, np.vstack([tri, ptri]), vp + [chain], vw + [np.full(len(chain), diam)], vo + [0], info)


def _crosses(a: np.ndarray, b: np.ndarray, ring: np.ndarray) -> bool:
    """Whether segment a–b properly crosses an edge of the closed polygon ``ring`` (touching
    at an end does not count: the strip's first edges start on the outline)."""
    c, d = ring, np.roll(ring, -1, axis=0)

    def side(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    return bool(((side(a, b, c) * side(a, b, d) < 0) & (side(c, d, a) * side(c, d, b) < 0)).any())


def _strip_half_widths(P: Points, remap, junction: list, centres: np.ndarray, nrm: np.ndarray, half: float) -> np.ndarray:
    """Half-width of each section of the strip: d/2, or narrower (× ``SHRINK`` at a time, down to
    ``MIN_HALF_WIDTH`` × d/2) where a side particle would lie on the blade or the strip's edges
    would cross the blade's outline: a stalk in a basal notch narrower than it (maple's, on
    meshes finer than the default, whose lobes' margins run down beside it).  A strip triangle
    over a blade triangle across a shared margin edge is a hinge folded by π at rest, which
    kicked the leaf apart at its first frame.  The rod's stiffness and mass keep the stalk's
    diameter; only the strip that carries them is narrower there."""
    out = np.full(len(centres), half)
    ring = remap[:P.n_contour]
    ring = ring[ring >= 0]
    if len(ring) < 3:
        return out
    ring_xy = P.pts[ring]
    prev_l, prev_r = P.pts[junction[0]], P.pts[junction[2]]
    for k, c in enumerate(centres):
        w = half
        while True:
            left, right = c + w * nrm, c - w * nrm
            clash = (points_in_region(np.array([left, right]), ring_xy, []).any()
                     or _crosses(prev_l, left, ring_xy) or _crosses(prev_r, right, ring_xy) or _crosses(left, right, ring_xy))
            if not clash or w <= MIN_HALF_WIDTH * half:
                break
            w = max(SHRINK * w, MIN_HALF_WIDTH * half)
        out[k] = w
        prev_l, prev_r = left, right
    return out


def _junction(P: Points, remap, base: int, d, nrm, r: float, length: float) -> tuple[list, float]:
    """Section 0 and how far ahead of its centre (along ``d``) the strip's sections start.

    The centre is the base particle when it lies on the outline, else the outline particle
    nearest to it (within 1.5 r: a base traced a little inside the blade); its two neighbours on
    the outline are the sides when they lie on either side of the stalk, and the sections start
    just past them (a base in a notch whose margin runs down beside the stalk, as maple's).  So
    the strip's first triangles share the blade's margin edges and hinges across them carry the
    stalk's moment.  Without such neighbours it is [base, base, base], a point the stalk can
    swivel about (its first triangles degenerate and are dropped)."""
    ring = remap[:P.n_contour]
    ring = ring[ring >= 0]
    if len(ring) >= 3:
        dist = np.linalg.norm(P.pts[ring] - P.pts[base], axis=1)
        k = int(np.argmin(dist))
        if dist[k] <= 1.5 * r:
            root = int(ring[k])
            nb = [int(ring[k - 1]), int(ring[(k + 1) % len(ring)])]
            side = [float(np.dot(P.pts[j] - P.pts[root], nrm)) for j in nb]
            ahead = max(0.0, *(float(np.dot(P.pts[j] - P.pts[root], d)) for j in nb))
            if side[0] * side[1] < 0 and ahead < 0.5 * length:
                left, right = (nb[0], nb[1]) if side[0] > 0 else (nb[1], nb[0])
                return [left, root, right], ahead + 0.1 * r
    return [base, base, base], 0.0


def rod_sides(info: Petiole | None, n: int) -> np.ndarray | None:
    """(n, 2) per particle: the two side particles of its section when it is a centre particle
    of the strip past the junction, else −1 (:func:`~leafsim.blade.masses.lump_masses` lumps the
    rod's mass over them); None without a stalk."""
    if info is None:
        return None
    out = np.full((n, 2), -1, np.int64)
    sec = info.sections[1:]
    out[sec[:, 1]] = sec[:, [0, 2]]
    return out


def petiole_hinge_rods(hinge_idx: np.ndarray, info: Petiole | None) -> tuple[np.ndarray, np.ndarray]:
    """(mask, rod) per hinge: the hinges whose shared edge is a crosswise edge of a section
    (left–centre, centre–right), a centre-row edge or a diagonal of the strip carry
    ``info.cross_rod`` = (πd⁴/64)/s/2 (two crosswise hinges per node: E I/s together), the
    junction's crosswise pair twice that (it stands for half a segment)."""
    mask = np.zeros(len(hinge_idx), bool)
    rod = np.zeros(len(hinge_idx))
    if info is None or len(hinge_idx) == 0:
        return mask, rod
    sec = info.sections
    share: dict = {}
    s = math.pi * info.diameter ** 4 / 64.0 / info.cross_rod / 2.0  # the section spacing
    junction = 2.0 * s / (s + info.lead)  # its half of a first segment that is lead + s long
    for k, (l_, c_, r_) in enumerate(sec[:-1]):
        for e in ((l_, c_), (c_, r_)):
            if e[0] != e[1]:
                # node k stands for the rod from s/2 before it to s/2 after it; the junction
                # (k = 0) only for the half on the stalk's side: I / (s/2)
                share[(min(e), max(e))] = info.cross_rod * (junction if k == 0 else 1.0)
    for c0, c1 in zip(sec[:-1, 1], sec[1:, 1]):
        share[(min(c0, c1), max(c0, c1))] = info.cross_rod
    # the diagonals too: under pure bending the strip's quads stay flat and these hinges stay
    # at rest, but without them the strip folds along its diagonals (a soft twist-and-fold
    # mode: a cantilevered stalk sagged 2x the beam theory's on a fine mesh, 1.13x with them)
    for (l0, c0, r0), (l1, c1, r1) in zip(sec[:-1], sec[1:]):
        for e in ((l0, c1), (c0, r1)):
            if e[0] != e[1]:
                share[(min(e), max(e))] = info.cross_rod
    a, b = hinge_idx[:, 2], hinge_idx[:, 3]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    for e in range(len(hinge_idx)):
        w = share.get((int(lo[e]), int(hi[e])))
        if w is not None:
            mask[e], rod[e] = True, w
    return mask, rod

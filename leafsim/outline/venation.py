"""The photo's own venation: midrib, main and lateral veins traced from the image.

A vein is a line of the blade lighter or darker than the tissue beside it (light on the
underside of most leaves and on back-lit scans, dark on some upper sides), or yellower (the
midrib of a back-lit oak leaf is a yellow band no lighter than the blade, with darker flanks
that a lightness ridge would follow instead).  Its strength at every pixel is the Hessian
ridge measure of that channel at the vein's scale (the larger eigenvalue's magnitude with the
polarity the leaf shows); the channel and polarity are the ones whose midrib stands out most
from the blade.  The cost of a pixel is small on strong ridges and large elsewhere.  Then:

* **midrib** — the cheapest 8-connected path from the base (petiole junction) to the apex;
* **main veins** — for a palmate leaf the cheapest path from the base to each lobe tip, for
  pinnate lobes the cheapest from anywhere on the midrib (multi-source Dijkstra);
* **laterals** — from every point of the main veins, on either side, the cheapest path to the
  margin band over the finer ridges (one shortest-path tree grown from the margin, so two
  laterals never cross: where their paths merge the weaker one ends), ridges that are lines
  (a spot, curved both ways, scores nothing); a path is a lateral when its median
  ridge strength is well above the blade's and it is at least 8 % of the leaf length long.
  Laterals closer than 4 % of the leaf length to a stronger one along most of their length
  are the same vein and are dropped.  The cheapest path through any texture finds ridges, so
  the photo's laterals are taken only when its strongest beats, by :data:`LATERAL_NULL_MARGIN`,
  the strongest the same search finds in the blade with its pixels shuffled (a photo with
  pixel noise but no visible laterals gets none, and the grower grows them);
* **basal laterals** — beside a main vein's base, where the margin is so near that those paths
  run straight to it, the strongest path to a far margin instead, leaving the main vein along
  the ray that follows a vein (:func:`_basal_laterals`; its own search, so it is kept from
  crossing the others by the vein grower).

Everything is computed on a copy scaled so the leaf is :data:`WORK_LENGTH` px long; the
polylines come back in photo pixels, smoothed over 1 % of the leaf length.  Used by the
vein grower (:func:`leafsim.veins.grow.grow_veins`'s ``given``) so the model's veins lie on the
photo's, and by ``leafsim compare`` to measure how far they are.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

#: the leaf's base→apex length on the working copy [px]
WORK_LENGTH = 500.0
#: ridge scale of the main veins and of the laterals, × leaf length
MAIN_SIGMA, LATERAL_SIGMA = 0.006, 0.0035
#: cost floor: a pixel on the strongest ridges costs this, the blade's median ≈ 1
_FLOOR = 0.03
#: width of the ring of lateral starts beside a main vein's own ridge [px of the working copy]
RING_WIDTH = 2
#: a traced lateral whose heading swings further than this turns back on itself [deg]; real
#: laterals bend toward the apex or loop along the margin by up to about 90-120
MAX_TURN_DEG = 150.0
#: lateral starts from this far along a main vein [× L] (aspen's basal veins leave at its base)
START_AT = 0.01
#: laterals leaving a main vein this near its start [× L] are also searched as the strongest
#: path to a margin at least BASAL_MIN_REACH away (the margin beside the base is near)
BASAL_ZONE, BASAL_MIN_REACH = 0.15, 0.25
#: one basal search a side every this far along a main vein [× L]
BASAL_EVERY = 0.025
#: the basal search keeps off this band along the margin [× L] (but to end in it, and where a
#: vein's ridge runs in it) and along the main veins; a basal lateral whose median distance to
#: the margin is under half of it runs along the margin and is dropped
BASAL_EDGE = 0.05
#: a basal lateral leaves its main vein's strip along the ray with the strongest median ridge
#: (a vein's: over BASAL_SCORE × the blade's) of rays at these angles to the main vein [deg],
#: each ranked over this length [× L], leaving out pixels this near a main vein [× L]
BASAL_ANGLES, BASAL_RAY, BASAL_BESIDE = tuple(range(20, 91, 5)), 0.06, 0.015
#: a basal lateral ends where it turns further than this from the heading it left with [deg]
BASAL_TURN_DEG = 60.0
#: a basal lateral's median ridge strength over the blade's must exceed this (the other
#: laterals' 2.5: its search reaches the margin from anywhere, so it asks for a clearer vein);
#: a ray or a pixel of the margin band counts as on a vein above it too
BASAL_SCORE = 5.0

#: a path is a lateral when its median ridge strength is over this × the blade's median
LATERAL_SCORE = 2.5
#: a photo shows laterals when its strongest scores over this × the strongest that the same
#: search finds in the blade with its pixels (off the main veins) shuffled: a texture of the
#: same values with no lines.  That null's best is 2.9–3.2 on the shipped photos (500–1700
#: candidates each), where their strongest laterals score 4.7–20; on a photo whose blade
#: shows pixel noise but no laterals the real search's best (2.9–3.0) is the null's own
LATERAL_NULL_MARGIN = 1.25
#: a lateral is lighter (darker) than both its flanks on at least this share of its points
#: (:func:`_ridge_share`): the shipped photos' laterals 0.32–1.0, a path along the edge of a
#: dark lesion 0.18
MIN_RIDGE_SHARE = 0.25
#: the null test above compares the photo's strongest lateral that is a ridge on at least this
#: share of its points (the shipped photos' strongest: 0.78–0.98; a path that follows a dark
#: lesion's edge for part of its way 0.33–0.38)
CLEAR_RIDGE_SHARE = 0.5
#: the colour channels a vein may show in (CIELAB): its lightness, or its yellowness — the
#: midrib of a back-lit oak leaf is a yellow band with darker flanks, no lighter than the blade
CHANNELS = (("lightness", 0), ("yellowness", 2))


@dataclass
class PhotoVeins:
    """Traced veins in photo pixels (x, y down): the midrib (base → apex), the other main veins
    and the laterals, each an (k, 2) polyline from its start to its end; ``parents[i]`` is the
    index in ``mains`` (0 = the midrib) a lateral leaves from; ``polarity`` is "light" or
    "dark" and ``channel`` "lightness" or "yellowness" (how the veins show); ``strength`` the
    midrib's mean ridge strength over the blade's median (a photo without visible veins has ≈ 1);
    ``lateral_test`` the laterals' null test: the strongest lateral's score (``best``), the
    shuffled blade's (``null``) and whether the photo shows laterals (``shown``)."""

    midrib: np.ndarray
    mains: list = field(default_factory=list)
    laterals: list = field(default_factory=list)
    parents: list = field(default_factory=list)
    polarity: str = "light"
    channel: str = "lightness"
    strength: float = 0.0
    lateral_test: dict = field(default_factory=dict)

    def all_mains(self) -> list:
        return [self.midrib, *self.mains]


def _ridge(L: np.ndarray, inner: np.ndarray, sigma: float, line: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(light ridge, dark ridge) strength at scale ``sigma`` px, scale-normalised, 0 outside.
    ``line``: less the curvature along the ridge, so that a spot (curved both ways, as the
    light speckles of an aspen blade) scores about nothing and only lines stand out."""
    fill = float(np.median(L[inner])) if inner.any() else 0.0
    g = cv2.GaussianBlur(np.where(inner, L, fill).astype(np.float32), (0, 0), sigma)
    xx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3)
    yy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3)
    xy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3)
    root = np.sqrt(0.25 * (xx - yy) ** 2 + xy ** 2)
    lo, hi = 0.5 * (xx + yy) - root, 0.5 * (xx + yy) + root
    s2 = sigma * sigma
    light, dark = -lo, hi
    if line:
        light, dark = light - np.abs(hi), dark - np.abs(lo)
    return np.where(inner, np.maximum(light, 0) * s2, 0), np.where(inner, np.maximum(dark, 0) * s2, 0)


class _Grid:
    """The 8-connected pixel graph of a cost image (edge weight = mean cost × step length)."""

    def __init__(self, cost: np.ndarray):
        h, w = cost.shape
        self.h, self.w, self.cost = h, w, cost
        idx = np.arange(h * w).reshape(h, w)
        rows, cols, wts = [], [], []
        for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
            x0, x1 = max(0, -dx), w - max(0, dx)
            a = idx[0:h - dy, x0:x1]
            b = idx[dy:h, x0 + dx:x1 + dx]
            ca, cb = cost.reshape(-1)[a.reshape(-1)], cost.reshape(-1)[b.reshape(-1)]
            rows.append(a.reshape(-1))
            cols.append(b.reshape(-1))
            wts.append(0.5 * (ca + cb) * np.hypot(dy, dx))
        r, c, wv = np.concatenate(rows), np.concatenate(cols), np.concatenate(wts)
        self.graph = coo_matrix((np.r_[wv, wv], (np.r_[r, c], np.r_[c, r])), shape=(h * w, h * w)).tocsr()

    def index(self, p) -> int:
        x, y = int(round(float(p[0]))), int(round(float(p[1])))
        return min(max(y, 0), self.h - 1) * self.w + min(max(x, 0), self.w - 1)

    def tree(self, sources) -> tuple[np.ndarray, np.ndarray]:
        d, pred, _ = dijkstra(self.graph, directed=False, indices=np.asarray(sources, int), min_only=True,
                              return_predecessors=True)
        return d, pred

    def path(self, pred: np.ndarray, end: int) -> np.ndarray:
        """(k, 2) pixel path from the tree's source to ``end`` (x, y)."""
        out = [end]
        while pred[out[-1]] >= 0 and len(out) < self.h * self.w:
            out.append(int(pred[out[-1]]))
        out = np.asarray(out[::-1])
        return np.column_stack([out % self.w, out // self.w]).astype(float)


def _nearest_inside(mask: np.ndarray, p) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    i = int(np.argmin((xs - p[0]) ** 2 + (ys - p[1]) ** 2))
    return np.array([xs[i], ys[i]], float)


def _smooth(path: np.ndarray, window: float) -> np.ndarray:
    """Moving average over ``window`` px of arc length, ends kept, resampled every window/2."""
    if len(path) < 3:
        return path
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    n = max(2, int(np.ceil(s[-1] / max(0.5 * window, 1e-9))) + 1)
    t = np.linspace(0, s[-1], n)
    xy = np.column_stack([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])])
    k = max(1, int(round(window / max(t[1] - t[0], 1e-9))))
    if k > 1 and n > 2 * k:
        ker = np.ones(2 * k + 1) / (2 * k + 1)
        pad = np.pad(xy, ((k, k), (0, 0)), mode="edge")
        sm = np.column_stack([np.convolve(pad[:, 0], ker, "valid"), np.convolve(pad[:, 1], ker, "valid")])
        sm[0], sm[-1] = xy[0], xy[-1]
        return sm
    return xy


def trace_venation(img: np.ndarray, mask: np.ndarray, base_px, apex_px, lobes_px=(), main_origin: str = "base",
                   laterals: bool = True, exclude: np.ndarray | None = None, holes: np.ndarray | None = None) -> PhotoVeins:
    """Trace the veins of the leaf in ``img`` (BGR, any size) inside ``mask`` (uint8 0/255, the
    image's size), base and apex in its pixels (module docstring).  ``lobes_px``: lobe tips that
    get a main vein (the apex excluded by the caller).  ``exclude`` (uint8, the image's size):
    pixels no vein may follow — a petiole lying on the blade is a ridge too; ``holes`` (uint8,
    the image's size): openings of the blade, whose edges are no veins either."""
    base, apex = np.asarray(base_px, float), np.asarray(apex_px, float)
    L0 = float(np.linalg.norm(apex - base))
    f = min(1.0, WORK_LENGTH / max(L0, 1.0))
    small = cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_AREA) if f < 1 else img
    m = cv2.resize(mask, (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST) > 0 if f < 1 else mask > 0
    L = L0 * f
    to_s = lambda p: (np.asarray(p, float) + 0.5) * f - 0.5  # noqa: E731
    back = lambda p: (np.asarray(p, float) + 0.5) / f - 0.5  # noqa: E731
    lab = cv2.cvtColor(small[..., :3].astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
    e = max(3, int(round(0.012 * L)) | 1)
    inner = cv2.erode(m.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (e, e))) > 0
    if not inner.any():
        inner = m
    if holes is not None and holes.any():
        hs = cv2.resize(holes, (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST) if f < 1 else holes
        inner = inner & ~(cv2.dilate((hs > 0).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (e, e))) > 0)
    if exclude is not None and exclude.any():
        ex = cv2.resize(exclude, (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST) > 0 if f < 1 else exclude > 0
        ex = cv2.dilate(ex.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        # the base itself stays reachable: a petiole ends at the junction
        near_base = np.hypot(*np.meshgrid(np.arange(m.shape[1]) - to_s(base)[0], np.arange(m.shape[0]) - to_s(base)[1])) < 0.03 * L
        under = inner & ex & ~near_base
        inner = inner & ~under
    else:
        under = np.zeros(m.shape, bool)
    b, a = _nearest_inside(inner, to_s(base)), _nearest_inside(inner, to_s(apex))
    best = None
    for channel, k in CHANNELS:
        image = lab[..., k]
        for pol, R in zip(("light", "dark"), _ridge(image, inner, MAIN_SIGMA * L)):
            scale = float(np.percentile(R[inner], 99.5)) or 1.0
            cost = np.where(inner, 1.0 / (_FLOOR + R / scale), 1e4).astype(np.float64)
            grid = _Grid(cost)
            d, pred = grid.tree([grid.index(b)])
            mid = grid.path(pred, grid.index(a))
            # the channel and polarity the leaf shows: the one whose midrib stands out most
            on = R[mid[:, 1].astype(int), mid[:, 0].astype(int)]
            strength = float(np.median(on)) / (float(np.median(R[inner])) or 1e-12)
            if best is None or strength > best[0]:
                best = (strength, pol, R, grid, mid, image, channel)
    strength, pol, R, grid, mid, image, channel = best
    if under.any() and len(lobes_px):
        # a main vein may pass under a petiole lying on the blade, as the hidden vein would,
        # at the cost of the midrib's typical pixel (it cannot follow the petiole's own ridge,
        # which is left out of R, and it is no cheaper there than on a vein)
        cost = grid.cost.copy()
        cost[under] = float(np.median(cost[mid[:, 1].astype(int), mid[:, 0].astype(int)]))
        grid = _Grid(cost)
    mains = []
    for tip in lobes_px:
        t = _nearest_inside(inner, to_s(tip))
        if main_origin == "base":
            d, pred = grid.tree([grid.index(b)])
        else:
            d, pred = grid.tree([grid.index(p) for p in mid[len(mid) // 20: -max(1, len(mid) // 10)]])
        mains.append(grid.path(pred, grid.index(t)))
    out_l, parents, test = [], [], {}
    if laterals:
        out_l, parents, test = _laterals(image, m, inner, [mid, *mains], L, pol, under)
    w = 0.01 * L
    return PhotoVeins(midrib=back(_smooth(mid, w)), mains=[back(_smooth(p, w)) for p in mains],
                      laterals=[back(_smooth(p, w)) for p in out_l], parents=parents, polarity=pol,
                      channel=channel, strength=round(strength, 2), lateral_test=test)


def _lateral_starts(mains, ring: np.ndarray, L: float) -> list:
    """Candidate starts of laterals: (main index, pixel (x, y)) of ``ring`` (the pixels just
    beside the main veins), every 0.5 % L along each main vein from :data:`START_AT` to 3 % L
    before its end, one to three on either side of it: of the ring's pixels within 4 % L (at
    least 12 px, for a small photo), those at most 1 px farther than the side's nearest plus
    the ring's width (so where a petiole lying on the blade hides the vein, at its edge)."""
    ys, xs = np.nonzero(ring)
    ring_pts = np.column_stack([xs, ys]).astype(float)
    cands = []
    if not len(ring_pts):
        return cands
    for mi, p in enumerate(mains):
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        s = np.r_[0.0, np.cumsum(seg)]
        for t in np.arange(START_AT * L, s[-1] - 0.03 * L, 0.005 * L):
            q = np.array([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])])
            dt = np.array([np.interp(t + 1.0, s, p[:, 0]), np.interp(t + 1.0, s, p[:, 1])]) - q
            dist = np.linalg.norm(ring_pts - q, axis=1)
            within = dist < max(0.04 * L, 12.0)
            near, dist = ring_pts[within], dist[within]
            # either side on its own: the ring's pixels come in raster order, each row's left
            # pixels before its right ones, so one stride over them all can land on one side
            side = dt[0] * (near[:, 1] - q[1]) - dt[1] * (near[:, 0] - q[0]) > 0
            for sel in (side, ~side):
                if not sel.any():
                    continue
                side_pts = near[sel][dist[sel] <= dist[sel].min() + RING_WIDTH + 1.0]
                for r in side_pts[:: max(1, len(side_pts) // 2)]:
                    cands.append((mi, r))
    return cands


def _laterals(image, m, inner, mains, L, pol, under=None) -> tuple[list, list, dict]:
    """Laterals leaving the main veins (module docstring) in ``image`` (the midrib's channel):
    (paths from main vein to margin band in working pixels, parent main index each, and the
    null test's figures: ``best`` and ``null`` scores, ``shown``).
    ``under``: a petiole lying on the blade (left out of ``inner``), which is no margin; the
    laterals of a main vein hidden under it leave from its edge."""
    k = 0 if pol == "light" else 1
    # keep the tree off the main veins themselves (a lateral must leave them)
    main_px = np.zeros(m.shape, np.uint8)
    for p in mains:
        cv2.polylines(main_px, [np.round(p).astype(np.int32).reshape(-1, 1, 2)], False, 255, 1)
    kw = max(3, int(round(0.012 * L)) | 1)  # a main vein's own ridge is that wide
    near_main = cv2.dilate(main_px, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (kw, kw))) > 0
    blade = inner
    if under is not None and under.any():
        blade = inner | under
        # the petiole's pieces a main vein runs under count as that vein
        n, lab = cv2.connectedComponents(under.astype(np.uint8), connectivity=8)
        hit = np.unique(lab[under & near_main])
        near_main = near_main | (np.isin(lab, hit[hit > 0]) & under)
    band_w = max(2, int(round(0.02 * L)))
    band = inner & ~(cv2.erode(blade.astype(np.uint8), np.ones((2 * band_w + 1, 2 * band_w + 1), np.uint8)) > 0) & ~near_main
    if not band.any():
        return [], [], {"best": 0.0, "null": 0.0, "shown": False}
    # candidate starts: the ring of pixels just beside every main vein
    ring = (cv2.dilate(near_main.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * RING_WIDTH + 1,) * 2)) > 0) \
        & ~near_main & inner
    cands = _lateral_starts(mains, ring, L)
    d_main = cv2.distanceTransform(np.where(main_px > 0, 0, 255).astype(np.uint8), cv2.DIST_L2, 5)
    scored, short, grid, R, med = _scored_paths(image, inner, near_main, band, cands, d_main, L, k)
    # the null: the same search in the blade with its pixels off the main veins shuffled; both
    # judged by their clear ridges (a path that is a ridge on under half its length may owe its
    # score to an edge it runs along for a while)
    shuffled = image.copy()
    pool = inner & ~near_main
    vals = shuffled[pool]
    shuffled[pool] = vals[np.random.default_rng(0).permutation(len(vals))]
    null = _clearest(_scored_paths(shuffled, inner, near_main, band, cands, d_main, L, k, 0.0)[0], shuffled, inner, L, k)
    basal = _basal_laterals(grid, short, mains, band, blade, R, med, d_main, L)
    # a basal lateral counts as it is: its own search asks for a ridge over BASAL_SCORE (5) × the
    # blade's along a ray that follows a vein, well above any null's best (2.5-3.5 measured)
    best = max([_clearest(scored, image, inner, L, k), *(sc for sc, _, _ in basal)])
    scored += basal
    test = {"best": round(best, 2), "null": round(null, 2), "shown": bool(best > LATERAL_NULL_MARGIN * null)}
    if not test["shown"]:
        return [], [], test
    out, parents = _distinct(scored, m.shape, mains, L)
    return out, parents, test


def _scored_paths(image, inner, near_main, band, cands, d_main, L, k, least=LATERAL_SCORE) -> tuple:
    """The candidate laterals of ``image``: from each start in ``cands`` the cheapest path to
    the margin ``band`` over the line ridges, scored by its median plain ridge strength over
    the blade's median, those over ``least`` (score, main index, path); with the starts whose
    path is too short (the margin is near), the grid, the ridge image and its median."""
    # the paths follow lines only; a path is scored by the plain ridge strength against the
    # blade's median (the line measure's median is 0: most of a blade is no line)
    R_line = _ridge(image, inner, LATERAL_SIGMA * L, line=True)[k]
    R = _ridge(image, inner, LATERAL_SIGMA * L)[k]
    med = float(np.median(R[inner])) or 1e-12
    scale = float(np.percentile(R_line[inner], 99.0)) or 1.0
    cost = np.where(inner, 1.0 / (_FLOOR + R_line / scale), 1e4).astype(np.float64)
    cost[near_main] = 1e4
    grid = _Grid(cost)
    _, pred = grid.tree(np.flatnonzero(band.reshape(-1)))
    g = _flanks(image, inner, L)
    scored, short = [], []
    for mi, r in cands:
        path = grid.path(pred, grid.index(r))[::-1]  # from the main vein to the margin
        if len(path) < 0.08 * L:
            short.append((mi, r))  # the margin is near: perhaps beside a main vein's base
            continue
        ix = path.astype(int)
        if float(np.median(d_main[ix[:, 1], ix[:, 0]])) < 0.03 * L:
            continue  # it runs along a main vein instead of leaving it
        v = R[path[:, 1].astype(int), path[:, 0].astype(int)]
        score = float(np.median(v)) / med
        if score > least and _ridge_share(path, g, L, k) >= MIN_RIDGE_SHARE:
            scored.append((score, mi, path))
    return scored, short, grid, R, med


def _clearest(scored, image, inner, L, k) -> float:
    """The best score of ``scored`` among paths that are a ridge on at least
    :data:`CLEAR_RIDGE_SHARE` of their points (0 when none is)."""
    g = _flanks(image, inner, L)
    return max((sc for sc, _, p in scored if _ridge_share(p, g, L, k) >= CLEAR_RIDGE_SHARE), default=0.0)


def _flanks(image: np.ndarray, inner: np.ndarray, L: float) -> np.ndarray:
    """``image`` blurred at the laterals' scale (the blade's median outside it), for
    :func:`_ridge_share`."""
    fill = float(np.median(image[inner]))
    return cv2.GaussianBlur(np.where(inner, image, fill).astype(np.float32), (0, 0), LATERAL_SIGMA * L)


def _ridge_share(path: np.ndarray, g: np.ndarray, L: float, k: int) -> float:
    """The share of ``path``'s points where the blurred channel ``g`` is lighter (``k`` 0) or
    darker (1) than at both flanks, 2.5 lateral scales to either side: about all of them on a
    vein, few beside an edge (the ridge measure also answers on the light side of a step, so
    a path can run along a lesion's or blotch's edge, with one flank darker and one as light)."""
    p = _smooth(path, 0.01 * L)
    if len(p) < 2:
        return 0.0  # a point has no flanks
    t = np.gradient(p, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True) + 1e-12
    off = 2.5 * LATERAL_SIGMA * L * np.column_stack([-t[:, 1], t[:, 0]])
    h, w = g.shape

    def at(q):
        return g[np.clip(np.round(q[:, 1]).astype(int), 0, h - 1), np.clip(np.round(q[:, 0]).astype(int), 0, w - 1)]

    c = at(p)
    sign = 1.0 if k == 0 else -1.0
    return float(np.mean((sign * (c - at(p + off)) > 0) & (sign * (c - at(p - off)) > 0)))


def _distinct(scored, shape, mains, L) -> tuple[list, list]:
    """The scored laterals, strongest first, less those that are the same vein as a stronger
    one, end where they join one, turn back on themselves or run back along their main vein."""
    scored.sort(key=lambda x: -x[0])
    taken = np.zeros(shape, np.uint8)  # within 2 % L of a kept lateral
    kept_px = np.zeros(shape, np.uint8)  # a kept lateral's own pixels
    out, parents = [], []
    for score, mi, path in scored:
        ix = path.astype(int)
        if float(np.mean(taken[ix[:, 1], ix[:, 0]] > 0)) > 0.3:
            continue  # the same vein as a stronger one
        # where it joins a kept lateral (tree paths share their pixels from there to the
        # margin) it ends: the shared tail would be a doubled vein closing a loop
        joined = kept_px[ix[:, 1], ix[:, 0]] > 0
        if joined.any():
            path = path[: int(np.argmax(joined)) + 1]
            if len(path) < 0.08 * L:
                continue
        if _turning_deg(path, L) > MAX_TURN_DEG or _backward(path, mains[mi]):
            continue  # it turns back on itself, or back along its main vein: a blotch's edge
        for mask, width in ((taken, max(1, int(round(0.04 * L)))), (kept_px, 1)):
            cv2.polylines(mask, [np.round(path).astype(np.int32).reshape(-1, 1, 2)], False, 255, width)
        out.append(path)
        parents.append(mi)
    return out, parents


def _basal_laterals(grid, short, mains, band, blade, R, med, d_main, L) -> list:
    """Laterals that leave a main vein near its base (aspen's basal pair, running from the
    petiole up to the side margins; grapevine's veins to its upper lobes, leaving the side main
    veins beside the petiole).  There the margin beside the base is so near that the cheapest
    path to any margin runs to it instead of along the vein: ``short`` are the starts whose
    path did.  So this search keeps off the margin and off the main veins: every pixel within
    :data:`BASAL_EDGE` of a main vein, or of the margin off a vein's ridge (a ridge over
    :data:`BASAL_SCORE` × the blade's: a vein may run that near a sinus), costs at least
    1 / :data:`_FLOOR`, as the blade off the lines.  From those starts along each main vein's
    first :data:`BASAL_ZONE` (one search a side every :data:`BASAL_EVERY`, from the start that
    leaves along the strongest ridge) it leaves that strip (:func:`_leave_strip`) and ends in
    the margin band at least :data:`BASAL_MIN_REACH` from the main vein's start, where the path
    is cheapest per unit of straight-line reach (the strongest vein, not the nearest margin).
    The path is cut where it turns away from its heading (:func:`_until_turn`; the vein grower
    joins it to its main vein in line with its first 2 % L) and scored as the others (median
    ridge over the blade's); of each side of each main vein the best path scored above
    :data:`BASAL_SCORE` is kept."""
    d_edge = cv2.distanceTransform(blade.astype(np.uint8), cv2.DIST_L2, 5)
    along = (d_edge < BASAL_EDGE * L) & (R < BASAL_SCORE * med) | (d_main < BASAL_EDGE * L)
    cost = grid.cost.copy()
    cost[along] = np.maximum(cost[along], 1.0 / _FLOOR)
    grid = _Grid(cost)
    band_idx = np.flatnonzero(band.reshape(-1))
    bxy = np.column_stack([band_idx % grid.w, band_idx // grid.w]).astype(float)
    bins: dict = {}  # one search a side every BASAL_EVERY: its start the one leaving along the strongest ray
    for mi, r in short:
        p = mains[mi]
        j = int(np.argmin(np.linalg.norm(p - r, axis=1)))
        t = float(np.linalg.norm(np.diff(p[: j + 1], axis=0), axis=1).sum())
        tm = p[min(j + 2, len(p) - 1)] - p[max(j - 2, 0)]
        key = (mi, bool(tm[0] * (r[1] - p[j][1]) - tm[1] * (r[0] - p[j][0]) > 0), int(t // (BASAL_EVERY * L)))
        if t > BASAL_ZONE * L:
            continue
        r0, ray = _leave_strip(r, r - p[j], tm, R, med, blade, d_main, L)
        if r0 is None:
            continue
        if key not in bins or ray > bins[key][2]:  # ties: the first start of the bin, as the ring lists them
            bins[key] = (r, r0, ray)
    best = {}
    for key, (r, r0, ray) in bins.items():
        mi = key[0]
        if mi > 0 and ray == 0.0:
            continue  # beside a side main vein only a vein seen leaving it is searched
        p = mains[mi]
        d, pred = dijkstra(grid.graph, directed=False, indices=grid.index(r0), return_predecessors=True)
        reach = np.linalg.norm(bxy - r0, axis=1)
        ok = (np.linalg.norm(bxy - p[0], axis=1) >= BASAL_MIN_REACH * L) & np.isfinite(d[band_idx])
        if not ok.any():
            continue
        k = np.flatnonzero(ok)[int(np.argmin(d[band_idx][ok] / reach[ok]))]
        path = grid.path(pred, int(band_idx[k]))
        if ray > 0:  # the vein itself leaves along the ray: the path starts beside its main vein
            k0 = max(2, int(np.ceil(np.linalg.norm(r0 - r))))
            path = np.vstack([r + np.linspace(0.0, 1.0, k0, endpoint=False)[:, None] * (r0 - r), path])
        path = _until_turn(path, L)
        ix = path.astype(int)
        if len(path) < 0.08 * L:
            continue
        if float(np.median(d_edge[ix[:, 1], ix[:, 0]])) < 0.5 * BASAL_EDGE * L \
                or float(np.median(d_main[ix[:, 1], ix[:, 0]])) < 0.03 * L:
            continue  # it runs along the margin, or along a main vein
        score = float(np.median(R[ix[:, 1], ix[:, 0]])) / med
        if score > BASAL_SCORE and score > best.get(key[:2], (0.0,))[0]:  # one a side: the starts find the same vein
            best[key[:2]] = (score, mi, path)
    return list(best.values())


def _leave_strip(r, normal, tangent, R, med, blade, d_main, L):
    """Where a basal lateral starting at ``r`` beside its main vein leaves that vein's strip
    (:data:`BASAL_EDGE`), and whether it gets there along a vein.  The rays from ``r`` at
    :data:`BASAL_ANGLES` to the main vein (``tangent``, toward its tip) on the side of
    ``normal`` are ranked by their median ridge over the first :data:`BASAL_RAY` L (leaving out
    the pixels beside any main vein, whose own ridge is no evidence): a vein that leaves at a
    sharp angle (grapevine's to its upper lobes) runs inside the strip for a while, and a start
    pushed straight out lands beside it.  The strongest ray whose median is a vein's (over
    :data:`BASAL_SCORE` × the blade's ``med``) and that leaves the strip within 4 ×
    :data:`BASAL_EDGE` without leaving the blade or meeting another main vein is followed to
    its first pixel outside the strip.  Otherwise (no ray on a vein: a start above where the
    vein leaves, as aspen's at its very base) the start is pushed straight out along
    ``normal``.  Returns (that pixel, or None when it is off the blade; the followed ray's
    median ridge over the blade's, or 0 when pushed straight out)."""
    t = np.asarray(tangent, float) / max(float(np.linalg.norm(tangent)), 1e-9)
    n = np.asarray(normal, float) - np.dot(normal, t) * t
    n /= max(float(np.linalg.norm(n)), 1e-9)
    h, w = R.shape
    steps = np.arange(1.0, BASAL_RAY * L)
    beside = BASAL_BESIDE * L
    rays = []
    for a in np.radians(BASAL_ANGLES):
        d = np.cos(a) * t + np.sin(a) * n
        pts = np.round(r + steps[:, None] * d).astype(int)
        if not ((pts >= 0).all() and (pts[:, 0] < w).all() and (pts[:, 1] < h).all()) or not blade[pts[:, 1], pts[:, 0]].all():
            continue
        off = d_main[pts[:, 1], pts[:, 0]] >= beside
        if off.sum() < 0.5 * len(pts):
            continue  # the ray runs along a main vein
        rays.append((float(np.median(R[pts[off, 1], pts[off, 0]])), d))
    for v, d in sorted(rays, key=lambda x: -x[0]):
        if v <= BASAL_SCORE * med:
            break
        left = False  # the walk has left the main vein's own ridge
        for k in np.arange(1.0, 4.0 * BASAL_EDGE * L):
            q = np.round(r + k * d).astype(int)
            if not (0 <= q[0] < w and 0 <= q[1] < h) or not blade[q[1], q[0]]:
                break
            dm = d_main[q[1], q[0]]
            if dm >= BASAL_EDGE * L:
                return q.astype(float), v / med
            if left and dm < 0.5 * beside:
                break  # it meets another main vein
            left = left or dm >= beside
    q = np.clip(np.round(r + n * BASAL_EDGE * L), 0, [w - 1, h - 1])
    return (q, 0.0) if blade[int(q[1]), int(q[0])] else (None, 0.0)


def _until_turn(path: np.ndarray, L: float, max_deg: float = BASAL_TURN_DEG) -> np.ndarray:
    """``path`` up to where its heading, over steps of 2 % L of arc length, has turned further
    than ``max_deg`` from the heading it has between 3 and 10 % L (once it has joined the vein's
    ridge: its start may jog sideways onto it): beyond, the cheapest path has gone on along
    another vein than the one it followed."""
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
    i3, i10 = (int(np.searchsorted(s, f * L)) for f in (0.03, 0.10))
    if i10 >= len(path) - 1:
        return path
    h0 = path[i10] - path[i3]
    a0 = np.arctan2(h0[1], h0[0])
    i = i10
    while True:
        k = int(np.searchsorted(s, s[i] + 0.02 * L))
        if k >= len(path):
            return path
        h = path[k] - path[i]
        if np.degrees(abs((np.arctan2(h[1], h[0]) - a0 + np.pi) % (2 * np.pi) - np.pi)) > max_deg:
            return path[: i + 1]
        i = k


def _backward(path: np.ndarray, main: np.ndarray) -> bool:
    """Whether a lateral heads back along its main vein (start → end more than 120° from the
    main vein's direction where it leaves): laterals leave toward the main vein's tip."""
    j = int(np.argmin(np.linalg.norm(main - path[0], axis=1)))
    t = main[min(j + 2, len(main) - 1)] - main[max(j - 2, 0)]
    c = path[-1] - path[0]
    nt, nc = float(np.linalg.norm(t)), float(np.linalg.norm(c))
    return nt > 0 and nc > 0 and float(np.dot(t, c)) < -0.5 * nt * nc


def _turning_deg(path: np.ndarray, L: float) -> float:
    """How far a path's heading swings, smoothed over 2 % L: the range of its unwrapped
    direction [deg] (a straight vein 0, a vein turning back on itself 180)."""
    sm = _smooth(path, 0.02 * L)
    d = np.diff(sm, axis=0)
    d = d[np.linalg.norm(d, axis=1) > 1e-9]
    if len(d) < 2:
        return 0.0
    a = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return float(np.degrees(a.max() - a.min()))

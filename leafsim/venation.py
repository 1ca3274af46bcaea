"""Vein growth from the leaf outline [Kim 2017; thesis §3.2–3.5].

Orders: 0 main, 1 lateral, 2 sublateral, 3 net (tertiary).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAIN, LATERAL, SUB, NET = 0, 1, 2, 3
ORDER_NAMES = ("main", "lateral", "sublateral", "net")


@dataclass
class Vein:
    """One vein polyline.

    Attributes
    ----------
    order : 0 main, 1 lateral, 2 sublateral, 3 net.
    points : (k, 2) float64 — polyline in world metres, from its start (on the parent) outwards.
    widths : (k,) float64 — vein width at each point in metres.
    parent : index of the parent vein in ``VeinGraph.veins`` (−1 for main veins).
    target : (2,) float64 — the point the vein grew toward.
    """

    order: int
    points: np.ndarray
    widths: np.ndarray
    parent: int = -1
    target: np.ndarray | None = None

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum()) if len(self.points) > 1 else 0.0


@dataclass
class VeinGraph:
    """All veins of one leaf plus the statistics the CLI reports."""

    veins: list[Vein] = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    def of_order(self, order: int) -> list[Vein]:
        return [v for v in self.veins if v.order == order]

    def segments(self, max_order: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All segments as (P (s,2), Q (s,2), order (s,)) up to ``max_order``."""
        P, Q, O = [], [], []
        for v in self.veins:
            if v.order <= max_order and len(v.points) > 1:
                P.append(v.points[:-1])
                Q.append(v.points[1:])
                O.append(np.full(len(v.points) - 1, v.order))
        if not P:
            return np.empty((0, 2)), np.empty((0, 2)), np.empty(0, int)
        return np.vstack(P), np.vstack(Q), np.concatenate(O)


# ============================================================================ growth
from scipy.spatial import ConvexHull, cKDTree  # noqa: E402

from .geometry import (  # noqa: E402
    LeafShape,
    crossing_pairs,
    outline_edges,
    points_in_region,
    ray_polygon_hit,
    segment_hits,
)
from .errors import LeafsimError  # noqa: E402
from .params import ParamSet  # noqa: E402


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _rot(v: np.ndarray, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def detect_lobe_tips(contour: np.ndarray, length: float, min_depth: float, max_angle: float = 160.0, radial: bool = True) -> np.ndarray:
    """Lobe tips of a leaf contour (world frame, base at origin, apex on +y).

    The contour is split at sinuses — the deepest contour point between two consecutive
    convex-hull vertices, when deeper than ``min_depth × length`` below the hull edge.
    In every piece the point farthest from the base is a lobe tip.  Pieces whose tip lies
    near the base (< 0.2 length) or points back along the petiole (angle from +y above
    ``max_angle``) are dropped.  ``radial`` (palmate leaves, lobes radiate from the base):
    the tip is the lobe point farthest from the base; otherwise (pinnate lobes) the point
    protruding farthest beyond the chord joining the lobe's two sinuses.
    Returns (k, 2) tips ordered by angle from the apex.
    """
    n = len(contour)
    thr = min_depth * length

    def deepest(idx):
        p, q = contour[idx[0]], contour[idx[-1]]
        d = q - p
        L = np.linalg.norm(d)
        if L == 0 or len(idx) < 3:
            return None
        chain = contour[idx]
        depth = np.abs(d[0] * (chain[:, 1] - p[1]) - d[1] * (chain[:, 0] - p[0])) / L
        k = int(np.argmax(depth))
        return int(idx[k]) if depth[k] > thr else None

    def refine(idx, out):
        """Sinuses inside an open chain: hull of the chain, deepest point under each hull edge."""
        if len(idx) < 4:
            return
        try:
            hv = np.sort(ConvexHull(contour[idx]).vertices)
        except Exception:
            return
        for a, b in zip(hv[:-1], hv[1:]):
            if b - a < 2:
                continue
            k = deepest(idx[a : b + 1])
            if k is not None:
                out.append(k)
                kk = int(np.flatnonzero(idx == k)[0])
                refine(idx[a : kk + 1], out)
                refine(idx[kk : b + 1], out)

    hull = np.sort(ConvexHull(contour).vertices)
    sinuses = []
    for a, b in zip(hull, np.roll(hull, -1)):
        idx = np.arange(a, b + (n if b <= a else 0) + 1) % n
        k = deepest(idx)
        if k is not None:
            sinuses.append(k)
            kk = int(np.flatnonzero(idx == k)[0])
            refine(idx[: kk + 1], sinuses)
            refine(idx[kk:], sinuses)
    r = np.linalg.norm(contour, axis=1)
    if len(sinuses) < 2:
        return contour[[int(np.argmax(r))]]
    sinuses = sorted(set(sinuses))
    tips = []
    for a, b in zip(sinuses, sinuses[1:] + [sinuses[0] + n]):
        idx = np.arange(a, b + 1) % n
        # the tip protrudes farthest beyond the chord joining the lobe's two sinuses
        p0, p1 = contour[idx[0]], contour[idx[-1]]
        d = p1 - p0
        prot = (d[0] * (contour[idx, 1] - p0[1]) - d[1] * (contour[idx, 0] - p0[0])) * -1.0
        if radial or np.linalg.norm(d) < 1e-12 or prot.max() <= 0:
            k = idx[int(np.argmax(r[idx]))]
        else:
            prot = prot / np.linalg.norm(d)
            if prot.max() < thr:
                continue
            k = idx[int(np.argmax(prot))]
        t = contour[k]
        ang = np.degrees(np.arctan2(t[0], t[1]))
        if r[k] >= 0.2 * length and abs(ang) <= max_angle:
            tips.append(t)
    if not tips:
        return contour[[int(np.argmax(r))]]
    tips = np.array(tips)
    return tips[np.argsort(np.abs(np.degrees(np.arctan2(tips[:, 0], tips[:, 1]))))]


class _Grower:
    """Vein growth with collision tests against every accepted segment and the contour."""

    def __init__(self, shape: LeafShape, params: ParamSet, rng: np.random.Generator):
        self.shape = shape
        self.p = params
        self.rng = rng
        self.L = shape.length
        self.C = shape.contour
        # margin edges: the contour and the holes (closed sinuses), veins never cross them
        self.CP, self.CQ = outline_edges(shape.contour, shape.holes)
        self.P = np.empty((0, 2))
        self.Q = np.empty((0, 2))
        self.budget = int(params["limits.vein_tests"])
        self.tests = 0

    # -- work budget: growth cost is dominated by segment-against-segment tests
    def charge(self, n: int) -> None:
        """Count ``n`` collision tests; past ``limits.vein_tests`` stop with a one-line error."""
        self.tests += n
        if self.tests > self.budget:
            p = self.p
            raise LeafsimError(
                f"veins: growing this venation needs more than limits.vein_tests = {self.budget:,} collision tests "
                f"(veins.main.step = {p['veins.main.step']:g}, veins.lateral.step = {p['veins.lateral.step']:g}, "
                f"veins.lateral.spacing = {p['veins.lateral.spacing']}, veins.sub.divisions = {p['veins.sub.divisions']} "
                "are very fine for this outline); coarsen them, or raise limits.vein_tests to wait longer")

    # -- obstacle bookkeeping
    def add(self, pts: np.ndarray):
        if len(pts) > 1:
            self.P = np.vstack([self.P, pts[:-1]])
            self.Q = np.vstack([self.Q, pts[1:]])

    def blocked(self, a: np.ndarray, b: np.ndarray) -> bool:
        self.charge(2 * len(self.CP) + len(self.P))
        if len(segment_hits(a, b, self.CP, self.CQ)):
            return True
        if len(segment_hits(a, b, self.P, self.Q)):
            return True
        return not self.shape.inside(((a + b) / 2)[None])[0]

    def _self_hit(self, pts: list, a: np.ndarray, b: np.ndarray) -> bool:
        """Would segment ab cross the growing vein's own earlier segments?"""
        if len(pts) < 3:
            return False
        self.charge(len(pts))
        arr = np.asarray(pts[:-1])
        return len(segment_hits(a, b, arr[:-1], arr[1:])) > 0

    def first_hit(self, a: np.ndarray, b: np.ndarray, skip_contour=False) -> float | None:
        self.charge(len(self.P) + (0 if skip_contour else len(self.CP)))
        t = segment_hits(a, b, self.P, self.Q)
        if not skip_contour:
            t = np.concatenate([t, segment_hits(a, b, self.CP, self.CQ)])
        return float(t.min()) if len(t) else None

    # -- growth (Alg. 1 and 2 of the thesis)
    def grow(self, start, target, step, kappa, omega, jitter, collide, initial_dir=None):
        """Grow from ``start`` toward ``target``; returns (points, reached).

        Each new direction is the mean of the direction to the target and the previous
        direction (thesis Alg. 1), rotated by ω plus a random angle in [−κ, κ].  An
        ``initial_dir`` other than the target direction makes the vein arc into its target.
        """
        pts = [np.asarray(start, float)]
        p = pts[0]
        dist0 = np.linalg.norm(target - p)
        prev = _unit(target - p) if initial_dir is None else _unit(initial_dir)
        travelled = 0.0
        max_steps = int(4 * dist0 / max(step * (1 - jitter), 1e-12)) + 20
        for _ in range(max_steps):
            to_t = target - p
            d_t = np.linalg.norm(to_t)
            if d_t <= step:
                if collide and self.blocked(p, target):
                    return np.array(pts), False
                pts.append(np.asarray(target, float))
                return np.array(pts), True
            v_gr = to_t / d_t
            d = _unit(v_gr + prev)
            d = _rot(d, omega + self.rng.uniform(-kappa, kappa))
            seg = step * self.rng.uniform(1 - jitter, 1 + jitter)
            q = p + d * min(seg, d_t)
            if collide and (self.blocked(p, q) or self._self_hit(pts, p, q)):
                return np.array(pts), False
            travelled += np.linalg.norm(q - p)
            pts.append(q)
            prev, p = d, q
            if travelled > 1.6 * dist0 + 2 * step:
                return np.array(pts), False
        return np.array(pts), False

    def grow_main(self, start, target, step, kappa, omega, jitter, tries=12):
        """Main veins must reach their target without crossing anything: retry, then relax."""
        for attempt in range(tries):
            k = kappa * (1 - attempt / tries)
            o = omega * (1 - attempt / tries)
            pts, ok = self.grow(start, target, step, k, o, jitter, collide=True)
            if ok:
                return pts
        # route through an interior waypoint: the point farthest from the margin near the
        # straight path (lobes that curve away from the base need it)
        for f in (0.35, 0.5, 0.65, 0.2):
            wp = self._waypoint(start + f * (target - start), 0.25 * np.linalg.norm(target - start))
            if wp is None:
                continue
            for attempt in range(tries):
                k = kappa * (1 - attempt / tries)
                a, ok1 = self.grow(start, wp, step, k, 0.0, jitter, collide=True)
                if not ok1:
                    continue
                self.add(a)
                b, ok2 = self.grow(wp, target, step, k, 0.0, jitter, collide=True, initial_dir=a[-1] - a[-2])
                self.P, self.Q = self.P[: -(len(a) - 1)], self.Q[: -(len(a) - 1)]
                if ok2 and not self._self_hit(list(a), b[0], b[1]):
                    return np.vstack([a, b[1:]])
        # last resort: a straight, finely stepped line (the caller checks it for crossings)
        n = max(2, int(np.ceil(np.linalg.norm(target - start) / step)) + 1)
        return np.linspace(start, target, n)

    def _waypoint(self, centre: np.ndarray, radius: float) -> np.ndarray | None:
        g = np.linspace(-radius, radius, 15)
        gx, gy = np.meshgrid(g, g)
        cand = centre + np.column_stack([gx.ravel(), gy.ravel()])
        cand = cand[self.shape.inside(cand)]
        if len(cand) == 0:
            return None
        score = self.shape.margin_distance(cand) - 0.3 * np.linalg.norm(cand - centre, axis=1)
        return cand[int(np.argmax(score))]


def _inside_point(shape: LeafShape, tip: np.ndarray, toward: np.ndarray, offset: float) -> np.ndarray:
    """A point ``offset`` inside the contour from ``tip`` along the line to ``toward``."""
    d = toward - tip
    n = np.linalg.norm(d)
    if n == 0:
        return tip
    for k in range(1, 8):
        q = tip + d / n * min(offset * k, 0.5 * n)
        if shape.inside(q[None])[0]:
            return q
    return tip + 0.5 * d


def _root(shape: LeafShape, g: "_Grower", d_target: np.ndarray, d_apex: np.ndarray, dist: float):
    """First point of a palmate main vein: half a step from the base into the blade, turned
    from the target direction toward the midrib until it is inside (bases often sit in a notch)."""
    for w in np.linspace(0.0, 0.9, 10):
        d = _unit((1 - w) * d_target + w * d_apex)
        q = shape.base + d * dist
        if shape.inside(q[None])[0] and not len(segment_hits(shape.base + 1e-9 * d, q, g.CP, g.CQ)) \
                and not len(segment_hits(shape.base, q, g.P, g.Q)):
            return q
    return None


def _widths(points: np.ndarray, w0: float, taper: float, thin_from: float | None = None) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    f = s / s[-1] if s[-1] > 0 else np.zeros_like(s)
    w = w0 * (1.0 - taper * f)
    if thin_from is not None:
        w = np.where(f > thin_from, w * 0.5, w)
    return w


def _arc_fraction(points: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / s[-1] if s[-1] > 0 else s


def grow_veins(
    shape: LeafShape,
    params: ParamSet,
    seed: int = 0,
    targets: np.ndarray | None = None,
    main_origin: str = "base",
    lateral_profile: np.ndarray | None = None,
) -> VeinGraph:
    """Grow the whole venation of one leaf (deterministic for a given seed).

    Parameters
    ----------
    shape : the leaf outline in metres (base at origin, apex on +y).
    params : all parameters; the ``veins.*`` group is read.
    seed : random seed.
    targets : (k, 2) main-vein targets in metres, or None for automatic detection from lobes.
    main_origin : ``"base"`` (palmate: every main vein starts at the petiole) or
        ``"midrib"`` (pinnate lobes: secondary main veins branch off the midrib).
    lateral_profile : (k, 2) table, position along the main vein in % → lateral length factor.
    """
    p = params
    rng = np.random.default_rng(seed)
    L = shape.length
    g = _Grower(shape, p, rng)
    prof = np.asarray(lateral_profile if lateral_profile is not None else [[0, 1], [100, 1]], float)
    taper = p["veins.taper"]
    graph = VeinGraph()

    # ---- main-vein targets
    inset = 0.035 * L
    apex_t = _inside_point(shape, shape.apex, np.zeros(2), inset)
    if targets is None:
        tips = detect_lobe_tips(shape.contour, L, p["outline.lobe_depth"], radial=main_origin == "base")
        others = []
        min_ang = p["veins.main.auto_min_angle"]
        ang_apex = 0.0
        for t in tips:
            ang = np.degrees(np.arctan2(t[0], t[1]))
            if np.linalg.norm(t - shape.apex) < 0.08 * L:
                continue
            if main_origin == "base" and abs(ang - ang_apex) < min_ang:
                continue
            if main_origin == "base" and any(abs(ang - np.degrees(np.arctan2(o[0], o[1]))) < min_ang for o in others):
                continue
            others.append(t)
        others = others[: max(0, p["veins.main.max_auto"] - 1)]
        auto = True
    else:
        t_arr = np.asarray(targets, float)
        i_apex = int(np.argmin(np.linalg.norm(t_arr - shape.apex, axis=1)))
        apex_t = t_arr[i_apex]
        others = [t for i, t in enumerate(t_arr) if i != i_apex]
        auto = False

    step_m = p["veins.main.step"] * L
    jit = p["veins.main.scale_jitter"]
    kappa, omega = p["veins.main.kappa"], p["veins.main.omega"]
    w_main = p["veins.main.width"] * L
    thr = p["veins.main.threshold"]

    # main veins leave the petiole junction straight into the blade for half a step, so that
    # no vein can slip out through the margin next to the base
    root = shape.base + _unit(apex_t - shape.base) * 0.5 * step_m
    mid = g.grow_main(root, apex_t, step_m, kappa, omega, jit)
    mid = np.vstack([shape.base[None].astype(float), mid])
    g.add(mid)
    graph.veins.append(Vein(MAIN, mid, _widths(mid, w_main, taper, 1 - thr), -1, apex_t))
    mid_frac = _arc_fraction(mid)

    main_targets = [apex_t]
    for t in others:
        if main_origin == "midrib":
            # branch point on the midrib at the lateral angle, then aim at the lobe tip
            ang = p["veins.lateral.angle"]
            best, best_err = 1, np.inf
            for i in range(1, len(mid) - 1):
                if mid_frac[i] > 1 - thr:
                    break
                fwd = _unit(mid[min(i + 1, len(mid) - 1)] - mid[i - 1])
                to = t - mid[i]
                a = np.degrees(np.arccos(np.clip(np.dot(fwd, _unit(to)), -1, 1)))
                if abs(a - ang) < best_err:
                    best, best_err = i, abs(a - ang)
            start = mid[best]
            tgt = _inside_point(shape, t, start, inset)
            parent = 0
            w0 = np.interp(mid_frac[best], mid_frac, graph.veins[0].widths) * 0.7
        else:
            tgt = _inside_point(shape, t, np.zeros(2), inset)
            start = _root(shape, g, _unit(tgt - shape.base), _unit(apex_t - shape.base), 0.5 * step_m)
            if start is None:
                continue
            parent = -1
            w0 = w_main * 0.75
        pts = g.grow_main(start, tgt, step_m, kappa, np.sign(t[0]) * abs(omega) * 0.5, jit)
        if main_origin != "midrib":
            pts = np.vstack([shape.base[None].astype(float), pts])
        if g.first_hit(pts[0], pts[1]) is not None or any(g.first_hit(a, b) is not None for a, b in zip(pts[:-1], pts[1:])):
            # could not reach without crossing: skip this lobe vein rather than cross
            continue
        g.add(pts)
        graph.veins.append(Vein(MAIN, pts, _widths(pts, w0, taper, 1 - thr), parent, tgt))
        main_targets.append(tgt)

    # ---- laterals
    if p["veins.lateral.enabled"]:
        lat_lines: list[tuple[np.ndarray, np.ndarray]] = []
        spacing = p["veins.lateral.spacing"]
        mode = p["veins.lateral.alternation"]
        lstep = p["veins.lateral.step"] * L
        lk = p["veins.lateral.kappa"]
        n_main = len(graph.veins)
        counter = 0
        for mi in range(n_main):
            mv = graph.veins[mi]
            pts = mv.points
            frac = _arc_fraction(pts)
            cand = [i for i in range(1, len(pts) - 1) if frac[i] <= 1 - thr]
            for ci, i in enumerate(cand[spacing - 1 :: spacing] if spacing > 1 else cand):
                fwd = _unit(pts[i + 1] - pts[i - 1])
                if mode == "opposite":
                    sides = (1, -1)
                elif mode == "left":
                    sides = (1,)
                elif mode == "right":
                    sides = (-1,)
                else:
                    sides = (1 if counter % 2 == 0 else -1,)
                counter += 1
                for side in sides:
                    ang = p["veins.lateral.angle"] + rng.uniform(-1, 1) * p["veins.lateral.angle_jitter"]
                    d = _rot(fwd, side * ang)
                    hit = ray_polygon_hit(pts[i], d, shape.contour, shape.holes)
                    if hit is None:
                        continue
                    f = float(np.interp(frac[i] * 100, prof[:, 0], prof[:, 1]))
                    length = hit * p["veins.lateral.reach"] * f
                    tgt = pts[i] + d * length
                    th = g.first_hit(pts[i], tgt, skip_contour=True)
                    if th is not None:
                        tgt = pts[i] + (tgt - pts[i]) * th * 0.8
                        length *= th * 0.8
                    if length < 2 * lstep:
                        continue
                    g.charge(len(lat_lines))
                    if any(_proper(pts[i], tgt, a, b) for a, b in lat_lines):
                        continue  # start–target line test (thesis §3.3)
                    # arching laterals leave the main vein more steeply and bend toward the apex
                    d0 = _rot(fwd, side * min(ang + 25.0, 88.0)) if p["veins.lateral.curve_apical"] else None
                    lv, _ = g.grow(pts[i], tgt, lstep, lk, 0.0, jit, True, d0)
                    if len(lv) < 3:
                        continue
                    g.add(lv)
                    lat_lines.append((pts[i], tgt))
                    w0 = float(mv.widths[i]) * p["veins.lateral.width"]
                    graph.veins.append(Vein(LATERAL, lv, _widths(lv, w0, taper), mi, tgt))

    # ---- sublaterals (quadratic Bézier aimed at the margin)
    if p["veins.sub.enabled"]:
        ndiv = p["veins.sub.divisions"]
        sstep = p["veins.lateral.step"] * L * 0.8
        for li in [k for k, v in enumerate(graph.veins) if v.order == LATERAL]:
            lv = graph.veins[li]
            frac = _arc_fraction(lv.points)
            for k in range(1, ndiv):
                i = int(np.argmin(np.abs(frac - k / ndiv)))
                if i <= 0 or i >= len(lv.points) - 1:
                    continue
                fwd = _unit(lv.points[i + 1] - lv.points[i - 1])
                side = 1 if (k + li) % 2 == 0 else -1
                d = _rot(fwd, side * p["veins.sub.angle"])
                hit = ray_polygon_hit(lv.points[i], d, shape.contour, shape.holes)
                if hit is None:
                    continue
                a = lv.points[i]
                b = a + d * hit * p["veins.sub.reach"]
                chord = np.linalg.norm(b - a)
                if chord < 2 * sstep:
                    continue
                perp = np.array([-d[1], d[0]])
                c = (a + b) / 2 + perp * rng.uniform(-1, 1) * p["veins.sub.bend"] * chord
                n = max(3, int(np.ceil(chord / sstep)) + 1)
                t = np.linspace(0, 1, n)[:, None]
                curve = (1 - t) ** 2 * a + 2 * (1 - t) * t * c + t**2 * b
                keep = [curve[0]]
                for q0, q1 in zip(curve[:-1], curve[1:]):
                    if g.blocked(q0, q1):
                        break
                    keep.append(q1)
                if len(keep) < 3:
                    continue
                sv = np.array(keep)
                g.add(sv)
                w0 = float(np.interp(frac[i], frac, lv.widths)) * p["veins.sub.width"]
                graph.veins.append(Vein(SUB, sv, _widths(sv, w0, taper), li, b))

    # ---- tertiary net: scattered points joined to the nearest vein
    if p["veins.net.enabled"]:
        sp = p["veins.net.spacing"] * L
        lo, hi = shape.contour.min(0), shape.contour.max(0)
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0], sp), np.arange(lo[1], hi[1], sp))
        pts = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(-0.35, 0.35, (gx.size, 2)) * sp
        pts = pts[shape.inside(pts)]
        owner_pts, owner_idx, owner_w = [], [], []
        for vi, v in enumerate(graph.veins):
            owner_pts.append(v.points)
            owner_idx.append(np.full(len(v.points), vi))
            owner_w.append(v.widths)
        allp = np.vstack(owner_pts)
        alli = np.concatenate(owner_idx)
        allw = np.concatenate(owner_w)
        tree = cKDTree(allp)
        for q in pts:
            d, j = tree.query(q)
            if d < 0.5 * sp or d > 2.5 * sp:
                continue
            a = allp[j]
            if g.blocked(a, q):
                continue
            nv = np.array([a, q])
            g.add(nv)
            graph.veins.append(Vein(NET, nv, _widths(nv, float(allw[j]) * p["veins.net.width"], taper), int(alli[j]), q))

    graph.stats = vein_stats(graph, shape, main_targets, auto)
    graph.stats["collision_tests"] = g.tests
    return graph


def _proper(p1, p2, q1, q2) -> bool:
    return len(segment_hits(np.asarray(p1), np.asarray(p2), np.asarray(q1)[None], np.asarray(q2)[None])) > 0


def count_crossings(graph: VeinGraph) -> int:
    """Number of proper intersections between vein segments (shared end points do not count)."""
    P, Q, _ = graph.segments()
    return len(crossing_pairs(P, Q))


def outside_length(graph: VeinGraph, contour: np.ndarray, holes=(), samples: int = 8) -> float:
    """Total vein length lying outside the blade: outside the contour or in a hole (sampled
    at segment interior points)."""
    P, Q, _ = graph.segments()
    if len(P) == 0:
        return 0.0
    t = (np.arange(samples) + 0.5) / samples
    pts = P[:, None, :] + (Q - P)[:, None, :] * t[None, :, None]
    inside = points_in_region(pts.reshape(-1, 2), contour, holes).reshape(len(P), samples)
    seg_len = np.linalg.norm(Q - P, axis=1)
    return float((seg_len * (1 - inside.mean(1))).sum())


def vein_stats(graph: VeinGraph, shape: LeafShape, main_targets=None, auto=True) -> dict:
    stats: dict = {"counts": {}, "lengths_m": {}, "segments": {}}
    for o, name in enumerate(ORDER_NAMES):
        vs = graph.of_order(o)
        stats["counts"][name] = len(vs)
        stats["lengths_m"][name] = round(sum(v.length for v in vs), 6)
        stats["segments"][name] = int(sum(max(len(v.points) - 1, 0) for v in vs))
    stats["crossings"] = count_crossings(graph)
    stats["outside_length"] = round(outside_length(graph, shape.contour, shape.holes), 9)
    mains = graph.of_order(MAIN)
    stats["main_target_error_m"] = round(max((float(np.linalg.norm(v.points[-1] - v.target)) for v in mains), default=0.0), 9)
    stats["main_last_step_m"] = round(max((float(np.linalg.norm(v.points[-1] - v.points[-2])) for v in mains if len(v.points) > 1), default=0.0), 9)
    stats["targets"] = "auto" if auto else "config"
    stats["main_targets"] = [[round(float(x), 6) for x in t] for t in (main_targets or [])]
    return stats

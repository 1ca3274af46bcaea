"""The mechanics of vein growth [Kim 2017; thesis Alg. 1–2]: a :class:`Grower` that steps a
vein toward its target with collision tests against every accepted vein segment and the
margin, and the small geometric helpers the growth stages share.

Every random draw goes through the grower's ``rng``, in a fixed order, so a seed gives one
venation.
"""

from __future__ import annotations

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import LeafShape, outline_edges, segment_hits
from leafsim.config.params import ParamSet


def unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def rot(v: np.ndarray, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


class Grower:
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
        prev = unit(target - p) if initial_dir is None else unit(initial_dir)
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
            d = unit(v_gr + prev)
            d = rot(d, omega + self.rng.uniform(-kappa, kappa))
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


def inside_point(shape: LeafShape, tip: np.ndarray, toward: np.ndarray, offset: float) -> np.ndarray:
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


def palmate_root(shape: LeafShape, g: "Grower", d_target: np.ndarray, d_apex: np.ndarray, dist: float):
    """First point of a palmate main vein: half a step from the base into the blade, turned
    from the target direction toward the midrib until it is inside (bases often sit in a notch)."""
    for w in np.linspace(0.0, 0.9, 10):
        d = unit((1 - w) * d_target + w * d_apex)
        q = shape.base + d * dist
        if shape.inside(q[None])[0] and not len(segment_hits(shape.base + 1e-9 * d, q, g.CP, g.CQ)) \
                and not len(segment_hits(shape.base, q, g.P, g.Q)):
            return q
    return None


def taper_widths(points: np.ndarray, w0: float, taper: float, thin_from: float | None = None) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    f = s / s[-1] if s[-1] > 0 else np.zeros_like(s)
    w = w0 * (1.0 - taper * f)
    if thin_from is not None:
        w = np.where(f > thin_from, w * 0.5, w)
    return w


def arc_fraction(points: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / s[-1] if s[-1] > 0 else s

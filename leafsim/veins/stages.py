"""The stages of vein growth, in the order :func:`leafsim.veins.grow.grow_veins` runs them:
main-vein targets → main veins → laterals → sublaterals → tertiary net [Kim 2017; thesis
§3.2–3.5].  Each stage appends its veins to the :class:`~leafsim.veins.graph.VeinGraph` and
its segments to the :class:`~leafsim.veins.grower.Grower`'s obstacles; each reads the random
generator in a fixed order, so the same seed gives the same leaf.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from leafsim.base.geometry import LeafShape, ray_polygon_hit
from leafsim.config.params import ParamSet
from leafsim.veins.graph import LATERAL, MAIN, NET, SUB, Vein, VeinGraph
from leafsim.veins.grower import Grower, arc_fraction, inside_point, palmate_root, rot, taper_widths, unit
from leafsim.veins.lobes import detect_lobe_tips
from leafsim.veins.stats import _proper

#: main-vein targets sit this far (× L) inside the margin
TARGET_INSET = 0.035


def main_targets(shape: LeafShape, p: ParamSet, targets: np.ndarray | None, main_origin: str):
    """(apex target (2,), other main-vein targets [(2,)], automatic?): the config's targets
    (the one nearest the apex leads), or the apex plus the detected lobe tips."""
    L = shape.length
    apex_t = inside_point(shape, shape.apex, np.zeros(2), TARGET_INSET * L)
    if targets is not None:
        t_arr = np.asarray(targets, float)
        i_apex = int(np.argmin(np.linalg.norm(t_arr - shape.apex, axis=1)))
        return t_arr[i_apex], [t for i, t in enumerate(t_arr) if i != i_apex], False
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
    return apex_t, others[: max(0, p["veins.main.max_auto"] - 1)], True


def _midrib_branch(p: ParamSet, mid: np.ndarray, mid_frac: np.ndarray, t: np.ndarray, thr: float) -> int:
    """Index of the midrib point where a pinnate lobe's main vein leaves at the lateral angle."""
    ang = p["veins.lateral.angle"]
    best, best_err = 1, np.inf
    for i in range(1, len(mid) - 1):
        if mid_frac[i] > 1 - thr:
            break
        fwd = unit(mid[min(i + 1, len(mid) - 1)] - mid[i - 1])
        a = np.degrees(np.arccos(np.clip(np.dot(fwd, unit(t - mid[i])), -1, 1)))
        if abs(a - ang) < best_err:
            best, best_err = i, abs(a - ang)
    return best


def grow_main_veins(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, apex_t: np.ndarray, others,
                    main_origin: str, taper: float) -> list[np.ndarray]:
    """The midrib to the apex target, then one main vein per other target (from the base, or
    from the midrib for ``main_origin == "midrib"``); a lobe vein that cannot reach its
    target without crossing is skipped.  Returns the targets reached (the apex's first)."""
    L = shape.length
    inset = TARGET_INSET * L
    step_m = p["veins.main.step"] * L
    jit = p["veins.main.scale_jitter"]
    kappa, omega = p["veins.main.kappa"], p["veins.main.omega"]
    w_main = p["veins.main.width"] * L
    thr = p["veins.main.threshold"]
    # main veins leave the petiole junction straight into the blade for half a step, so that
    # no vein can slip out through the margin next to the base
    root = shape.base + unit(apex_t - shape.base) * 0.5 * step_m
    mid = g.grow_main(root, apex_t, step_m, kappa, omega, jit)
    mid = np.vstack([shape.base[None].astype(float), mid])
    g.add(mid)
    graph.veins.append(Vein(MAIN, mid, taper_widths(mid, w_main, taper, 1 - thr), -1, apex_t))
    mid_frac = arc_fraction(mid)
    reached = [apex_t]
    for t in others:
        if main_origin == "midrib":
            best = _midrib_branch(p, mid, mid_frac, t, thr)
            start = mid[best]
            tgt = inside_point(shape, t, start, inset)
            parent = 0
            w0 = np.interp(mid_frac[best], mid_frac, graph.veins[0].widths) * 0.7
        else:
            tgt = inside_point(shape, t, np.zeros(2), inset)
            start = palmate_root(shape, g, unit(tgt - shape.base), unit(apex_t - shape.base), 0.5 * step_m)
            if start is None:
                continue
            parent = -1
            w0 = w_main * 0.75
        pts = g.grow_main(start, tgt, step_m, kappa, np.sign(t[0]) * abs(omega) * 0.5, jit)
        if main_origin != "midrib":
            pts = np.vstack([shape.base[None].astype(float), pts])
        if g.first_hit(pts[0], pts[1]) is not None or any(g.first_hit(a, b) is not None for a, b in zip(pts[:-1], pts[1:])):
            continue  # could not reach without crossing: skip this lobe vein rather than cross
        g.add(pts)
        graph.veins.append(Vein(MAIN, pts, taper_widths(pts, w0, taper, 1 - thr), parent, tgt))
        reached.append(tgt)
    return reached


def _inside_prefix(shape: LeafShape, pts: np.ndarray) -> np.ndarray:
    """The polyline up to its first point outside the outline (or in a hole)."""
    from leafsim.base.geometry import points_in_region

    inside = points_in_region(pts, shape.contour, shape.holes)
    inside[0] = True
    k = int(np.argmin(inside)) if not inside.all() else len(pts)
    return pts[:k]


def _segment_inside(shape: LeafShape, a: np.ndarray, b: np.ndarray, n: int = 16) -> bool:
    """Whether the straight segment a → b stays inside the outline (and out of the holes),
    sampled at ``n`` points."""
    from leafsim.base.geometry import points_in_region

    t = np.linspace(0.0, 1.0, n)[:, None]
    return bool(points_in_region(a + t * (b - a), shape.contour, shape.holes).all())


def _until_crossing(g: Grower, pts: np.ndarray) -> np.ndarray:
    """The polyline up to just before it first crosses a vein already in ``g`` (a traced vein
    smoothed near a junction may clip its neighbour; veins never cross)."""
    for i in range(len(pts) - 1):
        t = g.first_hit(pts[i], pts[i + 1], skip_contour=True)
        if t is not None:
            end = pts[i] + (pts[i + 1] - pts[i]) * 0.8 * t
            return np.vstack([pts[: i + 1], end[None]]) if i > 0 or t > 0.1 else pts[: i + 1]
    return pts


def _branch_off_shared_trunk(graph: VeinGraph, pts: np.ndarray, parent: int, tol: float) -> tuple[np.ndarray, int]:
    """A traced main vein that first runs along an earlier one (a grapevine's basal veins leave
    the lower main veins, not the petiole) starts where it leaves it, as its branch."""
    best = None
    half = len(pts) // 2
    for vi, v in enumerate(graph.veins):
        d = np.min(np.linalg.norm(pts[1:half, None, :] - v.points[None, :, :], axis=2), axis=1) if half > 1 else np.zeros(0)
        near = np.flatnonzero(d < tol)
        if len(near) and (best is None or near[-1] > best[0]):
            best = (int(near[-1]) + 1, vi)
    if best is None:
        return pts, parent
    j, vi = best
    trunk = graph.veins[vi].points
    k = int(np.argmin(np.linalg.norm(trunk - pts[j], axis=1)))
    return np.vstack([trunk[k][None], pts[j + 1:]]), vi


def given_main_veins(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, mains, main_origin: str,
                     taper: float) -> list[np.ndarray]:
    """The main veins traced from the photo (the midrib first), in place of grown ones: a palmate
    leaf's start at the base, a pinnate lobe's on the midrib; each is cut where it would leave
    the outline.  Returns their ends (the targets "reached") and, per traced main vein, its
    index in ``graph.veins`` (-1 for one left out: too short inside the outline)."""
    w_main = p["veins.main.width"] * shape.length
    thr = p["veins.main.threshold"]
    reached, index = [], [-1] * len(mains)
    for i, pts in enumerate(mains):
        pts = _inside_prefix(shape, np.asarray(pts, float))
        if len(pts) < 3:
            continue
        if i == 0 or main_origin == "base":
            # from the base straight to where the vein is 4 % L away from it: veins leaving one
            # junction never cross there (the traced paths may braid within a few pixels)
            far = np.flatnonzero(np.linalg.norm(pts - shape.base, axis=1) > 0.04 * shape.length)
            if not len(far):
                continue
            pts = np.vstack([shape.base[None].astype(float), pts[far[0]:]])
            parent, w0 = -1, (w_main if i == 0 else 0.75 * w_main)
            pts, parent = _branch_off_shared_trunk(graph, pts, parent, 0.012 * shape.length)
        else:
            mid = graph.veins[0].points
            j = int(np.argmin(np.linalg.norm(mid - pts[0], axis=1)))
            pts = np.vstack([mid[j][None], pts[1:]])
            parent, w0 = 0, 0.7 * float(np.interp(j / max(len(mid) - 1, 1), np.linspace(0, 1, len(mid)), graph.veins[0].widths))
        pts = _until_crossing(g, pts)
        if len(pts) < 3:
            continue
        g.add(pts)
        index[i] = len(graph.veins)
        graph.veins.append(Vein(MAIN, pts, taper_widths(pts, w0, taper, 1 - thr), parent, pts[-1].copy()))
        reached.append(pts[-1].copy())
    return reached, index


def _join_index(main: np.ndarray, pts: np.ndarray, L: float) -> int:
    """Where on its main vein a traced lateral joins: the main vein's point most in line with the
    lateral's first 2 % L, among those within 2.5 × the nearest one's distance of its start (the
    traced path starts beside the main vein's own ridge; joining it at the nearest point would
    add a peg at right angles)."""
    d = np.linalg.norm(main - pts[0], axis=1)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    ahead = pts[min(int(np.searchsorted(s, 0.02 * L)), len(pts) - 1)] - pts[0]
    near = np.flatnonzero(d <= 2.5 * max(float(d.min()), 1e-12))
    if np.linalg.norm(ahead) == 0 or len(near) < 2:
        return int(np.argmin(d))
    back = pts[0] - main[near]
    cos = back @ ahead / (np.linalg.norm(back, axis=1) * np.linalg.norm(ahead) + 1e-300)
    return int(near[np.argmax(cos)])


def given_laterals(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, laterals, parents, taper: float,
                   index=None) -> None:
    """The laterals traced from the photo, each joining its main vein in line with its start
    (:func:`_join_index`).  ``index``: the graph index of each traced main vein
    (:func:`given_main_veins`; default the same index); a lateral whose main vein was left out
    joins the nearest main vein."""
    n_main = len(graph.veins)
    index = list(range(n_main)) if index is None else list(index)
    for pts, parent in zip(laterals, parents):
        pts = np.asarray(pts, float)
        if not 0 <= parent < len(index):
            continue
        parent = index[parent]
        if not 0 <= parent < n_main:
            parent = int(np.argmin([np.linalg.norm(v.points - pts[0], axis=1).min() for v in graph.veins[:n_main]]))
        mv = graph.veins[parent]
        j = _join_index(mv.points, pts, shape.length)
        if not _segment_inside(shape, mv.points[j], pts[0]):
            # in line it would cut across the margin (beside the base, where the outline is
            # concave): join at the nearest point instead
            j = int(np.argmin(np.linalg.norm(mv.points - pts[0], axis=1)))
        pts = _until_crossing(g, _inside_prefix(shape, np.vstack([mv.points[j][None], pts])))
        if len(pts) < 3:
            continue
        w0 = float(mv.widths[j]) * p["veins.lateral.width"]
        g.add(pts)
        graph.veins.append(Vein(LATERAL, pts, taper_widths(pts, w0, taper), parent, pts[-1].copy()))


def _lateral_sides(mode: str, counter: int) -> tuple:
    if mode == "opposite":
        return (1, -1)
    if mode == "left":
        return (1,)
    if mode == "right":
        return (-1,)
    return (1 if counter % 2 == 0 else -1,)


def grow_laterals(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, rng: np.random.Generator,
                  profile: np.ndarray, taper: float) -> None:
    """Laterals from every ``veins.lateral.spacing``-th candidate segment of each main vein:
    target at the lateral angle, length from the species' profile × the ray to the margin; a
    lateral whose start–target line crosses an accepted one is skipped (thesis §3.3)."""
    L = shape.length
    lat_lines: list[tuple[np.ndarray, np.ndarray]] = []
    spacing = p["veins.lateral.spacing"]
    mode = p["veins.lateral.alternation"]
    lstep = p["veins.lateral.step"] * L
    lk = p["veins.lateral.kappa"]
    jit = p["veins.main.scale_jitter"]
    thr = p["veins.main.threshold"]
    counter = 0
    for mi in range(len(graph.veins)):
        mv = graph.veins[mi]
        pts = mv.points
        frac = arc_fraction(pts)
        cand = [i for i in range(1, len(pts) - 1) if frac[i] <= 1 - thr]
        for i in cand[spacing - 1 :: spacing] if spacing > 1 else cand:
            fwd = unit(pts[i + 1] - pts[i - 1])
            sides = _lateral_sides(mode, counter)
            counter += 1
            for side in sides:
                ang = p["veins.lateral.angle"] + rng.uniform(-1, 1) * p["veins.lateral.angle_jitter"]
                d = rot(fwd, side * ang)
                hit = ray_polygon_hit(pts[i], d, shape.contour, shape.holes)
                if hit is None:
                    continue
                length = hit * p["veins.lateral.reach"] * float(np.interp(frac[i] * 100, profile[:, 0], profile[:, 1]))
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
                d0 = rot(fwd, side * min(ang + 25.0, 88.0)) if p["veins.lateral.curve_apical"] else None
                lv, _ = g.grow(pts[i], tgt, lstep, lk, 0.0, jit, True, d0)
                if len(lv) < 3:
                    continue
                g.add(lv)
                lat_lines.append((pts[i], tgt))
                w0 = float(mv.widths[i]) * p["veins.lateral.width"]
                graph.veins.append(Vein(LATERAL, lv, taper_widths(lv, w0, taper), mi, tgt))


def _bezier_toward(g: Grower, a: np.ndarray, b: np.ndarray, d: np.ndarray, bend: float, step: float,
                   rng: np.random.Generator) -> np.ndarray | None:
    """A quadratic Bézier a → b through a control point pushed sideways by up to ``bend`` ×
    the chord, cut at its first blocked segment; None when fewer than 3 points remain."""
    chord = np.linalg.norm(b - a)
    perp = np.array([-d[1], d[0]])
    c = (a + b) / 2 + perp * rng.uniform(-1, 1) * bend * chord
    n = max(3, int(np.ceil(chord / step)) + 1)
    t = np.linspace(0, 1, n)[:, None]
    curve = (1 - t) ** 2 * a + 2 * (1 - t) * t * c + t**2 * b
    keep = [curve[0]]
    for q0, q1 in zip(curve[:-1], curve[1:]):
        if g.blocked(q0, q1):
            break
        keep.append(q1)
    return np.array(keep) if len(keep) >= 3 else None


def grow_sublaterals(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, rng: np.random.Generator,
                     taper: float) -> None:
    """Sublaterals at the ``veins.sub.divisions`` division points of each lateral, alternating
    sides, aimed at the margin along a ray and grown as quadratic Bézier curves (Kim)."""
    ndiv = p["veins.sub.divisions"]
    sstep = p["veins.lateral.step"] * shape.length * 0.8
    for li in [k for k, v in enumerate(graph.veins) if v.order == LATERAL]:
        lv = graph.veins[li]
        frac = arc_fraction(lv.points)
        for k in range(1, ndiv):
            i = int(np.argmin(np.abs(frac - k / ndiv)))
            if i <= 0 or i >= len(lv.points) - 1:
                continue
            fwd = unit(lv.points[i + 1] - lv.points[i - 1])
            side = 1 if (k + li) % 2 == 0 else -1
            d = rot(fwd, side * p["veins.sub.angle"])
            hit = ray_polygon_hit(lv.points[i], d, shape.contour, shape.holes)
            if hit is None:
                continue
            a = lv.points[i]
            b = a + d * hit * p["veins.sub.reach"]
            if np.linalg.norm(b - a) < 2 * sstep:
                continue
            sv = _bezier_toward(g, a, b, d, p["veins.sub.bend"], sstep, rng)
            if sv is None:
                continue
            g.add(sv)
            w0 = float(np.interp(frac[i], frac, lv.widths)) * p["veins.sub.width"]
            graph.veins.append(Vein(SUB, sv, taper_widths(sv, w0, taper), li, b))


#: the most sublaterals :func:`fill_gaps` adds to one leaf
MAX_FILL = 40


def fill_gaps(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, rng: np.random.Generator,
              taper: float) -> int:
    """Sublaterals into the parts of the blade farther than ``veins.sub.gap`` × length from
    every vein: a real blade has veins everywhere, and its water and mass (Jeong's τ), drying
    and colour follow them.  The farthest point of the blade (sampled every 1 % of the length)
    gets one from the nearest vein point that sees it, aimed through it and on toward the margin
    to ``veins.sub.reach`` of the ray but at most twice as far as the point, bent as the other
    sublaterals (so it passes within a quarter of its distance of the point); repeated until no
    point is that far, :data:`MAX_FILL` were added, or the rest cannot be reached without
    crossing a vein (a point that cannot is given up with its neighbourhood).  Returns how many
    were added (``graph.stats["gap_fills"]``)."""
    gap = p["veins.sub.gap"] * shape.length
    if gap <= 0 or not graph.veins:
        return 0
    h = 0.01 * shape.length
    lo, hi = shape.contour.min(0), shape.contour.max(0)
    gx, gy = np.meshgrid(np.arange(lo[0] + h / 2, hi[0], h), np.arange(lo[1] + h / 2, hi[1], h))
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    pts = pts[shape.inside(pts)]
    sstep = p["veins.lateral.step"] * shape.length * 0.8
    added = 0
    while added < MAX_FILL and len(pts):
        allp = np.vstack([v.points for v in graph.veins])
        alli = np.concatenate([np.full(len(v.points), vi) for vi, v in enumerate(graph.veins)])
        allw = np.concatenate([v.widths for v in graph.veins])
        tree = cKDTree(allp)
        d, _ = tree.query(pts)
        k = int(np.argmax(d))
        if d[k] <= gap:
            break
        q = pts[k]
        # from the nearest vein point that sees it (vein points are a step apart: the nearest
        # one can lie behind another vein's segment)
        near = tree.query(q, k=min(8, len(allp)))[1]
        seen = [i for i in np.atleast_1d(near) if not g.blocked(allp[i], q)]
        if not seen:
            pts = pts[np.linalg.norm(pts - q, axis=1) > gap]
            continue
        a, src = allp[seen[0]], seen[0]
        direction = unit(q - a)
        # the margin ahead, seen from the gap's point (the nearest vein point may be a vein's
        # end at the margin itself)
        hit = ray_polygon_hit(q, direction, shape.contour, shape.holes)
        sv = None
        if hit is not None:
            # through the gap, on toward the margin but not beyond twice its distance (a vein
            # may end in the blade)
            dq = float(np.linalg.norm(q - a))
            reach = min((dq + hit) * p["veins.sub.reach"], 2.0 * dq)
            if reach >= 2 * sstep:
                sv = _bezier_toward(g, a, a + direction * reach, direction, p["veins.sub.bend"], sstep, rng)
        if sv is None or np.linalg.norm(sv[-1] - a) < 0.5 * np.linalg.norm(q - a):
            pts = pts[np.linalg.norm(pts - q, axis=1) > gap]  # unreachable from here: give it up
            continue
        g.add(sv)
        # a sublateral's width: × veins.sub.width of its vein's there, and where it leaves a
        # main vein also × veins.lateral.width (never as wide as a lateral from there)
        parent = int(alli[src])
        w0 = float(allw[src]) * p["veins.sub.width"] * (p["veins.lateral.width"] if graph.veins[parent].order == MAIN else 1.0)
        graph.veins.append(Vein(SUB, sv, taper_widths(sv, w0, taper), parent, sv[-1]))
        added += 1
    return added


def grow_net(g: Grower, graph: VeinGraph, shape: LeafShape, p: ParamSet, rng: np.random.Generator,
             taper: float) -> None:
    """Tertiary net (Kim's "hair" veins): jittered grid points inside the blade, each joined to
    the nearest vein point between 0.5 and 2.5 grid spacings away when nothing blocks it."""
    sp = p["veins.net.spacing"] * shape.length
    lo, hi = shape.contour.min(0), shape.contour.max(0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], sp), np.arange(lo[1], hi[1], sp))
    pts = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(-0.35, 0.35, (gx.size, 2)) * sp
    pts = pts[shape.inside(pts)]
    allp = np.vstack([v.points for v in graph.veins])
    alli = np.concatenate([np.full(len(v.points), vi) for vi, v in enumerate(graph.veins)])
    allw = np.concatenate([v.widths for v in graph.veins])
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
        graph.veins.append(Vein(NET, nv, taper_widths(nv, float(allw[j]) * p["veins.net.width"], taper), int(alli[j]), q))

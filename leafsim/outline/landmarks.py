"""Landmarks of a traced leaf: the petiole and its junction with the blade (the base), the apex,
lobe tips and sinuses, from the outline's shape and its mirror symmetry."""

from __future__ import annotations

import cv2
import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.outline.image import _DEBUG, _disk, _fill_holes, _largest_component


def _hull_pockets(P: np.ndarray, closed: bool = True):
    """Concave pockets of polygon P: (i, j, f, depth) — hull edge P[i]→P[j] (indices in P's
    order, j may exceed len(P) when it wraps), deepest chain point f, its depth.

    With ``closed=False`` the edge from the last back to the first point is an artificial
    closing chord: pockets spanning it are skipped.
    """
    m = len(P)
    if m < 4:
        return []
    hull = cv2.convexHull(P.astype(np.float32), returnPoints=False)
    if hull is None or len(hull) < 3:
        return []
    h = np.sort(hull.ravel().astype(int))
    out = []
    for k in range(len(h)):
        i = int(h[k])
        j = int(h[k + 1]) if k + 1 < len(h) else int(h[0]) + m
        if j - i < 2:
            continue
        if not closed and j >= m:
            continue
        chain = np.arange(i + 1, j) % m
        a, b = P[i], P[j % m]
        ab = b - a
        L = float(np.hypot(*ab))
        if L < 1e-9:
            dep = np.linalg.norm(P[chain] - a, axis=1)
        else:
            dep = np.abs((P[chain, 0] - a[0]) * ab[1] - (P[chain, 1] - a[1]) * ab[0]) / L
        q = int(np.argmax(dep))
        out.append((i, j, int(chain[q]), float(dep[q])))
    return out


def _sinuses(P: np.ndarray, thr: float) -> list[int]:
    """Indices of sinus bottoms deeper than ``thr`` (recursively, so a lobe hidden below the
    hull of its neighbours still separates its sinuses)."""
    found: list[int] = []

    def rec(idx: np.ndarray, closed: bool, depth_left: int):
        if depth_left <= 0 or len(idx) < 5:
            return
        for i, j, f, d in _hull_pockets(P[idx], closed):
            if d < thr:
                continue
            m = len(idx)
            found.append(int(idx[f]))
            # sub-polygons hull-vertex → sinus and sinus → hull-vertex (in contour order)
            left = idx[np.arange(i, f + (m if f < i else 0) + 1) % m]
            right = idx[np.arange(f, j + (m if j < f else 0) + 1) % m]
            rec(left, False, depth_left - 1)
            rec(right, False, depth_left - 1)

    rec(np.arange(len(P)), True, 6)
    return sorted(set(found))


def _reflect_iou(small: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """IoU of a mask with its mirror image about the line through a and b."""
    d = b - a
    n = float(np.hypot(*d))
    if n < 1e-9:
        return 0.0
    u = d / n
    R = 2.0 * np.outer(u, u) - np.eye(2)
    t = a - R @ a
    M = np.hstack([R, t[:, None]]).astype(np.float32)
    ref = cv2.warpAffine(small, M, (small.shape[1], small.shape[0]), flags=cv2.INTER_NEAREST)
    inter = np.count_nonzero(ref & small)
    union = np.count_nonzero(ref | small)
    return inter / union if union else 0.0


def _width_across(P: np.ndarray, b: np.ndarray, a: np.ndarray, frac: float) -> float:
    """Width of the polygon across the b→a axis at ``frac`` of the way from b."""
    d = a - b
    L = float(np.hypot(*d))
    u = d / L
    v = np.array([-u[1], u[0]])
    s = (P - b) @ u
    t = (P - b) @ v
    target = frac * L
    Q = np.roll(np.arange(len(P)), -1)
    cross = (s - target) * (s[Q] - target) <= 0
    if not cross.any():
        return 0.0
    i = np.nonzero(cross)[0]
    j = Q[i]
    ds = s[j] - s[i]
    w = np.where(np.abs(ds) > 1e-12, (target - s[i]) / np.where(np.abs(ds) > 1e-12, ds, 1), 0.0)
    tt = t[i] + w * (t[j] - t[i])
    return float(tt.max() - tt.min())


def _petiole_candidates(sm: np.ndarray, sscale: float):
    """Thin protrusions of a leaf mask (scaled to a leaf size ``sscale`` ≈ 320 px) that an
    opening with a disk of ≈ 6 % of the leaf size removes: attached to the opened blade,
    sticking out at least one disk diameter, ≥ 2.5× longer than wide.

    Returns (labels of the removed pieces, [(score, label, tip_xy, width, bbox), ...]).
    """
    d = int(np.clip(0.06 * sscale, 7, 301))
    blade = _largest_component(cv2.morphologyEx(sm, cv2.MORPH_OPEN, _disk(d)))
    removed = cv2.bitwise_and(sm, cv2.bitwise_not(blade))
    if not blade.any() or not removed.any():
        return None, []
    dist_out = cv2.distanceTransform(cv2.bitwise_not(blade), cv2.DIST_L2, 5)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(removed, connectivity=8)
    found = []
    half = 0.5 * d
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] < 6:
            continue
        x0, y0 = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        x1, y1 = x0 + stats[k, cv2.CC_STAT_WIDTH], y0 + stats[k, cv2.CC_STAT_HEIGHT]
        sub = lab[y0:y1, x0:x1] == k
        ys, xs = np.nonzero(sub)
        ys = ys + y0
        xs = xs + x0
        dv = dist_out[ys, xs]
        if dv.min() > 2.0:  # not attached to the blade
            continue
        prot = float(dv.max())
        if prot < max(0.05 * sscale, d):
            continue
        far = dv > half
        piece_k = np.where(sub, 255, 0).astype(np.uint8)
        inner = cv2.distanceTransform(np.pad(piece_k, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
        width = max(2.0 * float(inner[ys[far] - y0, xs[far] - x0].max()), 1.0)
        elong = prot / width
        if _DEBUG:
            print("petiole candidate", k, "prot", round(prot, 1), "width", round(width, 1), "elong", round(elong, 2))
        if elong < 2.5:
            continue
        q = int(np.argmax(dv))
        found.append((prot * min(elong, 10.0), k, (xs[q], ys[q]), width, (x0, y0, x1, y1)))
    return lab, found


def _find_petiole(mask: np.ndarray, scale: float, where: str = "image"):
    """Detect the petiole as the longest thin protrusion that an opening removes.

    Candidates come from :func:`_petiole_candidates` on a copy of the mask scaled to a leaf
    size of ~320 px (so detection does not depend on the photo's resolution); the
    longest/thinnest wins.  Two strong candidates (the second scoring ≥ 30 % of the first) are
    two petioles: overlapping leaves, refused with a LeafsimError.  The winner is then cut at
    full resolution with a finer opening just wider than the petiole.

    Returns (blade_mask, junction_xy, tip_xy, width_px) or None.
    """
    H, W = mask.shape
    f = min(1.0, 320.0 / max(scale, 1.0))
    sm = mask if f >= 1.0 else np.where(
        cv2.resize(mask, (max(1, round(W * f)), max(1, round(H * f))), interpolation=cv2.INTER_AREA) >= 128, 255, 0
    ).astype(np.uint8)
    lab, cands = _petiole_candidates(sm, scale * f)
    if not cands:
        return None
    cands.sort(key=lambda c: -c[0])
    best = cands[0]
    strong = [c for c in cands if c[0] >= 0.3 * best[0]]
    if len(strong) > 1:
        h, w = sm.shape
        at = " and ".join(f"({100 * c[2][0] / w:.0f} %, {100 * c[2][1] / h:.0f} %)" for c in strong[:3])
        raise LeafsimError(f"{where}: found {len(strong)} petioles, tips at {at} of the image width, height: "
                           "overlapping leaves? (expected one leaf per photo)")
    _, k, (tx, ty), width, (x0, y0, x1, y1) = best
    tip = (np.array([tx, ty], float) + 0.5) / f - 0.5
    width_full = width / f
    # --- precise cut at full resolution, inside a window around the piece
    fine_d = int(max(3, round(1.6 * width_full + 3)))
    pad = 2 * fine_d + 4
    X0, Y0 = max(0, int(x0 / f) - pad), max(0, int(y0 / f) - pad)
    X1, Y1 = min(W, int(np.ceil(x1 / f)) + pad), min(H, int(np.ceil(y1 / f)) + pad)
    roi = mask[Y0:Y1, X0:X1]
    piece_small = np.where(lab == k, 255, 0).astype(np.uint8)
    piece_up = cv2.resize(piece_small, (W, H), interpolation=cv2.INTER_NEAREST)[Y0:Y1, X0:X1] if f < 1.0 else piece_small[Y0:Y1, X0:X1]
    piece_up = cv2.dilate(piece_up, _disk(max(3, int(2 / f) | 1)))
    fine_removed = cv2.bitwise_and(cv2.bitwise_and(roi, cv2.bitwise_not(cv2.morphologyEx(roi, cv2.MORPH_OPEN, _disk(fine_d)))), piece_up)
    m2, lab2, st2, _ = cv2.connectedComponentsWithStats(fine_removed, connectivity=8)
    cut_roi = None
    if m2 > 1:
        # the removed piece nearest the detected tip
        yy, xx = np.nonzero(lab2)
        dd = (xx + X0 - tip[0]) ** 2 + (yy + Y0 - tip[1]) ** 2
        tk = lab2[yy[int(np.argmin(dd))], xx[int(np.argmin(dd))]]
        cut_roi = np.where(lab2 == tk, 255, 0).astype(np.uint8)
    if cut_roi is None:
        cut_roi = cv2.bitwise_and(piece_up, roi)
    cut = np.zeros_like(mask)
    cut[Y0:Y1, X0:X1] = cut_roi
    blade_mask = _fill_holes(_largest_component(cv2.bitwise_and(mask, cv2.bitwise_not(cut))))
    # junction: where the cut petiole touches the blade; tip: cut pixel farthest from it
    touch = cv2.bitwise_and(cv2.dilate(cut_roi, _disk(3)), blade_mask[Y0:Y1, X0:X1])
    ys, xs = np.nonzero(touch)
    if not len(xs):
        return None
    junction = np.array([xs.mean() + X0, ys.mean() + Y0])
    ys, xs = np.nonzero(cut_roi)
    dd = (xs + X0 - junction[0]) ** 2 + (ys + Y0 - junction[1]) ** 2
    q = int(np.argmax(dd))
    tip = np.array([xs[q] + X0, ys[q] + Y0], float)
    return blade_mask, junction, tip, float(width_full)


def _base_from_shape(P: np.ndarray, mask: np.ndarray, L: float) -> np.ndarray:
    """Base of a leaf without a visible petiole.

    A leaf is mirror-symmetric about its base→apex axis, and the apex is the contour point
    farthest from the base.  Candidate bases (points spread along the contour and the bottoms
    of hull concavities) are scored by how symmetric the mask is about the axis to their
    farthest point; the best are refined locally.  Of the axis' two ends, the base is the one
    sitting deeper in a notch (petiolar sinus) or, failing that, the blunter one.
    """
    m = len(P)
    sc_f = min(1.0, 160.0 / max(mask.shape))
    small = cv2.resize(mask, None, fx=sc_f, fy=sc_f, interpolation=cv2.INTER_AREA)
    small = np.where(small >= 128, 255, 0).astype(np.uint8)
    to_small = lambda q: (q + 0.5) * sc_f - 0.5  # noqa: E731
    hull_pts = cv2.convexHull(P.astype(np.float32))
    cache: dict[int, float] = {}

    def score(i: int) -> float:
        if i not in cache:
            b = P[i]
            dist = np.linalg.norm(P - b, axis=1)
            a = P[int(np.argmax(dist))]
            dep = max(0.0, cv2.pointPolygonTest(hull_pts, (float(b[0]), float(b[1])), True))
            cache[i] = _reflect_iou(small, to_small(b), to_small(a)) + 0.5 * min(dep / L, 0.3)
        return cache[i]

    cand = set(np.linspace(0, m, 72, endpoint=False).astype(int).tolist())
    for _, _, f, d in _hull_pockets(P, True):
        if d >= 0.01 * L:
            cand.add(int(f))
    ranked = sorted(cand, key=score, reverse=True)
    best = ranked[0]
    seeds: list[int] = []
    for i in ranked:
        if all(min(abs(i - j), m - abs(i - j)) > m // 20 for j in seeds):
            seeds.append(i)
        if len(seeds) == 3:
            break
    win = max(2, m // 30)
    for s0 in seeds:
        cur = s0
        for step in (max(1, win // 4), 1):
            improved = True
            while improved:
                improved = False
                for j in (cur - step, cur + step):
                    j %= m
                    if score(j) > score(cur):
                        cur, improved = j, True
        if score(cur) > score(best):
            best = cur
    b = P[best]
    a = P[int(np.argmax(np.linalg.norm(P - b, axis=1)))]

    def end_score(x: np.ndarray, y: np.ndarray) -> float:
        dep = max(0.0, cv2.pointPolygonTest(hull_pts, (float(x[0]), float(x[1])), True))
        Lxy = float(np.linalg.norm(y - x))
        return 2.0 * min(dep / L, 0.3) + _width_across(P, x, y, 0.1) / max(Lxy, 1e-9)

    if end_score(a, b) > end_score(b, a):
        b = a
    return b.copy()


def _lobe_tips(P: np.ndarray, base: np.ndarray, apex: np.ndarray, thr: float) -> np.ndarray:
    """Lobe tips (the apex included).

    The contour is cut at the sinuses deeper than ``thr`` and at the base; each stretch that
    protrudes at least ``thr`` beyond the chord between its two ends is a lobe, its tip the
    point farthest from the base — a contour extremum — or, when that is an end of the
    stretch (a lobe pointing back toward the base), its point farthest from the chord; the
    stretch holding the apex has the apex as its tip.
    """
    m = len(P)
    ib = int(np.argmin(np.linalg.norm(P - base, axis=1)))
    ia = int(np.argmin(np.linalg.norm(P - apex, axis=1)))
    bounds = sorted(set(_sinuses(P, thr)) | {ib})
    # merge boundaries closer than 2 % of the contour (keep the base)
    gap = max(2, int(0.02 * m))
    merged: list[int] = []
    for b in bounds:
        if merged and b - merged[-1] < gap:
            if b == ib:
                merged[-1] = b
            continue
        merged.append(b)
    if len(merged) > 1 and merged[0] + m - merged[-1] < gap:
        if merged[0] == ib:
            merged.pop()
        else:
            merged.pop(0)
    tips = []
    edge = max(1, int(0.005 * m))
    for k, b0 in enumerate(merged):
        b1 = merged[k + 1] if k + 1 < len(merged) else merged[0] + m
        if b1 - b0 < 3:
            continue
        idx = np.arange(b0, b1 + 1) % m
        a, c = P[idx[0]], P[idx[-1]]
        ac = c - a
        La = float(np.hypot(*ac))
        if La < 1e-9:
            off = np.linalg.norm(P[idx] - a, axis=1)
        else:
            off = np.abs((P[idx, 0] - a[0]) * ac[1] - (P[idx, 1] - a[1]) * ac[0]) / La
        if float(off.max()) < thr:
            continue
        hit = np.nonzero(idx == ia)[0]
        if len(hit) and edge <= hit[0] <= len(idx) - 1 - edge:
            tips.append(apex)
            continue
        q = int(np.argmax(np.linalg.norm(P[idx] - base, axis=1)))
        if not edge <= q <= len(idx) - 1 - edge:
            q = int(np.argmax(off))  # a lobe pointing back toward the base: its most protruding point
        if edge <= q <= len(idx) - 1 - edge:
            tips.append(P[idx[q]])
    return np.array(tips, float).reshape(-1, 2)


#: below this score (:func:`vein_direction`), the veins say the apex lies at the other end
VEINS_AGAINST = -0.1
#: :func:`vein_direction` looks at the leaf at most this many pixels long
VEIN_PX = 800.0


def vein_direction(img: np.ndarray, mask: np.ndarray, base: np.ndarray, apex: np.ndarray) -> float:
    """How much the photo's veins say the apex lies at ``apex`` rather than at ``base``, in
    [−1, 1] (0: they say nothing, a flat or veinless picture).  Side veins leave the midrib at
    an acute angle opening towards the apex (pinnate laterals, a palmate leaf's main veins):
    seen from the base→apex axis, a ridge on either side runs outwards and forwards.  The
    ridges are the Hessian's of the lightness at 0.8 % of the leaf's length (veins lighter or
    darker than the lamina alike), weighted by their strength, over the blade between 10 and
    90 % of the axis, off the midrib band (5 %) and the margin (4 %: its own edge, blurred).  On
    the photos of oak, aspen, hornbeam and grapevine it gives +0.14 to +0.80 with the true ends,
    and −0.37 to −0.38 on an oak photo (on grey, JPEG, upright or turned 35°) that
    :func:`_base_from_shape` put upside down (its wide end is the tip)."""
    t = np.asarray(apex, float) - np.asarray(base, float)
    L = float(np.linalg.norm(t))
    if L < 10.0:
        return 0.0
    t /= L
    # the leaf's box only, at most VEIN_PX long: the blur is a share of the leaf's length anyway
    # (on a 2000 px photo the whole image took 1.1 s and 460 MB)
    ys, xs = np.nonzero(mask)
    if not len(ys):
        return 0.0
    x0, y0, x1, y1 = int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1
    f = min(1.0, VEIN_PX / L)
    img = np.ascontiguousarray(img[y0:y1, x0:x1, :3])
    mask = np.ascontiguousarray(mask[y0:y1, x0:x1]).astype(np.uint8)
    if f < 1.0:
        size = (max(1, round(img.shape[1] * f)), max(1, round(img.shape[0] * f)))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST)
    base = (np.asarray(base, float) - (x0, y0)) * f
    L *= f
    (tx, ty) = (float(t[0]), float(t[1]))
    t, n = (tx, ty), (-ty, tx)  # python floats: float32 arrays stay float32
    g = cv2.cvtColor(img, cv2.COLOR_BGR2Lab)[..., 0].astype(np.float32)
    g = cv2.GaussianBlur(g, (0, 0), max(0.008 * L, 1.0))
    dxx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3)
    dyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3)
    dxy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3)
    half = np.sqrt(0.25 * (dxx - dyy) ** 2 + dxy ** 2)
    l1, l2 = 0.5 * (dxx + dyy) + half, 0.5 * (dxx + dyy) - half
    first = np.abs(l1) >= np.abs(l2)
    strength = np.abs(np.where(first, l1, l2)) - np.abs(np.where(first, l2, l1))
    across = 0.5 * np.arctan2(2.0 * dxy, dxx - dyy) + np.where(first, np.float32(0.0), np.float32(0.5 * np.pi))  # the larger curvature's
    dx, dy = -np.sin(across), np.cos(across)  # along the ridge
    H, W = g.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    rx, ry = xx - float(base[0]), yy - float(base[1])
    along, side = rx * t[0] + ry * t[1], rx * n[0] + ry * n[1]
    k = max(int(0.08 * L) | 1, 3)  # the margin's own edge blurred: 5 σ off it
    inner = cv2.erode((mask > 0).astype(np.uint8), np.ones((k, k), np.uint8)) > 0
    sel = inner & (np.abs(side) > 0.05 * L) & (along > 0.1 * L) & (along < 0.9 * L)
    if not sel.any():
        return 0.0
    score = (dx * t[0] + dy * t[1]) * (dx * n[0] + dy * n[1]) * np.sign(side)
    w = strength[sel]
    den = float((w * np.abs(score[sel])).sum())
    return float((w * score[sel]).sum() / den) if den > 0 else 0.0

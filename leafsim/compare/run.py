"""``leafsim compare``: the model rendered top-down beside photographs, with the metrics of
:mod:`leafsim.compare.metrics` and a montage.

Rows of a comparison: the young model against the species photo (or ``--photo``); with a
senescent reference photo in the config (``senescent_photo``), the stage of a drying run
that matches it best (least total-variation distance of the colour classes, sampled every
``MATCH_EVERY`` frames until 2 % of the water is left) against it, and how the whole
senescent window does against it (``senescent_window``: every sampled stage once the leaf
has lost half its chlorophyll, through the dried one); with ``--stage`` one row
for that stage (``young``, ``dried`` = 2 % of the water left, or a frame number).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from leafsim.appearance.photo import species_photo_rgba
from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError, LeafsimWarning
from leafsim.base.resources import display_path
from leafsim.compare import metrics as C
from leafsim.outline.trace import refuse_non_leaf, to_leaf_shape
from leafsim.pipeline import build_leaf, check_given_ends, photo_veins, trace_photo
from leafsim.render.topdown import TopDown
from leafsim.sim.run import NotReached, Run
from leafsim.sim.simulator import Simulator

#: senescent-stage matching samples the drying run every this many frames
MATCH_EVERY = 50
#: the senescent window: stages with less than this share of the leaf's chlorophyll left
WINDOW_CHLOROPHYLL = 0.5
#: the colour-bin TV a stage of the window should reach against the senescent photo
WINDOW_TV = 0.35
#: a drying run stops when this share of the water is left (as "Dry to end" does)
DRY_LEFT = 0.02
#: and after at most this many frames
MAX_FRAMES = 12000


@dataclass
class Row:
    kind: str           # "young", "senescent" or "stage"
    ref: C.Reference
    state: object
    metrics: dict | None = None
    picture: np.ndarray | None = None
    mask: np.ndarray | None = None
    note: str = ""
    veins: np.ndarray | None = None  # main + lateral vein lines in the comparison frame
    scale_k: float = 1.0  # the grown-back leaf's length ÷ the photo-sized leaf's (senescent rows)
    stage: dict | None = None  # frame, time, water left (when the state is not the leaf's own)
    window: dict | None = None  # the senescent window's colour TV (senescent rows)


class _Leaf:
    """One species' model, its view and renders in the comparison frame."""

    def __init__(self, sp, params, seed, effects, frame=None):
        self.sp, self.params, self.seed, self.effects = sp, params, seed, effects
        self.shape, self.veins, self.model = build_leaf(sp, params, seed)
        self.sim = Simulator(self.model, params, effects=effects, seed=seed)
        self.state0 = self.sim.state()
        photo = species_photo_rgba(sp, params) if sp.image is not None else None
        self.view = LeafView(self.model, photo, self.state0.pigments.copy(), photo_tint=False, photo_colour=sp.photo_colour,
                              blade_only=True)
        self.albedo = "detail" if photo is not None else "colours"
        self.frame = C.frame_for(self.shape) if frame is None else frame
        self.td = TopDown(self.frame)
        self._mesh = None
        self.progress = None  # called with the Run after every frame of the drying (a progress bar)

    def render(self, state, veins=True):
        if self._mesh is None:
            self._mesh = self.view.mesh(state, self.params)
            arg = self._mesh
        else:
            arg = self.view.update(state, self.params)
        return self.td.render(arg, {"albedo": self.albedo, "veins": veins})

    def picture(self, state):
        """(picture with veins, silhouette without them) of ``state``."""
        rgb, _ = self.render(state, True)
        _, mask = self.td.render(None, {"albedo": self.albedo, "veins": False})
        return rgb, mask

    def vein_lines(self, state):
        q = state.particle_q
        return C.vein_mask([q[idx, :2] for idx, _, order in self.model.vein_polylines() if order <= 1], self.frame)

    def release(self):
        self.td.release()


def _reference(path, params, frame, length_m, base_px=None, apex_px=None, key: str = "", error=None):
    """The traced reference photo at ``path``; given ends off the photo, or off the leaf traced
    there, are one line naming ``key`` + the end (``error(key, message)`` makes it, e.g. the
    species' config error)."""
    from leafsim.outline.trace import HintError

    try:
        traced = trace_photo(path, params, base_px, apex_px)
    except HintError as e:  # name the config key it came from (senescent_photo.base_px)
        raise LeafsimError(f"{path}: {key}{e.key} {e.detail}") from None
    # a given end on the background (or another leaf) would match the wrong leaf axis
    error = error or (lambda name, msg: LeafsimError(f"{key}{name} {msg}"))
    check_given_ends(traced, path, {"base_px": base_px, "apex_px": apex_px}, lambda name, msg: error(key + name, msg))
    for text in refuse_non_leaf(traced):  # refuses a cut leaf, the background or a rectangle (a meaningless IoU)
        warnings.warn(LeafsimWarning(f"{path}: {text}"), stacklevel=1)  # and says what only warns (a guessed base)
    return C.reference(traced, to_leaf_shape(traced, length_m), frame)


def _dry_run(leaf: _Leaf, want_frame: int | None, target: C.Reference | None, last: int = MAX_FRAMES):
    """Run the leaf drying (to ``DRY_LEFT`` of the water, at most frame ``last``); returns
    (dried state, state at ``want_frame`` or None, best match to ``target``'s colours (state,
    tv, frames sampled, the senescent window's record) or None).  The window: every sampled
    stage at which the leaf has visibly turned (less than ``WINDOW_CHLOROPHYLL`` of its
    chlorophyll left, area-weighted), through the dried one."""
    if want_frame is None and not leaf.sim.effects.get("osmosis", False):  # refused now, not after MAX_FRAMES frames
        raise LeafsimError(f"{leaf.sp.key}: the drying run (to {DRY_LEFT:g} of the water) cannot dry the leaf with "
                           "effects.osmosis off: add osmosis to --effects, or give --stage a frame number")
    run = Run(leaf.model, simulator=leaf.sim, state=leaf.state0.copy(), name=leaf.sp.key)
    at, best, tried = None, None, 0
    window: list[float] = []
    area = leaf.model.particle_area * leaf.model.blade_T
    goal = target.colour if target is not None else None
    fp = C.colour_classes(target.rgb, goal) if target is not None else None

    def look(state) -> bool:
        """Record what this state offers; True when the run is done."""
        nonlocal at, best, tried
        if want_frame is not None and state.frame == want_frame:
            at = state.copy()
        if target is not None and state.frame % MATCH_EVERY == 0:
            rgb, mask = leaf.render(state, True)
            inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
            tv = C.total_variation(fp, C.colour_classes(rgb, inner))
            tried += 1
            if state.pigments is not None and float(area @ state.pigments.chlorophyll) < WINDOW_CHLOROPHYLL * float(area.sum()):
                window.append(tv)
            if best is None or tv < best[1]:
                best = (state.copy(), tv)
        dry = leaf.model.water_fraction(state.particle_water) <= DRY_LEFT
        return (dry or state.frame >= min(last, MAX_FRAMES)) and (want_frame is None or state.frame >= want_frame)

    if not look(run.state):
        for _ in run.frames(until=look):
            if leaf.progress is not None:
                leaf.progress(run)
    if target is not None and run.state.frame % MATCH_EVERY:  # the dried stage itself
        rgb, mask = leaf.render(run.state, True)
        inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        window.append(C.total_variation(fp, C.colour_classes(rgb, inner)))
    return run.state, at, (None if best is None else (best[0], best[1], tried, _window(window)))


def _window(tvs: list[float]) -> dict:
    """The colour-bin TV against the senescent photo over the senescent window: how many stages,
    median, 90th percentile and worst, the share within ``WINDOW_TV``, and the dried stage's."""
    if not tvs:
        return {"stages": 0}
    a = np.asarray(tvs)
    return {"stages": int(a.size), "median_tv": round(float(np.median(a)), 4), "p90_tv": round(float(np.percentile(a, 90)), 4),
            "max_tv": round(float(a.max()), 4), f"share_tv_le_{WINDOW_TV}": round(float((a <= WINDOW_TV).mean()), 3),
            "dried_tv": round(float(a[-1]), 4)}


def _vein_offset(leaf: _Leaf, state) -> dict | None:
    """The model's main veins and laterals against the species photo's traced ones (the young
    leaf: both in the photo's frame).  Traced whatever ``veins.photo`` says, so the grown veins
    of ``veins.photo = off`` are measured the same way."""
    pv = photo_veins(leaf.sp, leaf.params)
    A = np.asarray(leaf.shape.px_to_world, float)
    world = [np.asarray(p, float) @ A[:, :2].T + A[:, 2] for p in [*pv.all_mains(), *pv.laterals]]
    q = state.particle_q
    model = [q[idx, :2] for idx, _, order in leaf.model.vein_polylines() if order <= 1]
    return C.vein_offset(world, model, leaf.frame, leaf.sp.length_m * leaf.frame.scale)


def _stage_info(leaf: _Leaf, state) -> dict:
    w = leaf.model.water_fraction(state.particle_water)
    return {"frame": state.frame, "time_s": round(state.time, 4), "water": round(w, 4)}


def run_compare(sp, params, seed=0, photo=None, stage=None, effects=None, progress=None) -> dict:
    """Compare species ``sp`` with its photos (module docstring); returns the report with the
    rows' pictures under the private key ``_rows`` (for :func:`leafsim.compare.metrics.montage`).
    ``progress(run)`` is called after every frame of the drying run."""
    t0 = time.perf_counter()
    if photo is None and sp.image is None:
        raise LeafsimError(f"species '{sp.key}' has no photo (drawn outline): give --photo IMAGE to compare with")
    leaf = _Leaf(sp, params, seed, effects)
    leaf.progress = progress
    try:
        ref_path = Path(photo) if photo is not None else sp.image
        given = (None, None) if photo is not None else (sp.base_px, sp.apex_px)
        own = _reference(ref_path, params, leaf.frame, sp.length_m, *given)
        rows = _rows(leaf, own, stage, photo is None)
        for r in rows:
            if r.picture is None:
                r.picture, r.mask = leaf.picture(r.state)
                r.veins = leaf.vein_lines(r.state)
            r.metrics = C.compare_images(r.ref, r.picture, r.mask, r.veins, sp.length_m * leaf.frame.scale)
        if photo is None and rows[0].kind == "young":
            rows[0].metrics["vein_offset"] = _vein_offset(leaf, rows[0].state)
    finally:
        leaf.release()
    report = {"species": sp.key, "seed": seed, "frame_px_per_m": round(leaf.frame.scale, 2),
              "seconds": round(time.perf_counter() - t0, 2),
              "rows": [dict(kind=r.kind, reference=_rel(r.ref.path), stage=r.stage or _stage_info(leaf, r.state), note=r.note,
                           **({"grown_back": round(r.scale_k, 4)} if r.scale_k != 1.0 else {}),
                           **({"senescent_window": r.window} if r.window is not None else {}), **r.metrics)
                       for r in rows]}
    report["_rows"] = rows
    return report


def _rows(leaf: _Leaf, own: C.Reference, stage, species_photo: bool) -> list[Row]:
    sp = leaf.sp
    if stage is not None and stage != "young":
        frame = None if stage == "dried" else int(stage)
        dried, at, _ = _dry_run(leaf, frame, None)
        left = leaf.model.water_fraction(dried.particle_water)
        if frame is None and left > DRY_LEFT:
            raise NotReached(f"{leaf.sp.key}: --stage dried: the leaf did not dry within {MAX_FRAMES} frames (water left "
                             f"{left:.3g}, expected ≤ {DRY_LEFT:g}): do the effects and parameters let it dry?")
        st = dried if frame is None else at
        return [Row("stage", own, st, note=f"stage {stage}")]
    rows = [Row("young", own, leaf.state0, note="photo of a senescent leaf: the young model is the palette green"
                if species_photo and sp.photo_stage == "senescent" else "")]
    if stage is None and species_photo and sp.senescent is not None:
        ref = own if sp.senescent.image == sp.image else _reference(sp.senescent.image, leaf.params, leaf.frame, sp.length_m,
                                                                  sp.senescent.base_px, sp.senescent.apex_px, "senescent_photo.",
                                                                  sp.error)
        _, _, best = _dry_run(leaf, None, ref)
        note = f"best of {best[2]} stages every {MATCH_EVERY} frames"
        if ref is own and sp.photo_stage == "senescent" and 0.3 < _kept(leaf, best[0]) < 1.0:
            rows.append(_grown_back(leaf, ref, best, note))
        else:  # (a leaf that did not shrink, or lost its silhouette, is compared as it is)
            rows.append(Row("senescent", ref, best[0], note=note
                            + ("" if ref is own else "; another leaf of the species: its IoU is only indicative")))
        rows[-1].window = best[3]
    return rows


#: the grown-back run samples stages this many frames past the first run's match at most
GROWN_BACK_MARGIN = 10 * MATCH_EVERY


def _silhouette_px(leaf: _Leaf, state) -> int:
    return int(leaf.picture(state)[1].sum())


def _kept(leaf: _Leaf, state) -> float:
    """Top-down area of ``state``'s silhouette ÷ the fresh leaf's."""
    return _silhouette_px(leaf, state) / max(_silhouette_px(leaf, leaf.state0), 1)


def _register(leaf: _Leaf, state, ref: C.Reference) -> float:
    """Translate ``state`` in the table's plane so its top-down silhouette's centroid is the
    photo blade's (a drying leaf creeps on the table as it shrinks; where it lies is no
    property of its shape).  No rotation, no scaling.  Returns the distance moved [m]."""
    _, mask = leaf.picture(state)
    if not mask.any() or not ref.blade.any():
        return 0.0
    rm, cm = np.nonzero(mask)
    rp, cp = np.nonzero(ref.blade)
    dx = (cp.mean() - cm.mean()) / leaf.frame.scale
    dy = -(rp.mean() - rm.mean()) / leaf.frame.scale  # image rows run down, y up
    state.particle_q[:, 0] += dx
    state.particle_q[:, 1] += dy
    return float(np.hypot(dx, dy))


def _grown_back(leaf: _Leaf, ref: C.Reference, best, note: str) -> Row:
    """The senescent row when the species' own photo shows the aged leaf: the photographed
    outline is the leaf *after* it shrank, so the fresh leaf was larger.  The first drying run
    (built at the photo's size) gives the matched stage and the top-down area it kept, r; the
    leaf is rebuilt 1/√r longer, translated so its area centroid is the photo-sized leaf's
    (a rigid move of a free leaf), dried again and matched again (to at most
    ``GROWN_BACK_MARGIN`` frames past the first match), then moved on the table so the
    silhouettes' centroids coincide (:func:`_register`).  The row is that second match: its
    size follows from the model's own shrinkage, not from fitting the photo."""
    from dataclasses import replace

    first, r = best[0], _kept(leaf, best[0])
    k = 1.0 / np.sqrt(r)
    big = _Leaf(replace(leaf.sp, length_m=leaf.sp.length_m * k), leaf.params, leaf.seed, leaf.effects, frame=leaf.frame)
    try:
        def centroid(lf):
            t = lf.model.blade_T
            a = lf.model.particle_area[t]
            return (lf.state0.particle_q[t, :2] * a[:, None]).sum(0) / a.sum()

        move = centroid(leaf) - centroid(big)
        big.state0.particle_q[:, :2] += move
        inner = big.state0.path
        while inner is not None:  # the drying-path meshes move with the leaf
            inner.particle_q[:, :2] += move
            inner = inner.path
        _, _, best2 = _dry_run(big, None, ref, last=first.frame + GROWN_BACK_MARGIN)
        shift = _register(big, best2[0], ref)
        picture, mask = big.picture(best2[0])
        veins = big.vein_lines(best2[0])
    finally:
        big.release()
    row = Row("senescent", ref, best2[0], note=f"{note}; grown back: the fresh leaf × {k:.3f} in length, so that at "
              f"the matched stage it has the photo's size (first pass at photo size: frame {first.frame}, top-down area "
              f"kept {r:.3f}); best of {best2[2]} stages of that run; moved {1e3 * shift:.2f} mm on the table "
              f"to the photo's centroid")
    row.picture, row.mask, row.veins, row.scale_k = picture, mask, veins, k
    row.stage = _stage_info(big, best2[0])
    return row


def _rel(path) -> str:
    return display_path(path)

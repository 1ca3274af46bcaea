"""``leafsim compare``: the model rendered top-down beside photographs, with the metrics of
:mod:`leafsim.compare` and a montage.

Rows of a comparison: the young model against the species photo (or ``--photo``); with a
senescent reference photo in the config (``senescent_photo``), the stage of a drying run
that matches it best (least total-variation distance of the colour classes, sampled every
``MATCH_EVERY`` frames until 2 % of the water is left) against it; with ``--stage`` one row
for that stage (``young``, ``dried`` = 2 % of the water left, or a frame number).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from leafsim import compare as C
from leafsim.errors import LeafsimError

#: senescent-stage matching samples the drying run every this many frames
MATCH_EVERY = 50
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


class _Leaf:
    """One species' model, its view and renders in the comparison frame."""

    def __init__(self, sp, params, seed, effects):
        from leafsim.leaf import build_leaf, species_photo_rgba
        from leafsim.render.topdown import TopDown
        from leafsim.sim.simulator import Simulator
        from leafsim.view import LeafView

        self.sp, self.params = sp, params
        self.shape, self.veins, self.model = build_leaf(sp, params, seed)
        self.sim = Simulator(self.model, params, effects=effects, seed=seed)
        self.state0 = self.sim.state()
        photo = species_photo_rgba(sp, params) if sp.image is not None else None
        self.view = LeafView(self.model, photo, self.state0.pigments.copy(), photo_tint=False, photo_colour=sp.photo_colour)
        self.albedo = "detail" if photo is not None else "colours"
        self.frame = C.frame_for(self.shape)
        self.td = TopDown(self.frame)
        self._mesh = None

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


def _reference(path, params, frame, length_m, base_px=None, apex_px=None):
    from leafsim.leaf import trace_photo
    from leafsim.outline import to_leaf_shape

    traced = trace_photo(path, params, base_px, apex_px)
    return C.reference(traced, to_leaf_shape(traced, length_m), frame)


def _dry_run(leaf: _Leaf, want_frame: int | None, target: C.Reference | None):
    """Run the leaf drying; returns (dried state, state at ``want_frame`` or None, best
    match to ``target``'s colours (state, tv, frames sampled) or None)."""
    sim, state = leaf.sim, leaf.state0.copy()
    w0 = float(leaf.model.particle_water0.sum())
    at, best, tried = None, None, 0
    goal = target.colour if target is not None else None
    fp = C.colour_classes(target.rgb, goal) if target is not None else None
    while True:
        if want_frame is not None and state.frame == want_frame:
            at = state.copy()
        if target is not None and state.frame % MATCH_EVERY == 0:
            rgb, mask = leaf.render(state, True)
            inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
            tv = C.total_variation(fp, C.colour_classes(rgb, inner))
            tried += 1
            if best is None or tv < best[1]:
                best = (state.copy(), tv)
        dry = float(state.particle_water.sum()) <= DRY_LEFT * w0
        if (dry or state.frame >= MAX_FRAMES) and (want_frame is None or state.frame >= want_frame):
            break
        sim.step(state)
        if not np.isfinite(state.particle_q).all():
            raise LeafsimError(f"{leaf.sp.key}: the simulation produced NaN at frame {state.frame}")
    return state, at, (None if best is None else (best[0], best[1], tried))


def _stage_info(leaf: _Leaf, state) -> dict:
    w = float(state.particle_water.sum() / max(leaf.model.particle_water0.sum(), 1e-300))
    return {"frame": state.frame, "time_s": round(state.time, 4), "water": round(w, 4)}


def run_compare(sp, params, seed=0, photo=None, stage=None, effects=None) -> dict:
    """Compare species ``sp`` with its photos (module docstring); returns the report with the
    rows' pictures under the private key ``_rows`` (for :func:`leafsim.compare.montage`)."""
    t0 = time.perf_counter()
    if photo is None and sp.image is None:
        raise LeafsimError(f"species '{sp.key}' has no photo (drawn outline): give --photo IMAGE to compare with")
    leaf = _Leaf(sp, params, seed, effects)
    try:
        ref_path = Path(photo) if photo is not None else sp.image
        given = (None, None) if photo is not None else (sp.base_px, sp.apex_px)
        own = _reference(ref_path, params, leaf.frame, sp.length_m, *given)
        rows = _rows(leaf, own, stage, photo is None)
        for r in rows:
            r.picture, r.mask = leaf.picture(r.state)
            r.metrics = C.compare_images(r.ref, r.picture, r.mask, leaf.vein_lines(r.state), sp.length_m * leaf.frame.scale)
    finally:
        leaf.release()
    report = {"species": sp.key, "seed": seed, "frame_px_per_m": round(leaf.frame.scale, 2),
              "seconds": round(time.perf_counter() - t0, 2),
              "rows": [dict(kind=r.kind, reference=_rel(r.ref.path), stage=_stage_info(leaf, r.state), note=r.note, **r.metrics)
                       for r in rows]}
    report["_rows"] = rows
    return report


def _rows(leaf: _Leaf, own: C.Reference, stage, species_photo: bool) -> list[Row]:
    sp = leaf.sp
    if stage is not None and stage != "young":
        frame = None if stage == "dried" else int(stage)
        dried, at, _ = _dry_run(leaf, frame, None)
        st = dried if frame is None else at
        return [Row("stage", own, st, note=f"stage {stage}")]
    rows = [Row("young", own, leaf.state0, note="photo of a senescent leaf: the young model is the palette green"
                if species_photo and sp.photo_stage == "senescent" else "")]
    if stage is None and species_photo and sp.senescent is not None:
        ref = own if sp.senescent.image == sp.image else _reference(sp.senescent.image, leaf.params, leaf.frame, sp.length_m,
                                                                  sp.senescent.base_px, sp.senescent.apex_px)
        _, _, best = _dry_run(leaf, None, ref)
        rows.append(Row("senescent", ref, best[0], note=f"best of {best[2]} stages every {MATCH_EVERY} frames"
                        + ("" if ref is own else "; another leaf of the species: its IoU is only indicative")))
    return rows


def _rel(path) -> str:
    from leafsim import ROOT

    p = Path(path).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(path)

"""Level of detail: simulate a leaf on a coarse mesh, show and export it on a fine one (core).

Both meshes are built from the same species, parameters and seed, so they share the outline
and the veins and differ only in ``mesh.spacing``.  Every particle of the fine mesh is
embedded once, by its rest position, in the coarse rest layer T (triangle + barycentric
coordinates, :func:`leafsim.sim.metrics.embed`) and follows the coarse deformation: fine
layer-T particles lie on the interpolated coarse surface, fine layer-V particles above it at
the interpolated coarse layer separation along the interpolated normal.  Water and pigments
are interpolated the same way; the fine mesh keeps its own vein pattern (vein pallor), so the
veins stay sharp.  The displayed state carries positions, water, pigments and the clock; its
constraint rest values stay at rest (nothing simulates it).

:func:`lod_error` measures what the coarse simulation costs in accuracy against the fine
simulation of the same leaf, with the accuracy study's probe metrics.

Example
-------
>>> lod = LevelOfDetail.build(sp, params, seed=3, simulate=0.07, show=0.035)   # doctest: +SKIP
>>> shown = lod.show(coarse_state)                     # a State of lod.fine       # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.sim.metrics import Embedding, Probe, embed, field_errors
from leafsim.sim.model import LAYER_T, Model, State

PIGMENT_FIELDS = ("chlorophyll", "carotenoid", "anthocyanin", "browning")


def _embed_fine(coarse, fine) -> Embedding:
    """The fine particles in the coarse mesh: the blade's in the blade's triangles, the
    petiole's in the petiole's (so the shown stalk follows the simulated one)."""
    pts = fine.particle_rest[:, :2]
    stalk_c = ~coarse.blade_tris
    if fine.particle_petiole is None or not stalk_c.any():
        return embed(coarse, pts)
    on = fine.particle_petiole
    tri = np.zeros(len(pts), np.int64)
    bary = np.zeros((len(pts), 3))
    for sel, tris in ((~on, None), (on, np.flatnonzero(stalk_c))):
        if sel.any():
            e = embed(coarse, pts[sel], tris)
            tri[sel], bary[sel] = e.tri, e.bary
    return Embedding(tri, bary)


@dataclass
class LevelOfDetail:
    """A coarse simulation mesh and a fine display mesh of one leaf.

    shape : LeafShape (shared); coarse, fine : Model; fine_params : ParamSet of the fine mesh;
    embedding : every fine particle in the coarse rest layer T; offset : (k, 2) rest-plane
    offset of each fine particle from its embedded point (non-zero only just outside the coarse
    mesh, whose margin is made of chords); fine_rest : a fresh fine State (summer pigments with
    the fine vein pattern) the shown states are made from.
    """

    shape: object
    coarse: Model
    fine: Model
    coarse_params: ParamSet
    fine_params: ParamSet
    embedding: Embedding
    offset: np.ndarray
    fine_rest: State

    @classmethod
    def build(cls, sp, params: ParamSet, seed: int, simulate: float, show: float, built=None) -> "LevelOfDetail":
        """Build both meshes (``simulate``/``show`` are ``mesh.spacing`` values); ``built``: an
        already built coarse ``(shape, veins, model)`` to reuse."""
        from leafsim.pipeline import build_leaf
        from leafsim.sim.simulator import Simulator

        # each mesh is simulated on its own (the display mesh's reference run too): no drying path
        cp = params.with_overrides({"mesh.spacing": simulate, "dynamics.path": "own"})
        fp = params.with_overrides({"mesh.spacing": show, "dynamics.path": "own"})
        shape, _, coarse = built if built is not None else build_leaf(sp, cp, seed)
        _, _, fine = build_leaf(sp, fp, seed)
        emb = _embed_fine(coarse, fine)
        offset = fine.particle_rest[:, :2] - emb.at(coarse, coarse.particle_rest)[:, :2]
        rest = Simulator(fine, fp, effects=(), seed=seed).state()
        return cls(shape, coarse, fine, cp, fp, emb, offset, rest)

    def _extrapolate(self, q: np.ndarray) -> np.ndarray:
        """(k, 3) displacement of the fine particles outside the coarse mesh: their rest offset
        mapped by the deformation gradient of the coarse triangle they are embedded in (affine
        extrapolation of that triangle, exact for rigid motions)."""
        out = np.zeros((len(self.offset), 3))
        far = np.flatnonzero(np.abs(self.offset).max(1) > 0)
        if not len(far):
            return out
        tri = self.coarse.tri_T[self.embedding.tri[far]]
        X = self.coarse.particle_rest[:, :2]
        rest = np.stack([X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]]], -1)  # (f, 2, 2)
        cur = np.stack([q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]]], -1)  # (f, 3, 2)
        F = cur @ np.linalg.inv(rest)
        out[far] = np.einsum("fij,fj->fi", F, self.offset[far])
        return out

    def show(self, state: State) -> State:
        """The coarse ``state`` carried over to the fine mesh (a new State of :attr:`fine`)."""
        from leafsim.sim.frame import blade_frame

        c, f, e = self.coarse, self.fine, self.embedding
        T = np.flatnonzero(c.particle_layer == LAYER_T)
        remap = np.zeros(c.particle_count, np.int64)
        remap[T] = np.arange(len(T))
        p, _, n, h = blade_frame(c, state, T, remap)
        full = lambda x: _scatter(c.particle_count, T, x)
        surf = e.at(c, full(p)) + self._extrapolate(state.particle_q)
        nrm = e.at(c, full(n))
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        top = (f.particle_layer != LAYER_T)[:, None]
        q = surf + top * (e.at(c, full(h))[:, None] * nrm)
        w_rel = e.at(c, state.particle_water / np.maximum(c.particle_water0, 1e-300))
        out = self.fine_rest.copy()
        out.particle_q[:] = q
        out.particle_water[:] = np.clip(w_rel, 0.0, None) * f.particle_water0
        out.scalars[:] = state.scalars
        if state.pigments is not None and out.pigments is not None:
            pig = out.pigments
            for name in PIGMENT_FIELDS:
                getattr(pig, name)[:] = e.at(c, np.asarray(getattr(state.pigments, name), np.float64))
            out = replace(out, pigments=replace(pig, age=state.pigments.age, _coeffs=None))
        return out


def _scatter(n: int, idx: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros((n,) + values.shape[1:], np.float64)
    out[idx] = values
    return out


def lod_error(shape, shown_model: Model, shown_state: State, ref_model: Model, ref_state: State) -> dict:
    """Error of the shown (coarse-simulated) leaf against the fine simulation ``ref``, with the
    probe metrics of :mod:`leafsim.sim.metrics`: position RMS / L in the leaves' own frames,
    height RMS / L, water RMS, margin lift, 3D and top-down area (absolute ``d_*`` and
    relative ``r_*`` differences), and the scalar measures of both."""
    probe = Probe(shape)
    a = probe.fields(shown_model, shown_state)
    b = probe.fields(ref_model, ref_state)
    out = field_errors(a, b, probe.length)
    for k in ("margin_lift", "area_3d", "area_top", "water"):
        out[f"lod_{k}"], out[f"fine_{k}"] = a[k], b[k]
    return out

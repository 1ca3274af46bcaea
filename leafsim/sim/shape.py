"""Whole-leaf shape measures of a state: the leaf's own rigid frame (:func:`leaf_frame`),
:func:`shape_metrics` (3D area kept, margin lift, inversions, ...) and the final-positions file
(:func:`save_npz`)."""

from __future__ import annotations

import io

import numpy as np

from leafsim.base.fileio import atomic_write_bytes
from leafsim.sim.model import Model, State


def save_npz(path, model: Model, state: State, meta: str | None = None) -> None:
    """Write model topology and state arrays to ``path`` (.npz) atomically (temp + os.replace);
    ``meta``: a JSON text stored as the array ``meta`` (what made it: ``leafsim run`` stores its
    provenance there).  ``scalars`` = (simulated time [s], frame, weather time [s])."""
    buf = io.BytesIO()
    extra = {} if meta is None else {"meta": np.array(meta)}
    np.savez_compressed(
        buf, particle_rest=model.particle_rest, particle_layer=model.particle_layer, tri_T=model.tri_T,
        particle_petiole=~model.blade_particles,
        tri_V=model.tri_V, spring_ij=model.spring_ij, vein_particles=model.vein_particles,
        vein_start=model.vein_start, vein_order=model.vein_order, vein_width=model.vein_width,
        particle_texcoord=model.particle_texcoord, particle_q=state.particle_q,
        particle_qd=state.particle_qd, particle_water=state.particle_water,
        particle_water0=model.particle_water0, spring_rest=state.spring_rest,
        scalars=state.scalars, **extra)
    atomic_write_bytes(path, buf.getvalue(), "positions")


def _area3(q, tri):
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def leaf_frame(model: Model, state: State) -> np.ndarray:
    """Positions in the leaf's own frame: best rigid fit (Kabsch) of layer T onto its rest."""
    T = model.blade_T
    P = state.particle_q[T]
    Q = model.particle_rest[T]
    pc, qc = P.mean(0), Q.mean(0)
    H = (P - pc).T @ (Q - qc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1, 1, d]) @ U.T
    return (state.particle_q - pc) @ R.T + qc


def shape_metrics(model: Model, state: State, own_frame: bool | None = None) -> dict:
    """Shape of the leaf.

    area_ratio : 3D area of layer T now / at rest.
    margin_lift : (max z of contour particles − min z of layer T) / leaf length.
    max_height : (max z − min z of layer T) / length.
    inverted : number of triangles whose V particle is below the triangle (layer inversion).
    max_displacement : largest |q − rest| / length (in the same frame as the heights).
    own_frame : measure in the leaf's best-fit rigid frame (:func:`leaf_frame`) instead of the
        world's, as for a leaf that falls or hangs (``leafsim run`` does so unless the scene is
        the ground); default False.  Every length is a fraction of the leaf's length L.
    """
    q = state.particle_q
    if own_frame:
        q = leaf_frame(model, state)
    T = model.blade_T
    L = model.length
    tri = model.tri_T
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    n = np.cross(b - a, c - a)
    hv = ((q[model.tri_V] - a) * n).sum(1)
    tri = model.blade_tri_T
    zc = q[model.contour_particles, 2]
    zmin = q[T, 2].min()
    return {
        "area_ratio": float(_area3(state.particle_q, tri).sum() / _area3(model.particle_rest, tri).sum()),
        "margin_lift": float((zc.max() - zmin) / L),
        "margin_lift_mean": float((np.median(zc) - zmin) / L),
        "max_height": float((q[T, 2].max() - zmin) / L),
        "inverted": int((hv <= 0).sum()),
        "max_displacement": float(np.linalg.norm(q - model.particle_rest, axis=1).max() / L),
        "water_fraction_left": model.water_fraction(state.particle_water),
    }

"""The shrink effect [Jeong eq. 2.10–2.11]: rest lengths, hinge rest angles (the bilayer
curvature), thickness volumes and the Voronoi layer follow the tissue strain as water is lost."""

from __future__ import annotations

import numpy as np

from leafsim.sim.kernels import shrink as ks
from leafsim.sim.model import (
    LAYER_T,
    SPRING_LINK,
    SPRING_SURFACE,
    SPRING_VEIN,
    Model,
    State,
)
from leafsim.sim.pleats import pleat_angles
from leafsim.sim.senescence import random_field
from leafsim.sim.veinframe import hinge_alignment

#: bilayer curvature gain κ = gain · Δε / h (prototype measured 1.3; Timoshenko equal layers 1.5)
BILAYER_GAIN = 1.3


#: salt of the shrinkage field's seed (shrink.patchiness), so it is not the senescence field
PATCH_SALT = 0x5A71C4

#: largest rest angle a bending hinge may ask for [rad]: a curvature the mesh cannot resolve
#: (radius below a few edge lengths) is clamped instead of fighting the stretch constraints
HINGE_MAX_ANGLE = 0.35

#: largest rest angle of a pleat (shrink.plication) [rad], added after the bilayer's clamp: the
#: pleats fold along vein lines, which the mesh follows (22° at hornbeam's depth, p99), but
#: where a vein ends inside a panel the field has a point dent whose angle grows as the mesh refines
PLEAT_MAX_ANGLE = 1.0


class Shrink:
    """The rest shape as the tissue dries (SPEC §7), one consistent bent state:

    * T springs (surface, veins): Jeong's law, σ per type, from the mass ratio;
    * bending hinges: the bilayer rest angle θ0 = gain (ε_top − ε_bottom)/h × d (Timoshenko;
      d the dual edge), which drying tissue keeps (plasticity); clamped, and 0 on hinges that
      bend a main/lateral vein lengthwise;
    * V springs: the top surface of that bent state, d (1 − h θ0 / d) × the T layer's shrink;
    * links and thickness volumes: the tissue shrinks isotropically with its bottom layer, the
      thickness too (h f), so the cross-section keeps its shape.

    So every constraint agrees with one shape whenever the bilayer curvature is developable;
    what remains is the physical frustration of a curvature that is not (cups), resolved by
    the energy, not by the solver's order (two layers and hinges each demanding their own
    curl made the result depend on the iteration count).

    With ``shrink.patchiness`` a > 0 the blade's tissue shrinks unevenly: every spring's σ
    and every hinge's bilayer angle × (1 + a z), z a seeded smooth random field of correlation
    length ``shrink.patch_size`` (:meth:`_patches`); both layers and the curl follow the same
    field, so each patch is a consistent shape of its own, incompatible with its neighbours.

    With ``shrink.plication`` δ > 0 every hinge's rest angle gains δ × the dihedral angle of the
    fresh blade's pleats across it (:mod:`leafsim.sim.pleats`: valleys on the main veins and
    laterals, the panels between them raised), after the bilayer's clamp (a pleat is a fold
    along a vein line, which the mesh follows; clamped on its own at ``PLEAT_MAX_ANGLE``); the
    pleats are a fold of the flat blade, so no rest length changes."""

    def __init__(self, model: Model):
        self.model = model
        t = model.spring_type
        self.links = np.flatnonzero(t == SPRING_LINK).astype(np.int64)
        ij = model.spring_ij[self.links]
        # the triangle of each V particle → that triangle's three T springs
        nT = int((model.particle_layer == LAYER_T).sum())
        self.nT = nT
        self.tri_springs = np.ascontiguousarray(model.vol_springs[np.argsort(model.vol_idx[:, 0])])
        self.link_tri = np.ascontiguousarray(ij[:, 0] - nT, dtype=np.int64)  # each link's triangle (its V end)
        self.vol_tri = np.ascontiguousarray(model.vol_idx[:, 0] - nT, dtype=np.int64)
        if not np.array_equal(np.sort(self.vol_tri), np.arange(len(self.vol_tri))):
            raise ValueError("shrink: the thickness volumes are not one per V particle, numbered after the T layer")
        self.ratios = np.empty((len(self.tri_springs), 3))  # scratch: tri_ratios
        # veins stay straight along their length: no bilayer curl on hinges that bend them;
        # elsewhere the curl is resolved in the local vein frame (veinframe.py)
        self.hinge_align = hinge_alignment(model)
        self.hinge_curl = np.where(model.hinge_vein, 0.0, 1.0)
        self.pleat = None  # shrink.plication's rest angles, set by configure
        self._pleat_unit = None  # the pleats' angles per unit depth, computed on first use

    def configure(self, params, seed: int = 0):
        t = self.model.spring_type
        sig = np.zeros(len(t))
        sig[t == SPRING_SURFACE] = params["shrink.sigma_surface_bottom"]
        sig[t == SPRING_VEIN] = params["shrink.sigma_vein"]
        spring_f, hinge_f = self._patches(float(params["shrink.patchiness"]), float(params["shrink.patch_size"]), seed)
        self.sigma = sig * spring_f
        self.sig_top = params["shrink.sigma_surface_top"]
        self.sig_bot = params["shrink.sigma_surface_bottom"]
        self.alpha = params["shrink.alpha"]
        self.l_min = params["shrink.l_min"]
        self.setw = min(params["dynamics.plasticity"] * params["dynamics.dt"], 1.0)
        beta = params["shrink.curl_anisotropy"]
        self.hinge_curl = np.where(self.model.hinge_vein, 0.0, 1.0 + beta * self.hinge_align) * hinge_f
        depth = float(params["shrink.plication"])
        self.pleat = (np.clip(depth * self._pleat_angles(), -PLEAT_MAX_ANGLE, PLEAT_MAX_ANGLE)
                      if depth > 0.0 and self.model.hinge_count else None)

    def _pleat_angles(self) -> np.ndarray:
        """The hinges' rest angles per unit ``shrink.plication`` (:mod:`leafsim.sim.pleats`),
        computed once per model."""
        if self._pleat_unit is None:
            self._pleat_unit = pleat_angles(self.model)
        return self._pleat_unit

    def _patches(self, a: float, size: float, seed: int) -> tuple:
        """The shrinkage field of ``shrink.patchiness`` (class doc): per spring and per hinge the
        factor 1 + a z at the midpoint of the spring and of the hinge's shared edge, ≥ 0; z the
        seeded random field of :func:`leafsim.sim.senescence.random_field` over the blade's
        rest positions (a function of position only, so every mesh of one leaf, the drying
        path's too, shrinks with the same patches).  The stalk shrinks uniformly.  Cached per
        (a, size, seed)."""
        key = (a, size, int(seed))
        if getattr(self, "_patch_key", None) == key:
            return self._patch_f
        m = self.model
        if a <= 0.0:
            f = (1.0, 1.0)
        else:
            blade = m.blade_particles
            z = np.zeros(m.particle_count)
            z[blade] = random_field(m.particle_rest[blade, :2], m.particle_area[blade], size, [int(seed), PATCH_SALT])
            ij, h = m.spring_ij, m.hinge_idx
            f = (np.clip(1.0 + a * 0.5 * (z[ij[:, 0]] + z[ij[:, 1]]), 0.0, None),
                 np.clip(1.0 + a * 0.5 * (z[h[:, 2]] + z[h[:, 3]]), 0.0, None))
        self._patch_key, self._patch_f = key, f
        return f

    def apply(self, state: State):
        m = self.model
        ks.shrink_springs(m.spring_ij, m.spring_rest0, self.sigma, self.alpha, self.l_min, m.particle_cytosol,
                          state.particle_water, m.particle_mass0, state.spring_rest)
        if m.hinge_count:
            ks.hinge_targets(m.hinge_idx, m.hinge_spring_V, m.spring_ij, m.spring_rest0, self.sig_top, self.sig_bot,
                             self.alpha, self.l_min, m.particle_cytosol, state.particle_water, m.particle_water0,
                             m.particle_mass0, m.thickness, BILAYER_GAIN, self.setw, state.hinge_plastic, state.hinge_rest)
            np.multiply(state.hinge_rest, self.hinge_curl, out=state.hinge_rest)
            np.clip(state.hinge_rest, -HINGE_MAX_ANGLE, HINGE_MAX_ANGLE, out=state.hinge_rest)
            if self.pleat is not None:  # the fresh blade's pleats (shrink.plication): folds on vein lines
                np.add(state.hinge_rest, self.pleat, out=state.hinge_rest)
        # the T springs' shrink, once per triangle, for the springs and volumes above them
        ks.tri_ratios(self.tri_springs, m.spring_rest0, state.spring_rest, self.ratios)
        if m.hinge_count:
            ks.dual_targets(m.hinge_spring_V, m.spring_ij, self.nT, self.ratios, m.spring_rest0, state.hinge_rest,
                            m.thickness, state.spring_rest)
        ks.link_targets(self.links, self.link_tri, self.ratios, m.spring_rest0, state.spring_rest)
        ks.vol_targets(self.vol_tri, self.ratios, m.vol_rest0, state.vol_rest)

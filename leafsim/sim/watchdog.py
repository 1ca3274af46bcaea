"""Energy and momentum watchdog: a run that is silently wrong stops with a clear error.

Every frame the :class:`Watchdog` measures (O(n), compiled) the kinetic energy split into the
leaf's rigid motion and its internal motion, the linear and angular momentum about the centre
of mass and the largest internal speed.  A drying leaf deforms at millimetres per second; its
internal motion is bounded by what the shrinking can drive.  Two signatures of a numerical
blow-up that produce no NaN are caught:

* an internal motion faster than a drying leaf can move: the mass-weighted RMS internal speed
  above :data:`MAX_RMS_SPEED` plus what the changing rest shape drives
  (``SHRINK_SPEED_FACTOR`` × (L × the fastest relative rest-length change per second + L²/2 ×
  the fastest change of the hinges' rest curvature per second) since the last check), or any
  particle's above :data:`MAX_INTERNAL_SPEED` (a single light margin particle may flutter at a
  fraction of that while a rolled leaf settles).  The shape allowance remembers: energy a
  sudden rest-shape change puts in takes time to damp out, so the allowance is the larger of
  the current shape speed and the previous allowance decayed with time constant
  :data:`RING_DOWN_S` (measured: an ellipse shrinking at 16-35 m/s of shape speed rings down at
  up to 0.30 m/s RMS for 0.06 s after its rest shape freezes; a runaway holds 1.1 m/s RMS for
  seconds at 0.07 m/s of shape speed).  A leaf that moves at its real speed (selective mass
  scaling: falling, swinging from its stalk, landing) flexes as it goes, with at most the
  energy its fall released: the allowance also holds √(2 g Δz), Δz the drop of the centre of
  mass from its highest point in the last :data:`FALL_WINDOW_S`, capped by the fastest rigid
  RMS speed in that window (a maple released beside its pin, undamped, swings with up to
  0.61 m/s RMS of internal motion after a 0.1 m drop; a leaf falling at its terminal speed
  gets that speed, 1.6 m/s, not the drop's);
* internal kinetic energy growing exponentially (doubling every ≤ :data:`DOUBLING_FRAMES`
  frames for :data:`GROWTH_WINDOWS` windows in a row) above a floor.

The error names the parameters most likely responsible (those changed from their defaults,
or from the run's quality level's settings, among the ones that drive the dynamics).
"""

from __future__ import annotations

import numpy as np

from leafsim.base.errors import Diverged
from leafsim.config.params import PARAMS, ParamSet
from leafsim.config.presets import QUALITY, quality_of
from leafsim.sim.kernels.rigid import internal_motion, momenta_sums

#: largest RMS (mass-weighted) internal speed of a drying leaf [m/s]
MAX_RMS_SPEED = 0.25
#: the shrinking moves the tissue at up to L × its relative rate; allowed on top of MAX_RMS_SPEED
SHRINK_SPEED_FACTOR = 3.0
#: the window [s] over which the centre of mass's drop counts (the energy of older falls is
#: spent or has rung down)
FALL_WINDOW_S = 1.0
#: time constant [s] with which the allowance for a rest-shape change decays once it stops
RING_DOWN_S = 0.1
#: largest internal (non-rigid) speed of any one particle [m/s]
MAX_INTERNAL_SPEED = 20.0
#: a growth window: internal kinetic energy compared every this many frames
DOUBLING_FRAMES = 50
#: consecutive windows of doubling (or faster) growth that count as a blow-up
GROWTH_WINDOWS = 6
#: ignore growth while the internal kinetic energy is below this × (mass × (L / s)²)
ENERGY_FLOOR = 1e-4
#: parameters that drive the dynamics, in the order they are blamed
#: suspects that only one integrator reads
SUN_ONLY = ("dynamics.sun_courant", "dynamics.sun_damping", "dynamics.sun_substeps", "material.turgor_pressure")
XPBD_ONLY = ("dynamics.relaxation", "dynamics.substeps", "dynamics.iterations")
SUSPECTS = ("material.turgor_pressure", "dynamics.sun_courant", "dynamics.sun_damping", "dynamics.sun_substeps", "dynamics.relaxation", "dynamics.dt", "dynamics.damping", "dynamics.substeps", "dynamics.iterations",
            "dynamics.mass_scaling", "dynamics.rigid_inertia", "dynamics.air_damping",
            "material.modulus", "material.vein_modulus", "material.dry_stiffening", "material.stiffening_stretch",
            "dynamics.substep_scaling",
            "shrink.sigma_surface_top", "shrink.sigma_surface_bottom", "shrink.sigma_vein", "shrink.l_min",
            "shrink.alpha", "dynamics.plasticity", "dynamics.gravity", "osmosis.evaporation_top",
            "osmosis.evaporation_bottom", "mesh.thickness")


def momenta(mass: np.ndarray, q: np.ndarray, qd: np.ndarray) -> dict:
    """Kinetic energy (total, rigid, internal) [J], linear momentum (3,) [kg·m/s], angular
    momentum about the centre of mass (3,) [kg·m²/s], largest internal speed [m/s].  The
    rigid part is the best-fit rigid motion (COM velocity + ω × r with I ω = L).  Three passes
    of compiled loops (:func:`~leafsim.sim.kernels.rigid.momenta_sums`,
    :func:`~leafsim.sim.kernels.rigid.internal_motion`; the numpy expressions they replace took
    16 × as long, docs/performance.md)."""
    if not (len(mass) == len(q) == len(qd) and q.shape[1:] == qd.shape[1:] == (3,)):
        raise ValueError(f"momenta: {len(mass)} masses, positions {q.shape}, velocities {qd.shape}: expected n, (n, 3), (n, 3)")
    s = np.empty(17)
    momenta_sums(np.ascontiguousarray(mass, np.float64), q, qd, s)
    M, c, v, Lang = float(s[0]), s[1:4].copy(), s[4:7].copy(), s[7:10].copy()
    xx, yy, zz, xy, xz, yz = s[10:16]
    I = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    try:
        w = np.linalg.solve(I, Lang)
    except np.linalg.LinAlgError:
        w = np.zeros(3)
    ke = float(s[16])
    ke_int, s2max = internal_motion(np.ascontiguousarray(mass, np.float64), q, qd, c, v, w)
    return {"mass": M, "com_z": float(c[2]), "kinetic": ke, "kinetic_internal": ke_int, "kinetic_rigid": ke - ke_int, "momentum": M * v,
            "angular_momentum": Lang, "omega": w, "rms_internal_speed": float(np.sqrt(2.0 * ke_int / M)),
            "max_internal_speed": float(np.sqrt(s2max))}


class Watchdog:
    """Per-frame checks of one run (see the module docstring).

    Parameters
    ----------
    model : Model; params : ParamSet (for blaming); every : check every this many frames.
    """

    def __init__(self, model, params: ParamSet, every: int = 1):
        self.model = model
        self.params = params
        self.every = max(int(every), 1)
        self.floor = ENERGY_FLOOR * float(model.particle_mass0.sum()) * model.length ** 2
        self.history: list[float] = []
        self.last: dict = {}
        self._rest = self._hrest = None
        self._time = 0.0
        self._allowance = 0.0
        self._heights: list[tuple[float, float, float]] = []  # (time, centre of mass height, rigid speed)

    def check(self, state) -> dict | None:
        """Measure ``state``; raise Diverged (a LeafsimError) on a blow-up.  Returns the measures (or None
        on frames that are skipped)."""
        if state.frame % self.every:
            return None
        m = self.model
        q, qd = state.particle_q, state.particle_qd
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            self._fail(state, "positions or velocities became NaN/Inf")
        mom = momenta(m.particle_cytosol + state.particle_water, q, qd)
        self.last = mom
        rigid = float(np.sqrt(2.0 * max(mom["kinetic_rigid"], 0.0) / max(mom["mass"], 1e-300)))
        bound = MAX_RMS_SPEED + self._allowance_for(state, self._fall_speed(state, mom["com_z"], rigid))
        if mom["rms_internal_speed"] > bound or mom["max_internal_speed"] > MAX_INTERNAL_SPEED:
            self._fail(state, f"internal motion at {mom['rms_internal_speed']:.3g} m/s RMS, {mom['max_internal_speed']:.3g} m/s "
                              f"at most (bounds {bound:.3g} and {MAX_INTERNAL_SPEED:g} m/s: drying tissue moves at "
                              "millimetres per second)")
        if (state.frame // self.every) % max(DOUBLING_FRAMES // self.every, 1) == 0:
            self.history.append(mom["kinetic_internal"])
            h = self.history[-(GROWTH_WINDOWS + 1):]
            if (len(h) == GROWTH_WINDOWS + 1 and h[0] > self.floor
                    and all(b >= 2.0 * a for a, b in zip(h[:-1], h[1:]))):
                self._fail(state, f"internal kinetic energy grew {h[-1] / h[0]:.3g}× in {GROWTH_WINDOWS * DOUBLING_FRAMES} "
                                  "frames without a source")
        return mom

    def _fall_speed(self, state, z: float, rigid: float) -> float:
        """What a fall can give the tissue: √(2 g Δz), Δz the centre of mass's drop from its
        highest point in the last FALL_WINDOW_S, but no more than the fastest rigid RMS speed
        in that window (a leaf falling at its terminal speed hands the fall's energy to the air,
        not to its tissue).  A run that went back in time (a reset) starts the window afresh."""
        now = state.time
        self._heights = [e for e in self._heights if now - FALL_WINDOW_S < e[0] <= now] + [(now, z, rigid)]
        drop = max(e[1] for e in self._heights) - z
        fastest = max(e[2] for e in self._heights)
        return min(float(np.sqrt(2.0 * float(self.params["dynamics.gravity"]) * max(drop, 0.0))), fastest)

    def _allowance_for(self, state, fall_speed: float) -> float:
        """SHRINK_SPEED_FACTOR × the shape speed + the fall speed, or the earlier allowance
        decayed by exp(-Δt / RING_DOWN_S) if larger."""
        before = self._time
        speed = SHRINK_SPEED_FACTOR * self._shape_speed(state) + fall_speed
        decayed = self._allowance * float(np.exp(-max(self._time - before, 0.0) / RING_DOWN_S))
        self._allowance = max(speed, decayed)
        return self._allowance

    def _shape_speed(self, state) -> float:
        """Speed [m/s] the rest shape's change since the previous check can drive: L × the
        largest relative rest-length rate + L²/2 × the largest rest-curvature rate."""
        m = self.model
        rest, hrest = state.spring_rest, state.hinge_rest
        speed = 0.0
        if self._rest is None:  # the first check: the change since the fresh leaf (time 0)
            self._rest, self._hrest, self._time = m.spring_rest0, np.zeros_like(hrest), 0.0
        if state.time > self._time:
            dt = state.time - self._time
            strain = float(np.max(np.abs(rest - self._rest) / np.maximum(m.spring_rest0, 1e-30))) if len(rest) else 0.0
            curv = (float(np.max(np.abs(hrest - self._hrest) / np.maximum(m.spring_rest0[m.hinge_spring_V], 1e-30)))
                    if len(hrest) else 0.0)
            speed = (m.length * strain + 0.5 * m.length ** 2 * curv) / dt
        self._rest, self._hrest = rest.copy(), hrest.copy()
        self._time = state.time
        return speed

    def _fail(self, state, what: str):
        # a quality level's own settings (draft: 10 substeps, ...) are its baseline, not a cause
        level = quality_of(self.params)
        base = {k: (QUALITY[level].get(k, PARAMS[k].default) if level else PARAMS[k].default) for k in SUSPECTS}
        # only the parameters of the integrator in use (and the integrator itself) are suspects
        sun = self.params["dynamics.integrator"] == "sun"
        skip = XPBD_ONLY if sun else SUN_ONLY
        changed = [k for k in SUSPECTS if k not in skip and k in self.params and self.params[k] != base[k]]
        if sun:
            changed = ["dynamics.integrator"] + changed
            base["dynamics.integrator"] = PARAMS["dynamics.integrator"].default
        what_base = f"{level} quality" if level else "default"
        blame = (", ".join(f"{k} = {_show(self.params[k])} ({what_base} {_show(base[k])})" for k in changed[:3])
                 if changed else f"none of the dynamics parameters differ from the {what_base} settings")
        raise Diverged(f"simulation unstable at frame {state.frame} (t = {state.time:.3f} s): {what}, "
                           f"fastest {where_fastest(self.model, state)}; likely cause: {blame}")


def where_fastest(model, state) -> str:
    """Where the particle moving fastest against the leaf's mean motion lies (or the first one
    whose position or velocity is not finite), in words: on the stalk, at the margin, on a vein
    or in the blade, and how far from the base (× L) — what a blow-up's message needs to point
    at its cause (the stalk's, on maple's finer meshes)."""
    qd = state.particle_qd
    mass = model.particle_cytosol + state.particle_water
    bad = ~np.isfinite(qd).all(1) | ~np.isfinite(state.particle_q).all(1)
    if bad.any():  # a NaN has no speed: the first particle that has one is where it is
        i = int(np.argmax(bad))
    else:
        v = qd - (mass[:, None] * qd).sum(0) / max(float(mass.sum()), 1e-300)
        i = int(np.argmax((v * v).sum(1)))
    if model.particle_petiole is not None and model.particle_petiole[i]:
        part = "on the stalk"
    elif model.particle_margin_distance[i] < 2.0 * model.spacing:
        part = "at the margin"
    elif model.particle_vein_order[i] >= 0:
        part = "on a vein"
    else:
        part = "in the blade"
    far = float(np.linalg.norm(model.particle_rest[i, :2] - model.particle_rest[model.base_particle, :2])) / model.length
    return f"{part}, {far:.2f} L from the base"


def _show(v) -> str:
    return f"{v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)

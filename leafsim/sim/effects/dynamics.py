"""The dynamics effect: XPBD substeps with springs, bending hinges, thickness volumes, ground
contact with friction and self-contacts, over coloured constraint sets (numba kernels of
:mod:`leafsim.sim.kernels.pbd`)."""

from __future__ import annotations

import math

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.sim.bending import hinge_weights
from leafsim.sim.kernels import blocked as kb
from leafsim.sim.kernels import pbd as kp
from leafsim.sim.kernels import rigid as kr
from leafsim.sim.kernels import sun as ks
from leafsim.sim.model import (
    LAYER_T,
    Model,
    State,
)

#: self-contact candidates are searched (spatial hash) at (1 + this) × the contact radius and
#: kept until the particles have moved against each other by what is left of that skin; the
#: projections walk only the near list filtered from it (:data:`CONTACT_NEAR_SKIN`).  The
#: results do not depend on either skin (canonical pair order; tests/test_kernels.py).
#: Measured on the bench's folded leaf: docs/performance.md.
CONTACT_SKIN = 3.0
#: a free leaf with a particle this close to the ground (× the blade's thickness) touches it
#: and keeps the scaled inertia (kernels.rigid): its contacts hold its weight.  Off the ground
#: it falls at the real g, so the hops a drying leaf makes where its curl lifts its centre
#: (under g / M M times higher than a real leaf's: maple after its hand-over up to 2
#: thicknesses, oak drying 20 × faster 0.05 L) and a dropped leaf's bounce stay real-sized
GROUND_REACH = 0.25
#: the most explicit steps Sun's integrator takes in one frame (dynamics.integrator = sun)
SUN_MAX_STEPS = 100_000
#: the near list holds the searched pairs closer than (1.05 + this) × the contact radius
CONTACT_NEAR_SKIN = 0.25


def held(model, params, effects) -> bool:
    """Something holds the leaf up, so it has a static equilibrium: it lies on the ground, or
    hangs by its pinned stalk, or nothing pulls it (no gravity)."""
    scene = params["dynamics.scene"]
    on_ground = bool(effects["ground"]) and scene == "ground"
    hanging = scene == "hanging" and bool(model.particle_pinned.any()) and bool(effects["pbd"])
    return on_ground or hanging or not effects["gravity"]


def effective_substeps(params, key: str = "dynamics.substeps") -> int:
    """Substeps per frame: ``dynamics.substeps`` at the default mesh spacing r₀, scaled by
    (r₀ / r)² with ``dynamics.substep_scaling``.  A bending hinge's XPBD stiffness relative to
    its particles' inertia per substep, k h² / (m ℓ²), falls like h² / r⁴; Gauss–Seidel carries
    a steady load (the blade's weight) across the mesh only while that number is not small,
    so h ∝ r² keeps a refined mesh converging (measured in docs/accuracy.md)."""
    from leafsim.config.params import PARAMS

    n = int(params[key])
    if params["dynamics.substep_scaling"]:
        n = round(n * (PARAMS["mesh.spacing"].default / params["mesh.spacing"]) ** 2)
    return int(min(max(n, 1), 4000 if key == "dynamics.sun_substeps" else 1000))


def substep_stiffness(params) -> float:
    """k h² / (M m ℓ²) up to a factor common to one species: h² / (M r⁴), with h the XPBD
    substep (:func:`effective_substeps`), M ``dynamics.mass_scaling`` and r ``mesh.spacing`` (× L):
    how stiff a bending hinge is against its particles' scaled inertia within one substep (the
    number :func:`effective_substeps` keeps constant as the mesh refines)."""
    h = params["dynamics.dt"] / effective_substeps(params)
    return h * h / (params["dynamics.mass_scaling"] * params["mesh.spacing"] ** 4)


def unmeasured_substeps(params) -> str | None:
    """A one-line warning when the XPBD substeps are coarser, for this mesh and mass scaling,
    than those of every quality level the accuracy study measured (:func:`substep_stiffness`
    above the coarsest level's, ``draft``), else None.  Nothing then says how far the shape is
    from the converged one, and the numbers say it is far: maple with ``dynamics.substeps`` 1
    dried nearly flat (margin lift 0.04 L against 0.37 L), with ``dynamics.dt`` 0.02 s to 0.29 L."""
    if params["dynamics.integrator"] != "xpbd" or not (params["effects.pbd"] or params["effects.bending"]):
        return None
    from leafsim.config.params import ParamSet
    from leafsim.config.presets import QUALITY

    coarsest = max(QUALITY, key=lambda k: substep_stiffness(ParamSet(QUALITY[k])))
    ratio = substep_stiffness(params) / substep_stiffness(ParamSet(QUALITY[coarsest]))
    if ratio <= 1.0 + 1e-9:
        return None
    h = params["dynamics.dt"] / effective_substeps(params)
    return (f"dynamics: substeps of {1e3 * h:.3g} ms (dynamics.dt {params['dynamics.dt']:g} s / "
            f"{effective_substeps(params)} substeps on mesh {params['mesh.spacing']:g} L, mass scaling "
            f"{params['dynamics.mass_scaling']:g}) are {ratio:.3g}x coarser in h^2/(M r^4) than the coarsest quality "
            f"level measured ({coarsest}): nothing says how far this shape is from the converged one (maple at "
            "dynamics.substeps 1 dries nearly flat); raise dynamics.substeps or lower dynamics.dt")


class Dynamics:
    """Gravity, XPBD constraints (distance, bending hinges, thickness), ground contact with
    friction, self-collision, damping and the Voronoi-layer handling (SPEC §8).

    The kernels see every constraint in *projection order*: the model's colour order, sorted by
    largest particle index inside each colour (no two constraints of one colour share a
    particle, so this changes no result and keeps the particle accesses nearly sequential),
    with uint32 indices.
    Per frame every constraint gets a record in that order (springs: rest length, compliance,
    1/W and both inverse masses; hinges: rest angle, compliance and four inverse masses;
    volumes: rest volume and four inverse masses), and the hinges and volumes are projected in
    SIMD blocks of one colour (:mod:`.kernels.blocked`)."""

    def __init__(self, model: Model):
        self.model = model
        #: solve the static equilibrium on the next frame whatever its number (set when a static
        #: finish takes over from the drying path, so the own mesh starts from its equilibrium)
        self.solve_now = False
        n = model.particle_count
        self.q_old = np.zeros((n, 3))
        self.invm = np.zeros(n)
        self.pen = np.zeros(n)
        self.sperm = projection_order(model.spring_ij, model.spring_colour_start)
        self.sij = model.spring_ij[self.sperm].astype(np.uint32)
        self.srec = np.zeros((model.spring_count, 5))
        self.slam = np.zeros(model.spring_count)
        self.hperm = projection_order(model.hinge_idx, model.hinge_colour_start)
        self.hidx = model.hinge_idx[self.hperm].astype(np.uint32)
        self.hrest = np.zeros(model.hinge_count)
        self.hlam = np.zeros(model.hinge_count)
        self.hrec = np.zeros((6, model.hinge_count))
        self.hblocks = kb.block_starts(model.hinge_colour_start)
        self.vperm = projection_order(model.vol_idx, model.vol_colour_start)
        self.vidx = model.vol_idx[self.vperm].astype(np.uint32)
        self.vrest = np.zeros(model.vol_count)
        self.vrec = np.zeros((5, model.vol_count))
        self.vblocks = kb.block_starts(model.vol_colour_start)
        self.blockbuf = kb.block_buffer()
        self.no_hinges = (np.zeros((0, 4), np.uint32), np.zeros((6, 0)), np.zeros(0), np.zeros(1, np.int64))
        self.hgt = np.zeros(model.vol_count)
        self.qa = np.zeros((n, 3))
        self.dint = np.zeros((n, 3))
        # hinge weights w (k = D w; leafsim.sim.bending, material.hinge_weights), projection
        # order; set by configure, per choice computed once
        self._weights: dict = {}
        self.hgeom = np.zeros(model.hinge_count)
        self.halpha = np.zeros(model.hinge_count)
        self.hrod = np.zeros(model.hinge_count)  # vein bending stiffness of the hinges that bend a vein
        T = np.flatnonzero(model.particle_layer == LAYER_T)
        self.T_idx = T.astype(np.int64)
        self.T_springs = np.flatnonzero(model.spring_layer == 0)
        # power of two ≥ 2 × |T| buckets: the contact hash uses a bit mask, not a 64-bit modulo
        self.table = np.zeros(1 << max(2 * len(T) - 1, 1).bit_length(), np.int64)
        self.out = np.zeros(3, np.int64)
        self.nxt = np.zeros(len(T), np.int64)
        # the contact lists (kernels.contacts.update_contacts): searched pairs and the near ones, with the T
        # positions (and rest positions) at the search and at the filtering, in T order (ascending,
        # as kernels.contacts.find_contacts needs); the lists double when a search fills them (the folded bench
        # leaf needs 2.3 pairs per T particle)
        self.pairs = np.zeros((4 * len(T) + 64, 2), np.int32)
        self.near = np.zeros_like(self.pairs)
        self.qc = np.zeros((len(T), 5))
        self.qn = np.zeros((len(T), 3))
        # search radius, search pairs (−1: none), searches, near reach, near pairs (−1: none),
        # filterings, a search overflowed its list, pairs within reach were missed
        self.cstate = np.array([0.0, -1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
        self.last_iterations = 0
        self.last_contacts = 0
        self.last_uninverted = 0

    @property
    def contact_searches(self) -> int:
        """Spatial-hash contact searches made so far (the Verlet skin skips the others)."""
        return int(self.cstate[2])

    def configure(self, params, effects):
        m = self.model
        mode = params["material.hinge_weights"]
        if mode not in self._weights:
            self._weights[mode] = hinge_weights(m, mode)
        self.hgeom = self._weights[mode][self.hperm]
        self.s_hgeom = self._weights[mode]
        dt = params["dynamics.dt"]
        self.dt = dt
        self.substeps = effective_substeps(params)
        self.h = dt / self.substeps
        # mass scaling (inertia × M, gravity ÷ M: the weight and every static force unchanged)
        self.mscale = float(params["dynamics.mass_scaling"])
        self.g = (-params["dynamics.gravity"] if effects["gravity"] else 0.0) / self.mscale
        # damping ÷ √M with the inertia × M: the scaled leaf moves exactly like the real one in
        # √M-stretched time (the same damping ratio); at the full rate the slowed modes were
        # overdamped ×√M more and a curled leaf took M times, not √M, longer to settle
        self.keep = math.exp(-params["dynamics.damping"] / math.sqrt(self.mscale) * self.h)
        # selective mass scaling (kernels.rigid): the rigid modes at their real inertia, damped
        # by the air in real time (also at M = 1: the rigid modes are damped by the air alone)
        on = params["dynamics.rigid_inertia"]
        # pinned: only at a stalk's tip (or one particle), where the leaf can swing; a blade
        # pinned over a patch at its base has no rigid mode (its moment about the patch is the
        # patch's stiff reaction, which amplified × (M − 1) blew up at M ≈ 3000)
        hanging = params["dynamics.scene"] == "hanging" and m.particle_pinned.any()
        stalk = (m.particle_petiole is not None and bool(m.particle_petiole.any())) or int(m.particle_pinned.sum()) == 1
        self.rigid_mode = 0 if not on else (1 if not hanging else (2 if stalk else 0))
        self.rigid_gain = self.mscale - 1.0
        self.air = params["dynamics.air_damping"]
        self.rigid_kratio = kr.air_factor(self.air, params["dynamics.damping"] / math.sqrt(self.mscale), self.h)
        self.iters = params["dynamics.iterations"]
        self.omega = params["dynamics.relaxation"]
        self.tol = params["dynamics.tolerance"] * m.length
        # membranes: k = E (h/2) ΣA/|e|² per layer (Van Gelder), veins add their rod E_v A_c / l
        E, Ev, h = params["material.modulus"], params["material.vein_modulus"], m.thickness
        k = E * 0.5 * h * m.spring_weight + Ev * m.spring_rod
        self.salpha = 1.0 / np.maximum(k, 1e-300) / (self.h * self.h)
        # dry stiffening of stretching (material.stiffening_stretch): the lamina's share of k
        self.kstretch = params["material.stiffening_stretch"] * params["material.dry_stiffening"]
        self.klam = E * 0.5 * h * m.spring_weight
        self.krod = Ev * m.spring_rod
        self.kdyn = np.zeros(m.spring_count) if self.kstretch > 0.0 else None
        # bending: D = E h³ / 12(1 − ν²) on discrete-shell hinges, veins add E_v I / ℓ̄
        self.kbend = E * h ** 3 / (12.0 * (1.0 - params["material.poisson"] ** 2))
        self.kdry = params["material.dry_stiffening"]
        self.turgor = params["material.turgor_share"]
        self.tlp = params["material.turgor_loss_rwc"]
        self.dry_power = params["material.stiffening_power"]
        np.multiply(Ev, m.hinge_rod[self.hperm], out=self.hrod)
        self.replace = params["dynamics.voronoi"] == "replace"
        self.scene = params["dynamics.scene"]
        self.mu = params["dynamics.friction"]
        self.radius = params["dynamics.collision_radius"] * m.spacing
        self.skip2 = (params["dynamics.collision_skip"] * m.spacing) ** 2
        self.cstate[1] = -1.0  # search again
        self.pbd = effects["pbd"]
        self.f32 = params["dynamics.precision"] == "float32"
        self.bending = effects["bending"] and m.hinge_count > 0 and self.kbend > 0
        self.ground = effects["ground"] and self.scene == "ground"
        self.self_coll = effects["self_collision"]
        self.sun = params["dynamics.integrator"] == "sun"
        self.static = params["dynamics.integrator"] == "static"
        if self.sun or self.static:
            self._configure_sun(params, k, E)
        if self.static:
            from leafsim.sim.equilibrium import Equilibrium

            if not held(m, params, effects):
                raise LeafsimError("dynamics.integrator = static: a leaf that nothing holds up has no equilibrium "
                                   "(it falls): expected dynamics.scene ground with effects.ground, or hanging with "
                                   "effects.pbd, or the xpbd integrator")
            was = getattr(self, "static_scene", None)
            self.static_scene = self.scene

            self.static_every = int(params["dynamics.static_every"])

            if getattr(self, "equilibrium", None) is None:
                self.equilibrium = Equilibrium(m, self)
            elif was != self.scene:
                self.equilibrium.reset()  # another scene (or back from another integrator)
            self.equilibrium.configure(params)
        else:
            self.static_scene = None

    def _configure_sun(self, params, k, E) -> None:
        """Sun's explicit integrator (:mod:`.kernels.sun`): its own step count (scaled with the
        mesh like the XPBD substeps), the springs' stiffness k [N/m] in model order, the
        thickness volumes' k_V = E / (2 C₀) from the current rest volumes (per frame), the
        drag c ÷ √M (the scaled leaf moves like the real one in √M-stretched time; the Rayleigh
        damping is set per frame from the stiffest mode), and the turgor force's per-spring contact area a = (h/2) × the face between the
        two cells (membrane springs of either layer)."""
        m = self.model
        self.sun_min_steps = effective_substeps(params, "dynamics.sun_substeps")
        self.sun_courant = params["dynamics.sun_courant"]
        self.sun_steps = self.sun_min_steps
        self.zeta = params["dynamics.sun_damping"]
        # the largest ω h the damped midpoint rule takes (every slower mode included)
        self.sun_limit = min(self.sun_courant, ks.stable_courant(self.zeta))
        self.sk = np.ascontiguousarray(k, dtype=np.float64)
        self.beta = 0.0
        self.drag = params["dynamics.damping"] / math.sqrt(self.mscale)
        self.vmod = E
        self.p_turgor = params["material.turgor_pressure"]
        if not hasattr(self, "sF"):
            n = m.particle_count
            self.sF, self.sacc, self.sqm, self.svm = (np.zeros((n, 3)) for _ in range(4))
            self.srow = np.zeros(n)
            self.s_ij = m.spring_ij.astype(np.uint32)
            self.s_hidx = m.hinge_idx.astype(np.uint32)
            self.s_vidx = m.vol_idx.astype(np.uint32)
            self.s_hk = np.zeros(m.hinge_count)
            self.s_vk = np.zeros(m.vol_count)
            self.s_tf = np.zeros(m.spring_count)
            membrane = m.spring_layer != 2
            self.s_area = np.where(membrane, 0.5 * m.thickness * m.spring_face, 0.0)
        self.s_hrod = params["material.vein_modulus"] * m.hinge_rod

    def gather(self, state) -> tuple:
        """This frame's inverse masses and constraint records in projection order (springs:
        :func:`~.kernels.pbd.pack_springs`; hinges, from their compliances and rest angles:
        :func:`~.kernels.blocked.pack_hinges`; volumes: :func:`~.kernels.blocked.pack_volumes`).
        Returns the constraint tuple ``cons`` of :func:`~.kernels.pbd.iteration`."""
        m = self.model
        np.divide(1.0 / self.mscale, m.particle_cytosol + state.particle_water, out=self.invm)
        if self.scene == "hanging":
            self.invm[m.particle_pinned] = 0.0
        if self.kdyn is not None:
            kp.spring_stiffness(m.spring_ij, state.particle_water, m.particle_water0, self.klam, self.krod, self.kstretch,
                                self.dry_power, self.kdyn)
            np.divide(1.0 / (self.h * self.h), np.maximum(self.kdyn, 1e-300), out=self.salpha)
        kp.pack_springs(self.sperm, self.sij, self.invm, state.spring_rest, self.salpha, self.srec)
        np.take(state.vol_rest, self.vperm, out=self.vrest)
        kb.pack_volumes(self.vidx, self.invm, self.vrest, self.vrec)
        if self.pbd and self.bending:
            kp.hinge_compliance(self.hidx, state.particle_water, m.particle_water0, self.kbend, self.kdry, self.hgeom,
                                self.hrod, 1.0 / (self.h * self.h), self.halpha, self.turgor, self.tlp, self.dry_power)
            np.take(state.hinge_rest, self.hperm, out=self.hrest)
            kb.pack_hinges(self.hidx, self.invm, self.hrest, self.halpha, self.hrec)
            hinges = (self.hidx, self.hrec, self.hlam, self.hblocks)
        else:
            hinges = self.no_hinges
        return (self.sij, self.srec, self.slam) + hinges + (self.vidx, self.vrec, self.vblocks, self.blockbuf)

    def apply(self, state: State):
        m = self.model
        if self.sun:
            self._apply_sun(state)
            return
        if self.static:
            if state.frame % self.static_every and not self.solve_now:
                return
            self.solve_now = False
            info = self.equilibrium.solve(state)
            self.last_iterations = info.iterations
            self.last_contacts = info.contacts
            self.last_uninverted = 0
            return
        self._xpbd(state)

    def _xpbd(self, state: State) -> None:
        """One XPBD frame (:func:`~.kernels.pbd.frame`) on ``state``."""
        m = self.model
        cons = self.gather(state)
        # contacts and the un-inversion keep to the tissue's size: as it shrinks (in the plane and
        # through the thickness) so do the contact radius and the thickness (fixed values would
        # hold a strongly shrunken leaf apart against its own springs)
        shrunk = max(float(np.mean(state.spring_rest[self.T_springs] / m.spring_rest0[self.T_springs])), 0.1)
        radius = self.radius * shrunk
        # a snapshot to run the frame again from if a contact list overflowed so badly that
        # pairs within reach were missed (cstate[7]; a list that merely filled is handled inside
        # the frame and only grows before the next one)
        snap = (state.particle_q.copy(), state.particle_qd.copy()) if self.pbd and self.self_coll else None
        while True:
            if self.cstate[6]:
                self._grow_contact_lists()
            out = self._frame(state, cons, radius, shrunk)
            if not self.cstate[7]:
                break
            state.particle_q[:] = snap[0]
            state.particle_qd[:] = snap[1]
        self.last_iterations = int(out[0])
        self.last_contacts = int(out[1])
        self.last_uninverted = int(out[2])

    def sun_elastic(self, state: State) -> tuple:
        """This frame's elastic records for :func:`.kernels.sun.frame`, in model order: spring
        stiffness and rest lengths, hinge stiffness (the XPBD hinge's, with drying, turgor and
        veins) and rest angles, volume stiffness and rest volumes, and Sun's turgor force per
        spring, a ΔP with ΔP = P (τ − 1) averaged over the spring's two cells, τ the share of
        turgor left (linear in RWC down to the turgor-loss point)."""
        m = self.model
        np.divide(1.0 / self.mscale, m.particle_cytosol + state.particle_water, out=self.invm)
        if self.scene == "hanging":
            self.invm[m.particle_pinned] = 0.0
        if self.pbd and self.bending:
            kp.hinge_compliance(self.s_hidx, state.particle_water, m.particle_water0, self.kbend, self.kdry,
                                self.s_hgeom, self.s_hrod, 1.0, self.s_hk, self.turgor, self.tlp, self.dry_power)
            np.divide(1.0, self.s_hk, out=self.s_hk)
            hinges = (self.s_hidx, self.s_hk)
        else:
            hinges = (self.s_hidx[:0], self.s_hk[:0])
        if self.kdyn is not None:
            kp.spring_stiffness(m.spring_ij, state.particle_water, m.particle_water0, self.klam, self.krod, self.kstretch,
                                self.dry_power, self.sk)
        np.divide(self.vmod * 0.5, np.maximum(np.abs(state.vol_rest), 1e-300), out=self.s_vk)
        if self.p_turgor > 0.0:
            rwc = state.particle_water / np.maximum(m.particle_water0, 1e-300)
            tau = np.clip((rwc - self.tlp) / max(1.0 - self.tlp, 1e-9), 0.0, 1.0)
            dp = self.p_turgor * (0.5 * (tau[m.spring_ij[:, 0]] + tau[m.spring_ij[:, 1]]) - 1.0)
            np.multiply(self.s_area, dp, out=self.s_tf)
        else:
            self.s_tf[:] = 0.0
        if not self.pbd:  # gravity alone: no internal forces
            return (self.s_ij[:0], self.sk[:0], state.spring_rest[:0], self.s_tf[:0], self.s_hidx[:0], self.s_hk[:0],
                    state.hinge_rest[:0], self.s_vidx[:0], self.s_vk[:0], state.vol_rest[:0])
        return (self.s_ij, self.sk, state.spring_rest, self.s_tf) + hinges + (state.hinge_rest, self.s_vidx, self.s_vk,
                                                                              state.vol_rest)

    def _apply_sun(self, state: State) -> None:
        """One frame of Sun's explicit midpoint integrator (float64 always)."""
        m = self.model
        elastic = self.sun_elastic(state)
        # the step: the stiffest mode's ω h within the Courant limit (a Gershgorin bound on ω,
        # this frame's stiffness and masses), and at least the floor dynamics.sun_substeps
        ij, sk, _, _, hidx, hk, _, vidx, vk, _ = elastic
        w2 = ks.stiffness_bound(state.particle_q, self.invm, ij, sk, hidx, hk, vidx, vk, self.srow)
        if not math.isfinite(w2):
            raise LeafsimError(f"dynamics.integrator = sun: the stiffness is not finite at frame {state.frame} "
                               f"(positions or material values): expected a finite state")
        need = math.ceil(self.dt * math.sqrt(max(w2, 0.0)) / self.sun_limit)
        if need > SUN_MAX_STEPS:
            raise LeafsimError(f"dynamics.integrator = sun needs {need} steps per frame (more than {SUN_MAX_STEPS}): "
                               f"expected a smaller dynamics.dt or the xpbd integrator for this stiffness")
        self.sun_steps = max(self.sun_min_steps, need)
        self.sun_h = self.dt / self.sun_steps
        # Rayleigh damping β = 2ζ/ω: damping ratio ζ at the bound, less below it
        self.beta = 2.0 * self.zeta / math.sqrt(w2) if w2 > 0.0 else 0.0
        shrunk = max(float(np.mean(state.spring_rest[self.T_springs] / m.spring_rest0[self.T_springs])), 0.1)
        radius = self.radius * shrunk
        contact = (m.particle_rest, self.T_idx, radius, CONTACT_SKIN * radius, CONTACT_NEAR_SKIN * radius, self.skip2,
                   self.table, self.nxt, self.pairs, self.qc, self.near, self.qn, self.cstate)
        snap = (state.particle_q.copy(), state.particle_qd.copy()) if self.pbd and self.self_coll else None
        while True:
            if self.cstate[6]:
                self._grow_contact_lists()
                contact = contact[:8] + (self.pairs, self.qc, self.near, self.qn, self.cstate)
            out = self.out
            out[:] = 0
            self.last_energy = ks.frame(state.particle_q, state.particle_qd, self.q_old, self.invm, self.g, self.sun_h,
                                        self.sun_steps, self.drag, self.beta, elastic, self.ground, self.pen, self.mu,
                                        self.pbd and self.self_coll, contact, self.replace, self.hgt, m.thickness * shrunk,
                                        self.sF, self.sacc, self.sqm, self.svm, self.qa, self.pbd, m.vol_idx,
                                        self._rigid(state, kr.air_factor(self.air, self.drag, self.sun_h)), out)
            # fastmath kernels cannot test for NaN: the positions are checked here
            if not (np.isfinite(state.particle_q).all() and np.isfinite(state.particle_qd).all()):
                raise LeafsimError(f"dynamics.integrator = sun blew up at frame {state.frame} with {self.sun_steps} steps "
                                   f"(dynamics.sun_courant = {self.sun_courant:g}, dynamics.sun_damping = {self.zeta:g}): "
                                   f"expected a smaller Courant number or more damping")
            if not self.cstate[7]:
                break
            state.particle_q[:] = snap[0]
            state.particle_qd[:] = snap[1]
        self.last_iterations = int(out[0])
        self.last_contacts = int(out[1])
        self.last_uninverted = int(out[2])

    def _grow_contact_lists(self) -> None:
        """Twice the room for the contact lists, searched afresh."""
        self.pairs = np.zeros((2 * len(self.pairs), 2), np.int32)
        self.near = np.zeros_like(self.pairs)
        self.cstate[1] = -1.0
        self.cstate[4] = -1.0
        self.cstate[6] = 0.0
        self.cstate[7] = 0.0

    def _frame(self, state: State, cons: tuple, radius: float, shrunk: float) -> np.ndarray:
        """One :func:`~.kernels.pbd.frame` call on ``state`` (on float32 copies with
        ``dynamics.precision`` float32); returns its counters."""
        m = self.model
        contact = (m.particle_rest, self.T_idx, radius, CONTACT_SKIN * radius, CONTACT_NEAR_SKIN * radius, self.skip2,
                   self.table, self.nxt, self.pairs, self.qc, self.near, self.qn, self.cstate)
        out = self.out
        out[:] = 0
        out[1] = self.last_contacts
        out[2] = self.last_uninverted
        q, qd, q_old, invm, pen, hgt, qa, dint = (state.particle_q, state.particle_qd, self.q_old, self.invm, self.pen,
                                                  self.hgt, self.qa, self.dint)
        if self.f32:  # the frame on float32 copies (the state stays float64 and holds their values)
            w = self._f32_buffers()
            cons = tuple(w.get(id(a), a) if a.dtype == np.float64 else a for a in cons)
            for a in cons:
                if a.dtype == np.float32:
                    np.copyto(a, self._f64_of[id(a)], casting="same_kind")
            contact = contact[:9] + (w["qc"], self.near, w["qn"], self.cstate)
            np.copyto(w["q"], q, casting="same_kind")
            np.copyto(w["qd"], qd, casting="same_kind")
            np.copyto(w["invm"], invm, casting="same_kind")
            q, qd, q_old, invm, pen, hgt, qa, dint = (w[k] for k in ("q", "qd", "q_old", "invm", "pen", "hgt", "qa", "dint"))
        # the whole frame (all substeps and iterations) in one numba call
        kp.frame(q, qd, q_old, invm, self.g, self.h, self.substeps,
                 self.keep, self.iters, self.tol, cons, m.vol_idx,
                 self.pbd, self.ground, pen, self.mu, self.self_coll, contact,
                 self.replace, hgt, m.thickness * shrunk, self.scene != "hanging",
                 qa, dint, self.omega, self._rigid(state), out)
        if self.f32:
            state.particle_q[:] = q
            state.particle_qd[:] = qd
        return out

    def _rigid(self, state: State, kratio: float | None = None) -> tuple:
        """The ``rigid`` argument of :func:`~.kernels.pbd.frame`: the mode, the pin (the mean of
        the pinned particles, which do not move), M − 1, the air's velocity factor and the
        ground's reach (:data:`GROUND_REACH` × the thickness)."""
        m = self.model
        mode = self.rigid_mode if self.pbd or self.rigid_mode == 1 else 0
        pin = state.particle_q[m.particle_pinned].mean(axis=0) if mode == 2 else (0.0, 0.0, 0.0)
        kratio = self.rigid_kratio if kratio is None else kratio
        return (mode, float(pin[0]), float(pin[1]), float(pin[2]), self.rigid_gain, kratio,
                GROUND_REACH * m.thickness)

    def _f32_buffers(self) -> dict:
        """float32 twins of the frame's float arrays (made once): by name for the per-particle
        ones, by ``id`` of the float64 array for the constraint records (``_f64_of`` maps back);
        the contact lists' positions ``qc`` and ``qn`` persist between frames like the float64
        ones."""
        if getattr(self, "_w32", None) is None:
            n = self.model.particle_count
            w = {k: np.zeros((n, 3), np.float32) for k in ("q", "qd", "q_old", "qa", "dint")}
            w.update(invm=np.zeros(n, np.float32), pen=np.zeros(n, np.float32), hgt=np.zeros(len(self.hgt), np.float32),
                     qc=self.qc.astype(np.float32), qn=self.qn.astype(np.float32))
            self._f64_of = {}
            for a in (self.srec, self.slam, self.hrec, self.hlam, self.vrec, self.blockbuf, self.no_hinges[1],
                      self.no_hinges[2]):
                b = a.astype(np.float32)
                w[id(a)] = b
                self._f64_of[id(b)] = a
            self._w32 = w
            self.cstate[1] = -1.0  # the float32 list is searched afresh
        return self._w32


def projection_order(idx: np.ndarray, colour_start: np.ndarray) -> np.ndarray:
    """Permutation of constraints ``idx`` (k, p) that keeps the colour order ``colour_start``
    and sorts each colour by its largest particle index (no two constraints of a colour share a
    particle, so the order inside a colour changes no result).  Measured at 100 k particles,
    interleaved: springs 9.9 → 9.0 ns and hinges 24.7 → 23.0 ns against the smallest index
    (the largest-index particles are then visited in order; no difference on the maple leaf)."""
    key = idx.max(axis=1) if len(idx) else np.zeros(0, np.int64)
    parts = [a + np.argsort(key[a:b], kind="stable") for a, b in zip(colour_start[:-1], colour_start[1:])]
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)



"""Immutable blade :class:`Model` (topology, rest state) and time-varying :class:`State`.

Names carry the element type (warp.sim style): ``particle_*`` (n,), ``spring_*`` (s,),
``tri_*`` (m,), ``hinge_*`` (h,), ``vol_*`` (m,).  Constraint arrays are stored sorted by
graph colour; ``*_colour_start`` (k+1,) gives the colour offsets, so that every colour can be
projected in parallel (Gauss–Seidel between colours, no write conflicts inside one).
"""

from __future__ import annotations

import functools
import hashlib

from dataclasses import dataclass, field
from typing import Any

import numpy as np

# particle layers / kinds
LAYER_T, LAYER_V = 0, 1
KIND_SURFACE, KIND_CONTOUR, KIND_VEIN, KIND_VORONOI, KIND_PETIOLE = 0, 1, 2, 3, 4
# spring types
SPRING_SURFACE, SPRING_VEIN, SPRING_V, SPRING_LINK = 0, 1, 2, 3


@dataclass(frozen=True)
class State:
    """Time-varying arrays of one leaf.

    particle_q : (n, 3) float64 positions [m];  particle_qd : (n, 3) velocities [m/s];
    particle_water : (n,) water [kg];  spring_rest : (s,) current rest lengths [m];
    hinge_plastic : (h,) plastic rest angle of the bending hinges [rad];
    time [s], frame, weather_time [s]; pigments : :class:`leafsim.sim.pigments.PigmentState` or None (the
    :class:`~leafsim.sim.simulator.Simulator` gives every state it makes one).  Arrays are
    mutated in place by the simulator; ``copy()`` snapshots everything.
    """

    particle_q: np.ndarray
    particle_qd: np.ndarray
    particle_water: np.ndarray
    spring_rest: np.ndarray
    hinge_rest: np.ndarray
    hinge_plastic: np.ndarray
    vol_rest: np.ndarray
    scalars: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [time, frame, weather time]
    pigments: Any = None
    path: Any = None  # the State of the drying-path mesh (Model.path), while it carries the mechanics
    #: the :attr:`Model.fingerprint` of the model this state is of ("" unknown): a state of another
    #: build of the same size (another seed) fits every array's shape, and gave wrong numbers
    model_key: str = ""

    @property
    def time(self) -> float:
        return float(self.scalars[0])

    @property
    def weather_time(self) -> float:
        """Real seconds of weather the leaf has dried in (``environment.drive = weather``: Δt ×
        the time warp in force at each frame; 0 while the rates drive)."""
        return float(self.scalars[2])

    @property
    def frame(self) -> int:
        return int(self.scalars[1])

    def copy(self) -> "State":
        arrays = {f: np.array(getattr(self, f)) for f in self.__dataclass_fields__ if f not in NOT_ARRAYS}
        return State(**arrays, pigments=None if self.pigments is None else self.pigments.copy(),
                     path=None if self.path is None else self.path.copy(), model_key=self.model_key)


#: the fields of a :class:`State` that are not its own arrays
NOT_ARRAYS = ("pigments", "path", "model_key")


@dataclass(frozen=True)
class Model:
    """Array-backed, immutable two-layer blade model (build with :func:`leafsim.blade.build.build_blade`).

    Particles
    ---------
    particle_rest (n,3) [m], particle_layer (n,) int8 0=T 1=V, particle_kind (n,) int8,
    particle_vein_order (n,) int8 (−1 for none), particle_area (n,) [m²] the blade area a
    particle stands for in its layer (T: a third of its triangles, V: its triangle),
    particle_cytosol (n,) dry mass [kg], particle_mass0 (n,) fresh mass [kg],
    particle_water0 (n,) [kg], particle_tau (n,) Jeong's graph-distance weight,
    particle_vein_width (n,) [m] (0 off the veins), particle_margin_distance (n,) [m] rest
    distance to the outline, particle_texcoord (n,2),
    particle_pinned (n,) bool (the petiole's tip, or the blade at the base without one: the
    hanging scene).  Each layer carries half the blade's areal mass; vein particles add their
    rod.  particle_petiole (n,) bool the stalk's particles (:mod:`leafsim.blade.petiole`; both
    layers, the base particle excluded), or None for a model without a petiole.

    Triangles (layer T) and Voronoi dual (layer V)
    ----------------------------------------------
    tri_T (m,3) CCW seen from +z, tri_V (m,) index of the V particle of each triangle.

    Springs (colour-sorted)
    -----------------------
    spring_ij (s,2), spring_rest0 (s,), spring_type (s,) int8 (SPRING_*), spring_layer (s,)
    0 T / 1 V / 2 link, spring_order (s,) vein order or −1, spring_colour_start;
    spring_weight (s,) membrane weight ΣA/|e|² (the area a spring stands for over its length
    squared: stiffness = E × layer thickness × weight, Van Gelder), spring_rod (s,) [m] vein
    cross-section / length (rod stiffness = E_vein × rod), spring_face (s,) [m] finite-volume
    face across which water flows (T edges: the barycentric dual; V springs: the shared T edge).

    Bending hinges on interior T edges (colour-sorted)
    --------------------------------------------------
    hinge_idx (h,4) = (c, d, a, b): opposite vertices c, d and shared edge a–b;
    hinge_spring_T (h,) the T spring a–b, hinge_spring_V (h,) the V spring across it,
    hinge_edge_len (h,), hinge_area (h,) area of the two triangles, hinge_colour_start;
    hinge_rod (h,) [m³] vein bending weight I/ℓ̄ (stiffness E_vein × rod, for hinges that bend a
    vein along its length), hinge_vein (h,) bool such a hinge on a main or lateral vein.

    Layer thickness (colour-sorted)
    -------------------------------
    vol_idx (m,4) = (v, a, b, c), vol_rest0 (m,) = 6 × signed volume of tetrahedron at rest,
    vol_springs (m,3) the three T springs of the triangle, vol_colour_start.

    Hydraulic patches
    -----------------
    particle_patch (n,) the seeded smooth patch field of :func:`leafsim.blade.build.patch_field`
    (zero mean, unit spread): where it is high the blade loses water faster
    (``osmosis.patchiness``); None for models made without it (zero).

    Drying path
    -----------
    path : a coarser Model of the same leaf (same outline and veins) that carries the mechanics
    while the leaf dries (``dynamics.path``, :mod:`leafsim.sim.path`); None: this mesh does.

    Veins for renderers
    -------------------
    vein_particles (k,) concatenated particle indices, vein_start (nv+1,), vein_order (nv,),
    vein_width (k,) [m].  contour_particles (c,) in contour order.
    """

    particle_rest: np.ndarray
    particle_layer: np.ndarray
    particle_kind: np.ndarray
    particle_vein_order: np.ndarray
    particle_area: np.ndarray
    particle_cytosol: np.ndarray
    particle_mass0: np.ndarray
    particle_water0: np.ndarray
    particle_tau: np.ndarray
    particle_vein_width: np.ndarray
    particle_margin_distance: np.ndarray
    particle_texcoord: np.ndarray
    particle_pinned: np.ndarray
    tri_T: np.ndarray
    tri_V: np.ndarray
    spring_ij: np.ndarray
    spring_rest0: np.ndarray
    spring_type: np.ndarray
    spring_layer: np.ndarray
    spring_order: np.ndarray
    spring_weight: np.ndarray
    spring_rod: np.ndarray
    spring_face: np.ndarray
    spring_colour_start: np.ndarray
    hinge_idx: np.ndarray
    hinge_spring_T: np.ndarray
    hinge_spring_V: np.ndarray
    hinge_edge_len: np.ndarray
    hinge_area: np.ndarray
    hinge_rod: np.ndarray
    hinge_vein: np.ndarray
    hinge_colour_start: np.ndarray
    vol_idx: np.ndarray
    vol_rest0: np.ndarray
    vol_springs: np.ndarray
    vol_colour_start: np.ndarray
    vein_particles: np.ndarray
    vein_start: np.ndarray
    vein_order: np.ndarray
    vein_width: np.ndarray
    contour_particles: np.ndarray
    base_particle: int
    length: float
    thickness: float
    spacing: float
    vein_edge_share: float
    particle_patch: np.ndarray | None = None
    path: "Model | None" = None
    particle_petiole: np.ndarray | None = None
    seed: int | None = None  # the seed build_leaf built it with (a Simulator's default seed); None: unknown
    built_with: tuple | None = None  # ParamSet.build_values() of the build (build_leaf); None: unknown

    # ------------------------------------------------------------------ blade vs stalk
    @property
    def blade_particles(self) -> np.ndarray:
        """(n,) bool: particles of the blade (everything but the petiole)."""
        if self.particle_petiole is None:
            return np.ones(self.particle_count, bool)
        return ~self.particle_petiole

    @property
    def blade_T(self) -> np.ndarray:
        """(n,) bool: layer-T particles of the blade (the petiole's left out)."""
        return (self.particle_layer == LAYER_T) & self.blade_particles

    @property
    def blade_tri_T(self) -> np.ndarray:
        """(m_b, 3) the blade's T triangles (the petiole's left out)."""
        return self.tri_T if self.particle_petiole is None else self.tri_T[self.blade_tris]

    @property
    def blade_tris(self) -> np.ndarray:
        """(m,) bool: T triangles of the blade (none of whose vertices is the petiole's)."""
        if self.particle_petiole is None:
            return np.ones(self.tri_count, bool)
        return ~self.particle_petiole[self.tri_T].any(1)

    # ------------------------------------------------------------------ counts
    @property
    def particle_count(self) -> int:
        return len(self.particle_rest)

    @property
    def spring_count(self) -> int:
        return len(self.spring_ij)

    @property
    def tri_count(self) -> int:
        return len(self.tri_T)

    @property
    def hinge_count(self) -> int:
        return len(self.hinge_idx)

    @property
    def vol_count(self) -> int:
        return len(self.vol_idx)

    @property
    def areal_mass0(self) -> np.ndarray:
        """(n,) fresh mass per area [kg/m²] of every particle (veins heavier than the lamina)."""
        return self.particle_mass0 / np.maximum(self.particle_area, 1e-300)

    def vein_polylines(self) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Per vein: (particle indices (k,), widths (k,) m, order)."""
        out = []
        for v in range(len(self.vein_order)):
            a, b = self.vein_start[v], self.vein_start[v + 1]
            out.append((self.vein_particles[a:b], self.vein_width[a:b], int(self.vein_order[v])))
        return out

    def state(self) -> State:
        """A fresh State at rest: positions = rest, zero velocity, full water (and a fresh
        state of the drying-path mesh when the model has one)."""
        return State(
            particle_q=self.particle_rest.copy(),
            particle_qd=np.zeros_like(self.particle_rest),
            particle_water=self.particle_water0.copy(),
            spring_rest=self.spring_rest0.copy(),
            hinge_rest=np.zeros(self.hinge_count),
            hinge_plastic=np.zeros(self.hinge_count),
            vol_rest=self.vol_rest0.copy(),
            path=None if self.path is None else self.path.state(),
            model_key=self.fingerprint,
        )

    @functools.cached_property
    def fingerprint(self) -> str:
        """Short hash of the model's geometry and topology: two builds that differ in anything
        a state depends on (seed, mesh, species) differ here; a rebuild of the same model does
        not (a checkpoint must match it)."""
        h = hashlib.sha256()
        for a in (self.particle_rest, self.spring_ij, self.spring_rest0, self.hinge_idx, self.vol_idx,
                  self.particle_cytosol, self.particle_water0):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:20]

    def water_fraction(self, water: np.ndarray) -> float:
        """The blade's water now / fresh (``water`` the (n,) particle water [kg]).  "Dry"
        (2 % left, the GUI's "Dry to end", ``--until dry``, the accuracy protocol) means the
        blade: the petiole, a thick rod, holds its water far longer, as a real stalk does."""
        b, w0 = self._blade_water0
        return float(water[b].sum() / w0)

    @functools.cached_property
    def _blade_water0(self) -> tuple[np.ndarray, float]:
        """(blade particle indices, the fresh blade's water, ≥ 1e-300): what every
        :meth:`water_fraction` needs, computed once (a model's arrays are fixed once built; three
        calls a frame on a 132 k-particle leaf took 1 ms)."""
        b = np.flatnonzero(self.blade_particles)
        return b, max(float(self.particle_water0[b].sum()), 1e-300)

    def blade_area(self) -> float:
        """Rest area of the blade's triangles [m²] (the petiole's left out)."""
        r = self.particle_rest
        t = self.blade_tri_T
        u, v = r[t[:, 1], :2] - r[t[:, 0], :2], r[t[:, 2], :2] - r[t[:, 0], :2]
        return float(0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum())

    def to_report(self) -> dict:
        """Counts per layer and type plus vein_edge_share (the CLI ``build --json``)."""
        lay = self.particle_layer
        st = self.spring_type
        return {
            "particles": self.particle_count,
            "particles_T": int((lay == LAYER_T).sum()),
            "particles_V": int((lay == LAYER_V).sum()),
            "springs": self.spring_count,
            "springs_T": int(((st == SPRING_SURFACE) | (st == SPRING_VEIN)).sum()),
            "springs_V": int((st == SPRING_V).sum()),
            "springs_link": int((st == SPRING_LINK).sum()),
            "springs_vein": int((st == SPRING_VEIN).sum()),
            "triangles": self.tri_count,
            "hinges": self.hinge_count,
            "veins": int(len(self.vein_order)),
            "vein_edge_share": float(self.vein_edge_share),
            "colours": {
                "springs": int(len(self.spring_colour_start) - 1),
                "hinges": int(len(self.hinge_colour_start) - 1),
                "volumes": int(len(self.vol_colour_start) - 1),
            },
            "length_m": self.length,
            "thickness_m": self.thickness,
            "spacing_m": self.spacing,
            "area_m2": self.blade_area(),
            "petiole_particles": int((~self.blade_particles).sum()),
            "fresh_mass_kg": float(self.particle_mass0.sum()),
            "fresh_water_kg": float(self.particle_water0.sum()),
            "fresh_blade_water_kg": float(self.particle_water0[self.blade_particles].sum()),
        }

"""The one declaration of every tunable parameter in leafsim.

Each :class:`Param` names a value once (dotted path such as ``veins.lateral.spacing``) with
its type, default, range, unit, help text, GUI group and whether changing it needs a rebuild
(``rebuild=True``: outline, veins or mesh must be regenerated) or applies live while the leaf
keeps drying.  Validation, species JSON, the CLI ``--set KEY=VALUE`` overrides, the GUI
widgets and the generated docs all read :data:`PARAMS`, so they cannot drift apart.

Example
-------
>>> p = ParamSet().with_overrides({"veins.main.kappa": 4.0})
>>> p["veins.main.kappa"]
4.0
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from leafsim.base.errors import LeafsimError


#: a number as the command line and the GUI write it (ASCII digits, an optional fraction and
#: exponent; inf and nan parse, to be refused as not finite)
NUMBER = re.compile(r"[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf(?:inity)?|nan)", re.IGNORECASE)


@dataclass(frozen=True)
class Param:
    """Declaration of one parameter.

    Parameters
    ----------
    name : dotted key, e.g. ``"osmosis.diffusion"``; the first component is the stage.
    kind : ``"float"``, ``"int"``, ``"bool"`` or ``"choice"``.
    default : value used when neither species nor user sets it.
    lo, hi : inclusive range (numbers only).
    unit : physical unit shown in the GUI and docs (``""`` for dimensionless).
    help : one sentence shown as tooltip and in ``docs/parameters.md``.
    group : GUI panel / docs section.
    rebuild : True when a change needs outline/veins/mesh to be regenerated.
    choices : allowed values for ``kind == "choice"``.
    log : GUI slider on a logarithmic scale.
    only : ``(key, value)``: the parameter acts only while ``key`` has ``value`` (the weather's
        temperature only with ``environment.drive = weather``); the GUI dims it otherwise.
    """

    name: str
    kind: str
    default: Any
    lo: float | None = None
    hi: float | None = None
    unit: str = ""
    help: str = ""
    group: str = ""
    rebuild: bool = False
    choices: tuple[str, ...] = ()
    log: bool = False
    only: tuple = ()  # (key, value or values): the parameter acts only while key has one of them (else unused)

    def applies(self, params) -> bool:
        """Whether this parameter acts under ``params`` (see ``only``)."""
        if not self.only:
            return True
        want = self.only[1]
        return params[self.only[0]] in want if isinstance(want, tuple) else params[self.only[0]] == want

    def only_text(self) -> str:
        """``key = value`` (or ``key = a or b``) of ``only``; "" without it."""
        if not self.only:
            return ""
        want = self.only[1]
        text = (lambda v: str(v).lower() if isinstance(v, bool) else str(v))  # (true, as --set and the docs write it)
        return f"{self.only[0]} = {' or '.join(map(text, want)) if isinstance(want, tuple) else text(want)}"

    def coerce(self, value: Any, where: str = "") -> Any:
        """Return ``value`` converted to this parameter's type, or raise LeafsimError."""
        at = f"{where}: " if where else ""
        expect = self.describe()
        if self.kind == "bool":
            if isinstance(value, (bool, np.bool_)):  # (numpy's bool too: a sweep over np.array([True, False]))
                return bool(value)
            if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "on", "off", "yes", "no"):
                return value.lower() in ("true", "1", "on", "yes")
            if isinstance(value, (int, float)) and value in (0, 1):
                return bool(value)
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}")
        if self.kind == "choice":
            if isinstance(value, str) and value in self.choices:
                return value
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}")
        # numbers
        if isinstance(value, (bool, np.bool_)):
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}")
        if isinstance(value, str) and not NUMBER.fullmatch(value.strip()):
            # float() also takes '1_0' and non-ASCII digits: a typo, not a number
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}")
        try:
            num = float(value)
        except (TypeError, ValueError, OverflowError):
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}") from None
        if not math.isfinite(num):
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected a finite value, {expect}")
        if self.kind == "int":
            if num != int(num):
                raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)}: expected {expect}")
            num = int(num)
        if (self.lo is not None and num < self.lo) or (self.hi is not None and num > self.hi):
            raise LeafsimError(f"{at}parameter '{self.name}' = {show(value)} is out of range: expected {expect}")
        return num

    def describe(self) -> str:
        if self.kind == "bool":
            return "true or false"
        if self.kind == "choice":
            return "one of " + ", ".join(self.choices)
        unit = f" {self.unit}" if self.unit else ""
        return f"{'an integer' if self.kind == 'int' else 'a number'} in [{self.lo:g}, {self.hi:g}]{unit}"


def show_json(value: Any, limit: int = 40) -> str:
    """A value read from a JSON file as JSON writes it ("0.3", [false, true]), shortened."""
    import json

    try:
        r = json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError):
        return show(value, limit)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def show(value: Any, limit: int = 40) -> str:
    """repr of a user-given value, shortened so that a message stays one short line."""
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


_DECL: list[Param] = []


def _f(name, default, lo, hi, unit="", help="", group="", rebuild=False, log=False, only=()):
    _DECL.append(Param(name, "float", float(default), lo, hi, unit, help, group, rebuild, (), log, tuple(only)))


def _i(name, default, lo, hi, unit="", help="", group="", rebuild=False, only=()):
    _DECL.append(Param(name, "int", int(default), lo, hi, unit, help, group, rebuild, (), False, tuple(only)))


def _b(name, default, help="", group="", rebuild=False):
    _DECL.append(Param(name, "bool", bool(default), None, None, "", help, group, rebuild))


def _c(name, default, choices, help="", group="", rebuild=False, only=()):
    _DECL.append(Param(name, "choice", default, None, None, "", help, group, rebuild, tuple(choices), False, tuple(only)))


# ---------------------------------------------------------------- outline (rebuild)
G = "Outline"
_f("outline.simplify", 0.001, 0.0, 0.02, "× diagonal", "Douglas–Peucker tolerance as a fraction of the image diagonal (1–2 px on the shipped photos: keeps the margin's teeth as corners, not the pixel staircase).", G, True)
_i("outline.points", 2000, 40, 8000, "", "Number of points the traced contour is resampled to (the simplified outline's corners kept, its edges split evenly); enough to carry a doubly serrate margin.", G, True)
_f("outline.lobe_depth", 0.06, 0.0, 0.5, "× length", "Minimum sinus depth (relative to leaf length) that separates two lobes.", G, True)

# ---------------------------------------------------------------- veins (rebuild)
G = "Veins: main"
_c("veins.photo", "main+lateral", ("off", "main", "main+lateral"), "Photo species: take the midrib and main veins (main) and also the laterals (main+lateral) from the photo's own veins, traced as ridges of its lightness, so the model's veins lie on the photo's; the grower fills the rest. off = grow every vein (as for a drawn outline).", G, True)
_f("veins.main.step", 0.035, 0.005, 0.2, "× length", "Base segment length of main veins, relative to the leaf length.", G, True)
_f("veins.main.scale_jitter", 0.3, 0.0, 0.9, "", "Random scale of each segment: step × U(1−j, 1+j).", G, True)
_f("veins.main.kappa", 5.0, 0.0, 45.0, "deg", "κ: local random angle added to each segment's direction, drawn in [−κ, κ].", G, True)
_f("veins.main.omega", 2.0, -30.0, 30.0, "deg", "ω: global angle that pushes main veins consistently left (+) or right (−).", G, True)
_f("veins.main.threshold", 0.12, 0.0, 0.6, "× vein", "Threshold zone: the last fraction of each main vein is thin and starts no laterals.", G, True)
_f("veins.main.width", 0.012, 0.001, 0.05, "× length", "Width of the midrib at the base, relative to the leaf length.", G, True)
_i("veins.main.max_auto", 7, 1, 15, "", "Maximum number of main veins found automatically from lobe tips.", G, True)
_f("veins.main.auto_min_angle", 18.0, 0.0, 90.0, "deg", "Automatic targets closer in angle (seen from the base) than this are merged; only for a species whose main veins start at the base (its config's main_origin: base, e.g. maple, grapevine), not along the midrib (oak).", G, True)

G = "Veins: lateral"
_b("veins.lateral.enabled", True, "Grow lateral (secondary) veins.", G, True)
_i("veins.lateral.spacing", 3, 1, 20, "segments", "Start a lateral on every x-th candidate segment of a main vein.", G, True)
_c("veins.lateral.alternation", "alternate", ("alternate", "opposite", "left", "right"), "How laterals are placed on the two sides of a main vein.", G, True)
_f("veins.lateral.angle", 50.0, 10.0, 85.0, "deg", "Angle between a lateral's start–target line and its main vein.", G, True)
_f("veins.lateral.angle_jitter", 5.0, 0.0, 30.0, "deg", "Random variation of the lateral angle.", G, True)
_f("veins.lateral.kappa", 4.0, 0.0, 45.0, "deg", "κ for laterals: local random angle per segment.", G, True)
_f("veins.lateral.step", 0.025, 0.005, 0.2, "× length", "Base segment length of laterals, relative to the leaf length.", G, True)
_f("veins.lateral.reach", 0.97, 0.3, 1.0, "", "Laterals stop at this fraction of the way to the margin (the margin vein gap).", G, True)
_f("veins.lateral.width", 0.45, 0.05, 1.0, "× parent", "Width of a lateral at its start relative to the parent vein there.", G, True)
_b("veins.lateral.curve_apical", True, "Laterals bend toward the apex as they approach the margin (brochidodromous look).", G, True)

G = "Veins: sublateral"
_b("veins.sub.enabled", True, "Grow sublateral (tertiary branching) veins as Bézier curves.", G, True)
_i("veins.sub.divisions", 4, 1, 16, "", "n_div: divisions of each lateral that start sublaterals.", G, True)
_f("veins.sub.angle", 45.0, 5.0, 85.0, "deg", "θ_div: angle of a sublateral to its lateral.", G, True)
_f("veins.sub.bend", 0.25, 0.0, 0.8, "", "Random perpendicular offset of the Bézier control point, relative to the chord.", G, True)
_f("veins.sub.reach", 0.92, 0.3, 1.0, "", "Sublaterals end at this fraction of the ray to the margin.", G, True)
_f("veins.sub.width", 0.5, 0.05, 1.0, "× parent", "Width of a sublateral relative to its lateral.", G, True)
_f("veins.sub.gap", 0.15, 0.0, 0.5, "× length", "With sublaterals on: where a part of the blade is farther than this from every vein (a photo's faint veins the tracer missed), a sublateral grows from the nearest vein toward its farthest point and on toward the margin, until no part is (at most 40); 0 = off.", G, True)

G = "Veins: net"
_b("veins.net.enabled", False, "Grow a tertiary net: scattered points joined to the nearest vein.", G, True)
_f("veins.net.spacing", 0.04, 0.01, 0.2, "× length", "Spacing of net points relative to the leaf length.", G, True)
_f("veins.net.width", 0.35, 0.05, 1.0, "× parent", "Width of net veins relative to the vein they join.", G, True)
_f("veins.taper", 0.6, 0.0, 1.0, "", "How much a vein thins from its start to its end (0 = constant).", "Veins: main", True)

# ---------------------------------------------------------------- mesh (rebuild)
G = "Mesh"
_f("mesh.spacing", 0.0199, 0.002, 0.1, "× length", "Poisson-disk spacing r of surface particles, relative to the leaf length.", G, True, log=True)
_f("mesh.vein_spacing", 0.75, 0.3, 2.0, "× r", "Spacing of vein particles along veins relative to r.", G, True)
_f("mesh.contour_spacing", 0.8, 0.3, 2.0, "× r", "Spacing of contour particles along the outline relative to r.", G, True)
_f("mesh.contour_detail", 0.05, 0.0, 1.0, "× r", "Contour particles also sit on the margin's corners (tooth tips and notches) that stand out more than this × r from a straight edge; 0 = evenly spaced only (teeth smaller than the spacing are cut).", G, True)
_f("mesh.thickness", 0.0004, 0.00005, 0.005, "m", "Blade thickness h: distance of layer V above layer T.", G, True, log=True)
_c("mesh.veins_included", "sublateral", ("main", "lateral", "sublateral", "net"), "Highest vein order that gets vein particles.", G, True)

# ---------------------------------------------------------------- petiole (rebuild)
G = "Petiole"
_f("petiole.length", 0.0, 0.0, 0.3, "m", "Length of the leaf stalk: a rod from the base, away from the apex, that bends, dries and is exported with the blade (its tip is what the hanging scene holds); 0 = no stalk (the blade is held at its base). Species set their own.", G, True)
_f("petiole.diameter", 0.0015, 0.0003, 0.01, "m", "Diameter d of the leaf stalk: a rod of cross-section πd²/4 (mass, stretching) and bending stiffness E_vein·πd⁴/64, vein tissue (material.vein_modulus).", G, True, log=True)

# ---------------------------------------------------------------- mass (rebuild)
G = "Mass"
_f("mass.weight_main", 1.0, 0.01, 1e4, "", "Dijkstra edge weight factor of main-vein springs.", G, True, log=True)
_f("mass.weight_lateral", 50.0, 0.01, 1e4, "", "Dijkstra edge weight factor of lateral springs.", G, True, log=True)
_f("mass.weight_sub", 200.0, 0.01, 1e4, "", "Dijkstra edge weight factor of sublateral/net springs.", G, True, log=True)
_f("mass.weight_surface", 1000.0, 0.01, 1e5, "", "Dijkstra edge weight factor of surface springs.", G, True, log=True)
_i("mass.D", 1, 1, 3, "", "Dispersion exponent D in τ = (1 − d/d_max)^D.", G, True)
_f("mass.lma", 0.06, 0.005, 0.5, "kg/m²", "Leaf mass per area: dry mass of the blade per m² (deciduous broadleaves 0.03–0.12; the blade's mean, veins add their own).", G, True, log=True)
_f("mass.profile_min", 0.3, 0.01, 1.0, "", "Areal mass far from the veins relative to its peak near the petiole (Jeong's graph-distance profile τ; 1 = uniform lamina).", G, True)
_f("mass.vein_density", 1100.0, 100.0, 3000.0, "kg/m³", "Fresh density of vein tissue: a vein adds π w²/4 × this per metre (minus the lamina it replaces).", G, True, log=True)
_f("mass.water_fraction", 0.7, 0.05, 0.95, "", "Fraction of the fresh mass that is water (rest is dry mass); fresh mass per area = lma / (1 − this).", G, True)

# ---------------------------------------------------------------- osmosis (live)
G = "Osmosis"
_f("osmosis.diffusion", 1e-5, 0.0, 1e5, "m²/s", "Osmotic diffusivity D of the water concentration (effective D·τ̄ with Jeong's τ); D·T_dry/L² ≲ 0.1 keeps margin-first drying visible, ≫ 1 dries every layer uniformly.", G, False, log=True)
_f("osmosis.evaporation_top", 0.014, 0.0, 100.0, "kg/(m²·s)", "Evaporation from the top surface (layer V) per unit leaf area and simulated second (the simulated clock is compressed: see docs/method.md).", G, False, log=True, only=("environment.drive", "rates"))
_f("osmosis.evaporation_bottom", 0.0105, 0.0, 100.0, "kg/(m²·s)", "Evaporation from the bottom surface (layer T) per unit leaf area and simulated second.", G, False, log=True, only=("environment.drive", "rates"))
_f("osmosis.edge_evaporation", 2.0, 0.0, 20.0, "", "Margin-enhanced evaporation β: a particle at distance d from the margin evaporates 1 + β √(ℓ/(d + ℓ)) times more (the boundary layer is thin at the edge), normalised so the blade's mean stays the declared rate; 0 = uniform.", G, False)
_f("osmosis.edge_length", 0.003, 0.0, 0.1, "m", "Length scale ℓ of the margin-enhanced evaporation (a few mm: the boundary layer thickness near the edge).", G, False, log=True)
_f("osmosis.patchiness", 0.0, 0.0, 2.0, "", "Patchy hydraulic failure a: evaporation × exp(a·f) for the blade's seeded smooth patch field f (zero mean, unit spread; patches ≈ 0.12 leaf lengths), normalised so the blade's mean stays the declared rate; 0 = none.", G, False)
_b("osmosis.through_thickness", True, "Water also flows between the two layers through the blade's thickness (D over h/2: they stay in balance within milliseconds); off = Jeong's separate layers, where the faster-drying top curls the leaf transiently.", G, False)
_i("osmosis.every", 1, 1, 50, "frames", "Solve osmosis and evaporation every k-th frame over k Δt (water moves far slower than the blade: a cheaper frame for a small error, see docs/accuracy.md).", G, False)
_c("osmosis.solver", "auto", ("auto", "direct", "halves", "cg", "jacobi"), "Linear solver of the implicit osmosis step: direct = factored once, two triangular solves a step; halves = the same factored in two halves and a separator, the halves solved on two threads when that times faster (a 132 k-particle solve 20 → 13–14 ms on a quiet 2-core machine, 12 % slower with the other core busy or drawing the window, and on one numba thread; docs/performance.md; direct where no cut is balanced with a separator under 5 % of the unknowns); cg, jacobi = iterative, to osmosis.tolerance; auto = direct up to 300 k unknowns, else cg.", G, False)
_f("osmosis.tolerance", 1e-8, 1e-14, 1e-2, "", "Relative residual at which the iterative osmosis solver stops.", G, False, log=True, only=("osmosis.solver", ("auto", "cg", "jacobi")))
_f("osmosis.g_min", 4.0, 0.1, 50.0, "mmol/(m²·s)", "Minimum (cuticular) leaf conductance to water vapour after the stomata have shut, both sides together per leaf area (Duursma et al. 2019 compile 1–11 for our genera); used when environment.drive = weather.", G, False, log=True, only=("environment.drive", "weather"))
_f("osmosis.g_stomata", 60.0, 0.0, 1000.0, "mmol/(m²·s)", "Stomatal conductance of the detached leaf while its stomata are open (environment.drive = weather); they shut as the tissue loses water (osmosis.stomata_*_rwc).", G, False, only=("environment.drive", "weather"))
_f("osmosis.stomata_top", 0.0, 0.0, 1.0, "", "Share of the stomatal conductance on the top (adaxial) surface: 0 = hypostomatous (the trees here), 0.5 = amphistomatous.", G, False, only=("environment.drive", "weather"))
_f("osmosis.stomata_open_rwc", 0.97, 0.0, 1.0, "", "Relative water content above which the stomata are fully open (weather drive); a value below osmosis.stomata_closed_rwc counts as that one (they then shut at once).", G, False, only=("environment.drive", "weather"))
_f("osmosis.stomata_closed_rwc", 0.85, 0.0, 1.0, "", "Relative water content below which the stomata are shut and only the cuticle loses water (weather drive); linear between the two.", G, False, only=("environment.drive", "weather"))

# ---------------------------------------------------------------- environment (live)
G = "Environment"
_c("environment.drive", "rates", ("rates", "weather"), "What drives evaporation: rates = the declared osmosis.evaporation_* per simulated second (a compressed clock); weather = temperature, humidity and wind through the cuticular, stomatal and boundary-layer conductances, in real time × environment.time_warp (docs/method.md §3).", G, False)
_f("environment.temperature", 20.0, -10.0, 45.0, "°C", "Air (and leaf) temperature; sets the saturation vapour pressure (weather drive).", G, False, only=("environment.drive", "weather"))
_f("environment.humidity", 0.5, 0.0, 0.99, "", "Relative humidity of the air, 0–1 (weather drive): the vapour-pressure deficit is e_s(T)(1 − RH).", G, False, only=("environment.drive", "weather"))
_f("environment.wind", 0.5, 0.0, 20.0, "m/s", "Air speed over the leaf (weather drive): the boundary-layer conductance grows as √(u/d); still air counts as 0.1 m/s.", G, False, only=("environment.drive", "weather"))
_f("environment.time_warp", 3.0e4, 1.0, 1.0e7, "s/s", "Real seconds of weather per simulated second (weather drive): drying takes hours to days, the blade's mechanics milliseconds, so the drying clock runs this much faster (3·10⁴: a day in ≈ 3 simulated seconds).", G, False, log=True, only=("environment.drive", "weather"))

# ---------------------------------------------------------------- shrink (live)
G = "Shrink"
_f("shrink.sigma_surface_top", 0.16, 0.0, 3.0, "", "Shrinkage σ of the top layer V's surface springs (dimensionless): a spring's rest length is l₀ (1 − σ (1 − v)^α), v its cells' mass over their fresh mass (α = shrink.alpha), clamped at shrink.l_min; a bone-dry spring loses the water fraction w of its mass, so 0.16 shortens it by 0.16 w^α (10 % at w 0.62, α 1). Top above bottom curls the blade up (the bilayer); 3 is far beyond any measured leaf (real leaves shrink a few to 20 % in area).", G, False)
_f("shrink.sigma_surface_bottom", 0.15, 0.0, 3.0, "", "Shrinkage σ of the bottom layer T's surface springs (dimensionless): rest length l₀ (1 − σ (1 − v)^α), v the cells' mass over their fresh mass, clamped at shrink.l_min; 0.15 shortens a bone-dry spring by 0.15 w^α (w the water fraction of the fresh mass: 9 % at w 0.62, α 1). Bottom above top curls the blade down.", G, False)
_f("shrink.sigma_vein", 0.05, 0.0, 3.0, "", "Shrinkage σ of the vein springs (dimensionless): rest length l₀ (1 − σ (1 − v)^α) as for the surface; veins shrink far less than the lamina (0.05: 0.05 w^α when bone dry, 3 % at w 0.62), so they hold the lamina between them.", G, False)
_f("shrink.alpha", 1.0, 0.1, 4.0, "", "Exponent α of (1 − v) in the shrink law, v a spring's cells' mass over their fresh mass (the share of their fresh mass lost is 1 − v).", G, False)
_f("shrink.curl_anisotropy", 0.6, 0.0, 1.0, "", "Anisotropy β of the bilayer curl relative to the local main/lateral vein direction: hinges that bend the blade across a vein curl × (1 + β), along it × (1 − β), so lobes cup about their own veins (0: isotropic).", G, False)
_f("shrink.patchiness", 0.0, 0.0, 1.5, "", "Spread of the shrinkage within the blade: each spring's shrink and each hinge's bilayer curl × (1 + a z), z a seeded smooth random field (zero mean, unit spread) with correlation length shrink.patch_size, the same at any mesh spacing; patches that shrink less than their surroundings are pressed by them and the blade crumples and twists (dried leaves crumple from internal strain gradients whose origin is not known: Guo et al. 2025).  0 = the tissue shrinks alike everywhere.", G, False)
_f("shrink.patch_size", 0.006, 0.001, 0.05, "m", "Correlation length of the shrinkage field of shrink.patchiness (the size of a patch that shrinks more or less than its surroundings).", G, False, log=True)
_f("shrink.plication", 0.0, 0.0, 0.02, "× length", "Depth of the fresh blade's pleats along its main veins and laterals (plicate vernation, as in hornbeam and beech: the veins lie in valleys, the panels between them rise), × the leaf length at the deepest panels (the 95th percentile); a rest angle on every bending hinge (leafsim.sim.pleats), so the pleats stay as the blade dries.  0 = a flat fresh blade.", G, False)
_f("shrink.l_min", 0.5, 0.1, 1.0, "× l⁰", "Rest lengths never go below l_min · l⁰ (≥ 0.1: tissue cannot shrink to nothing; at 0 a leaf collapsed to a point and never came to rest).", G, False)

# ---------------------------------------------------------------- dynamics (live)
G = "Dynamics"
_f("dynamics.dt", 0.002, 1e-5, 0.1, "s", "Time step Δt.", G, False, log=True)
_f("dynamics.gravity", 9.81, 0.0, 50.0, "m/s²", "Gravity magnitude (acts along −z).", G, False)
_f("dynamics.damping", 25.0, 0.0, 1000.0, "1/s", "Velocity damping rate c (v ← v·e^(−c·Δt)): internal friction of the tissue, and air drag too with dynamics.rigid_inertia off (on, the leaf's rigid motion is damped by dynamics.air_damping instead).", G, False, log=True)
_i("dynamics.substeps", 40, 1, 200, "", "Dynamics substeps per frame at the default mesh spacing (small steps make stiff constraints converge far better than more iterations).", G, False)
_b("dynamics.substep_scaling", True, "Scale the substeps with (default spacing / mesh.spacing)² so a finer mesh stays as converged (h ∝ r²; a coarse mesh gets fewer, at least 1).", G, False)
_i("dynamics.iterations", 2, 1, 200, "", "Maximum constraint-projection iterations per substep.", G, False)
_c("dynamics.integrator", "xpbd", ("xpbd", "sun", "static"), "How the blade's mechanics is stepped: xpbd = constraint projections (substeps × iterations; stable at any Δt); sun = Sun et al. 2021's plant dynamics, the same elastic energy as forces with damping and the cells' turgor force, integrated by the explicit midpoint rule (stable only for small steps: dynamics.sun_substeps; docs/method.md); static = no motion, the blade at its static equilibrium every frame (drying is quasi-static: a Newton solve of the same energy to dynamics.static_tolerance; docs/method.md).", G, False)
_f("dynamics.static_tolerance", 1e-2, 1e-8, 1.0, "× weight", "With dynamics.integrator = static: the equilibrium solve stops when the largest force left on any particle is below this share of its weight (the stiff tissue puts the rounding floor of that force near 10⁻³ on the finer meshes).", G, False, log=True)
_i("dynamics.static_every", 1, 1, 1000, "frames", "With dynamics.integrator = static: solve the equilibrium every this many frames (the leaf holds its shape in between): the drying's increments.  The water, shrink and plastic rest state do not depend on the shape, so only friction's path and where a snap-through lands see the increment (its convergence: docs/accuracy.md).", G, False)
_i("dynamics.static_iterations", 200, 1, 1000, "", "With dynamics.integrator = static: the most Newton iterations of one equilibrium solve (where the drying leaf buckles off the ground into its curl it can take them all; a solve that stops at the cap leaves the leaf where the energy was lowest, and the next one goes on from there).", G, False)
_i("dynamics.sun_substeps", 40, 1, 4000, "", "With dynamics.integrator = sun: the fewest explicit midpoint steps per frame at the default mesh spacing (scaled like dynamics.substeps); more are taken whenever the Courant limit needs them.", G, False, only=("dynamics.integrator", "sun"))
_f("dynamics.sun_courant", 1.5, 0.05, 2.0, "", "With dynamics.integrator = sun: the largest ω h allowed, ω a bound on the stiffest mode's frequency from this frame's stiffness and masses; it sets the step count.  Capped at what dynamics.sun_damping keeps stable (1.65 at ζ = 0.3, 2 from ζ = 0.5; docs/method.md).", G, False, only=("dynamics.integrator", "sun"))
_f("dynamics.sun_damping", 0.3, 0.05, 1.0, "", "With dynamics.integrator = sun: damping ratio ζ at the stiffness bound (Sun's damping force as Rayleigh damping F_d = −β k Ċ ∇C, β = 2ζ/ω, less for slower modes): the explicit step amplifies an undamped oscillation however small the step, so ζ also sets the largest stable ω h.", G, False, only=("dynamics.integrator", "sun"))
_f("dynamics.mass_scaling", 64.0, 1.0, 4096.0, "", "Inertia × M with gravity ÷ M (weight and every static force unchanged; motion √M slower; with dynamics.rigid_inertia only the deformation modes').  A constraint's XPBD regime depends on h²/(compliance · mass): scaling the mass by M is, for the quasi-static drying, the same as √M times more substeps at no cost.  64: the drying shape of 160 substeps from 20 (docs/accuracy.md); from ≈ 256 the slowed leaf lags behind its drying; 1 = real inertia (a falling or swinging leaf moves at its real speed).", G, False, log=True)
_b("dynamics.rigid_inertia", True, "Selective mass scaling: the leaf's rigid motion (falling through the air, swinging about its pinned stalk) keeps its real inertia and dynamics.mass_scaling slows only the deformation modes (bending, stretching), whose convergence the drying needs; the static shapes are the same either way.  A leaf touching the ground keeps the scaled inertia (tipping over and sliding stay √M slower).  Off: every motion √M slower.", G, False)
_f("dynamics.air_damping", 6.0, 0.0, 1000.0, "1/s", "With dynamics.rigid_inertia: damping rate of the leaf's rigid motion in real time (air drag, linearised): a falling leaf's terminal speed is g / this (6/s: 1.6 m/s, a plate of 0.2 kg/m² falling broadside, drag coefficient 1.2).", G, False, log=True, only=("dynamics.rigid_inertia", True))
_f("dynamics.relaxation", 1.0, 0.5, 1.3, "", "Over-relaxation ω of the bending projections (successive over-relaxation): > 1 carries a steady load across the mesh in fewer sweeps but a free curling leaf may then never come to rest (limit cycles measured from ω 1.3, blow-ups from 1.5 without damping); 1 = plain Gauss–Seidel.", G, False)
_f("dynamics.tolerance", 1e-4, 1e-9, 1.0, "", "Stop iterating when the largest position change per iteration falls below this × leaf length.", G, False, log=True)
_c("dynamics.path", "draft", ("own", "draft", "fine"), "Mesh that carries the blade's mechanics while the leaf dries: own = this mesh throughout; draft = a coarser mesh of the same leaf (the draft quality's mesh and solver) until the water falls to dynamics.handover, then this mesh (as close to the converged shape as own for 2.5–3.3× less CPU on maple; docs/performance.md); fine = the default quality's mesh and solver, for a mesh finer than it (with dynamics.handover 0 this mesh takes that mesh's shape to the end: a 100 k-particle leaf dries in minutes, not hours; docs/performance.md).  No effect when this mesh is not finer than the path's one, or when the solver settings (substeps, iterations, tolerance, inertia scaling) are not the defaults it stands in for.", G, True)
_f("dynamics.handover", 0.15, 0.0, 1.0, "", "With dynamics.path = draft or fine: the share of the fresh leaf's water at which the leaf's own mesh takes over the mechanics (0 = never; 1 = at once).", G, False, only=("dynamics.path", ("draft", "fine")))
_c("dynamics.finish", "xpbd", ("xpbd", "static"), "With dynamics.path = draft or fine: how the leaf's own mesh (and with fine the default mesh under it) finishes the drying after the hand-over: xpbd = XPBD frames, as for motion; static = the blade's static equilibrium every dynamics.static_every frames (the static integrator), only while the leaf has an equilibrium (on the ground, hanging by its stalk, or with no gravity; a free leaf that falls keeps xpbd); the first solve comes at the hand-over.  Measured per species (docs/performance.md, 'A static finish'): on oak 3–4× closer to the converged limit in position for less CPU, on maple, hornbeam, chestnut, walnut and pokeweed 1.3–15× slower.", G, False, only=("dynamics.path", ("draft", "fine")))
_c("dynamics.precision", "float64", ("float64", "float32"), "Floating-point type the dynamics frame works in: positions, velocities and constraint records (float32: half the memory, positions rounded to ≈ 4·10⁻⁹ m on a 12 cm leaf near the origin, more on a leaf falling away from it in the free scene; its error and cost are measured in docs/accuracy.md); the xpbd integrator only, sun always runs in float64.", G, False)
_f("dynamics.plasticity", 2.0, 0.0, 100.0, "1/s", "Rate at which drying tissue sets: bending hinges keep the largest bilayer curl they reached (0 = purely elastic, the curl relaxes when both layers are dry).", G, False, log=True)

# ---------------------------------------------------------------- material (live)
G = "Material"
_f("material.modulus", 1e7, 1e4, 1e10, "Pa", "Young's modulus E of the fresh lamina: membrane springs E·(h/2)·ΣA/|e|², bending D = E h³ / 12(1 − ν²) on discrete-shell hinges.", G, False, log=True)
_f("material.poisson", 0.3, 0.0, 0.49, "", "Poisson ratio ν of the lamina (enters the bending stiffness D).", G, False)
_c("material.hinge_weights", "discrete_shells", ("discrete_shells", "cylinder"), "How a hinge's dihedral angle becomes bending energy (k = D·w): discrete_shells = Grinspun's weight w = 3|e|²/(A₁+A₂), whose hinges store about 4 × a plate's energy in cylindrical bending on these meshes (1.5 × in a cup, 5.7 × in a saddle); cylinder = those weights scaled once per mesh so that cylindrical bending stores exactly the plate's ½Dκ²A (a cup then 0.5 ×, a saddle 1.9 ×). The two membrane layers add their own bending on top (tools/bending_stiffness.py; docs/method.md §5).", G, False)
_f("material.dry_stiffening", 20.0, 0.0, 1000.0, "", "Dry tissue is stiffer: the bending modulus grows to E·(1 + this) as the tissue loses its water.", G, False, log=True)
_f("material.turgor_share", 0.0, 0.0, 0.95, "", "Share T of the fresh leaf's bending stiffness (lamina and veins) that turgor provides: it is lost as the tissue's RWC falls to the turgor-loss point, so a drying leaf first wilts (goes limp, a hanging one droops), then stiffens as its walls dry; 0 = no wilting.", G, False)
_f("material.turgor_loss_rwc", 0.85, 0.5, 0.99, "", "Relative water content at the turgor-loss point, where the cells' turgor (and T of the stiffness) is gone; 0.8–0.9 in temperate broadleaves (Bartlett et al. 2012).", G, False)
_f("material.stiffening_power", 1.0, 1.0, 6.0, "", "Dry stiffening grows as (1 − RWC)^p: 1 = in proportion to the water lost; larger = only once the walls themselves dry (with turgor_share > 0 the wilting dip then shows).", G, False)
_f("material.stiffening_stretch", 0.0, 0.0, 1.0, "", "Share of the dry stiffening that stiffens stretching too (the lamina's membrane springs × (1 + share·k_dry·dry^p)): 0 = bending only; 1 = the dried wall material is stiffer alike in bending and stretching, so its bending-to-stretching ratio (which sets wrinkle wavelengths and buckling strains) stays the fresh one.", G, False)
_f("material.turgor_pressure", 0.0, 0.0, 3e6, "Pa", "With dynamics.integrator = sun or static, or a static finish (dynamics.finish = static): turgor pressure P of the fresh cells for Sun's turgor force (0.5–1 MPa in temperate broadleaves), lost linearly as the RWC falls to the turgor-loss point; cells losing it pull their neighbours in (a ΔP per membrane spring, a = the face between the two cells × half the thickness).  0 = off: the shrink effect already carries the whole drying contraction, calibrated per species, and P > 0 adds about (4/3) P / E of area loss on top.", G, False)
_f("material.vein_modulus", 5e8, 1e5, 1e11, "Pa", "Young's modulus of vein tissue: vein springs E_v·πw²/4/l, vein bending E_v·πw⁴/64 on the hinges that bend a vein lengthwise.", G, False, log=True)
_c("dynamics.voronoi", "free", ("free", "replace"), "Layer V: free particles (stable) or re-placed over their triangle each frame (thesis).", G, False)
_c("dynamics.scene", "ground", ("ground", "hanging", "free"), "Scene: lying on the ground, hanging from a pinned petiole, or free.", G, False)
_f("dynamics.friction", 0.6, 0.0, 2.0, "", "Coulomb friction coefficient against the ground.", G, False)
_f("dynamics.collision_radius", 0.45, 0.05, 2.0, "× r", "Self-collision distance between layer-T particles, relative to the mesh spacing r.", G, False)
_f("dynamics.collision_skip", 2.5, 1.0, 10.0, "× r", "Particle pairs closer than this at rest are sheet neighbours and never collide.", G, False)

# ---------------------------------------------------------------- effects (live)
G = "Effects"
for _name, _on, _help in [
    ("osmosis", True, "Osmotic water flow and evaporation."),
    ("shrink", True, "Rest lengths shrink as water is lost."),
    ("gravity", True, "Gravity."),
    ("pbd", True, "Position-based constraint projection (the blade's elasticity)."),
    ("bending", True, "Bending stiffness constraints."),
    ("ground", True, "Ground-plane collision with friction."),
    ("self_collision", True, "Self-collision so a curling leaf never passes through itself."),
    ("colour", True, "Pigment aging and colour change."),
]:
    _b(f"effects.{_name}", _on, _help, G, False)

# ---------------------------------------------------------------- colour (live)
G = "Colour"
_f("colour.age_rate", 0.05, 0.0, 10.0, "1/s", "Senescence clock speed: season units advanced per second of simulated time (age = season + age_rate·t).", G, False, log=True)
_f("colour.season", 0.0, 0.0, 2.0, "", "Starting season of the age clock: 0 = summer, 1 = late autumn, >1 = dead winter leaf.", G, False)
_f("colour.onset", 0.25, 0.0, 1.5, "season", "Season at which programmed senescence (chlorophyll breakdown) begins.", G, False)
_f("colour.chlorophyll", 1.0, 0.0, 3.0, "", "Summer chlorophyll content (1 = typical): how deep the young leaf's green is.", G, False)
_f("colour.chlorophyll_decay", 4.5, 0.0, 40.0, "1/season", "Chlorophyll breakdown rate per season unit after the onset (fully hydrated tissue).", G, False)
_f("colour.water_sensitivity", 3.0, 0.0, 20.0, "", "Senescence speed-up by water loss: rates × (1 + s·(1 − water_rel)); makes margins and intercostal areas turn first.", G, False)
_f("colour.carotenoid", 1.0, 0.0, 3.0, "", "Carotenoid content (yellow/orange) unmasked when chlorophyll breaks down.", G, False)
_f("colour.carotenoid_decay", 0.6, 0.0, 10.0, "1/season", "Slow carotenoid loss per season unit after the onset.", G, False)
_f("colour.anthocyanin", 0.0, 0.0, 3.0, "", "Anthocyanin (or betacyanin) made during senescence: reds and purples (maple, pokeweed).", G, False)
_f("colour.anthocyanin_fade", 1.2, 0.0, 20.0, "1/season", "Anthocyanin breakdown per season unit after the onset (so reds peak, then fade).", G, False)
_f("colour.browning", 1.0, 0.0, 10.0, "", "Browning rate of dead tissue (oxidised phenolics); high for oak, low for maple.", G, False)
_f("colour.brown_level", 1.0, 0.0, 2.0, "", "Browning pigments (oxidised phenolics, tannins) in fully browned tissue: how dark a dead leaf gets; tannin-rich oak and walnut 1, golden-yellow species (aspen, hornbeam, birch) about half, so they dry yellow-brown.", G, False)
_f("colour.dry_threshold", 0.35, 0.0, 0.95, "× water₀", "Relative water content at or below which tissue counts as fully dry (dead).", G, False)
_f("colour.dry_rate", 2.0, 0.0, 100.0, "1/s", "How fast dead dry tissue turns: the chlorophyll it still holds becomes dark pheophytin (necrosis) and it browns, per second of simulated time.", G, False, log=True)
_f("colour.reaction_water", 0.0, 0.0, 0.95, "× water₀", "Relative water content below which the reactions of dead tissue (chlorophyll to dark pheophytin, browning by colour.dry_rate) slow in proportion to the water left, so tissue that dries fast keeps the colour it died with (herbarium green: LaJollo et al. 1971); 0 = they never slow.", G, False)
_f("colour.stress_water", 0.8, 0.05, 1.0, "× water₀", "Relative water content below which living tissue is drought-stressed and runs its senescence program (colour.drought).", G, False)
_f("colour.drought", 2.0, 0.0, 20.0, "season/s", "Drought-induced senescence: season units of senescence per second of simulated time in fully stressed living tissue (a detached, drying leaf turns this way; fast = yellow before it dies, slow = dies green and turns necrotic).", G, False, log=True)
_f("colour.necrosis", 1.0, 0.0, 3.0, "", "Darkness of tissue that died before its chlorophyll was broken down (pheophytins, oxidised phenolics: dark necrotic spots); 0 = it just browns.", G, False)
_f("colour.vein_pallor", 0.3, 0.0, 1.0, "", "Heavy (vein) tissue holds this much less chlorophyll than the thinnest lamina.", G, False)
_f("colour.patchiness", 0.0, 0.0, 2.0, "", "Patchy senescence p: neighbouring patches of the blade turn at rates × exp(p·z − p²/2) for a seeded smooth field z (zero mean, unit spread); 0 = the whole blade at one rate.", G, False)
_f("colour.patch_size", 0.008, 0.001, 0.1, "m", "Correlation length of the senescence patches (colour.patchiness).", G, False, log=True)
_f("colour.mottle", 0.7, 0.0, 1.0, "", "Sub-grid mottle a: below the mesh, areoles and cell groups turn at their own pace, so each reaction's progress p (chlorophyll and carotenoids lost, browning, necrosis) is p + a·n·p(1 − p) at a point, n a seeded field in [−1, 1] of zero mean and correlation length colour.mottle_size, drawn per pixel by the renderer from the interpolated pigments (the pigment amounts keep their mean; fresh and finished tissue stay uniform). The window, frames, compare pictures and a mesh exported with --texture baked (the window's Export mesh) show it; per-vertex colours and scene images do not. 0 = the mesh's smooth colour.", G, False)
_f("colour.mottle_size", 0.0006, 0.0001, 0.005, "m", "Correlation length of the sub-grid mottle (colour.mottle): about an areole, the smallest vein-bounded islet of a dicot leaf (0.3–1 mm).", G, False, log=True)
_f("colour.margin_first", 0.0, 0.0, 10.0, "", "Senescence speed-up at the margin: rate × (1 + m·exp(−distance to the outline / colour.margin_width)); the margin turns (and browns) first.", G, False)
_f("colour.margin_width", 0.003, 0.0002, 0.05, "m", "Width of the margin band that turns first (colour.margin_first).", G, False, log=True)
_f("colour.vein_islands", 0.0, 0.0, 0.95, "", "Green islands along the main and lateral veins: rate × (1 − g·exp(−(distance to the vein / colour.island_width)²)); the tissue along the veins stays green longest.", G, False)
_f("colour.island_width", 0.002, 0.0002, 0.02, "m", "Half-width of the green band along the veins (colour.vein_islands).", G, False, log=True)
_f("colour.spots", 0.0, 0.0, 20000.0, "1/m²", "Leaf spots per square metre of blade (seeded): lesion tissue dies green (dark) inside a yellow halo; maple tar spot ≈ 300, small fungal spots ≈ 5000; 0 = none.", G, False)
_f("colour.spot_radius", 0.002, 0.0002, 0.02, "m", "Mean radius of a leaf spot (each × a log-normal factor of spread 0.3).", G, False, log=True)
_f("colour.vein_browning", 0.0, 0.0, 1.0, "", "Veins brown this much less than the lamina (heavy vein tissue holds 1 − b·m̂ of its browning): the pale veins of a dried leaf.", G, False)
_f("colour.variation", 0.1, 0.0, 1.0, "", "Random per-leaf variation of pigment contents, rates and onset (drawn from the seed).", G, False)

# ---------------------------------------------------------------- render (live)
G = "Render"
_f("render.vein_alpha", 1.0, 0.0, 1.0, "", "Opacity of the drawn veins in the window and in rendered frames (run --every, Export frame); 0 hides them.", G, False)
_f("render.translucency", 0.35, 0.0, 1.0, "", "Back-lit translucency of the blade, in the window and in rendered frames (run --every, Export frame).", G, False)
_f("render.specular", 0.25, 0.0, 1.0, "", "Specular strength of the blade, in the window and in rendered frames (run --every, Export frame).", G, False)
_f("render.crinkle", 1.0, 0.0, 2.0, "", "Sub-grid crinkle of a compressed lamina: a dried blade held in compression between its veins takes the excess length Δ up in crinkles finer than the mesh (leafsim.sim.crinkle), whose RMS slope, averaged over directions, is √(2Δ) whatever their wavelength; where the lamina is squeezed one way and stretched the other, the crinkle is parallel wrinkles across the squeeze, all of the slope along it. The renderer tilts the blade's normals by this factor × that slope over seeded fields. 1 = the compression the simulation leaves, 0 = a smooth blade. Drawing only: the mechanics never see it.", G, False)
_f("render.crinkle_size", 0.001, 0.0002, 0.005, "m", "Correlation length of the crinkle field (render.crinkle): about the veinlets' spacing, the scale at which a dried lamina bulges between them (crests ≈ 2.5 × this apart).", G, False, log=True)
_b("render.texture", True, "Use the species photo as the blade's albedo when the species has one.", G, False)

# ---------------------------------------------------------------- resource limits (rebuild)
# Guards against parameter combinations or inputs that would take minutes or gigabytes; each
# error names the limit, so a user who means it can raise it deliberately with --set.
G = "Limits"
_i("limits.max_particles", 200_000, 1_000, 50_000_000, "", "Largest blade model (both layers) the builder makes; the count is estimated from outline area / spacing² before anything is built.", G, True)
_i("limits.vein_tests", 100_000_000, 100_000, 1_000_000_000, "", "Budget of segment-against-segment collision tests while growing the venation (about 10 million per second here); growth stops with an error past it.", G, True)
_i("limits.image_pixels", 4_000_000, 10_000, 1_000_000_000, "px", "Photos with more pixels are traced on a copy downscaled to this many (coordinates stay in photo pixels).", G, True)

PARAMS: dict[str, Param] = {p.name: p for p in _DECL}
GROUPS: list[str] = list(dict.fromkeys(p.group for p in _DECL))


# ---------------------------------------------------------------- joint constraints
# Constraints between several parameters, declared once here (after the per-parameter
# declarations).  ParamSet checks every one after coercing the single values; the error
# names every key with its value and says which values are still the declared defaults.

@dataclass(frozen=True)
class Joint:
    """A constraint over several declared parameters.

    keys : the parameters involved, in the order ``holds`` takes their values.
    holds : predicate over the values.
    rule : the rule as shown to users, e.g. ``"dynamics.collision_radius < dynamics.collision_skip"``.
    """

    keys: tuple[str, ...]
    holds: Callable[..., bool]
    rule: str

    def violation(self, values: Mapping[str, Any]) -> str | None:
        """One-line description of a violation by ``values``, or None when it holds."""
        vals = [values[k] for k in self.keys]
        if self.holds(*vals):
            return None
        parts = []
        for k, v in zip(self.keys, vals):
            default = " (default)" if v == PARAMS[k].default else ""
            parts.append(f"'{k}' = {v:g}{default}" if isinstance(v, (int, float)) and not isinstance(v, bool)
                         else f"'{k}' = {show(v)}{default}")
        return f"parameters {' and '.join(parts)} break the rule {self.rule} (set them together)"


JOINTS: list[Joint] = [
    # a pair closer than the contact radius at rest would start in contact and push the sheet apart
    Joint(("dynamics.collision_radius", "dynamics.collision_skip"), lambda rad, skip: rad < skip,
          "dynamics.collision_radius < dynamics.collision_skip"),
]


def unknown_key_message(key: str, where: str = "") -> str:
    """One-line error for a key that is not declared, with the closest declared names."""
    import difflib

    near = difflib.get_close_matches(key, PARAMS.keys(), n=3, cutoff=0.6)
    hint = f" (did you mean {', '.join(near)}?)" if near else f" (see `leafsim params` for the {len(PARAMS)} declared names)"
    at = f"{where}: " if where else ""
    return f"{at}unknown parameter '{key}'{hint}"


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested dicts ``{"veins": {"main": {"kappa": 5}}}`` to dotted keys."""
    if not isinstance(tree, Mapping):  # a list of pairs or a 'KEY=VALUE' string
        raise LeafsimError(f"parameter values {show(tree)}: expected a mapping of parameter names to values, "
                           f"e.g. {{'mesh.spacing': 0.03}}")
    out: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping) and key not in PARAMS:
            out.update(flatten(v, key))
        else:
            out[key] = v
    return out


def json_typed(tree: Mapping[str, Any], where: str = "") -> Mapping[str, Any]:
    """``tree`` (parameter values read from a JSON file) when no number or switch is written as
    a string (a switch may be true / false or 0 / 1); a LeafsimError naming the first one that
    is, otherwise.  ``--set`` values are text by nature and are parsed by :meth:`Param.coerce`; in
    a file a quoted "0.3" is most often a slip (a value meant for another key, a unit kept), so
    it is refused rather than read."""
    if not isinstance(tree, Mapping):
        return tree  # ParamSet says what it expected
    at = f"{where}: " if where else ""
    for key, value in flatten(tree).items():
        p = PARAMS.get(key)
        if p is not None and p.kind != "choice" and isinstance(value, str):
            kind = "JSON true or false" if p.kind == "bool" else "JSON number"
            raise LeafsimError(f"{at}parameter '{key}' = {show_json(value)} is a string: expected {p.describe()}, "
                               f"written as a {kind} without quotes")
    return tree


class ParamSet(Mapping[str, Any]):
    """Immutable, validated mapping of every declared parameter to its value."""

    __slots__ = ("_values",)

    def __init__(self, values: Mapping[str, Any] | None = None, where: str = ""):
        vals = {name: p.default for name, p in PARAMS.items()}
        for key, value in flatten(values or {}).items():
            if key not in PARAMS:
                raise LeafsimError(unknown_key_message(key, where))
            vals[key] = PARAMS[key].coerce(value, where)
        for joint in JOINTS:
            bad = joint.violation(vals)
            if bad:
                raise LeafsimError(f"{where + ': ' if where else ''}{bad}")
        self._values = vals

    def __getitem__(self, key: str) -> Any:
        try:
            return self._values[key]
        except KeyError:
            raise LeafsimError(unknown_key_message(key)) from None

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def with_overrides(self, overrides: Mapping[str, Any] | None, where: str = "") -> "ParamSet":
        """A new ParamSet with ``overrides`` applied and validated."""
        merged = dict(self._values)
        merged.update(flatten(overrides or {}))
        return ParamSet(merged, where)

    def changed(self) -> dict[str, Any]:
        """Only the values that differ from the declared defaults."""
        return {k: v for k, v in self._values.items() if v != PARAMS[k].default}

    def build_values(self) -> tuple:
        """The values of every parameter a model is built from ((name, value) pairs in name order;
        the size guards ``limits.*`` left out, which shape no model, and ``dynamics.path``, which
        builds the path mesh but which a simulator also obeys as it runs: ``own`` leaves it unused)."""
        return tuple((k, self[k]) for k in sorted(PARAMS)
                     if PARAMS[k].rebuild and not k.startswith("limits.") and k != "dynamics.path")

    def rebuild_differs(self, other: "ParamSet") -> bool:
        """True when any rebuild-needing parameter differs between two sets."""
        return any(self._values[k] != other._values[k] for k, p in PARAMS.items() if p.rebuild)

    def group(self, prefix: str) -> dict[str, Any]:
        """Values whose key starts with ``prefix.``, keyed by the remainder."""
        n = len(prefix) + 1
        return {k[n:]: v for k, v in self._values.items() if k.startswith(prefix + ".")}

    def to_dict(self) -> dict[str, Any]:
        return dict(self._values)

    def __repr__(self) -> str:
        return f"ParamSet({self.changed()!r})"


def as_params(params: Any, where: str) -> ParamSet:
    """``params`` as given to a library entry point (``build_leaf``, ``Run``, ``export_mesh``): a
    :class:`ParamSet`, else one LeafsimError line.  A plain dict is refused rather than filled
    up with the declared defaults, which would silently drop the species' own values."""
    if isinstance(params, ParamSet):
        return params
    raise LeafsimError(f"{where}: params {show(params)} ({type(params).__name__}): expected a ParamSet, e.g. "
                       f"sp.params or sp.params.with_overrides({{...}}) for sp = get_species(...)")


#: seeds are non-negative integers below 2**63 (numpy's generators take them as-is; a
#: checkpoint's record keeps them), as ``--seed`` and a scene's seeds take them
SEED_MAX = 2**63 - 1


def check_seed(seed: Any, where: str) -> int:
    """``seed`` as a Python int in [0, :data:`SEED_MAX`], else one LeafsimError line (a float,
    a string, a bool or a negative number reached numpy's generators, which raised a bare
    TypeError or ValueError, or was truncated silently)."""
    import numbers

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= int(seed) <= SEED_MAX:
        raise LeafsimError(f"{where}: seed = {show(seed)}: expected an integer in [0, 2**63-1]")
    return int(seed)


def parse_set_args(items: Iterable[str]) -> dict[str, Any]:
    """Parse CLI ``KEY=VALUE`` strings; keys are validated against the declaration."""
    out: dict[str, Any] = {}
    for item in items or ():
        if "=" not in item:
            raise LeafsimError(f"--set {show(item, 60)}: expected KEY=VALUE, e.g. --set osmosis.diffusion=1e-3")
        key, value = item.split("=", 1)
        key = key.strip()
        if key not in PARAMS:
            raise LeafsimError("--set: " + unknown_key_message(key))
        out[key] = PARAMS[key].coerce(value.strip(), "--set")
    return out


def markdown_table() -> str:
    """The parameter reference (docs/parameters.md) generated from the declaration."""
    lines = ["# leafsim parameters", "", "Generated from `leafsim/config/params.py` by `leafsim params --markdown`.", ""]
    for g in GROUPS:
        lines += [f"## {g}", "", "| name | default | range | unit | rebuild | help |", "|---|---|---|---|---|---|"]
        for p in _DECL:
            if p.group != g:
                continue
            rng = ", ".join(p.choices) if p.kind == "choice" else ("true/false" if p.kind == "bool" else f"{p.lo:g} … {p.hi:g}")
            only = f" Acts only with `{p.only_text()}`." if p.only else ""
            lines.append(f"| `{p.name}` | {p.default} | {rng} | {p.unit} | {'yes' if p.rebuild else 'live'} | {p.help}{only} |")
        lines.append("")
    if JOINTS:
        lines += ["## Joint constraints", "", "Checked after the single values (species values and `--set` together):", ""]
        lines += [f"- {j.rule}" for j in JOINTS]
        lines.append("")
    return "\n".join(lines)

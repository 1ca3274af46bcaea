"""Leaf colour from pigments: chlorophyll, carotenoids, anthocyanins, browning and necrosis.

Beyond the thesis (SPEC §9; Wang et al. 2009, *Survey on modeling and visualization of plant
leaf color*).  Each particle carries five pigment amounts that change with the season clock
(``age``) and with the particle's water content; a Beer–Lambert style model turns them into a
linear-RGB reflectance.  The stage is O(n), has no OpenGL and no state outside
:class:`PigmentState`.

Pigment dynamics (:func:`step_pigments`)
----------------------------------------
Let ``w`` = water_rel ∈ [0, 1] (current / initial water of the particle), ``G(age) =
max(age − onset, 0)`` the senescence exposure (season units after the onset), ``ΔG`` its
increase over the step, ``stress = 1 + water_sensitivity·(1 − w)``, the dryness
``d = clip((1 − w)/(1 − dry_threshold), 0, 1)`` (1 = dead dry tissue) and the drought stress
``σ = clip((stress_water − w)/0.05, 0, 1)`` (living tissue below ``colour.stress_water``).
The senescence exposure of a step is the season's and the drought's::

    H = stress·ΔG + drought·σ·(1 − d)·dt

(a detached, drying leaf runs its senescence program while its cells still live; Munné-Bosch
& Alegre 2004, Funct. Plant Biol. 31:203).  Death comes with dryness: ``E = dry_rate·d⁴·a·dt``,
where ``a = min(w / colour.reaction_water, 1)`` (1 when that is 0): the dead tissue's reactions
run on the water it still holds, so tissue that dries fast keeps the green it died with
(herbarium green); a bone-dry particle then changes only with the season clock.

* chlorophyll  ``C ← C·exp(−chlorophyll_decay·H)``, then a share ``1 − exp(−E)`` of what is
  left turns necrotic — programmed breakdown in living cells (unmasking the carotenoids),
  conversion to dark pheophytins in dying ones.  Never increases.
* necrosis     ``N ← N + C·(1 − exp(−E))`` — chlorophyll that was still there when the tissue
  died: tissue that dies before it senesced turns dark (necrotic spots), tissue that
  senesced first just browns.  Never decreases.
* carotenoids  ``K ← K·exp(−(carotenoid_decay·H + 0.1·E))`` — they mostly persist and are
  *unmasked* as chlorophyll goes: yellow/orange.
* anthocyanins ``A ← (A + 2·(1 − d)·(1 − C)·ΔC_sen)·exp(−(anthocyanin_fade·stress·ΔG + 0.05·E))``
  — made in still-living cells from the programmed chlorophyll breakdown ``ΔC_sen`` and late
  in it (factor ``1 − C``: sugars accumulate once photosynthesis has declined, so the red
  follows the unmasked yellow instead of muddying full green), they peak and then fade with
  the season; dry dead cells make none and keep most of theirs.  The species level
  ``colour.anthocyanin`` scales them at colour time (0 = species makes none).
* browning     ``B ← 1 − (1 − B)·exp(−browning·(1 − C)²·(0.5·stress·ΔG + E))`` — oxidised
  phenolics in tissue whose chlorophyll is gone, fast where it is dying.  Never decreases.

All five are exact exponential updates, so any step size is stable and monotone; large steps
are sub-stepped (no exponent above 0.1 per sub-step; season and time advance together, so a
step that crosses the onset while drying is resolved) so the couplings (anthocyanin from
chlorophyll loss, browning from dead tissue) stay accurate.  With ``w = 1``
and a constant ``age`` nothing changes at all.  Nothing here looks at positions or distances;
the spatial pattern comes from two fields.  The water field's: margins and intercostal areas
lose more water (the margin evaporates more, light intercostal tissue holds less, veins carry
extra water and feed their neighbours), and where the blade's seeded patch field makes it lose
water faster (``osmosis.patchiness``: patchy hydraulic failure) tissue is stressed earlier and,
if it dies before it senesced, necrotic.  The drought stress switches on within 5 % of water, so
a small difference in water becomes a difference in *when* a place turns.  And the senescence
field's (:mod:`leafsim.sim.senescence`, the ``field`` argument): a per-particle rate ``r``
multiplying the senescence exposure (``H ← r·H``, and the season's fading and browning) — the
margin first, green islands along the veins, patches — and a spot share ``s`` whose tissue dies
as it senesces (death exposure ``E + 12·s·H``).  Uniform water, uniform mass and no field give
a uniform colour.

Amounts are stored relative to the leaf's own summer content (``C``, ``K`` start at 1,
``A``, ``B`` at 0), so the palette parameters below act live (GUI sliders) at colour time.

Colour (:func:`pigments_to_rgb`)
--------------------------------
A leaf is a thin scattering slab; light that is reflected diffusely has crossed pigmented
tissue (twice), so per RGB band (Beer–Lambert with band-averaged absorbances)::

    reflectance = surface + base · exp(−Σ_p c_p · k_p)

``surface`` = 0.03 is the unabsorbed first-surface (cuticle) reflection that keeps greens from
being over-saturated and dark browns from going black; ``base`` = (0.82, 0.80, 0.72) is
pigment-free leaf tissue (white-ish, slightly yellow from cell walls).  Concentrations
``c_p`` (1 = typical summer content) are

    c_chl = colour.chlorophyll · leaf_chl · (1 − vein_pallor·m̂) · C
    c_car = colour.carotenoid  · leaf_car · K
    c_ant = colour.anthocyanin · leaf_ant · A
    c_brn = colour.brown_level · (1 − colour.vein_browning·m̂) · B
    c_nec = colour.necrosis · colour.chlorophyll · leaf_chl · (1 − vein_pallor·m̂) · N

with per-leaf factors ``leaf_*`` from the seed and ``m̂`` the min–max normalised rest mass
(heavy vein tissue is paler).  Absorption coefficients ``k_p`` (natural-log absorbance per unit
concentration, double pass, in linear R, G, B; the table is
:data:`leafsim.appearance.reflectance.ABSORPTION`):

=============  =====  =====  =====  ============================================================
pigment          R      G      B    reasoning
=============  =====  =====  =====  ============================================================
chlorophyll    3.20   1.15   3.00   a and b absorb 430–470 nm and 640–680 nm; the green window
                                    550 nm is weak → green.  Calibrated so a summer leaf is
                                    ≈ sRGB (70, 115, 48) (leaf spectra: ~5 %, 15 %, 4 %).
carotenoid     0.02   0.45   3.50   lutein/β-carotene absorb 400–500 nm only: blue is lost,
                                    some green at high content → yellow, then orange.
anthocyanin    0.25   2.60   0.50   cyanidin (and pokeweed's betacyanins) absorb 500–560 nm:
                                    green is lost → red with carotenoids (maple scarlet),
                                    magenta/purple without them (pokeweed).
browning       1.15   1.85   3.30   oxidised phenolics/melanoidins absorb broadly, rising
                                    toward the blue → brown (dry leaf ≈ sRGB (137, 90, 50)).
necrosis       2.40   2.40   2.60   pheophytins and oxidised phenolics of tissue that died
                                    green absorb across the spectrum → olive-black spots.
=============  =====  =====  =====  ============================================================

``c_nec = colour.necrosis · (the chlorophyll content) · (1 − vein_pallor·m̂) · N``: the darker
a leaf was, the darker its necrotic tissue.

Photo species (:func:`fit_photo_contents`, :class:`leafsim.appearance.view.LeafView`): the young colour is
the photo's; the chlorophyll content and an extra surface reflectance are fitted so the
model's young colour is the photo's mean colour, and aging multiplies the photo by the model's
reflectance change, rgb(now) / rgb(young) with those contents.

Band-averaged Beer–Lambert is an approximation (the exponential of a mean absorbance is not
the mean of the exponentials), good enough for RGB rendering; the coefficients were tuned by
eye (palette strips, summer → autumn → dry) against the photos in data/: aspen-like summer
leaf ≈ sRGB (56, 73, 40), oak (153, 183, 83), yellow hornbeam-like autumn leaf (176, 137, 58).

Palettes
--------
:data:`PALETTES` suggests ``colour.*`` values per species; the species config copies them
(docs/method.md §7 cites the trajectories; docs/aging/ shows them at the defaults):

* maple (Norway maple) — carotenoid 1.4, a little anthocyanin 0.15 that varies between leaves:
  clear yellow, sometimes orange; dried yellow-brown.  (Sugar/red maple: anthocyanin 1.6, the
  config's ``maple_sugar`` variant: scarlet.)
* oak — carotenoid 0.5, browning 8, no anthocyanin: tan, then russet brown.
* chestnut — carotenoid 1.4: golden yellow, then copper-brown.
* walnut — early onset 0.15, carotenoid 1.1, browning 2: dull yellow/ochre.
* pokeweed — betacyanins 2.5 (anthocyanin channel), carotenoid 0.1: magenta / purple-red.
* grapevine (white cultivar) — carotenoid 1.2: yellow; ``grapevine_red``: anthocyanin 1.2, red.
* aspen — carotenoid 1.3 with slow decay, small leaf spots: golden, then yellow-brown.
* hornbeam — carotenoid 1.3: golden yellow, then yellow-brown.

Every palette starts at a summer green ≈ (70, 118, 50).  How dark the dead leaf gets is the
species' ``colour.brown_level`` (tannins: oak and walnut 1, the golden species about half).
Every species also takes :data:`PATTERN`: where the blade turns first
(:mod:`leafsim.sim.senescence`).

Time: ``age`` is the season clock (0 summer, 1 late autumn; :func:`age_at` =
``colour.season + colour.age_rate·t``), ``dt`` is simulated seconds.  Per physics step the cost
is one vectorised pass (~2 ns per particle, see :func:`bench_colour`): the exponentials are
float32 polynomials (relative error < 1e-5) chosen by the largest exponent of the step.

Example
-------
>>> import numpy as np
>>> from leafsim.config.params import ParamSet
>>> p = ParamSet(PALETTES["maple"])
>>> pig = init_pigments(100, p, seed=1)
>>> step_pigments(pig, np.ones(100, np.float32), age=0.9, dt=0.0, params=p)
>>> rgb = pigments_to_rgb(pig, p)          # (100, 3) float32 linear RGB, now yellow
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np
from numba import njit

from leafsim.base.cache import configure_numba_cache
from leafsim.config.params import ParamSet
from leafsim.sim.senescence import SPOT_KILL

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources

__all__ = [
    "PigmentState",
    "PALETTES",
    "init_pigments",
    "step_pigments",
    "age_at",
]


#: Large steps are split so that no exponent exceeds this per sub-step (couplings stay accurate),
#: the onset is resolved to _MAX_DG season units, and at most _MAX_SUBSTEPS sub-steps are taken.
_MAX_EXPOSURE = 0.1
_MAX_DG = 0.02
_MAX_SUBSTEPS = 100_000

#: Suggested palette values per species (copied into configs/leaves.json by the species config);
#: every species also takes the spatial pattern of :data:`PATTERN` (where the blade turns first).
PATTERN: dict[str, float] = {"colour.patchiness": 0.5, "colour.patch_size": 0.01, "colour.margin_first": 1.5, "colour.margin_width": 0.003, "colour.vein_islands": 0.6, "colour.island_width": 0.002, "colour.vein_browning": 0.4}
PALETTES: dict[str, dict[str, float]] = {
    # Acer platanoides (Norway maple): carotenoids unmasked → clear yellow; a little anthocyanin that
    # varies from leaf to leaf (colour.variation) → sometimes orange.  (Sugar/red maple: the config's
    # maple_sugar variant, anthocyanin 1.6 → scarlet.)
    "maple": {**PATTERN, **{"colour.brown_level": 0.6, "colour.chlorophyll": 1.0, "colour.carotenoid": 1.4, "colour.anthocyanin": 0.15, "colour.anthocyanin_fade": 0.8, "colour.browning": 0.7, "colour.onset": 0.25, "colour.variation": 0.3}},
    # Quercus robur/petraea: little carotenoid, no anthocyanin, heavy tannins → tan, then russet
    # brown, the margin first.
    "oak": {**PATTERN, **{"colour.brown_level": 1.0, "colour.chlorophyll": 1.2, "colour.carotenoid": 0.5, "colour.anthocyanin": 0.0, "colour.browning": 8.0, "colour.onset": 0.35, "colour.chlorophyll_decay": 4.0, "colour.margin_first": 2.5}},
    # Castanea sativa: high carotenoid → golden yellow, then copper-brown.
    "chestnut": {**PATTERN, **{"colour.brown_level": 0.8, "colour.chlorophyll": 1.0, "colour.carotenoid": 1.4, "colour.anthocyanin": 0.0, "colour.browning": 1.2, "colour.onset": 0.3}},
    # Juglans regia: early, dull yellow, browns and drops quickly.
    "walnut": {**PATTERN, **{"colour.brown_level": 1.0, "colour.chlorophyll": 0.9, "colour.carotenoid": 1.1, "colour.anthocyanin": 0.0, "colour.browning": 2.0, "colour.onset": 0.15}},
    # Phytolacca americana: betacyanins (treated as the anthocyanin channel), few carotenoids
    # → magenta / purple-red.
    "pokeweed": {**PATTERN, **{"colour.brown_level": 0.6, "colour.chlorophyll": 1.0, "colour.carotenoid": 0.1, "colour.anthocyanin": 2.5, "colour.anthocyanin_fade": 0.6, "colour.browning": 0.3, "colour.onset": 0.2}},
    # Vitis vinifera, white-berried cultivar: yellow, then brown (the red-berried cultivar is the
    # config's grapevine_red variant: anthocyanin 1.2).
    "grapevine": {**PATTERN, **{"colour.brown_level": 0.6, "colour.chlorophyll": 0.9, "colour.carotenoid": 1.2, "colour.anthocyanin": 0.0, "colour.browning": 1.0, "colour.onset": 0.25}},
    # Populus tremula/tremuloides: golden yellow → yellow-brown → brown, small dark leaf spots
    # (Marssonina-like).
    "aspen": {**PATTERN, **{"colour.brown_level": 0.5, "colour.chlorophyll": 0.9, "colour.carotenoid": 1.3, "colour.anthocyanin": 0.0, "colour.browning": 0.6, "colour.onset": 0.3, "colour.carotenoid_decay": 0.2, "colour.spots": 3000.0, "colour.spot_radius": 0.0006}},
    # Carpinus betulus: golden yellow, then yellow-brown.
    "hornbeam": {**PATTERN, **{"colour.brown_level": 0.45, "colour.chlorophyll": 1.0, "colour.carotenoid": 1.3, "colour.anthocyanin": 0.0, "colour.browning": 1.0, "colour.onset": 0.3, "colour.carotenoid_decay": 0.3}},
}


@dataclass
class PigmentState:
    """Pigment amounts per particle (all ``(n,) float32``) plus per-leaf factors.

    Parameters
    ----------
    chlorophyll : (n,) float32, fraction of the leaf's summer chlorophyll left, 1 → 0.
    carotenoid : (n,) float32, fraction of the summer carotenoids left, 1 → 0.
    anthocyanin : (n,) float32, anthocyanin made, in units of the species level (0 → ~0.7).
    browning : (n,) float32, browning (oxidised phenolics), 0 → 1.
    necrosis : (n,) float32, chlorophyll that was still there when the tissue died (turned into
        dark pheophytins: necrotic spots), in units of the summer content, 0 → 1.
    vein : (n,) float32, min–max normalised rest mass m̂ (0 thinnest lamina, 1 heaviest vein);
        the tissue holds ``1 − colour.vein_pallor·m̂`` of the lamina's chlorophyll (live).
    leaf : (6,) float64 per-leaf factors from the seed: chlorophyll, carotenoid, anthocyanin,
        browning and rate multipliers, and the onset shift (season units).
    age : largest season clock seen so far (the next step ages from here).
    seed : the seed the leaf factors were drawn from.
    """

    chlorophyll: np.ndarray
    carotenoid: np.ndarray
    anthocyanin: np.ndarray
    browning: np.ndarray
    vein: np.ndarray
    leaf: np.ndarray
    age: float = 0.0
    seed: int = 0
    necrosis: np.ndarray | None = None
    _coeffs: tuple | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.necrosis is None:  # states saved before necrosis existed: none yet
            self.necrosis = np.zeros_like(self.chlorophyll)

    @property
    def n(self) -> int:
        return int(self.chlorophyll.shape[0])

    def copy(self) -> "PigmentState":
        """Deep copy (e.g. keep the young state ``pig0`` for :func:`tint_for_texture`)."""
        return replace(
            self,
            chlorophyll=self.chlorophyll.copy(),
            carotenoid=self.carotenoid.copy(),
            anthocyanin=self.anthocyanin.copy(),
            browning=self.browning.copy(),
            necrosis=self.necrosis.copy(),
            vein=self.vein.copy(),
            leaf=self.leaf.copy(),
            _coeffs=None,
        )


def _get(params: Mapping[str, Any], key: str) -> float:
    return float(params[key])


def init_pigments(n: int, params: Mapping[str, Any], seed: int = 0,
                  rest_relative_mass: np.ndarray | None = None) -> PigmentState:
    """Summer (age 0) pigment state of one leaf with ``n`` particles.

    Parameters
    ----------
    n : number of particles.
    params : ParamSet (or mapping with the ``colour.*`` keys).
    seed : per-leaf random variation of contents, rates and onset (scaled by colour.variation);
        the same seed gives the identical leaf.
    rest_relative_mass : optional (n,) rest mass per particle (any positive scale); it is
        min–max normalised to m̂ ∈ [0, 1] and heavy (vein) tissue gets
        ``1 − colour.vein_pallor·m̂`` of the lamina's chlorophyll.  Uniform mass → uniform.

    The state starts at age 0 (summer); the first :func:`step_pigments` call ages it to the
    season clock it is given (``colour.season`` at t = 0, see :func:`age_at`).
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"init_pigments: n = {n} must be >= 0")
    vein = np.zeros(n, np.float32)
    if rest_relative_mass is not None:
        m = np.asarray(rest_relative_mass, dtype=np.float64).reshape(-1)
        if m.shape[0] != n:
            raise ValueError(f"init_pigments: rest_relative_mass has {m.shape[0]} entries, expected {n}")
        if not np.all(np.isfinite(m)):
            raise ValueError("init_pigments: rest_relative_mass contains NaN or inf")
        lo, hi = (float(m.min()), float(m.max())) if n else (0.0, 0.0)
        if hi - lo > 1e-12 * max(abs(hi), 1.0):
            vein = ((m - lo) / (hi - lo)).astype(np.float32)
    v = _get(params, "colour.variation")
    z = np.random.default_rng(seed).standard_normal(6)
    # log-normal multipliers: anthocyanin varies most between leaves in nature.
    leaf = np.array([
        math.exp(0.35 * v * z[0]),   # chlorophyll content
        math.exp(0.35 * v * z[1]),   # carotenoid content
        math.exp(0.8 * v * z[2]),    # anthocyanin level
        math.exp(0.5 * v * z[3]),    # browning rate
        math.exp(0.3 * v * z[4]),    # senescence rates
        0.15 * v * z[5],             # onset shift (season units)
    ], dtype=np.float64)
    return PigmentState(
        chlorophyll=np.ones(n, np.float32),
        carotenoid=np.ones(n, np.float32),
        anthocyanin=np.zeros(n, np.float32),
        browning=np.zeros(n, np.float32),
        necrosis=np.zeros(n, np.float32),
        vein=vein,
        leaf=leaf,
        age=0.0,
        seed=int(seed),
    )


def age_at(t: float, params: Mapping[str, Any]) -> float:
    """Season clock at simulated time ``t`` seconds: ``colour.season + colour.age_rate·t``."""
    return _get(params, "colour.season") + _get(params, "colour.age_rate") * float(t)


# --------------------------------------------------------------------------- kernels
# exp(-x) for x >= 0 in float32, without libm calls so that the particle loop vectorises
# (numba has no SVML here; libm exp made the step ~8x slower).  Three accuracies: the caller
# picks the cheapest one whose range covers the largest exponent of the step.
ONE32 = np.float32(1.0)
#: fast-math without 'nnan'/'ninf' so NaN water can be caught (treated as dry).
FASTMATH_FLAGS = {"nsz", "arcp", "contract", "afn", "reassoc"}
ZERO32 = np.float32(0.0)
SPOT_KILL32 = np.float32(SPOT_KILL)


@njit(inline="always", fastmath=FASTMATH_FLAGS)
def _exp_tiny(x):  # pragma: no cover - numba; x <= 0.01: Taylor deg 3, rel. err < 5e-10
    return ONE32 - x * (ONE32 - x * (np.float32(0.5) - x * np.float32(1.0 / 6.0)))


@njit(inline="always", fastmath=FASTMATH_FLAGS)
def _exp_small(x):  # pragma: no cover - numba; x <= 0.1: Taylor deg 5, rel. err < 2e-9
    return ONE32 - x * (ONE32 - x * (np.float32(0.5) - x * (np.float32(1.0 / 6.0) - x * (
        np.float32(1.0 / 24.0) - x * np.float32(1.0 / 120.0)))))


@njit(inline="always", fastmath=FASTMATH_FLAGS)
def exp_neg_any(x):  # pragma: no cover - numba; any x >= 0: (e^(-x/128))^128, rel. err < 1e-5
    y = min(x, np.float32(80.0)) * np.float32(1.0 / 128.0)
    p = ONE32 - y * (ONE32 - y * (np.float32(0.5) - y * (np.float32(1.0 / 6.0) - y * (np.float32(1.0 / 24.0) - y * (
        np.float32(1.0 / 120.0) - y * (np.float32(1.0 / 720.0) - y * (np.float32(1.0 / 5040.0) - y * np.float32(1.0 / 40320.0))))))))
    for _ in range(7):
        p = p * p
    return p


@njit(inline="always", fastmath=FASTMATH_FLAGS)
def _expneg(x, mode):  # pragma: no cover - numba; mode is a literal at every call site
    if mode == 0:
        return _exp_tiny(x)
    if mode == 1:
        return _exp_small(x)
    return exp_neg_any(x)


@njit(inline="always", fastmath=FASTMATH_FLAGS)
def _particle(c, k, a, b, nn, wi, ri, si, h, e, dr, kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off, mode):  # pragma: no cover
    """One (sub-)step of one particle: ΔG = h season units, dry exposure e = dry_rate·dt,
    drought exposure dr = drought·dt (season units at full water stress); ri the particle's
    senescence rate and si its spot share (:mod:`leafsim.sim.senescence`)."""
    half = np.float32(0.5)
    wi = min(wi if wi >= ZERO32 else ZERO32, ONE32)  # NaN → 0 (needs the no-'nnan' flag set)
    lack = ONE32 - wi
    d = min(lack * inv_dry, ONE32)          # dryness, 1 = dead dry tissue
    stress = ONE32 + ws * lack               # water loss speeds seasonal senescence
    sig = min(max((w_s - wi) * np.float32(20.0), ZERO32), ONE32)  # drought stress below w_s
    hs = ri * (stress * h + dr * sig * (ONE32 - d))  # senescence exposure: season and drought, living cells
    esen = kc * hs                          # programmed chlorophyll breakdown
    d2 = d * d
    aw = min(wi * inv_rw + rw_off, ONE32)  # the water the dead tissue's reactions still have
    enec = e * d2 * d2 * aw + SPOT_KILL32 * si * hs  # death (dry tissue, or spot tissue as it senesces): what chlorophyll is left turns necrotic
    fc = _expneg(esen, mode)
    # phi = (1 − e^−x)/x: the breakdown per unit exposure, without 0/0
    phi = ONE32 - esen * (half - esen * (np.float32(1.0 / 6.0) - esen * (
        np.float32(1.0 / 24.0) - esen * np.float32(1.0 / 120.0))))
    if mode == 2:
        phi = phi if esen < np.float32(0.1) else (ONE32 - fc) / esen
    # anthocyanin: 2·(1 − C)·ΔC_sen in living cells, then fading
    a = (a + np.float32(2.0) * (ONE32 - d) * esen * phi * c * (ONE32 - c)) * _expneg(
        kaf * ri * stress * h + np.float32(0.05) * enec, mode)
    c = c * fc
    lost = c * (ONE32 - _expneg(enec, mode))
    c = c - lost
    nn = nn + lost
    k = k * _expneg(kk * hs + np.float32(0.1) * enec, mode)
    gone = ONE32 - c
    b = max(b, ONE32 - (ONE32 - b) * _expneg(kb * (half * ri * stress * h + enec) * gone * gone, mode))  # no float32 round-down
    # every factor is in [0, 1]: C and K never grow, N and B never shrink, even in float32
    return c, k, a, b, nn


# Explicit top-level kernels (not a factory: numba's on-disk cache cannot tell closures apart
# and would recompile them in every process).  Straight-line bodies: the loop vectorises.
@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _kernel_tiny(C, K, A, B, N, w, R, S, h, e, dr, co):  # pragma: no cover - numba
    """One step of all particles when every exponent is ≤ 0.01 (ordinary physics steps);
    ``co`` = (kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off) as float32 (the last two: the
    reaction-water factor min(w·inv_rw + rw_off, 1))."""
    h, e, dr = np.float32(h), np.float32(e), np.float32(dr)
    kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off = co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7], co[8]
    for i in range(C.shape[0]):
        C[i], K[i], A[i], B[i], N[i] = _particle(C[i], K[i], A[i], B[i], N[i], w[i], R[i], S[i], h, e, dr, kc, ws, kk, kaf, kb,
                                                 inv_dry, w_s, inv_rw, rw_off, 0)


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _kernel_small(C, K, A, B, N, w, R, S, h, e, dr, co):  # pragma: no cover - numba
    """One step of all particles when every exponent is ≤ 0.1."""
    h, e, dr = np.float32(h), np.float32(e), np.float32(dr)
    kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off = co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7], co[8]
    for i in range(C.shape[0]):
        C[i], K[i], A[i], B[i], N[i] = _particle(C[i], K[i], A[i], B[i], N[i], w[i], R[i], S[i], h, e, dr, kc, ws, kk, kaf, kb,
                                                 inv_dry, w_s, inv_rw, rw_off, 1)


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _kernel_substeps(C, K, A, B, N, w, R, S, hs, e, dr, co):  # pragma: no cover - numba
    """Large steps: sub-steps with season exposures hs[j] (follows the onset), dry exposure e
    and drought exposure dr per sub-step."""
    e, dr = np.float32(e), np.float32(dr)
    kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off = co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7], co[8]
    for i in range(C.shape[0]):
        c, k, a, b, nn, wi, ri, si = C[i], K[i], A[i], B[i], N[i], w[i], R[i], S[i]
        for j in range(hs.shape[0]):
            c, k, a, b, nn = _particle(c, k, a, b, nn, wi, ri, si, hs[j], e, dr, kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off, 2)
        C[i], K[i], A[i], B[i], N[i] = c, k, a, b, nn


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _kernel_small_idx(C, K, A, B, N, w, R, S, idx, h, e, dr, co):  # pragma: no cover - numba
    """:func:`_kernel_small` on the particles ``idx`` only (the slowly turning ones of a patterned
    blade while the fast ones are sub-stepped)."""
    h, e, dr = np.float32(h), np.float32(e), np.float32(dr)
    kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off = co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7], co[8]
    for ii in range(idx.shape[0]):
        i = idx[ii]
        C[i], K[i], A[i], B[i], N[i] = _particle(C[i], K[i], A[i], B[i], N[i], w[i], R[i], S[i], h, e, dr, kc, ws, kk, kaf, kb,
                                                 inv_dry, w_s, inv_rw, rw_off, 1)


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _kernel_substeps_idx(C, K, A, B, N, w, R, S, idx, hs, e, dr, co):  # pragma: no cover - numba
    """:func:`_kernel_substeps` on the particles ``idx`` only."""
    e, dr = np.float32(e), np.float32(dr)
    kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off = co[0], co[1], co[2], co[3], co[4], co[5], co[6], co[7], co[8]
    for ii in range(idx.shape[0]):
        i = idx[ii]
        c, k, a, b, nn, wi, ri, si = C[i], K[i], A[i], B[i], N[i], w[i], R[i], S[i]
        for j in range(hs.shape[0]):
            c, k, a, b, nn = _particle(c, k, a, b, nn, wi, ri, si, hs[j], e, dr, kc, ws, kk, kaf, kb, inv_dry, w_s, inv_rw, rw_off, 2)
        C[i], K[i], A[i], B[i], N[i] = c, k, a, b, nn


def _coefficients(pig: PigmentState, params: Mapping[str, Any]) -> tuple:
    """Step constants from params × per-leaf factors; cached on ``pig`` for an (immutable) ParamSet."""
    leaf = pig.leaf
    rate = float(leaf[4])
    args = np.array([
        float(params["colour.chlorophyll_decay"]) * rate,
        float(params["colour.water_sensitivity"]),
        float(params["colour.carotenoid_decay"]) * rate,
        float(params["colour.anthocyanin_fade"]) * rate,
        float(params["colour.browning"]) * float(leaf[3]),
        1.0 / (1.0 - float(params["colour.dry_threshold"])),
        float(params["colour.stress_water"]),
        1.0 / rw if (rw := float(params["colour.reaction_water"])) > 0.0 else 0.0,
        0.0 if rw > 0.0 else 1.0,
    ], np.float32)
    co = (params, float(params["colour.onset"]) + float(leaf[5]), float(params["colour.dry_rate"]),
          float(params["colour.drought"]) * rate, args)
    # only a ParamSet is immutable; a plain dict could change behind our back
    pig._coeffs = co if isinstance(params, ParamSet) else None
    return co


_UNIFORM: dict = {}


def _field_arrays(pig: PigmentState, field) -> tuple:
    """(rate, spot, max rate, max spot) for the kernels: the field's arrays, checked, or a
    uniform blade's (ones, zeros; kept per particle count)."""
    n = pig.n
    if field is None:
        if n not in _UNIFORM:
            if len(_UNIFORM) > 8:
                _UNIFORM.clear()
            _UNIFORM[n] = (np.ones(n, np.float32), np.zeros(n, np.float32), 1.0, 0.0)
        return _UNIFORM[n]
    rate, spot = field[0], field[1]
    for name, a in (("rate", rate), ("spot", spot)):
        if not (isinstance(a, np.ndarray) and a.dtype == np.float32 and a.flags.c_contiguous and a.shape == (n,)):
            raise ValueError(f"step_pigments: field {name} must be a C-contiguous float32 array of shape ({n},)")
    if len(field) >= 4:  # the maxima given (computed once when the field was made)
        return field[:4]
    return rate, spot, float(rate.max()) if n else 1.0, float(spot.max()) if n else 0.0


def step_pigments(pig: PigmentState, water_rel: np.ndarray, age: float, dt: float,
                  params: Mapping[str, Any], field: tuple | None = None) -> None:
    """Advance the pigments in place from ``pig.age`` to season clock ``age`` over ``dt`` s.

    Parameters
    ----------
    pig : state from :func:`init_pigments`, modified in place.
    water_rel : (n,) current water / initial water per particle, clipped to [0, 1]; NaN counts
        as dry (float32 C-contiguous avoids a conversion copy).
    age : season clock now (0 summer, 1 late autumn, unbounded); see :func:`age_at`.  A
        clock that goes backwards ages nothing (pigments cannot come back).
    dt : simulated seconds since the last call (drives drying damage via colour.dry_rate).
    params : ParamSet with the ``colour.*`` values (read live every call).
    field : optional (rate (n,), spot (n,)) float32 C-contiguous arrays from
        :func:`leafsim.sim.senescence.senescence_field` (where the blade turns first, and its
        spots), optionally followed by their maxima and then by the particles in order of falling
        rate with those rates (then only the fastest-turning particles are sub-stepped when a
        step needs it); None = a uniform blade (rate 1, no spots).

    Cost: O(n), about 2 ns per particle for ordinary steps (all exponents below 0.1: one
    vectorised pass with polynomial exps); larger steps are sub-stepped.
    """
    w = water_rel
    if not (isinstance(w, np.ndarray) and w.dtype == np.float32 and w.flags.c_contiguous):
        w = np.ascontiguousarray(w, dtype=np.float32)
    if w.shape != pig.chlorophyll.shape:
        raise ValueError(f"step_pigments: water_rel has shape {w.shape}, expected {pig.chlorophyll.shape}")
    co = pig._coeffs
    if co is None or co[0] is not params:
        co = _coefficients(pig, params)
    _, onset, dry_rate, drought, args = co
    a0, a1 = pig.age, float(age)
    dG = max(a1 - onset, 0.0) - max(a0 - onset, 0.0)
    if dG < 0.0:
        dG = 0.0
    if a1 > a0:
        pig.age = a1
    dt = max(float(dt), 0.0)
    dry, dr = dry_rate * dt, drought * dt
    if dG == 0.0 and dry == 0.0 and dr == 0.0:
        return
    kc, ws, kk, kaf, kb = (float(x) for x in args[:5])
    rate, spot, rmax, smax_spot = _field_arrays(pig, field)
    # the largest exponent any particle can see this step picks the cheapest accurate kernel
    smax = rmax * ((1.0 + ws) * dG + dr)
    dry_all = dry + SPOT_KILL * smax_spot * smax
    xmax = max(kc * smax, kaf * rmax * (1.0 + ws) * dG + 0.05 * dry_all, kk * smax + 0.1 * dry_all,
               kb * (0.5 * rmax * (1.0 + ws) * dG + dry_all), dry_all)
    arrays = (pig.chlorophyll, pig.carotenoid, pig.anthocyanin, pig.browning, pig.necrosis, w, rate, spot)
    if xmax <= 0.01:
        _kernel_tiny(*arrays, dG, dry, dr, args)
        return
    if xmax <= 0.1:
        _kernel_small(*arrays, dG, dry, dr, args)
        return
    nsub = max(1, math.ceil(xmax / _MAX_EXPOSURE))
    if (dry > 0.0 or dr > 0.0) and dG > 0.0:  # resolve the onset within the step: age and dt advance together
        nsub = max(nsub, math.ceil((a1 - a0) / _MAX_DG))
    nsub = min(nsub, _MAX_SUBSTEPS)
    ages = np.linspace(a0, max(a0, a1), nsub + 1)
    hs = np.diff(np.maximum(ages - onset, 0.0)).astype(np.float32)
    slow = _slow_count(field, rmax, (kc, ws, kk, kaf, kb), dG, dr, dry, smax_spot) if len(field or ()) == 6 else pig.n
    if 0 < slow < pig.n and not (dG > 0.0 and (dry > 0.0 or dr > 0.0) and math.ceil((a1 - a0) / _MAX_DG) > 1):
        # a patterned blade: only its fastest-turning particles need the sub-steps
        order = field[4]
        _kernel_substeps_idx(*arrays, order[:slow], hs, dry / nsub, dr / nsub, args)
        _kernel_small_idx(*arrays, order[slow:], dG, dry, dr, args)
        return
    _kernel_substeps(*arrays, hs, dry / nsub, dr / nsub, args)


def _slow_count(field, rmax, k, dG, dr, dry, smax_spot) -> int:
    """How many of the blade's particles, fastest-turning first (``field[4]`` sorts them by
    rate, ``field[5]`` holds the sorted rates), see an exponent above ``_MAX_EXPOSURE`` this
    step: the bound of every exponent is a + b·rate, so the ones above the rate where the
    first bound reaches it."""
    kc, ws, kk, kaf, kb = k
    s1 = (1.0 + ws) * dG + dr          # senescence exposure per unit rate
    spot = SPOT_KILL * smax_spot * s1  # necrosis exposure of spot tissue per unit rate
    lines = ((0.0, kc * s1), (0.05 * dry, kaf * (1.0 + ws) * dG + 0.05 * spot), (0.1 * dry, kk * s1 + 0.1 * spot),
             (kb * dry, kb * (0.5 * (1.0 + ws) * dG + spot)), (dry, spot))
    r_star = rmax
    for a, b in lines:
        if a >= _MAX_EXPOSURE:
            return len(field[5])
        if b > 0.0:
            r_star = min(r_star, (_MAX_EXPOSURE - a) / b)
    rates = field[5]  # descending
    return int(np.searchsorted(-rates, -r_star, side="left"))




def precompile() -> None:
    """Compile (and cache) every pigment kernel now: the small, sub-step and per-index ones
    are otherwise compiled when a drying leaf first needs them, a pause of seconds mid-run
    (``scripts/setup.sh`` calls this)."""
    one = np.ones(1, np.float32)
    arrays = [one.copy() for _ in range(5)] + [one.copy(), one.copy(), np.zeros(1, np.float32)]
    co = np.zeros(9, np.float32)
    idx = np.zeros(1, np.int64)
    _kernel_tiny(*arrays, 0.0, 0.0, 0.0, co)
    _kernel_small(*arrays, 0.0, 0.0, 0.0, co)
    _kernel_substeps(*arrays, np.zeros(1, np.float32), 0.0, 0.0, co)
    _kernel_small_idx(*arrays, idx, 0.0, 0.0, 0.0, co)
    _kernel_substeps_idx(*arrays, idx, np.zeros(1, np.float32), 0.0, 0.0, co)

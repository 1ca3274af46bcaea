"""The petiole (leafsim.blade.petiole): a stalk meshed as a three-row strip from the base.

Its geometry and counts, its mass (a rod of the vein density), its bending stiffness against
beam theory (a cantilevered stalk under its own weight), the hanging scene holding its tip,
the blade measures leaving it out, and the species' stalk lengths against their photos."""

import dataclasses
import math

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, lobed_shape, synthetic_veins
from leafsim.base.geometry import LeafShape, points_in_polygon
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.model import KIND_PETIOLE, LAYER_T
from leafsim.sim.shape import shape_metrics
from leafsim.sim.simulator import Simulator

STALK = {"mesh.spacing": 0.04, "petiole.length": 0.03, "petiole.diameter": 0.002}


@pytest.fixture(scope="module", params=["ellipse", "lobed"])
def pair(request):
    s = ellipse_shape() if request.param == "ellipse" else lobed_shape()
    v = synthetic_veins(s)
    without = build_blade(s, v, ParamSet({"mesh.spacing": 0.04}), seed=3)
    with_ = build_blade(s, v, ParamSet(STALK), seed=3)
    return s, without, with_


def test_stalk_is_a_strip_below_the_base(pair):
    s, m0, m = pair
    T = m.particle_layer == LAYER_T
    stalk_T = m.particle_petiole & T
    assert (m.particle_kind[stalk_T] == KIND_PETIOLE).all()
    n_sec = math.ceil(0.03 / m.spacing)
    assert stalk_T.sum() == 3 * n_sec
    # the blade is meshed exactly as without a stalk
    assert m.blade_tris.sum() == m0.tri_count
    assert m.to_report()["area_m2"] == pytest.approx(m0.to_report()["area_m2"], rel=1e-12)
    r = m.particle_rest
    a, b, c = r[m.tri_T[:, 0]], r[m.tri_T[:, 1]], r[m.tri_T[:, 2]]
    assert (np.cross(b - a, c - a)[:, 2] > 0).all()  # CCW, none degenerate
    assert not points_in_polygon(r[stalk_T, :2], s.contour).any()  # off the blade
    d = np.linalg.norm(r[stalk_T, :2] - r[m.base_particle, :2], axis=1)
    assert d.max() == pytest.approx(math.hypot(0.03, 0.001), rel=1e-6)
    # the V layer over the stalk's triangles belongs to it too; the base particle does not
    assert m.particle_petiole[m.tri_V[~m.blade_tris]].all()
    assert not m.particle_petiole[m.base_particle]


def test_centre_row_is_a_vein_rod_to_the_base(pair):
    _, _, m = pair
    stalk_veins = [(idx, w, o) for idx, w, o in m.vein_polylines() if m.particle_petiole[idx].any()]
    assert len(stalk_veins) == 1
    idx, w, o = stalk_veins[0]
    assert o == 0 and idx[-1] == m.base_particle and np.allclose(w, 0.002)
    assert (m.particle_vein_width[idx] >= 0.002).all()
    # its springs are rods of cross-section πd²/4
    ij = np.sort(m.spring_ij, 1)
    for a, b in zip(idx[:-1], idx[1:]):
        k = np.flatnonzero((ij[:, 0] == min(a, b)) & (ij[:, 1] == max(a, b)))
        assert len(k) == 1
        assert m.spring_rod[k[0]] * m.spring_rest0[k[0]] == pytest.approx(math.pi * 0.002 ** 2 / 4, rel=1e-9)


def test_stalk_weighs_a_rod_of_vein_tissue(pair):
    """The strip is as wide as the rod, so the lamina it stands for is exactly what the rod
    replaces: its mass is ρ_v πd²/4 per metre (the first half segment lumps to the base)."""
    _, _, m = pair
    p = ParamSet(STALK)
    n_sec = math.ceil(0.03 / m.spacing)
    s = 0.03 / n_sec
    expect = p["mass.vein_density"] * math.pi * 0.002 ** 2 / 4 * (0.03 - 0.5 * s)
    assert m.particle_mass0[m.particle_petiole].sum() == pytest.approx(expect, rel=0.1)


def test_hanging_scene_holds_the_stalk_tip(pair):
    _, m0, m = pair
    tip = m.particle_pinned
    assert tip.sum() == 3 and m.particle_petiole[tip].all()
    d = np.linalg.norm(m.particle_rest[tip, :2] - m.particle_rest[m.base_particle, :2], axis=1)
    assert d.min() == pytest.approx(0.03, rel=1e-6)
    # without a stalk the blade is held at its base as before
    assert m0.particle_petiole is None and m0.particle_pinned.sum() >= 1


def test_blade_measures_leave_the_stalk_out(pair):
    _, m0, m = pair
    a, b = shape_metrics(m0, m0.state(), own_frame=False), shape_metrics(m, m.state(), own_frame=False)
    for k in ("area_ratio", "margin_lift", "max_height", "max_displacement"):
        assert a[k] == pytest.approx(b[k], abs=1e-12), k
    # a stalk bent down under the blade does not change the blade's area or lift
    st = m.state()
    st.particle_q[m.particle_petiole, 2] -= 0.01
    c = shape_metrics(m, st, own_frame=False)
    assert c["area_ratio"] == pytest.approx(1.0, abs=1e-12)
    assert c["margin_lift"] == pytest.approx(b["margin_lift"], abs=1e-12)


def test_cantilevered_stalk_sags_as_beam_theory_says():
    """The blade held still, the stalk sticks out level and sags under its own weight: the tip
    drop of a cantilever under a uniform load, δ = q L⁴ / (8 E I), I = π d⁴ / 64, with q the
    stalk's weight per length.  The converged strip (many iterations, a static answer) sags
    1.08× that at 14 segments (the strip's lumped, discrete rod); without its diagonal hinges
    it sagged 1.2–2× (a soft fold mode), and with the junction at a full segment's compliance
    1.3×."""
    Ev, L, d = 2e7, 0.04, 0.002
    # a small, coarse blade (held still anyway): the iterations go to the stalk (r = 3 mm, 14 segments)
    p = ParamSet({"mesh.spacing": 0.1, "petiole.length": L, "petiole.diameter": d, "material.vein_modulus": Ev,
                  "effects.osmosis": False, "effects.shrink": False, "effects.colour": False,
                  "dynamics.scene": "hanging", "dynamics.iterations": 60, "dynamics.substeps": 80,
                  "dynamics.tolerance": 1e-9, "dynamics.damping": 200.0, "dynamics.mass_scaling": 1.0,
                  "dynamics.substep_scaling": False})
    s = ellipse_shape(length=0.03, width=0.02)
    m = build_blade(s, synthetic_veins(s), p, seed=4)
    m = dataclasses.replace(m, particle_pinned=m.blade_particles.copy())  # the blade held still
    sim = Simulator(m, p)
    st = sim.state()
    chain = next(idx for idx, _, _ in m.vein_polylines() if m.particle_petiole[idx].any())
    tip = int(chain[0])
    q = float(m.particle_mass0[m.particle_petiole].sum()) / L * p["dynamics.gravity"]
    expect = q * L ** 4 / (8 * Ev * math.pi * d ** 4 / 64)
    prev = 0.0
    for frame in range(4000):  # until the sag settles (frames, not a clock)
        sim.step(st)
        if frame % 50 == 49:
            z = -float(st.particle_q[tip, 2])
            if abs(z - prev) < 1e-3 * z:
                break
            prev = z
    assert np.isfinite(st.particle_q).all()
    print(f"stalk tip drop {z * 1e3:.4f} mm, beam theory {expect * 1e3:.4f} mm, ratio {z / expect:.3f}, frames {frame + 1}")
    assert 0.95 * expect < z < 1.2 * expect


def test_species_stalks_match_their_photos():
    """Oak's and hornbeam's photos show the whole stalk: the config's length is the traced one."""
    from leafsim.config.species import get_species, load_library
    from leafsim.pipeline import species_trace

    for key, sp in load_library().items():
        assert sp.params["petiole.length"] > 0, key
    for key in ("oak", "hornbeam"):
        sp = get_species(key)
        t = species_trace(sp)
        px = float(np.linalg.norm(t.petiole_px[1] - t.petiole_px[0]))
        traced = px * sp.length_m / float(np.linalg.norm(np.asarray(t.base_px) - np.asarray(t.apex_px)))
        assert sp.params["petiole.length"] == pytest.approx(traced, rel=0.05), key


def test_stalk_holds_water_longer_but_turns_with_the_blade():
    """A drying leaf is dry when its blade is (Model.water_fraction): the stalk, a thick rod,
    still holds several times the blade's share of its water then, yet its pigments have aged
    with the blade (before, it stayed green on a brown leaf)."""
    from leafsim.sim.run import Run

    p = ParamSet({"mesh.spacing": 0.05, "petiole.length": 0.04, "petiole.diameter": 0.002})
    s = ellipse_shape()
    m = build_blade(s, synthetic_veins(s), p, seed=2)
    run = Run(m, p)
    for _ in run.frames(until=lambda st: m.water_fraction(st.particle_water) <= 0.05 or st.frame >= 20000):
        pass
    st = run.state
    assert m.water_fraction(st.particle_water) <= 0.05
    stalk, blade = m.particle_petiole & (m.particle_layer == LAYER_T), m.blade_T
    rel = st.particle_water / m.particle_water0
    assert rel[stalk].mean() > 5 * m.water_fraction(st.particle_water)
    assert float(st.particle_water.sum() / m.particle_water0.sum()) > m.water_fraction(st.particle_water)
    pg = st.pigments
    assert pg.chlorophyll[stalk].mean() <= 2 * pg.chlorophyll[blade].mean() + 1e-3
    assert pg.browning[stalk].mean() >= 0.9 * pg.browning[blade].mean()


def test_every_species_stalk_is_joined_to_the_blade_by_hinges():
    """The stalk's first section is the base and its neighbours on the outline, so hinges join
    stalk and blade triangles and carry its moment (a stalk joined at one particle would swivel
    freely; maple's base sits in a notch whose margin runs down beside the stalk, grapevine's
    was traced just inside the blade)."""
    from leafsim.config.presets import QUALITY
    from leafsim.config.species import load_library
    from leafsim.pipeline import build_leaf
    from leafsim.sim.kernels.pbd import dihedral_angles

    for key, sp in load_library().items():
        m = build_leaf(sp, sp.params.with_overrides(QUALITY["draft"]), 0).model
        st, h = m.particle_petiole, m.hinge_idx
        joined = st[h].any(1) & ((~st[h]) & (h != m.base_particle)).any(1)
        assert joined.sum() >= 4, key
        assert (m.hinge_rod[joined] > 0).any(), key
        # and nothing is folded at rest (a strip triangle over a blade triangle is a hinge at π)
        assert np.abs(dihedral_angles(m.particle_rest, m.hinge_idx)).max() < 1e-9, key



def notched_shape(length: float = 0.12, width: float = 0.08, notch: float = 0.006, gap: float = 0.0015) -> LeafShape:
    """An elliptic blade with a narrow basal notch (as maple's sinus): the base at the notch's
    top (0, 0), its sides straight down to ± ``gap`` at ``notch`` below it, so within a few
    millimetres of the base the notch is narrower than a 2 mm stalk."""
    eps = math.asin(2.0 * gap / width)
    t = np.linspace(-np.pi / 2 + eps, 1.5 * np.pi - eps, 400)
    arc = np.column_stack([0.5 * width * np.cos(t), 0.5 * length * (1 + np.sin(t)) - notch])  # counter-clockwise
    f = np.linspace(0.0, 1.0, 12)[1:-1, None]
    up_left = arc[-1] * (1.0 - f)           # from the arc's end up the notch's left side to the base
    down_right = arc[0] * f                 # from the base down its right side to the arc's start
    poly = np.vstack([arc, up_left, [[0.0, 0.0]], down_right])
    return LeafShape(contour=poly, base=np.zeros(2), apex=np.array([0.0, length - notch]), lobes=np.empty((0, 2)),
                     length=length)


def test_stalk_in_a_narrow_notch_narrows_instead_of_overlapping_the_blade():
    """A stalk wider than the basal notch it leaves from: its strip narrows there (only there),
    so no strip particle lies on the blade and no hinge is folded at rest.  Before, on maple
    at meshes finer than the default, a strip triangle lay over a blade triangle across a
    shared margin edge: a hinge folded by π at rest, which threw the stalk about at 14 m/s in
    the first frames and stopped every run at 0.01 L (the watchdog)."""
    from leafsim.sim.kernels.pbd import dihedral_angles

    s = notched_shape()
    d = 0.002
    m = build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": 0.01, "petiole.length": 0.03, "petiole.diameter": d}),
                    seed=2)
    r = m.particle_rest
    stalk_T = m.particle_petiole & (m.particle_layer == LAYER_T)
    assert not points_in_polygon(r[stalk_T, :2], s.contour).any()
    assert np.abs(dihedral_angles(r, m.hinge_idx)).max() < 1e-9
    a, b, c = r[m.tri_T[:, 0]], r[m.tri_T[:, 1]], r[m.tri_T[:, 2]]
    assert (np.cross(b - a, c - a)[:, 2] > 0).all()
    # sections: three stalk particles at one distance along the stalk; width = their spread
    ids = np.flatnonzero(stalk_T & (m.particle_kind == KIND_PETIOLE))
    along = np.round(-r[ids, 1], 9)
    widths = {y: np.ptp(r[ids[along == y], 0]) for y in np.unique(along)}
    ys = sorted(widths)
    assert widths[ys[0]] < 0.9 * d          # narrowed in the notch
    assert widths[ys[-1]] == pytest.approx(d, rel=1e-9)   # the stalk's own width once clear of it
    assert all(widths[y] == pytest.approx(d, rel=1e-9) for y in ys if y > 0.008)


def test_rod_mass_is_lumped_with_the_rod_s_polar_inertia(pair):
    """Past the junction every section carries its rod as M/2 on the centre and M/4 on each
    side: the same total, and the polar moment 2 (M/4)(d/2)² = M d²/8 of a round rod (all of it
    on the centre row made the sides up to 1600× lighter than the centre, and the stalk went
    unstable on fine meshes)."""
    s, _, m = pair
    # the same build with twice the vein density: the difference is the rods' mass alone (as
    # lumped), the lamina's cancels
    heavy = build_blade(s, synthetic_veins(s), ParamSet({**STALK, "mass.vein_density": 2 * 1100.0}), seed=3)
    assert heavy.particle_count == m.particle_count
    rod = heavy.particle_mass0 - m.particle_mass0
    r = m.particle_rest
    ids = np.flatnonzero(m.particle_petiole & (m.particle_layer == LAYER_T) & (m.particle_kind == KIND_PETIOLE))
    centre = ids[m.particle_vein_order[ids] == 0]
    sides = np.setdiff1d(ids, centre)
    assert rod[centre].min() > 0
    assert rod[sides].sum() == pytest.approx(rod[centre].sum(), rel=1e-9)
    for c in centre:
        near = sides[np.argsort(np.linalg.norm(r[sides, :2] - r[c, :2], axis=1))[:2]]
        assert rod[near] == pytest.approx([0.5 * rod[c]] * 2, rel=1e-9)
        assert 2 * rod[near[0]] * 0.001 ** 2 == pytest.approx(2 * rod[c] * 0.002 ** 2 / 8, rel=1e-9)  # M d²/8, M = 2 rod[c]


@pytest.mark.slow
def test_maple_on_a_finer_mesh_starts_at_rest():
    """Maple at 0.0141 L (the accuracy study's reference mesh): no hinge folded at rest, and the
    first frames move the tissue at millimetres per second at most, as on the default mesh
    (with the folded hinges of before: 22 mm/s RMS, 0.35 m/s at 0.01 L)."""
    from leafsim.config.species import get_species
    from leafsim.pipeline import build_leaf
    from leafsim.sim.kernels.pbd import dihedral_angles
    from leafsim.sim.watchdog import momenta

    sp = get_species("maple")
    p = sp.params.with_overrides({"mesh.spacing": 0.0141, "dynamics.path": "own", "effects.colour": False})
    m = build_leaf(sp, p, 0).model
    assert np.abs(dihedral_angles(m.particle_rest, m.hinge_idx)).max() < 1e-9
    sim = Simulator(m, p)
    st = sim.state()
    for _ in range(10):
        sim.step(st)
    mom = momenta(m.particle_cytosol + st.particle_water, st.particle_q, st.particle_qd)
    assert mom["rms_internal_speed"] < 0.005

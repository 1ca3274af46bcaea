"""The hinges' weights (leafsim.sim.bending): Grinspun's discrete-shells weight stores several
times the plate's bending energy in a cylinder; the cylinder-scaled weights store exactly
½ D κ² A in a cylinder, on any mesh, bent about either axis (not in a cup or a saddle: no single
scale can); the elastic energy the solvers minimise takes the parameter's weights, also when
it changes live."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.bending import _dihedral, cylinder_ratio, hinge_weights, mode_ratios, shells_weights
from leafsim.sim.kernels import static as kst
from leafsim.sim.simulator import Simulator


@pytest.fixture(scope="module", params=[0.03, 0.02])
def model(request):
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": request.param}), seed=1)


def _cylinder(model, kappa, axis):
    r = model.particle_rest
    q = r.copy()
    R = 1.0 / kappa
    u = r[:, axis] - r[model.blade_particles, axis].mean()
    q[:, axis] = R * np.sin(u / R)
    q[:, 2] = R - R * np.cos(u / R)
    return q


def _ratio(model, w, kappa, axis):
    """Σ ½ w θ² / ½ κ² A for one bend, computed here from the triangles' normals."""
    hidx = np.asarray(model.hinge_idx, np.int64)
    on = model.blade_particles[hidx].all(1)
    th = _dihedral(_cylinder(model, kappa, axis), hidx[on])
    return float((w[on] * th ** 2).sum()) / (kappa ** 2 * float(model.particle_area[model.blade_T].sum()))


def test_discrete_shells_weights_store_several_times_the_plate_energy(model):
    w = shells_weights(model)
    assert np.array_equal(w, hinge_weights(model, "discrete_shells"))
    for axis in (0, 1):
        assert 2.8 < _ratio(model, w, 2.0, axis) < 5.0  # 3 on a regular mesh, more on an irregular one


@pytest.mark.parametrize("kappa", [0.5, 2.0, 8.0])
def test_cylinder_weights_store_the_plate_energy_about_either_axis(model, kappa):
    w = hinge_weights(model, "cylinder")
    r = [_ratio(model, w, kappa, axis) for axis in (0, 1)]
    assert np.mean(r) == pytest.approx(1.0, abs=0.01)
    assert all(0.9 < x < 1.1 for x in r), r  # each axis near it (the mesh is nearly isotropic)
    assert cylinder_ratio(model, w) == pytest.approx(1.0, rel=1e-9)
    assert np.allclose(w / shells_weights(model), w[0] / shells_weights(model)[0])  # one factor for all


def test_cylinder_weights_scale_the_blade_and_leave_a_stalk_alone():
    """With a stalk, only the blade's hinges (all four particles the blade's) take the factor;
    the stalk's strip hinges keep the discrete-shells weights, and the blade's factor is the one
    the blade alone would get."""
    s = ellipse_shape()
    m = build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": 0.04, "petiole.length": 0.03}), seed=1)
    hidx = np.asarray(m.hinge_idx, np.int64)
    on = m.blade_particles[hidx].all(1)
    assert on.any() and (~on).sum() >= 4  # the stalk has hinges
    sh, cy = shells_weights(m), hinge_weights(m, "cylinder")
    assert np.array_equal(cy[~on], sh[~on])
    f = cy[on] / sh[on]
    assert np.allclose(f, f[0]) and f[0] == pytest.approx(1.0 / cylinder_ratio(m, sh), rel=1e-12)
    assert 0.15 < f[0] < 0.4  # the blade's hinges stored 2.5-7 x the plate
    assert cylinder_ratio(m, cy) == pytest.approx(1.0, rel=1e-9)


def test_the_solvers_energy_takes_the_chosen_weights(model):
    """The static and Sun integrators' hinge stiffness is D w with the parameter's weights: the
    hinges' share of the elastic energy of a cylinder bend is ½ D κ² A × the ratio."""
    kappa = 2.0
    for mode, expect in (("discrete_shells", None), ("cylinder", 1.0)):
        p = ParamSet({"mesh.spacing": 0.03, "material.hinge_weights": mode, "material.vein_modulus": 1e5,
                      "dynamics.integrator": "static", "dynamics.scene": "ground"})
        sim = Simulator(model, p, seed=1)
        st = sim.state()
        dyn = sim._dynamics
        ij, sk, srest, _, hidx, hk, hrest, vidx, vk, vrest = dyn.sun_elastic(st)
        on = model.blade_particles[hidx].all(1)
        q = _cylinder(model, kappa, 0)
        e = kst.elastic_energy(q, ij[:0], sk[:0], srest[:0], hidx[on], hk[on], hrest[on], vidx[:0], vk[:0], vrest[:0])
        ratio = e / (0.5 * dyn.kbend * kappa ** 2 * float(model.particle_area[model.blade_T].sum()))
        w = hinge_weights(model, mode)
        assert ratio == pytest.approx(_ratio(model, w, kappa, 0), rel=2e-3)  # (the veins' 1e5 Pa rods: ~0)
        if expect is not None:
            assert ratio == pytest.approx(expect, abs=0.1)


def test_the_dihedral_angle_of_two_triangles_folded_by_a_known_angle():
    """(c, d, a, b): wings c, d, shared edge a-b; the wing d turned up by phi about the edge."""
    for phi in (0.0, 0.1, 0.7, 1.5):
        q = np.array([[0.0, -1.0, 0.0], [0.0, np.cos(phi), np.sin(phi)], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
        assert _dihedral(q, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(phi, abs=1e-9)


def test_no_single_scale_is_the_plate_in_every_mode(model):
    """A cup and a saddle against a cylinder: the discrete-shells weights store 3-5 x the plate in
    a cylinder and less in a cup, more in a saddle (their energy has no Poisson term); the
    cylinder-scaled ones are the plate in a cylinder only."""
    nu = 0.3
    sh = mode_ratios(model, shells_weights(model), nu)
    assert 2.8 < sh["cylinder"] < 5.0 and sh["cup"] < 0.7 * sh["cylinder"] and sh["saddle"] > 1.5 * sh["cylinder"]
    cy = mode_ratios(model, hinge_weights(model, "cylinder"), nu)
    assert cy["cylinder"] == pytest.approx(1.0, abs=0.03)
    assert cy["cup"] < 0.7 and cy["saddle"] > 1.5


def test_the_weights_follow_the_parameter_in_both_integrators_and_live(model):
    """The default is the discrete-shells weight exactly (XPBD's in projection order, the static
    and Sun integrators' in model order); a live change of material.hinge_weights takes effect
    in both."""
    p = ParamSet({"mesh.spacing": 0.03})
    sim = Simulator(model, p, seed=1)
    dyn = sim._dynamics
    w = 3.0 * model.hinge_edge_len ** 2 / np.maximum(model.hinge_area, 1e-30)
    assert np.array_equal(dyn.hgeom, w[dyn.hperm]) and np.array_equal(dyn.s_hgeom, w)
    sim.set_params(p.with_overrides({"material.hinge_weights": "cylinder"}))
    c = hinge_weights(model, "cylinder")
    assert np.array_equal(dyn.hgeom, c[dyn.hperm]) and np.array_equal(dyn.s_hgeom, c)
    sim.set_params(p)
    assert np.array_equal(dyn.hgeom, w[dyn.hperm])

"""Resource guards (issue 9, point 3): too-large models, endless vein growth and huge photos
are refused (or downscaled) before they cost minutes or gigabytes, with a one-line error
naming the parameter and the limit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import points_in_polygon
from leafsim.blade import budget
from leafsim.blade.budget import check_mesh_budget, estimate_particles
from leafsim.blade.build import build_blade
from leafsim.cli import main
from leafsim.config.species import load_library
from leafsim.pipeline import leaf_shape, species_veins

LIB = load_library()


def one_line_error(capsys, argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, (code, err)
    return err


@pytest.mark.parametrize("key,spacing", [("maple", 0.028), ("maple", 0.012), ("oak", 0.02), ("chestnut", 0.015)])
def test_particle_estimate_close_to_the_built_model(key, spacing):
    sp = LIB[key]
    p = sp.params.with_overrides({"mesh.spacing": spacing})
    shape = leaf_shape(sp, p)
    model = build_blade(shape, species_veins(sp, shape, p, 0), p, 0)
    n = model.to_report()["particles"]
    assert 0.85 * n <= estimate_particles(shape, p) <= 1.15 * n


def test_declared_minimum_spacing_refused_before_growing_veins(capsys, monkeypatch):
    import leafsim.commands.shape  # noqa: F401  (imported before the patch: it must not keep the fake)
    import leafsim.pipeline

    def no_growth(*a, **k):
        raise AssertionError("veins grown for a model that is refused anyway")

    monkeypatch.setattr(leafsim.pipeline, "species_veins", no_growth)
    err = one_line_error(capsys, ["build", "--species", "maple", "--set", "mesh.spacing=0.002"])
    assert "mesh.spacing = 0.002" in err and "limits.max_particles = 200,000" in err
    assert "use mesh.spacing ≥ 0.00" in err and "GB" in err


def test_suggested_spacing_is_within_the_limit():
    sp = LIB["maple"]
    p = sp.params.with_overrides({"mesh.spacing": 0.002})
    shape = leaf_shape(sp, p)
    with pytest.raises(LeafsimError) as e:
        check_mesh_budget(shape, p)
    suggested = float(str(e.value).split("use mesh.spacing ≥ ")[1].split(",")[0])
    assert check_mesh_budget(shape, p.with_overrides({"mesh.spacing": suggested})) <= 200_000


def test_limit_can_be_raised_deliberately(capsys):
    one_line_error(capsys, ["build", "--species", "oak", "--set", "limits.max_particles=1000"])
    assert main(["build", "--species", "oak", "--set", "limits.max_particles=5000", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["particles"] <= 5000


def test_memory_guard_uses_the_machine_size(monkeypatch):
    sp = LIB["oak"]
    p = sp.params.with_overrides({"limits.max_particles": 50_000_000, "mesh.spacing": 0.003})
    shape = leaf_shape(sp, p)
    monkeypatch.setattr(budget, "physical_memory", lambda: 0.5e9)
    with pytest.raises(LeafsimError, match=r"needing ≈ [\d.]+ GB, more than 75 % of this machine's 0.5 GB"):
        check_mesh_budget(shape, p)


def test_session_build_refuses_too(monkeypatch):
    from leafsim.interactive.session import Session

    with pytest.raises(LeafsimError, match="limits.max_particles"):
        Session("oak", overrides={"limits.max_particles": 1000})


def test_vein_growth_budget(capsys):
    err = one_line_error(capsys, ["veins", "--species", "maple", "--set", "limits.vein_tests=200000"])
    assert "limits.vein_tests = 200,000" in err and "veins.lateral.step" in err
    assert main(["veins", "--species", "maple", "--json"]) == 0
    used = json.loads(capsys.readouterr().out)["collision_tests"]
    assert 200_000 < used < 100_000_000


def test_points_in_polygon_chunks_agree():
    """Chunked over the points (memory): the answer does not depend on where a chunk ends."""
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 700, endpoint=False)
    poly = np.column_stack([np.cos(t) * (1 + 0.3 * np.cos(5 * t)), np.sin(t) * (1 + 0.3 * np.cos(5 * t))])
    pts = rng.uniform(-1.4, 1.4, (5000, 2))
    whole = points_in_polygon(pts, poly)
    parts = np.concatenate([points_in_polygon(pts[i:i + 137], poly) for i in range(0, len(pts), 137)])
    assert np.array_equal(whole, parts) and 0.2 < whole.mean() < 0.8
    r = np.hypot(*pts.T)
    ang = np.arctan2(pts[:, 1], pts[:, 0])
    clear = np.abs(r - (1 + 0.3 * np.cos(5 * ang))) > 0.02
    assert np.array_equal(whole[clear], (r < 1 + 0.3 * np.cos(5 * ang))[clear])

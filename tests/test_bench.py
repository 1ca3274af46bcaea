"""``leafsim bench`` is a measurement, so its tests check what it measures, never how fast:
every contender of the spring race really projects (the residual falls), the Gauss–Seidel
contenders that sweep in our order agree with ours (the peers too, when installed), and the
frame and memory reports have their shape.  No timing assertions."""

from __future__ import annotations

import pytest

from leafsim import bench


@pytest.fixture(scope="module")
def tiny():
    return bench.build_bench_model("tiny")


@pytest.fixture(scope="module")
def race(tiny):
    return {r["contender"]: r for r in bench.spring_race(tiny, rounds=1)}


def test_every_contender_projects(race):
    for name, r in race.items():
        assert r["residual"] < 0.5 * r["residual0"], name  # a kernel that does nothing cannot win
        assert r["median_ms"] > 0 and r["p90_ms"] >= r["median_ms"]


def test_same_order_contenders_agree(race):
    """The float32 ceiling and the peers sweep our springs in our order: the same positions to
    float32 round-off; the coloured parallel kernel to float64 round-off."""
    assert race["coloured parallel (before)"]["agree"] < 1e-9
    for name in ["ceiling (f32, serial)"] + [k for k in race if k.endswith(" CPU")]:
        assert race[name]["agree"] < 1e-4, name
    for name in ("2-block parallel", "numpy Jacobi"):  # other orders: the same problem, other iterates
        assert race[name]["agree"] < 0.1, name


def test_peers_raced_when_installed(race):
    from leafsim.peers import available

    assert set(available()) <= set(race)


def test_frame_and_memory_report(tiny):
    f = bench.frame_bench(tiny, rounds=1)
    for k in ("frame", "frame folded", "springs ×10", "hinges ×10", "volumes ×10", "osmosis", "shrink"):
        assert f["ms"][k]["median_ms"] > 0
    assert 0.0 <= f["contact_share"] <= 1.0 and 0.0 <= f["contact_share_folded"] <= 1.0
    m = bench.memory(tiny)
    assert m["bytes_per_particle_total"] > 0 and m["peak_rss_mb"] > 0
    text = bench.format_bench({"tiny": {"particles": tiny.particle_count, "springs": tiny.spring_count,
                                        "hinges": tiny.hinge_count, "volumes": tiny.vol_count,
                                        "race": bench.spring_race(tiny, rounds=1, peers=False, parallel=False),
                                        "frame": f, "memory": m}})
    assert "ceiling (f32, serial)" in text and "hinge" in text

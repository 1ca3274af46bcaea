"""``leafsim bench`` is a measurement, so its tests check what it measures, never how fast:
every contender of the spring race really projects (the residual falls), the Gauss–Seidel
contenders that sweep in our order agree with ours (the peers too: a stand-in peer always, warp
and Taichi when installed), and the frame and memory reports have their shape.  No timing assertions."""

from __future__ import annotations

import numpy as np
import pytest

from leafsim.measure import bench


@pytest.fixture(scope="module")
def race(tiny):
    return {r["contender"]: r for r in bench.spring_race(tiny, rounds=1)}


@pytest.mark.slow
def test_every_contender_projects(race):
    for name, r in race.items():
        assert r["residual"] < 0.5 * r["residual0"], name  # a kernel that does nothing cannot win
        assert r["median_ms"] > 0 and r["p90_ms"] >= r["median_ms"]


def test_same_order_contenders_agree(race):
    """The float32 ceiling sweeps our springs in our order: the same positions to float32
    round-off; the coloured parallel kernel to float64 round-off.  (The peers: below.)"""
    assert race["coloured parallel (before)"]["agree"] < 1e-9
    assert race["ceiling (f32, serial)"]["agree"] < 1e-4
    for name in ("2-block parallel", "numpy Jacobi"):  # other orders: the same problem, other iterates
        assert race[name]["agree"] < 0.1, name


#: the stand-in peer (tests/helpers/numpy_peer.py) registered in place of warp and Taichi
STUB = "numpy stub CPU"


@pytest.fixture
def stub_race(tiny, monkeypatch):
    """The race with the peer registry holding only the stand-in peer: the plumbing from
    ``PEERS`` through ``available()`` into the race is tested whatever is installed here."""
    from helpers import numpy_peer
    from leafsim.measure import peers

    monkeypatch.setattr(peers, "PEERS", {STUB: "helpers.numpy_peer"})
    assert peers.available() == {STUB: numpy_peer.Peer}
    runs = []
    monkeypatch.setattr(numpy_peer.Peer, "run", lambda self, npass, run=numpy_peer.Peer.run: (runs.append(npass),
                                                                                                  run(self, npass)))
    rows = {r["contender"]: r for r in bench.spring_race(tiny, rounds=1, numpy=False, parallel=False)}
    return rows, runs


def test_an_available_peer_is_raced_and_agrees(stub_race):
    """A peer that ``available()`` lists is raced with every contender's passes and compared
    with ours: it projects, and sweeping in our colour order in float32 it agrees as the
    float32 ceiling does."""
    from leafsim.measure.models import PASSES

    race, runs = stub_race
    assert STUB in race and runs and set(runs) == {PASSES}
    r = race[STUB]
    assert r["residual"] < 0.5 * r["residual0"]
    assert r["agree"] < 1e-4
    assert r["median_ms"] > 0 and r["p90_ms"] >= r["median_ms"]


def test_installed_peers_raced_and_agree(race):
    """The real peers (warp, Taichi), when installed: raced, projecting, and agreeing with ours
    to float32 round-off."""
    from leafsim.measure.peers import available

    found = available()
    if not found:
        pytest.skip('no peer engine installed here (pip install -e ".[peers]": warp-lang, taichi); '
                    "the peer plumbing is tested with the stand-in peer above")
    for name in found:
        assert name in race, name
        assert race[name]["residual"] < 0.5 * race[name]["residual0"], name
        assert race[name]["agree"] < 1e-4, name


def test_frame_and_memory_report(tiny):
    f = bench.frame_bench(tiny, rounds=1)
    for k in ("frame", "frame folded", "springs ×10", "hinges ×10", "volumes ×10", "hinges ×10, one at a time",
              "volumes ×10, one at a time", "osmosis", "shrink"):
        assert f["ms"][k]["median_ms"] > 0
    for k in ("hinge_vs_spring", "volume_vs_spring", "hinge_vs_spring_one_at_a_time", "volume_vs_spring_one_at_a_time"):
        assert f[k] > 0
    assert 0.0 <= f["contact_share"] <= 1.0 and 0.0 <= f["contact_share_folded"] <= 1.0
    # Sun's explicit integrator beside the XPBD frame: many more steps than XPBD's substeps
    assert f["sun"]["steps"] > f["substeps"] and f["sun"]["ms"]["sun"]["median_ms"] > 0 and f["sun"]["ratio"] > 0
    m = bench.memory(tiny)
    assert m["bytes_per_particle_total"] > 0 and m["peak_rss_mb"] > 0
    text = bench.format_bench({"tiny": {"particles": tiny.particle_count, "springs": tiny.spring_count,
                                        "hinges": tiny.hinge_count, "volumes": tiny.vol_count,
                                        "race": bench.spring_race(tiny, rounds=1, peers=False, parallel=False),
                                        "frame": f, "memory": m}})
    assert "ceiling (f32, serial)" in text and "hinge" in text and "Sun's explicit integrator" in text


def test_parallel_vs_serial_rows_under_load(tiny):
    """Every parallel kernel is timed with its serial twin quietly and with a busy process
    running; the ratios are p90 ÷ the twin's p90 (1 for the twin itself), and the parallel
    shrink writes the serial shrink's rest lengths."""
    from leafsim.sim.effects.shrink import Shrink
    from leafsim.measure.parallel import parallel_twin
    from leafsim.sim.kernels import shrink as ks

    rows = bench.parallel_vs_serial(tiny, rounds=2, busy=1)
    jobs = {r["job"] for r in rows}
    assert {"springs ×10: ours (f64, serial)", "springs ×10: 2-block parallel", "springs ×10: coloured parallel (before)",
            "shrink: serial", "shrink: parallel (prange)"} <= jobs
    assert {r["busy"] for r in rows} == {0, 1}
    for r in rows:
        assert r["median_ms"] > 0 and r["p90_ms"] >= r["median_ms"] * 0.999
        if r["job"] in ("springs ×10: ours (f64, serial)", "shrink: serial"):
            assert r["p90_vs_serial"] == 1.0
    st = tiny.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, tiny.particle_count)
    sh = Shrink(tiny)
    sh.configure(bench.bench_params(tiny))
    a, b = np.zeros(tiny.spring_count), np.zeros(tiny.spring_count)
    twin = parallel_twin(ks._shrink_springs)
    # its own cache entry: numba keys the cache by name and line, not by `parallel`, so a second
    # decoration of the same function loaded the serial code the first one had cached
    assert twin._cache._cache_file._index_path != ks.shrink_springs._cache._cache_file._index_path
    assert twin.targetoptions["parallel"] is True
    for fn, out in ((ks.shrink_springs, a), (twin, b)):
        fn(tiny.spring_ij, tiny.spring_rest0, sh.sigma, sh.alpha, sh.l_min, tiny.particle_cytosol, st.particle_water,
           tiny.particle_mass0, out)
    assert np.array_equal(a, b) and (a < tiny.spring_rest0).any()
    text = bench.format_bench({"tiny": {"particles": tiny.particle_count, "springs": tiny.spring_count,
                                        "hinges": tiny.hinge_count, "volumes": tiny.vol_count,
                                        "race": bench.spring_race(tiny, rounds=1, peers=False, parallel=False),
                                        "frame": bench.frame_bench(tiny, rounds=1), "parallel": rows}})
    assert "busy processes" in text and "p90 ÷ serial" in text


def test_json_output_stays_pure_when_contenders_print(monkeypatch, capfd):
    """`leafsim bench --json`: banners the peers print while they load (from Python or straight
    to file descriptor 1) go to stderr, so stdout parses as JSON."""
    import ctypes
    import json
    import os

    def noisy(*a, **k):
        print("Warp 1.19.0 initialized:")
        os.write(1, b"[Taichi] Starting on arch=x64\n")
        ctypes.CDLL(None).printf(b"C stdio banner\n")  # buffered by the C library, not by Python
        return {"tiny": {"particles": 1}}

    monkeypatch.setattr(bench, "run_bench", noisy)
    assert bench.main(json_out=True, quick=True) == 0
    out, err = capfd.readouterr()
    got = json.loads(out)
    prov = got.pop("provenance")
    assert isinstance(prov["command"], str) and prov["cpus"] >= 1 and got == {"tiny": {"particles": 1}}
    assert "Warp" in err and "Taichi" in err and "C stdio banner" in err

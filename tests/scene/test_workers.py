"""Scene workers never outlive their parent, and a Dask worker killed mid-scene costs no leaf
and corrupts no output.  Both wait for progress (processes appearing, leaves finishing), never
for a fixed time."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from leafsim.scene.run import load_scene, run_scene

#: generous bounds for waiting on progress on a busy machine (never reached when things work)
PATIENCE_S = 600.0


def _scene(tmp_path: Path, count: int, frames: int) -> Path:
    data = {"name": "slow", "seed": 1, "layout": {"kind": "row"}, "overview": False,
            "groups": [{"name": "leaf", "species": "chestnut", "count": count, "seed": 0,
                        "params": {"mesh.spacing": 0.06}, "stop": {"frames": frames}}]}
    p = tmp_path / "slow.json"
    p.write_text(json.dumps(data))
    return p


def _children(pid: int) -> set[int]:
    """PIDs whose parent is ``pid`` (Linux /proc)."""
    out = set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat[stat.rindex(")") + 2:].split()[1]) == pid:
                out.add(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def _wait(cond, what: str) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > PATIENCE_S:
            pytest.fail(f"no progress: {what}")
        time.sleep(0.1)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and prctl are Linux's")
def test_scene_workers_die_with_a_killed_parent(tmp_path):
    scene = _scene(tmp_path, count=4, frames=1_000_000)  # far longer than the test
    proc = subprocess.Popen([sys.executable, "-m", "leafsim", "scene", str(scene), "--out", str(tmp_path / "out"),
                             "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # the workers exist and have started simulating (their leaf folders are not written
        # before the end, so wait for two spawned children that use a CPU)
        _wait(lambda: len(_children(proc.pid)) >= 2, "the scene's worker processes did not start")
        kids = _children(proc.pid)
        grandkids = set().union(*(_children(k) for k in kids))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        _wait(lambda: not any(_alive(k) for k in kids | grandkids), "scene workers outlived their killed parent")
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux's")
@pytest.mark.parametrize("how", ["SIGTERM to the command", "Ctrl-C twice to its process group"])
def test_an_interrupted_scene_stops_without_running_its_queued_leaves(tmp_path, how):
    """A signal ends ``leafsim scene`` at once: the queued leaves are dropped and the running ones
    end with their workers.  Before, leaving the pool waited for every queued leaf (these never
    end), and a second Ctrl-C hung the command in multiprocessing's exit handler."""
    scene = _scene(tmp_path, count=6, frames=1_000_000)  # far longer than the test
    proc = subprocess.Popen([sys.executable, "-m", "leafsim", "scene", str(scene), "--out", str(tmp_path / "out"),
                             "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        _wait(lambda: len(_children(proc.pid)) >= 2, "the scene's worker processes did not start")
        kids = _children(proc.pid)
        if how.startswith("SIGTERM"):
            os.kill(proc.pid, signal.SIGTERM)
            want = 128 + signal.SIGTERM
        else:
            os.killpg(proc.pid, signal.SIGINT)
            time.sleep(0.5)  # (the second press comes while the first is handled, or after it: either must end)
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
            want = 128 + signal.SIGINT
        err = proc.communicate(timeout=PATIENCE_S)[1]
        assert proc.returncode == want, err
        assert err.strip().splitlines()[-1].startswith("leafsim: interrupted") and "Traceback" not in err
        _wait(lambda: not any(_alive(k) for k in kids), "scene workers outlived the interrupted command")
        assert not list((tmp_path / "out" / "leaves").glob("*/done.json"))  # no leaf finished, none was started anew
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux's")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_the_workers_start_prints_no_traceback(tmp_path, sig):
    """The signal sent as soon as the command's first child process appears, while the pool is
    still launching its workers: a launch interrupted between making the child and writing its
    start-up data left the child to print "EOFError: Ran out of input" after the command's
    "interrupted" (2 of 30 such SIGTERMs before).  Repeated, since it is a race."""
    scene = _scene(tmp_path, count=6, frames=1_000_000)
    for _ in range(6):
        proc = subprocess.Popen([sys.executable, "-m", "leafsim", "scene", str(scene), "--out", str(tmp_path / "out"),
                                 "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            _wait(lambda: len(_children(proc.pid)) >= 1 or proc.poll() is not None, "the scene started no process")
            if sig == signal.SIGTERM:
                os.kill(proc.pid, sig)
            else:
                os.killpg(proc.pid, sig)  # Ctrl-C: the whole process group, the children too
            err = proc.communicate(timeout=PATIENCE_S)[1]
            assert proc.returncode == 128 + sig, err
            assert err.strip().splitlines()[-1].startswith("leafsim: interrupted") and "Traceback" not in err, err
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)


def test_a_dask_worker_killed_mid_scene_costs_no_leaf(tmp_path):
    from distributed import Client, LocalCluster

    scene = load_scene(_scene(tmp_path, count=4, frames=400))
    out = tmp_path / "out"
    result = {}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster.scheduler_address) as client:
        pids = client.run(os.getpid)
        worker = threading.Thread(target=lambda: result.update(rep=run_scene(
            scene, out, scheduler=cluster.scheduler_address, progress=False)))
        worker.start()
        # kill a worker while it is busy with a leaf
        _wait(lambda: any(client.processing().values()), "no leaf started on the Dask workers")
        busy = next(addr for addr, tasks in client.processing().items() if tasks)
        os.kill(pids[busy], signal.SIGKILL)
        worker.join(PATIENCE_S)
    rep = result["rep"]
    names = {f"leaf-{k:03d}" for k in range(4)}
    done = {p.name for p in (out / "leaves").iterdir()}
    failed = {f["name"] for f in rep["failed"]}
    assert done | failed == names and not done & failed  # every leaf finished or was reported by name
    for name in done:  # and nothing written is corrupt
        leaf = out / "leaves" / name
        assert json.loads((leaf / "done.json").read_text())["frames"] == 400
        with np.load(leaf / "view.npz") as v:
            assert np.isfinite(v["positions"]).all()
    assert not list(out.rglob("*.tmp"))

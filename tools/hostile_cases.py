"""Re-run the hostile user's cases of the robustness issue and print a markdown table: input,
exit status, the message, and the verdict (a one-line error with status 2, or a run that
finishes; never a traceback, a crash, a hang or a replaced special file).

    .venv/bin/python tools/hostile_cases.py > docs/robustness.md.table

Special files are made in a temporary folder (a character device needs root: without it
that row uses a named pipe); nothing outside it is touched.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
LEAFSIM = [sys.executable, "-m", "leafsim"]
OAK = ["--species", "oak", "--set", "mesh.spacing=0.06"]
HANG_S = 900


def run(args, cwd, check=None) -> tuple[int | None, str, float]:
    """Run leafsim; the message is stderr's last line (all its lines on success, then what
    ``check`` makes of stdout)."""
    t0 = time.time()
    try:
        r = subprocess.run(LEAFSIM + [str(a) for a in args], capture_output=True, text=True, timeout=HANG_S, cwd=cwd)
        lines = r.stderr.strip().splitlines() or [""]
        msg = " / ".join(lines) if r.returncode == 0 else lines[-1]
        if r.returncode == 0 and check is not None:
            msg = (msg + " / " if msg else "") + check(r.stdout)
        return r.returncode, msg, time.time() - t0
    except subprocess.TimeoutExpired:
        return None, f"still running after {HANG_S} s", time.time() - t0


def verdict(code, msg, expect_ok=False) -> str:
    if code is None:
        return "HANG"
    if "Traceback" in msg or "internal error" in msg or code < 0:
        return "CRASH"
    if expect_ok:
        return ("WRONG" if msg.endswith("WRONG") else "ok") if code == 0 else "WRONG (refused)"
    return "clean error" if code == 2 and msg.startswith("leafsim: ") else f"WRONG (exit {code})"


def cases(tmp: Path):
    dev = tmp / "device.png"
    if os.geteuid() == 0:
        os.mknod(dev, 0o666 | 0o020000, os.makedev(1, 7))  # a character device like /dev/full
    else:
        os.mkfifo(dev)
    fifo = tmp / "pipe.png"
    os.mkfifo(fifo)
    (tmp / "loop").symlink_to(tmp / "loop2")
    (tmp / "loop2").symlink_to(tmp / "loop")
    sq = np.full((500, 500, 3), 235, np.uint8)
    sq[120:380, 120:380] = (30, 30, 200)
    cv2.imwrite(str(tmp / "square.png"), sq)
    rng = np.random.default_rng(0)
    cut = np.full((480, 640, 3), 235, np.uint8)  # a mottled green ellipse running off the bottom edge
    leaf = np.zeros((480, 640), np.uint8)
    cv2.ellipse(leaf, (320, 380), (120, 200), 0, 0, 360, 255, -1)
    green = (np.array([40, 140, 60]) * (0.8 + 0.4 * rng.random((480, 640, 1)))).astype(np.uint8)
    cut[leaf > 0] = green[leaf > 0]
    cv2.imwrite(str(tmp / "cut.png"), cut)
    lit = np.full((600, 800, 3), (205, 225, 240), np.float32)  # a sheet lit from the right, a soft shadow
    leaf = np.zeros((600, 800), np.uint8)
    cv2.ellipse(leaf, (400, 280), (90, 160), 15, 0, 360, 255, -1)
    cv2.line(leaf, (440, 430), (465, 530), 255, 5)
    shadow = cv2.GaussianBlur(np.roll(leaf, (18, 24), (0, 1)).astype(np.float32) / 255, (0, 0), 12)[..., None]
    lit *= (0.3 + 0.7 * np.linspace(0, 1, 800))[None, :, None] * (1 - 0.45 * shadow)
    green = np.array([40, 140, 60]) * (0.8 + 0.4 * rng.random((600, 800, 1)))
    lit[leaf > 0] = green[leaf > 0]
    cv2.imwrite(str(tmp / "lit.png"), lit.astype(np.uint8))

    def scene(name, body):
        (tmp / name).write_text(body)
        return tmp / name
    big = json.loads((ROOT / "configs" / "leaves.json").read_text())
    big["species"]["maple"]["outline"]["points"] = [[0.5 * np.cos(t), 0.5 + 0.5 * np.sin(t)] for t in np.linspace(0, 6.28, 1_200_000)]
    (tmp / "huge_outline.json").write_text(json.dumps(big))
    yield "outline --out <character device>", ["outline", "images/quercus_01.png", "--out", dev], False
    yield "export --out <character device>", ["export", *OAK, "--out", dev], False
    yield "outline --out <named pipe>", ["outline", "images/quercus_01.png", "--out", fifo], False
    yield "outline --out x.jpg", ["outline", "images/quercus_01.png", "--out", tmp / "x.jpg"], False
    yield "export --out <folder>", ["export", *OAK, "--out", tmp], False
    yield "run --stats /proc/x", ["run", *OAK, "--frames", "2", "--stats", "/proc/leafsim.jsonl"], False
    yield "outline --out /sys/x.png", ["outline", "images/quercus_01.png", "--out", "/sys/leafsim.png"], False
    yield "species --config /dev/zero", ["species", "--config", "/dev/zero"], False
    yield "outline <named pipe>", ["outline", fifo], False
    yield "species --config <symlink loop>", ["species", "--config", tmp / "loop"], False
    yield "species --config <1.2 M-point outline>", ["species", "--config", tmp / "huge_outline.json"], False
    yield "scene: count 1000000", ["scene", scene("c1.json", '{"groups":[{"name":"a","species":"oak","count":1000000,"stop":{"frames":1}}]}'), "--out", tmp / "o1"], False
    yield "scene: count 1e9", ["scene", scene("c2.json", '{"groups":[{"name":"a","species":"oak","count":1e9,"stop":{"frames":1}}]}'), "--out", tmp / "o2"], False
    yield "scene: floor [100,100] cell 0.0001", ["scene", scene("c3.json", '{"layout":{"kind":"floor","size":[100,100],"cell":0.0001},"groups":[{"name":"a","species":"oak","count":1,"stop":{"frames":1}}]}'), "--out", tmp / "o3"], False
    yield 'scene: "count": 2, "count": 100000', ["scene", scene("c4.json", '{"groups":[{"name":"a","species":"oak","count":2,"count":100000,"stop":{"frames":1}}]}'), "--out", tmp / "o4"], False
    yield "outline <red square>", ["outline", tmp / "square.png"], True
    yield "compare --photo <red square>", ["compare", *OAK, "--photo", tmp / "square.png"], False
    yield "outline <leaf cut by the border>", ["outline", tmp / "cut.png"], True
    drawn = float(np.count_nonzero(leaf)) / leaf.size

    def traced_area(out: str) -> str:
        d = json.loads(out)
        f = d["leafness"]["area_fraction"]
        return (f"traced {f / drawn:.3f} of the drawn leaf's area, cut by {d['leafness']['cut_by'] or 'no border'}"
                + ("" if abs(f / drawn - 1) < 0.05 and not d["leafness"]["cut_by"] else " WRONG"))
    yield "outline <leaf on an unevenly lit sheet, soft shadow>", ["outline", tmp / "lit.png", "--json"], traced_area
    yield "--set limits.image_pixels=10000", ["outline", "images/quercus_01.png", "--set", "limits.image_pixels=10000"], False
    yield "--species ''", ["build", "--species", ""], False
    yield "--species mapel", ["build", "--species", "mapel"], False
    yield "--set dynamics.dt=nan", ["build", *OAK, "--set", "dynamics.dt=nan"], False
    (tmp / "precious.txt").write_text("keep")
    (tmp / "link.png").symlink_to(tmp / "precious.txt")
    (tmp / "dangling.png").symlink_to(tmp / "nowhere.txt")
    (tmp / "ro.png").write_text("keep")
    (tmp / "ro.png").chmod(0o444)
    shutil.copy(ROOT / "images" / "quercus_01.png", tmp / "photo.png")
    yield "outline --out <symbolic link to another file>", ["outline", "images/quercus_01.png", "--out", tmp / "link.png"], False
    yield "outline --out <broken symbolic link>", ["outline", "images/quercus_01.png", "--out", tmp / "dangling.png"], False
    yield "outline --out <read-only file>", ["outline", "images/quercus_01.png", "--out", tmp / "ro.png"], False
    yield "outline photo.png --out photo.png", ["outline", tmp / "photo.png", "--out", tmp / "photo.png"], False
    oak = json.loads((ROOT / "configs" / "leaves.json").read_text())["species"]["oak"]
    oak["image"] = str(ROOT / oak["image"])
    oak.pop("senescent_photo", None)
    for name, bp in (("base_px [1e6, 1e6]", [1e6, 1e6]), ("base_px [1e300, 1e300]", [1e300, 1e300])):
        (tmp / "bp.json").write_text(json.dumps({"species": {"oak": {**oak, "base_px": bp}}}))
        yield f"build, species {name}", ["build", "--config", tmp / "bp.json", *OAK], False
    grape = json.loads((ROOT / "configs" / "leaves.json").read_text())
    grape["species"]["grapevine"]["params"] = [1, 2]
    (tmp / "pl.json").write_text(json.dumps(grape))
    yield "species with params [1, 2] and variants", ["species", "--config", tmp / "pl.json"], False
    yield "run --frames 99999999999999999999", ["run", *OAK, "--frames", "99999999999999999999"], False
    yield "compare --stage 99999999999999999999", ["compare", *OAK, "--stage", "99999999999999999999"], False
    yield "accuracy --seed -1", ["accuracy", "--quick", "--seed", "-1"], False
    yield "--set veins.main.kappa=1_0", ["build", *OAK, "--set", "veins.main.kappa=1_0"], False
    yield "run --effects ''", ["run", *OAK, "--frames", "2", "--effects", ""], False
    yield "runaway: sigma_surface_bottom=3, l_min=0.1", ["run", "--species", "maple", "--quality", "draft", "--frames", "1000",
                                                        "--set", "shrink.sigma_surface_bottom=3", "--set", "shrink.l_min=0.1", "--json"], False


def checkpoint_cases(tmp: Path):
    out = tmp / "ck"
    subprocess.run(LEAFSIM + ["run", *OAK, "--frames", "8", "--out", str(out), "--checkpoint-every", "4"], cwd=ROOT,
                   capture_output=True, check=True)
    base = dict(np.load(out / "checkpoint.npz"))
    for name, damage in (("shortened positions", lambda d: d.update(state_particle_q=d["state_particle_q"][:-5])),
                         ("float32 state", lambda d: d.update(state_particle_q=d["state_particle_q"].astype(np.float32))),
                         ("negative water", lambda d: d.update(state_particle_water=-d["state_particle_water"])),
                         ("NaN velocity", lambda d: d["state_particle_qd"].__setitem__((0, 0), np.nan)),
                         ("all the water in one particle", lambda d: d.update(state_particle_water=np.where(
                             np.arange(len(d["state_particle_water"])) == 0, d["state_particle_water"].sum(), 0.0))),
                         ("every particle at the origin", lambda d: d.update(state_particle_q=np.zeros_like(d["state_particle_q"])))):
        d = {k: v.copy() for k, v in base.items()}
        damage(d)
        folder = tmp / f"ck_{name.replace(' ', '_')}"
        folder.mkdir()
        np.savez(folder / "checkpoint.npz", **d)
        yield f"--resume from a checkpoint with {name}", ["run", *OAK, "--frames", "12", "--out", folder, "--resume"], False
    yield "--resume --frames 4 on a frame-8 checkpoint", ["run", *OAK, "--frames", "4", "--out", out, "--checkpoint-every", "4", "--resume"], False


def alive(pid: int) -> bool:
    """Running (a zombie has exited: it waits only for a reaper, and PID 1 in a container may not reap)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def orphan_case(tmp: Path) -> tuple[str, str]:
    p = tmp / "slow.json"
    p.write_text(json.dumps({"groups": [{"name": "a", "species": "chestnut", "count": 4, "params": {"mesh.spacing": 0.06},
                                         "stop": {"frames": 1_000_000}}], "overview": False}))
    proc = subprocess.Popen(LEAFSIM + ["scene", str(p), "--out", str(tmp / "orphans"), "--workers", "2"], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def kids():
        out = set()
        for d in Path("/proc").iterdir():
            if d.name.isdigit():
                try:
                    st = (d / "stat").read_text()
                except OSError:
                    continue
                if int(st[st.rindex(")") + 2:].split()[1]) == proc.pid:
                    out.add(int(d.name))
        return out

    t0 = time.time()
    while len(kids()) < 2 and time.time() - t0 < HANG_S:
        time.sleep(0.1)
    workers = kids()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    t1 = time.time()
    while any(alive(k) for k in workers) and time.time() - t1 < 60:
        time.sleep(0.1)
    left = [k for k in workers if alive(k)]
    return f"{len(workers)} child processes, {len(left)} running {time.time() - t1:.1f} s after the kill", "ok" if not left else "ORPHANED"


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="leafsim-hostile-"))
    try:
        print("| input | exit | message | verdict |")
        print("|---|---|---|---|")
        for gen in (cases(tmp), checkpoint_cases(tmp)):
            for name, args, ok in gen:
                code, msg, secs = run(args, ROOT, ok if callable(ok) else None)
                msg = msg.replace(str(tmp), "TMP").replace(str(ROOT) + "/", "").replace("|", "\\|")
                print(f"| {name} | {code} | {msg[:400]} | {verdict(code, msg, ok)} ({secs:.0f} s) |", flush=True)
        what, v = orphan_case(tmp)
        print(f"| kill -9 of `leafsim scene --workers 2` | – | {what} | {v} |")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

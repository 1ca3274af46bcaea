"""Measure the GUI: frames per second of the full app and the time to first frame.

Run ``python -m leafsim.gui.bench_gui [--species maple] [--frames 80] [--scales 1,0.5] [--json]``.
Each configuration runs the real application (``LeafApp`` on hello_imgui, moderngl renderer,
live simulation, panels and plots) in a fresh process, so start-up is measured honestly from
process spawn (numba's on-disk cache is warmed by a first, discarded run).  Without a DISPLAY
an Xvfb server is started for the duration.

Reported per configuration: time to the first window frame, time to the first frame with the
leaf, median frame time and fps while playing, and the median split of a frame into
simulation step, renderer upload, GL submit and the rest (imgui + llvmpipe rasterisation and
buffer swap).  Goals: ≥ 30 fps at maple size, ≤ 2 s to the first frame.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time


def _child(args) -> None:
    t_spawn = float(os.environ["LEAFSIM_BENCH_T0"])
    import numpy as np

    from leafsim.gui.app import LeafApp, _configure_threads

    _configure_threads()
    from imgui_bundle import hello_imgui, immapp

    from leafsim.session import Session

    session = Session(args.species, seed=0, build=False)
    session.rebuild_async()
    app = LeafApp(session, frames=args.frames, play=True)
    app.auto_quality = False
    app.render_scale = args.scale
    app.show_ground = app.shadows = bool(int(str(args.ground).split(",")[0]))
    t_first = {}
    parts = {"step": [], "upload": [], "draw": []}
    orig = app.custom_background

    cpu = []

    def bg():
        if "frame" not in t_first:
            t_first["frame"] = time.time()
        if session.ready:
            cpu.append((time.perf_counter(), time.process_time()))
        orig()
        if session.ready and "leaf" not in t_first:
            t_first["leaf"] = time.time()
        if session.ready and app.timing:
            for k in parts:
                parts[k].append(app.timing.get(k, 0.0))

    rp = app.runner_params()
    rp.callbacks.custom_background = bg
    immapp.run(rp, app.addons())
    skip = 10
    ft = np.asarray(app.frame_ms[-(args.frames - skip):], float)
    med = float(np.median(ft)) if ft.size else float("nan")
    out = {
        "species": args.species,
        "particles": session.model.particle_count if session.model is not None else 0,
        "scale": args.scale,
        "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
        "first_frame_s": round(t_first.get("frame", float("nan")) - t_spawn, 3),
        "first_leaf_s": round(t_first.get("leaf", float("nan")) - t_spawn, 3),
        "frame_ms": round(med, 1),
        "fps": round(1000.0 / med, 1) if med > 0 else 0.0,
        "sim_frames": session.frame,
        "ground": app.show_ground,
    }
    c = cpu[skip:]
    if len(c) > 2:
        # CPU seconds of all our threads (incl. llvmpipe's) per frame: what an idle 2-core machine
        # would need at least cpu_ms / 2 per frame for
        out["cpu_ms"] = round((c[-1][1] - c[0][1]) / (len(c) - 1) * 1e3, 1)
    for k, v in parts.items():
        v = v[skip:]
        out[f"{k}_ms"] = round(float(np.median(v)), 1) if v else None
    out["rest_ms"] = round(med - sum(out[f"{k}_ms"] or 0.0 for k in parts), 1)
    print("BENCH " + json.dumps(out), flush=True)


def _start_xvfb():
    for n in range(90, 140):
        if os.path.exists(f"/tmp/.X{n}-lock") or os.path.exists(f"/tmp/.X11-unix/X{n}"):
            continue
        proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                return proc, f":{n}"
            if proc.poll() is not None:
                break
            time.sleep(0.05)
        proc.kill()
    raise RuntimeError("could not start Xvfb")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m leafsim.gui.bench_gui", description=__doc__.split("\n")[0])
    ap.add_argument("--species", default="maple")
    ap.add_argument("--frames", type=int, default=80)
    ap.add_argument("--scales", default="1.0,0.5", help="render scales of the 3-D view to compare")
    ap.add_argument("--lp-threads", default="", help="comma-separated LP_NUM_THREADS values to compare")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--scale", type=float, default=1.0, help=argparse.SUPPRESS)
    ap.add_argument("--ground", default="0,1", help="ground plane + shadows off/on (comma-separated 0/1) to compare")
    args = ap.parse_args(argv)
    if args.child:
        _child(args)
        return 0
    xvfb = None
    env = dict(os.environ)
    if not env.get("DISPLAY"):
        if shutil.which("Xvfb") is None:
            print("bench_gui: no DISPLAY and no Xvfb", file=sys.stderr)
            return 2
        xvfb, env["DISPLAY"] = _start_xvfb()
    rows = []
    try:
        configs = [(float(s), lp, int(g)) for s in args.scales.split(",") for g in args.ground.split(",")
                   for lp in (args.lp_threads.split(",") if args.lp_threads else [""])]
        for i, (scale, lp, ground) in enumerate([configs[0]] + configs):  # the first run only warms caches
            e = dict(env)
            if lp:
                e["LP_NUM_THREADS"] = lp
            e["LEAFSIM_BENCH_T0"] = repr(time.time())
            cmd = [sys.executable, "-m", "leafsim.gui.bench_gui", "--child", "--species", args.species,
                   "--frames", str(args.frames), "--scale", str(scale), "--ground", str(ground)]
            r = subprocess.run(cmd, env=e, capture_output=True, text=True, timeout=600)
            line = [ln for ln in r.stdout.splitlines() if ln.startswith("BENCH ")]
            if not line:
                print(f"bench_gui: run failed (rc {r.returncode}): {r.stderr.strip()[-800:]}", file=sys.stderr)
                return 1
            row = json.loads(line[-1][6:])
            if i > 0:
                rows.append(row)
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(10)
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    if args.json:
        print(json.dumps({"runs": rows, "loadavg_1min": load}))
    else:
        keys = ["species", "particles", "scale", "ground", "LP_NUM_THREADS", "first_frame_s", "first_leaf_s", "fps", "frame_ms",
                "step_ms", "upload_ms", "draw_ms", "rest_ms", "cpu_ms"]
        print(" ".join(f"{k:>13s}" for k in keys))
        for r in rows:
            print(" ".join(f"{str(r.get(k)):>13s}" for k in keys))
        print(f"(1-min load average {load:.2f} on {os.cpu_count()} cores; other processes skew fps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The child processes of the GUI benchmark (``leafsim.measure.gui_bench``): the real window
run for a number of frames with the leaf playing, or one render pass profile, each printing one
JSON line.  Started as ``python -m leafsim.gui.bench_child window|passes-egl|passes-window``."""

from __future__ import annotations

import argparse
import json
import os
import time

import moderngl
import numpy as np
from imgui_bundle import hello_imgui, immapp

from leafsim.config.params import parse_set_args
from leafsim.gui.app import LeafApp, _configure_threads
from leafsim.interactive.session import Session
from leafsim.render.camera import OrbitCamera
from leafsim.render.options import RenderOptions
from leafsim.render.renderer import Renderer

#: the 3-D view's size in the 1280×800 window [px]
VIEW_SIZE = (570, 766)


def thread_cpu() -> dict[str, float]:
    """CPU seconds per thread group of this process (Linux /proc): the UI thread and the
    rasteriser's threads ("ui"), the simulation worker ("sim"), builds and the rest ("other")."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    out = {"ui": 0.0, "sim": 0.0, "other": 0.0}
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return out
    main = str(os.getpid())
    for t in tasks:
        try:
            with open(f"/proc/self/task/{t}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        name = stat[stat.index("(") + 1: stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        sec = (int(fields[11]) + int(fields[12])) / tick
        group = "ui" if (t == main or name.startswith("llvmpipe")) else "sim" if name.startswith("leafsim-sim") else "other"
        out[group] += sec
    return out


def window_child(args) -> None:
    t_spawn = float(os.environ["LEAFSIM_BENCH_T0"])
    _configure_threads()
    session = Session(args.species, seed=0, build=False, overrides=parse_set_args(args.set))
    session.rebuild_async()
    app = LeafApp(session, window_frames=args.frames, play=True)
    app.render_scale = args.scale
    app.show_ground = app.shadows = bool(int(str(args.ground).split(",")[0]))
    marks = {}
    cpu = []
    orig = app.custom_background

    def bg():
        marks.setdefault("frame", time.time())
        if session.ready:
            cpu.append((time.perf_counter(), time.process_time(), session.time))
            if len(cpu) == 11:
                marks["threads0"] = thread_cpu()
            elif len(cpu) > 11:
                marks["threads1"] = thread_cpu()  # the last one before the window (and llvmpipe) closes
        orig()
        if session.ready:
            marks.setdefault("leaf", time.time())

    rp = app.runner_params()
    rp.callbacks.custom_background = bg
    immapp.run(rp, app.addons())
    skip = 10
    c = cpu[skip:]
    ft = np.diff([x[0] for x in c]) * 1e3 if len(c) > 1 else np.zeros(0)
    out = {"species": args.species, "particles": session.model.particle_count if session.model is not None else 0,
           "scale": args.scale, "ground": app.show_ground,
           "first_frame_s": round(marks.get("frame", float("nan")) - t_spawn, 3),
           "first_leaf_s": round(marks.get("leaf", float("nan")) - t_spawn, 3),
           "frame_ms": float(np.median(ft)) if ft.size else float("nan"),
           "p90_ms": float(np.percentile(ft, 90)) if ft.size else float("nan")}
    out["fps"] = 1000.0 / out["frame_ms"] if out["frame_ms"] > 0 else 0.0
    if len(c) > 2:
        # CPU seconds of all our threads (llvmpipe's and the worker's included) per frame
        out["cpu_ms"] = (c[-1][1] - c[0][1]) / (len(c) - 1) * 1e3
        out["sim_s_per_s"] = (c[-1][2] - c[0][2]) / max(c[-1][0] - c[0][0], 1e-9)
        if "threads1" in marks:  # the UI's own CPU per frame (main + llvmpipe threads); the worker's apart
            t1, t0 = marks["threads1"], marks["threads0"]
            out["ui_cpu_ms"] = (t1["ui"] - t0["ui"]) / (len(c) - 2) * 1e3
            out["sim_cpu_ms"] = (t1["sim"] - t0["sim"]) / (len(c) - 2) * 1e3
    print("BENCH " + json.dumps(out), flush=True)



# ------------------------------------------------------------------ per-pass render profile

PASSES = ("_shadow_pass", "_ground_shadow_pass", "_draw_ground", "_draw_blade", "_draw_veins")
CONFIGS = ((False, False), (True, False), (True, True), (False, True))


def _measure(ctx, species: str, reps: int, fbo=None, sets=()) -> dict:
    W, H = VIEW_SIZE
    r = Renderer(ctx)
    r.populate(Session(species, overrides=parse_set_args(list(sets))).render_mesh())
    cam = OrbitCamera(yaw=-90, pitch=55)
    cam.frame_bounds(np.stack([r.lo, r.hi]), margin=1.05)
    if fbo is None:
        fbo = ctx.framebuffer(ctx.texture((W, H), 4), ctx.depth_renderbuffer((W, H)))
    parts: dict = {}

    def wrap(name, fn):
        def timed(*a, **k):
            ctx.finish()
            c0 = time.process_time()
            out = fn(*a, **k)
            ctx.finish()
            parts.setdefault(name, []).append((time.process_time() - c0) * 1e3)
            return out
        return timed

    for name in PASSES:
        setattr(r, name, wrap(name.strip("_"), getattr(r, name)))
    res: dict = {}
    for _ in range(reps):
        for g, sh in CONFIGS:
            parts.clear()
            r._geometry += 1  # as while playing: the leaf moved, the shadow passes are redone
            opts = RenderOptions(ground=g, shadows=sh, self_shadow=sh)
            ctx.finish()
            c0 = time.process_time()
            r.render(cam, W, H, opts, framebuffer=fbo)
            ctx.finish()
            row = res.setdefault(f"ground={int(g)} shadows={int(sh)}", {})
            row.setdefault("total", []).append((time.process_time() - c0) * 1e3)
            for k, v in parts.items():
                row.setdefault(k, []).append(sum(v))
    return {c: {k: round(float(np.median(v)), 2) for k, v in row.items()} for c, row in res.items()}


def passes_child(where: str, species: str, reps: int, sets=()) -> None:
    """Measure in ``where`` = "egl" or "window" (parameters ``sets``, KEY=VALUE) and print one JSON line."""
    if where == "egl":
        out = _measure(moderngl.create_standalone_context(backend="egl", require=330), species, reps, sets=sets)
        print("PASSES " + json.dumps(out), flush=True)
        return
    done = {}

    def bg():
        if not done:
            ctx = moderngl.create_context()
            fb = ctx.detect_framebuffer()
            done["out"] = _measure(ctx, species, reps, sets=sets)
            fb.use()
            hello_imgui.get_runner_params().app_shall_exit = True

    rp = hello_imgui.RunnerParams()
    rp.app_window_params.window_geometry.size = (1280, 800)
    rp.fps_idling.enable_idling = False
    rp.ini_disable = True
    rp.renderer_backend_options.open_gl_options.anti_aliasing_samples = 0
    rp.callbacks.custom_background = bg
    rp.callbacks.show_gui = lambda: None
    immapp.run(rp, immapp.AddOnsParams())
    print("PASSES " + json.dumps(done["out"]), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m leafsim.gui.bench_child")
    ap.add_argument("what", choices=("window", "passes-egl", "passes-window"))
    ap.add_argument("--species", default="maple")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--ground", default="1")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--set", action="append", default=[])
    args = ap.parse_args(argv)
    if args.what == "window":
        window_child(args)
    else:
        passes_child(args.what.split("-")[1], args.species, args.reps, args.set)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

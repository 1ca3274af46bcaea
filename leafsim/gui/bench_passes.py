"""Per-pass render profile (``python -m leafsim.gui.bench_gui --passes``).

Each pass of :meth:`leafsim.render.renderer.Renderer.render` is wrapped with ``glFinish``
before and after, and timed in CPU milliseconds of all the process's threads (llvmpipe
rasterises in its own threads; wall time without a finish only measures command submission,
which is how the ground once looked free offscreen).  The same leaf and view size are
measured in an EGL offscreen context and in the window's (hello_imgui) context, with
interleaved repetitions of four configurations (ground on/off × shadows -- ground shadow and
self-shadow -- on/off), each as while playing (the leaf moved since the last frame).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

PASSES = ("_shadow_pass", "_ground_shadow_pass", "_draw_ground", "_draw_blade", "_draw_veins")
CONFIGS = ((False, False), (True, False), (True, True), (False, True))


def _measure(ctx, species: str, reps: int, fbo=None) -> dict:
    import numpy as np

    from ..render.camera import OrbitCamera
    from ..render.options import RenderOptions
    from ..render.renderer import Renderer
    from ..session import Session
    from .bench_gui import VIEW_SIZE

    W, H = VIEW_SIZE
    r = Renderer(ctx)
    r.populate(Session(species).render_mesh())
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


def passes_child(where: str, species: str, reps: int) -> None:
    """Measure in ``where`` = "egl" or "window" and print one JSON line."""
    import moderngl

    if where == "egl":
        out = _measure(moderngl.create_standalone_context(backend="egl", require=330), species, reps)
        print("PASSES " + json.dumps(out), flush=True)
        return
    from imgui_bundle import hello_imgui, immapp

    done = {}

    def bg():
        if not done:
            ctx = moderngl.create_context()
            fb = ctx.detect_framebuffer()
            done["out"] = _measure(ctx, species, reps)
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


def run_passes(env: dict, species: str, reps: int) -> str:
    """Both contexts, as a text table (CPU ms per pass, medians)."""
    env = dict(env)
    env.setdefault("LP_NUM_THREADS", "2" if (os.cpu_count() or 1) <= 2 else "4")
    lines = []
    for where in ("egl", "window"):
        cmd = [sys.executable, "-m", "leafsim.gui.bench_gui", "--passes-child", where, "--species", species,
               "--reps", str(max(reps, 5))]
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        got = [ln for ln in r.stdout.splitlines() if ln.startswith("PASSES ")]
        if not got:
            raise RuntimeError(f"passes ({where}) failed: {r.stderr.strip()[-600:]}")
        for cfg, row in json.loads(got[-1][7:]).items():
            lines.append(f"{where:>7s} {cfg:>20s}  " + "  ".join(f"{k} {v:.1f}" for k, v in row.items()))
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    lines.append(f"(CPU ms of all threads per pass with glFinish around it, {species}, 1-min load {load:.2f})")
    return "\n".join(lines)

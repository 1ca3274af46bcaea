"""A minimal renderer that draws a glTF file the way glTF viewers do (headless EGL): every mesh's
POSITION, NORMAL and COLOR_0, double-sided materials lit with the normal flipped on back
faces (as the glTF spec asks), so a face wound against its stored normal comes out dark, as
in Blender.  Seen from above (+y, the file's up), orthographic, Lambert + ambient."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from leafsim.export.blender_import import _floats, _load

VERT = """
#version 330
uniform mat4 mvp;
in vec3 in_pos; in vec3 in_nrm; in vec3 in_col;
out vec3 v_nrm; out vec3 v_col;
void main() { v_nrm = in_nrm; v_col = in_col; gl_Position = mvp * vec4(in_pos, 1.0); }
"""
FRAG = """
#version 330
in vec3 v_nrm; in vec3 v_col;
out vec4 f_col;
void main() {
    vec3 n = normalize(v_nrm);
    if (!gl_FrontFacing) n = -n;   // glTF: a double-sided material's back face uses -normal
    float lit = 0.25 + 0.75 * max(dot(n, normalize(vec3(0.2, 1.0, 0.3))), 0.0);
    f_col = vec4(pow(clamp(v_col * lit, 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);
}
"""


def meshes(path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """{name: (positions, normals, colours, triangles)} of a static glTF (frame 0 only)."""
    doc, blob = _load(Path(path))
    out = {}
    for mesh in doc["meshes"]:
        prim = mesh["primitives"][0]
        a = prim["attributes"]
        acc = doc["accessors"][prim["indices"]]
        view = doc["bufferViews"][acc["bufferView"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        idx = np.frombuffer(blob, np.uint32, acc["count"], start).reshape(-1, 3)
        out[mesh["name"]] = tuple(np.asarray(_floats(doc, blob, a[k]), np.float32)[:, :3]
                                  for k in ("POSITION", "NORMAL", "COLOR_0")) + (idx,)
    return out


def render_top(path, size: int = 400, only=None) -> np.ndarray:
    """(size, size, 3) uint8 RGB of the file seen from above (meshes named in ``only``, or all);
    background black."""
    import moderngl

    ms = meshes(path)
    allp = np.concatenate([m[0] for m in ms.values()])
    lo, hi = allp.min(0), allp.max(0)
    c, half = (lo + hi) / 2, 0.55 * max(hi[0] - lo[0], hi[2] - lo[2])
    # look down -y: screen x = file x, screen y = -file z (the leaf's length runs along -z)
    mvp = np.array([[1 / half, 0, 0, -c[0] / half],
                    [0, 0, -1 / half, c[2] / half],
                    [0, -1 / (hi[1] - lo[1] + half), 0, 0],
                    [0, 0, 0, 1]], np.float32)
    mvp[2, 3] = -mvp[2, 1] * c[1]
    ctx = moderngl.create_standalone_context(backend="egl", require=330)
    try:
        prog = ctx.program(vertex_shader=VERT, fragment_shader=FRAG)
        prog["mvp"].write(mvp.T.copy().tobytes())
        fbo = ctx.simple_framebuffer((size, size))
        fbo.use()
        fbo.clear(0, 0, 0, 1)
        ctx.enable(moderngl.DEPTH_TEST)
        depth = ctx.depth_renderbuffer((size, size))
        fbo = ctx.framebuffer(fbo.color_attachments, depth)
        fbo.use()
        fbo.clear(0, 0, 0, 1, depth=1.0)
        for name, (p, n, col, tri) in ms.items():
            if only is not None and name not in only:
                continue
            data = np.hstack([p, n, col]).astype(np.float32)
            vbo, ibo = ctx.buffer(data.tobytes()), ctx.buffer(tri.astype(np.uint32).tobytes())
            vao = ctx.vertex_array(prog, [(vbo, "3f 3f 3f", "in_pos", "in_nrm", "in_col")], ibo)
            vao.render(moderngl.TRIANGLES)
        img = np.frombuffer(fbo.read(components=3, alignment=1), np.uint8).reshape(size, size, 3)[::-1]
        return np.ascontiguousarray(img)
    finally:
        ctx.release()

"""The moderngl leaf renderer: ``populate(mesh)`` once, ``update(...)`` each frame, ``render``.

The same :class:`Renderer` draws on screen (a context created by the GUI, rendering into the
currently bound framebuffer) and offscreen (see :mod:`leafsim.render.offscreen`).
"""

from __future__ import annotations

import re
from pathlib import Path

import moderngl
import numpy as np

from leafsim.appearance.mesh import NO_CHROMA, slope_tensors_ok, validate_mesh
from leafsim.appearance.mottle import CRINKLE_OFFSET, CRINKLE_ORIENTED_OFFSETS, crinkle_gradient, crinkle_gradient_rms, mottle_levels, mottle_scale
from leafsim.appearance.reflectance import ABSORPTION, BASE_REFLECTANCE, MOTTLE_COLUMNS
from leafsim.appearance.texture import clean_texture
from leafsim.base.errors import LeafsimError
from leafsim.base.resources import shader_dir as default_shader_dir
from leafsim.render.camera import look_at, orthographic
from leafsim.render.geom import VeinRibbons, bounds, orient_up, unique_edges, vertex_normals
from leafsim.render.options import BASIC_VIEWS, RenderOptions

DEFAULT_COLOUR = np.array([0.10, 0.32, 0.05], dtype=np.float32)  # linear summer green
#: the most the vein ribbons' depth test is pulled toward the eye beyond their half width [m]:
#: twice the 0.07 mm a lobe curled to a 10 mm radius sags below a 2.4 mm chord between two vein
#: points, and far less than the gap between two leaves lying on each other (shaders/vein.vert)
VEIN_PULL_MAX = 1.5e-4
GL_SRGB8_ALPHA8 = 0x8C43
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)


def load_shader(shader_dir: Path, name: str, defines: dict | None = None) -> str:
    """Read ``shader_dir/name`` and paste ``#include "file"`` lines (one level deep);
    ``defines`` become ``#define NAME VALUE`` lines right after the ``#version`` line."""
    path = Path(shader_dir) / name
    try:
        src = path.read_text()
    except OSError as exc:
        raise LeafsimError(f"cannot read shader {path}: {exc.strerror or exc}") from None
    src = _INCLUDE.sub(lambda m: load_shader(shader_dir, m.group(1)), src)
    if defines:
        head, nl, rest = src.partition("\n")
        lines = "".join(f"#define {k} {int(v)}\n" for k, v in sorted(defines.items()))
        src = f"{head}{nl}{lines}{rest}" if head.startswith("#version") else lines + src
    return src


def _mat(m: np.ndarray) -> bytes:
    return np.ascontiguousarray(np.asarray(m, dtype=np.float32).T).tobytes()


def _set(prog, name, value):
    u = prog.get(name, None)
    if u is None:
        return
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        u.write(_mat(value))
    else:
        u.value = value


def _largest_trace(tensors: np.ndarray) -> float:
    """The largest xx + yy of (n, 3) slope tensors (0 for none): the crinkle is drawn when > 0."""
    return float((tensors[:, 0] + tensors[:, 2]).max()) if len(tensors) else 0.0


def _srgb(c) -> tuple:
    """Linear RGB -> display sRGB (0..1) tuple."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return tuple(float(x) for x in np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055))


class Renderer:
    """Draw one leaf with a moderngl context someone else owns.

    Parameters
    ----------
    ctx : moderngl.Context
        An OpenGL >= 3.3 core context (GUI window or EGL standalone).
    shader_dir : path
        Folder of the ``.vert``/``.frag``/``.glsl`` files (default: the shipped ``shaders/``, :func:`leafsim.base.resources.shader_dir`).
    """

    def __init__(self, ctx: moderngl.Context, shader_dir: Path | str | None = None):
        self.ctx = ctx
        self.shader_dir = Path(shader_dir) if shader_dir is not None else default_shader_dir()
        self._variants: dict = {}     # (name, defines) -> program with compile-time switches
        self._shadow_cache: dict = {}
        self._geometry = 0
        self.programs = {name: self._program(name) for name in
                         ("shadow", "gshadow", "blur", "points", "lines")}
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype=np.float32)
        self._ground_vbo = ctx.buffer(quad.tobytes())
        self._ground_vaos = {sh: ctx.vertex_array(self._variant("ground", LS_SHADOW=sh), [(self._ground_vbo, "2f", "in_xy")])
                             for sh in (0, 1)}
        self._blur_vao = ctx.vertex_array(self.programs["blur"], [(self._ground_vbo, "2f", "in_xy")])
        self._mask = None  # ground shadow coverage: (texture, fbo) twice (blur ping-pong)
        self._white = ctx.texture((1, 1), 4, b"\xff\xff\xff\xff")
        self._noise = None  # the sub-grid mottle field (made on first use)
        self._crinkle_grad = None  # its central differences, for the crinkle (made on first use)
        self._shadow_tex = None
        self._shadow_fbo = None
        self._objects: list = []
        self._specs: dict = {}        # vertex-array content per program name (this mesh)
        self._variant_vaos: dict = {}  # (name, defines) -> vertex array of this mesh
        self.mesh = None
        self.n = 0

    # --- setup ----------------------------------------------------------------------------
    def _program(self, name: str, defines: dict | None = None) -> moderngl.Program:
        vs = load_shader(self.shader_dir, f"{name}.vert", defines)
        fs = load_shader(self.shader_dir, f"{name}.frag", defines)
        try:
            return self.ctx.program(vertex_shader=vs, fragment_shader=fs)
        except moderngl.Error as exc:
            raise LeafsimError(f"shader {self.shader_dir / name}.vert/.frag does not compile: "
                               f"{' '.join(str(exc).split())[:400]}") from None

    def _variant(self, name: str, **defines) -> moderngl.Program:
        """The program ``name`` compiled with ``#define``s (cached): the switches a software
        rasteriser would otherwise evaluate on both sides of every uniform branch."""
        key = (name, tuple(sorted(defines.items())))
        prog = self._variants.get(key)
        if prog is None:
            prog = self._variants[key] = self._program(name, defines)
        return prog

    def _variant_vao(self, name: str, **defines):
        """This mesh's vertex array for a program variant (made on first use)."""
        key = (name, tuple(sorted(defines.items())))
        vao = self._variant_vaos.get(key)
        if vao is None:
            content, index = self._specs[name]
            vao = self._variant_vaos[key] = self._vao_for(self._variant(name, **defines), content, index)
        return vao

    def _buf(self, data: np.ndarray, dynamic=False):
        b = self.ctx.buffer(np.ascontiguousarray(data).tobytes(), dynamic=dynamic)
        self._objects.append(b)
        return b

    def _vao_for(self, prog, content, index=None):
        vao = self.ctx.vertex_array(prog, content, index_buffer=index, skip_errors=True)
        self._objects.append(vao)
        return vao

    def _vao(self, prog_name, content, index=None):
        return self._vao_for(self.programs[prog_name], content, index)

    def release_mesh(self) -> None:
        for o in self._objects:
            o.release()
        self._objects = []
        self._specs = {}
        self._variant_vaos = {}
        self.mesh = None

    def release(self) -> None:
        """Free every GL object this renderer made."""
        self.release_mesh()
        for p in (*self.programs.values(), *self._variants.values()):
            p.release()
        self._variants = {}
        for o in (*self._ground_vaos.values(), self._blur_vao, self._ground_vbo, self._white, self._shadow_fbo,
                  self._shadow_tex, self._noise, self._crinkle_grad, *(self._mask or ())):
            if o is not None:
                o.release()

    def populate(self, mesh) -> None:
        """Create the GL buffers, arrays and textures for ``mesh`` (a :class:`RenderMesh`)."""
        validate_mesh(mesh)
        self.release_mesh()
        self.mesh = mesh
        uv = self._take_mesh(mesh)
        self._blade_buffers(uv)
        self._line_buffers(getattr(mesh, "springs", None), getattr(mesh, "spring_kind", None))
        self._vein_buffers(getattr(mesh, "vein_lines", None), uv)
        self._upload_texture(getattr(mesh, "texture_rgba", None))
        self._dirty_particles = True
        self._dirty_springs = True
        self._geometry += 1  # the shadow passes depend on it only
        self._bounds()

    def _take_mesh(self, mesh) -> np.ndarray:
        """Keep ``mesh``'s per-vertex arrays as float32 copies the frames overwrite (absent
        optional ones as their neutral values); returns the texture coordinates (zeros
        without a photo)."""
        pos = np.ascontiguousarray(mesh.positions, dtype=np.float32)
        n = self.n = pos.shape[0]
        self.tri = orient_up(pos, np.asarray(mesh.triangles))
        self.edges = unique_edges(self.tri)
        self.pos = pos.copy()
        self.nrm = vertex_normals(self.pos, self.tri)
        colours = mesh.colours if getattr(mesh, "colours", None) is not None else np.broadcast_to(DEFAULT_COLOUR, (n, 3))
        tint = getattr(mesh, "tint", None)
        self.colours = np.ascontiguousarray(colours, dtype=np.float32).copy()
        self.tint = np.ones((n, 3), np.float32) if tint is None else np.ascontiguousarray(tint, dtype=np.float32).copy()
        vein_col = getattr(mesh, "vein_colours", None)
        self.vein_col = None if vein_col is None else np.ascontiguousarray(vein_col, dtype=np.float32).copy()
        chroma = getattr(mesh, "chroma", None)
        self.chroma = np.tile(NO_CHROMA, (n, 1)) if chroma is None else np.ascontiguousarray(chroma, dtype=np.float32).copy()
        uv = getattr(mesh, "texcoords", None)
        self.has_uv = uv is not None
        uv = np.zeros((n, 2), np.float32) if uv is None else np.ascontiguousarray(uv, dtype=np.float32)
        self.scalars = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in (getattr(mesh, "scalars", None) or {}).items()}
        self._scalar_name = None
        mottle = getattr(mesh, "mottle", None)
        self.mottle = (np.zeros((n, len(MOTTLE_COLUMNS)), np.float32) if mottle is None
                       else np.ascontiguousarray(mottle, dtype=np.float32).copy())
        rest = getattr(mesh, "mottle_rest", None)
        self.has_rest = rest is not None  # without where the tissue samples the field, no mottle
        rest = np.zeros((n, 2), np.float32) if rest is None else np.ascontiguousarray(rest, dtype=np.float32)
        self.rest = rest
        self.mottle_size = float(getattr(mesh, "mottle_size", 0.0) or 0.0) if mottle is not None else 0.0
        self.mottle_amount = float(getattr(mesh, "mottle_amount", 0.0) or 0.0)
        crinkle = getattr(mesh, "crinkle", None)
        self.crinkle = (np.zeros((n, 3), np.float32) if crinkle is None
                        else np.ascontiguousarray(crinkle, dtype=np.float32).copy())
        self.crinkle_size = float(getattr(mesh, "crinkle_size", 0.0) or 0.0)
        self.crinkle_peak = _largest_trace(self.crinkle)  # rad²: the crinkle is drawn when > 0
        top = getattr(mesh, "top_positions", None)
        self.top = None if top is None else np.ascontiguousarray(top, dtype=np.float32).copy()
        self.k = 0 if self.top is None else self.top.shape[0]
        return uv

    def _blade_buffers(self, uv: np.ndarray) -> None:
        """The blade's vertex buffers, its triangles and the shadow passes' arrays."""
        rest, n = self.rest, self.n
        self.vbo_pos = self._buf(self.pos, dynamic=True)
        self.vbo_nrm = self._buf(self.nrm, dynamic=True)
        self.vbo_col = self._buf(self.colours, dynamic=True)
        self.vbo_tint = self._buf(self.tint, dynamic=True)
        self.vbo_chroma = self._buf(self.chroma, dynamic=True)
        self.vbo_uv = self._buf(uv)
        self.vbo_scalar = self._buf(np.zeros(n, np.float32), dynamic=True)
        self.vbo_mottle = self._buf(self.mottle, dynamic=True)
        self.vbo_rest = self._buf(rest)
        self.vbo_crinkle = self._buf(self.crinkle, dynamic=True)
        self.ibo_tri = self._buf(self.tri)
        self._specs["blade"] = ([
            (self.vbo_pos, "3f", "in_pos"), (self.vbo_nrm, "3f", "in_nrm"), (self.vbo_col, "3f", "in_col"),
            (self.vbo_tint, "3f", "in_tint"), (self.vbo_chroma, "4f", "in_chroma"), (self.vbo_uv, "2f", "in_uv"),
            (self.vbo_scalar, "1f", "in_scalar"), (self.vbo_mottle, "4f 4f 2f", "in_conc", "in_state", "in_extra"),
            (self.vbo_rest, "2f", "in_rest"), (self.vbo_crinkle, "3f", "in_crinkle")],
            self.ibo_tri)
        self.vao_shadow = self._vao("shadow", [(self.vbo_pos, "3f", "in_pos"), (self.vbo_uv, "2f", "in_uv")],
                                    self.ibo_tri)
        self.vao_gshadow = self._vao("gshadow", [(self.vbo_pos, "3f", "in_pos"), (self.vbo_uv, "2f", "in_uv")],
                                     self.ibo_tri)

    def _line_buffers(self, springs, kind) -> None:
        """The wireframe, the particles (bottom then top layer) and the springs' lines."""
        n = self.n
        self.ibo_edges = self._buf(self.edges)
        self.vbo_minus1 = self._buf(np.full(n, -1.0, np.float32))
        self.vao_wire = self._vao("lines", [(self.vbo_pos, "3f", "in_pos"), (self.vbo_minus1, "1f", "in_kind")],
                                  self.ibo_edges)
        # particles (bottom then top layer)
        layer = np.concatenate([np.zeros(n, np.float32), np.ones(self.k, np.float32)])
        self.vbo_particles = self._buf(np.zeros((n + self.k, 3), np.float32), dynamic=True)
        self.vbo_layer = self._buf(layer)
        self.vao_points = self._vao("points", [(self.vbo_particles, "3f", "in_pos"), (self.vbo_layer, "1f", "in_layer")])
        self.springs = None if springs is None or len(springs) == 0 else np.asarray(springs, dtype=np.int64)
        if self.springs is not None:
            kind = np.zeros(len(self.springs)) if kind is None else np.asarray(kind)
            self.vbo_spring_pos = self._buf(np.zeros((2 * len(self.springs), 3), np.float32), dynamic=True)
            self.vbo_spring_kind = self._buf(np.repeat(kind.astype(np.float32), 2))
            self.vao_springs = self._vao("lines", [(self.vbo_spring_pos, "3f", "in_pos"),
                                                   (self.vbo_spring_kind, "1f", "in_kind")])

    def _vein_buffers(self, lines, uv: np.ndarray) -> None:
        """The drawn veins' ribbons (none without vein lines)."""
        self.veins = VeinRibbons(lines, self.n, uv if self.has_uv else None, self.rest if self.has_rest else None)
        if self.veins.count:
            self.vbo_vein_dyn = self._buf(self.veins.frame(self.pos, self.nrm), dynamic=True)
            self.vbo_vein_base = self._buf(self.veins.base_colours(self.colours, self.tint, self.chroma, self.vein_col), dynamic=True)
            self.vbo_vein_static = self._buf(self.veins.static)
            self.ibo_vein = self._buf(self.veins.indices)
            self.vbo_vein_mottle = self._buf(self.veins.mottle_rows(self.mottle, self.rest), dynamic=True)
            self._specs["vein"] = ([
                (self.vbo_vein_mottle, "4f 4f 2f 2f", "in_conc", "in_state", "in_extra", "in_rest"),
                (self.vbo_vein_dyn, "3f 3f 3f", "in_center", "in_side", "in_nrm"),
                (self.vbo_vein_static, "1f 1f 2f 1f", "in_hw", "in_v", "in_uv", "in_order"),
                (self.vbo_vein_base, "3f 3f 4f 3f", "in_base", "in_tint", "in_chroma", "in_vein")], self.ibo_vein)

    def _upload_texture(self, tex) -> None:
        """The photo (sRGB, mipmapped, dilated past the leaf mask) and its mean leaf colour."""
        ctx = self.ctx
        self.texture = None
        self.tex_mean = (0.2, 0.3, 0.1)
        if tex is not None:
            rgba = clean_texture(tex)
            h, w = rgba.shape[:2]
            limit = min(int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 4096)), 4096)
            if max(h, w) > limit:
                import cv2

                f = limit / max(h, w)
                rgba = cv2.resize(rgba, (max(1, int(w * f)), max(1, int(h * f))), interpolation=cv2.INTER_AREA)
                h, w = rgba.shape[:2]
            try:
                t = ctx.texture((w, h), 4, rgba.tobytes(), internal_format=GL_SRGB8_ALPHA8)
                self._tex_srgb = True
            except Exception:  # pragma: no cover - drivers without sRGB textures
                t = ctx.texture((w, h), 4, rgba.tobytes())
                self._tex_srgb = False
            t.build_mipmaps()
            t.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
            self.texture = t
            self._objects.append(t)
            inside = tex[:, :, 3] >= 128
            lin = (tex[:, :, :3][inside].astype(np.float64) / 255.0) ** 2.2
            if lin.size:
                self.tex_mean = tuple(float(x) for x in lin.mean(axis=0))

    # --- per frame ------------------------------------------------------------------------
    def update(self, positions, colours=None, scalar=None, tint=None, top_positions=None, chroma=None,
               vein_colours=None, mottle=None, mottle_size=None, mottle_amount=None, crinkle=None,
               crinkle_size=None) -> None:
        """Write new per-frame data into the GL buffers.

        Parameters
        ----------
        positions : (n, 3) float
            Blade vertex positions (normals are recomputed from the triangles).
        colours : (n, 3) float, optional
            Linear RGB albedo per vertex.
        scalar : dict str -> (n,) float, optional
            New heat-map fields (merged into the populated ones).
        tint : (n, 3) float, optional
            Albedo multiplier per vertex.
        top_positions : (k, 3) float, optional
            Top-layer particles for the particle / spring views.
        chroma : (n, 4) float, optional
            The "detail" albedo's young chromaticity and living weight per vertex
            (:class:`~leafsim.appearance.mesh.RenderMesh`).
        vein_colours : (n, 3) float, optional
            Linear RGB albedo of the vein tissue per vertex (a mesh populated without them
            keeps drawing its veins in the blade's albedo).
        mottle : (n, 10) float, optional
            The sub-grid mottle's pigments (:class:`~leafsim.appearance.mesh.RenderMesh`).
        mottle_size : float, optional
            The mottle field's correlation length in metres; 0 turns the mottle off.
        mottle_amount : float, optional
            ``colour.mottle`` a, 0..1.
        crinkle : (n, 3) float, optional
            Slope tensor of the sub-grid crinkle per vertex (:class:`~leafsim.appearance.mesh.RenderMesh`).
        crinkle_size : float, optional
            The crinkle field's correlation length in metres; 0 turns the crinkle off.
        """
        if self.mesh is None:
            raise LeafsimError("renderer: update() before populate()")
        pos, c, mt, ck = self._checked_frame(positions, colours, tint, vein_colours, chroma, mottle, mottle_size,
                                             mottle_amount, crinkle, crinkle_size)
        self.pos[:] = pos
        vertex_normals(self.pos, self.tri, self.nrm)
        self.vbo_pos.write(self.pos)
        self.vbo_nrm.write(self.nrm)
        if top_positions is not None and self.top is not None:
            self.top[:] = top_positions  # before the bounds, which frame the shadow map and the camera
        self._bounds()
        recolour = self._write_albedo(colours, tint, c, vein_colours)
        self._write_subgrid(mt, mottle_size, mottle_amount, ck, crinkle_size)
        if scalar is not None:
            for k, v in scalar.items():
                v = np.asarray(v, dtype=np.float32)
                if v.shape != (self.n,):
                    raise LeafsimError(f"renderer: scalar field {k!r} must be ({self.n},), got {v.shape}")
                self.scalars[k] = v
            self._scalar_name = None
        if self.veins.count:
            self.vbo_vein_dyn.write(self.veins.frame(self.pos, self.nrm))
            if recolour:
                self.vbo_vein_base.write(self.veins.base_colours(self.colours, self.tint, self.chroma, self.vein_col))
        self._dirty_particles = self._dirty_springs = True
        self._geometry += 1

    def _checked_frame(self, positions, colours, tint, vein_colours, chroma, mottle, mottle_size, mottle_amount,
                       crinkle, crinkle_size):
        """``update``'s arrays checked before any buffer is written (one line naming the
        argument and what was expected); returns (positions, chroma, mottle, crinkle) as arrays
        (None where not given)."""
        pos = np.asarray(positions)
        if pos.shape != (self.n, 3):
            raise LeafsimError(f"renderer: positions must be ({self.n}, 3), got {pos.shape}")
        for name, a in (("colours", colours), ("tint", tint), ("vein_colours", vein_colours)):
            if a is not None and (np.shape(a) != (self.n, 3) or not np.all(np.isfinite(a))):
                raise LeafsimError(f"renderer: {name} must be finite, ({self.n}, 3), got {np.shape(a)}")
        c = None if chroma is None else np.asarray(chroma, dtype=np.float32)
        if c is not None and (c.shape != (self.n, 4) or not np.all(np.isfinite(c))):
            raise LeafsimError(f"renderer: chroma must be finite, ({self.n}, 4), got {c.shape}")
        mt = None if mottle is None else np.asarray(mottle, dtype=np.float32)
        k = len(MOTTLE_COLUMNS)
        if mt is not None and (mt.shape != (self.n, k) or not np.all(np.isfinite(mt))):
            raise LeafsimError(f"renderer: mottle must be finite, ({self.n}, {k}), got {mt.shape}")
        if mottle_amount is not None and not (np.isfinite(mottle_amount) and 0.0 <= mottle_amount <= 1.0):
            raise LeafsimError(f"renderer: mottle_amount must be in [0, 1], got {mottle_amount}")
        ck = None if crinkle is None else np.asarray(crinkle, dtype=np.float32)
        if ck is not None and (ck.shape != (self.n, 3) or not np.all(np.isfinite(ck)) or not slope_tensors_ok(ck)):
            raise LeafsimError(f"renderer: crinkle must be finite positive semi-definite slope tensors (xx, xy, yy), "
                               f"({self.n}, 3), got {ck.shape}")
        for name, size, what in (("mottle_size", mottle_size, "mottle"), ("crinkle_size", crinkle_size, "crinkle")):
            if size is not None and not (np.isfinite(size) and size >= 0.0):
                raise LeafsimError(f"renderer: {name} must be a finite length >= 0 m, got {size}")
            if size and not self.has_rest:
                raise LeafsimError(f"renderer: {name} > 0 needs the mesh populated with mottle_rest "
                                   f"(where the tissue samples the {what} field)")
        return pos, c, mt, ck

    def _write_albedo(self, colours, tint, chroma, vein_colours) -> bool:
        """Write the given albedo arrays; True when the veins' base colours must follow."""
        recolour = False
        for a, mine, vbo in ((colours, self.colours, self.vbo_col), (tint, self.tint, self.vbo_tint),
                             (chroma, self.chroma, self.vbo_chroma)):
            if a is not None:
                mine[:] = a
                vbo.write(mine)
                recolour = True
        if vein_colours is not None and self.vein_col is not None:
            self.vein_col[:] = vein_colours
            recolour = True
        return recolour

    def _write_subgrid(self, mottle, mottle_size, mottle_amount, crinkle, crinkle_size) -> None:
        """Write the sub-grid mottle's pigments and the crinkle's slopes, and their settings."""
        if mottle is not None:
            self.mottle[:] = mottle
            self.vbo_mottle.write(self.mottle)
            if self.veins.count:
                self.vbo_vein_mottle.write(self.veins.mottle_rows(self.mottle, self.rest))
        if mottle_size is not None:
            self.mottle_size = float(mottle_size)
        if mottle_amount is not None:
            self.mottle_amount = float(mottle_amount)
        if crinkle is not None:
            self.crinkle[:] = crinkle
            self.crinkle_peak = _largest_trace(self.crinkle)
            self.vbo_crinkle.write(self.crinkle)
        if crinkle_size is not None:
            self.crinkle_size = float(crinkle_size)

    def _bounds(self):
        self.lo, self.hi = bounds(self.pos)
        if self.top is not None and len(self.top):
            tlo, thi = bounds(self.top)
            self.lo, self.hi = np.minimum(self.lo, tlo), np.maximum(self.hi, thi)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi))):  # all NaN: keep drawable
            self.lo, self.hi = np.full(3, -0.05), np.full(3, 0.05)
        self.center = (self.lo + self.hi) / 2.0
        self.radius = max(float(np.linalg.norm(self.hi - self.lo)) / 2.0, 1e-4)

    def _all_positions(self):
        return self.pos if self.top is None else np.concatenate([self.pos, self.top])

    # --- drawing --------------------------------------------------------------------------
    def _shadow_pass(self, opts: RenderOptions, L: np.ndarray) -> np.ndarray:
        size = int(opts.shadow_size)
        if self._shadow_tex is None or self._shadow_tex.size != (size, size):
            for o in (self._shadow_fbo, self._shadow_tex):
                if o is not None:
                    o.release()
            self._shadow_tex = self.ctx.depth_texture((size, size))
            self._shadow_tex.compare_func = "<="
            self._shadow_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self._shadow_tex.repeat_x = self._shadow_tex.repeat_y = False
            self._shadow_fbo = self.ctx.framebuffer(depth_attachment=self._shadow_tex)
        R = self.radius * 1.15
        up = (0.0, 0.0, 1.0) if abs(L[2]) < 0.99 else (0.0, 1.0, 0.0)
        # far plane well past the ground even for a low sun (depth precision is ample)
        light_mat = orthographic(-R, R, -R, R, 0.0, 12.0 * R) @ look_at(self.center + L * 2.0 * R, self.center, up)
        self._shadow_fbo.use()
        self._shadow_fbo.viewport = (0, 0, size, size)
        self._shadow_fbo.clear(depth=1.0)
        sp = self.programs["shadow"]
        _set(sp, "u_light_mat", light_mat)
        cut = bool(opts.texture_cutout) and opts.view in ("shaded", "wireframe") and self._albedo_mode(opts) == 1
        _set(sp, "u_cutout", int(cut))
        _set(sp, "u_tex", 0)
        (self.texture if cut else self._white).use(location=0)
        self.vao_shadow.render(moderngl.TRIANGLES)
        return light_mat

    def _cached(self, name: str, key: tuple, make):
        """A shadow pass's result, redone only when the leaf moved (``update``/``populate``)
        or its settings changed: orbiting the camera over a paused leaf costs no shadow pass."""
        key = (self._geometry, id(self.mesh), key)
        hit = self._shadow_cache.get(name)
        if hit is not None and hit[0] == key:
            return hit[1]
        value = make()
        self._shadow_cache[name] = (key, value)
        return value

    def _mask_targets(self, size: int):
        if self._mask is None or self._mask[0].size != (size, size):
            for o in self._mask or ():
                o.release()
            texs = [self.ctx.texture((size, size), 1, dtype="f1") for _ in range(2)]
            for t in texs:
                t.filter = (moderngl.LINEAR, moderngl.LINEAR)
                t.repeat_x = t.repeat_y = False
            fbos = [self.ctx.framebuffer(color_attachments=[t]) for t in texs]
            self._mask = (texs[0], fbos[0], texs[1], fbos[1])
        return self._mask

    def _ground_shadow_pass(self, opts: RenderOptions, L: np.ndarray, gz: float) -> tuple:
        """The leaf's shadow on the ground plane ``z = gz`` as a small blurred coverage mask:
        the blade projected along ``L`` (a parallel sun) into a ``ground_shadow_size``² texture,
        then a 3x3 binomial blur into the second texture (the one the ground samples).
        Returns the mask's ground rectangle (x0, y0, x1, y1)."""
        size = int(opts.ground_shadow_size)
        tex_a, fbo_a, tex_b, fbo_b = self._mask_targets(size)
        corners = np.array([[x, y, z] for x in (self.lo[0], self.hi[0]) for y in (self.lo[1], self.hi[1])
                            for z in (self.lo[2], self.hi[2])])
        lz = max(float(L[2]), 0.05)
        q = corners[:, :2] - L[None, :2] * ((corners[:, 2:3] - gz) / lz)
        pad = 0.06 * self.radius + 1e-6  # room for the blur
        rect = (*(q.min(axis=0) - pad), *(q.max(axis=0) + pad))
        p = self.programs["gshadow"]
        _set(p, "u_light_dir", (float(L[0]), float(L[1]), lz))
        _set(p, "u_ground_z", gz)
        _set(p, "u_rect", tuple(float(v) for v in rect))
        cut = bool(opts.texture_cutout) and opts.view in ("shaded", "wireframe") and self._albedo_mode(opts) == 1
        _set(p, "u_cutout", int(cut))
        _set(p, "u_tex", 0)
        (self.texture if cut else self._white).use(location=0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        fbo_a.use()
        fbo_a.viewport = (0, 0, size, size)
        fbo_a.clear(0.0)
        self.vao_gshadow.render(moderngl.TRIANGLES)
        b = self.programs["blur"]
        _set(b, "u_src", 2)
        _set(b, "u_texel", (1.0 / size, 1.0 / size))
        tex_a.use(location=2)
        fbo_b.use()
        fbo_b.viewport = (0, 0, size, size)
        self._blur_vao.render(moderngl.TRIANGLE_STRIP)
        self.ctx.enable(moderngl.DEPTH_TEST)
        return rect

    def render(self, camera, width: int, height: int, options=None, framebuffer=None,
               viewport: tuple | None = None) -> None:
        """Draw the leaf as seen by ``camera`` into ``framebuffer``.

        Parameters
        ----------
        camera : OrbitCamera (anything with ``view()``, ``proj(aspect)``, ``eye``)
        width, height : int
            Viewport size in pixels.
        options : RenderOptions or dict, optional
        framebuffer : moderngl.Framebuffer, optional
            Target; default the framebuffer bound when ``render`` is called (the GUI's).
        viewport : (x, y, w, h), optional
            Sub-rectangle of the target to draw in (default ``(0, 0, width, height)``);
            the aspect ratio is taken from ``width / height``.
        """
        if self.mesh is None:
            raise LeafsimError("renderer: render() before populate()")
        opts = RenderOptions.coerce(options)
        opts.check()
        view = opts.view
        heat = view not in BASIC_VIEWS
        if heat and view not in self.scalars:
            raise LeafsimError(f"render options: view {view!r} is neither one of {', '.join(BASIC_VIEWS)} "
                               f"nor a scalar field of the mesh ({', '.join(sorted(self.scalars)) or 'none'})")
        ctx = self.ctx
        target = framebuffer if framebuffer is not None else ctx.detect_framebuffer()
        width, height = max(int(width), 1), max(int(height), 1)
        L = np.asarray(opts.light_dir, dtype=np.float64)
        L = L / max(np.linalg.norm(L), 1e-12)

        ctx.enable_only(moderngl.DEPTH_TEST)
        self_shadow = bool(opts.shadows) and bool(opts.self_shadow)
        light_mat = self._cached("shadow", (opts.shadow_size, tuple(L), opts.texture_cutout, opts.view, opts.albedo),
                                 lambda: self._shadow_pass(opts, L)) if self_shadow else np.eye(4)
        gz = float(self.lo[2]) - 0.004 * self.radius if opts.ground_z is None else float(opts.ground_z)
        ground_shadow = bool(opts.shadows) and bool(opts.ground) and bool(opts.ground_shadow) and L[2] > 0.05
        mask_rect = self._cached("ground_shadow", (opts.ground_shadow_size, tuple(L), gz, opts.texture_cutout, opts.view,
                                                   opts.albedo), lambda: self._ground_shadow_pass(opts, L, gz)) if ground_shadow else None

        self._target = target
        target.use()
        rect = (0, 0, width, height) if viewport is None else tuple(int(v) for v in viewport)
        target.viewport = rect
        if opts.clear:
            target.clear(*opts.background, 1.0, depth=1.0, viewport=rect)
        vp = camera.proj(width / height) @ camera.view()
        eye = np.asarray(camera.eye, dtype=np.float64)
        light = dict(u_eye=tuple(eye), u_light_dir=tuple(L), u_light_col=tuple(opts.light_colour),
                     u_sky_col=tuple(opts.sky_colour), u_translucency=float(opts.translucency),
                     u_specular=float(opts.specular), u_shininess=float(opts.shininess))
        if self_shadow:
            self._shadow_tex.use(location=1)
        if ground_shadow:
            self._mask[2].use(location=2)
        tex = self.texture if self.texture is not None else self._white
        tex.use(location=0)

        blade = view in ("shaded", "wireframe") or heat
        if opts.ground and not blade:
            self._draw_ground(opts, vp, L, gz, mask_rect)
        if blade:
            # the blade first, then the ground: its pixels under the leaf fail the depth test
            # before they are shaded (under llvmpipe the ground is a per-pixel cost)
            self._draw_blade(opts, vp, light, light_mat, heat, self_shadow)
            if opts.ground:
                self._draw_ground(opts, vp, L, gz, mask_rect)
            if opts.veins and self.veins.count and not heat:
                self._draw_veins(opts, vp, light, width, height, light_mat, self_shadow)
        else:
            self._draw_debug(view, vp, eye, opts)
        if view == "wireframe" or (opts.wireframe and view != "springs"):
            self._draw_lines(self.vao_wire, vp, eye, opts, lift=0.002 * self.radius, colour=tuple(opts.wire_colour))
        ctx.disable(moderngl.BLEND)

    def _draw_debug(self, view, vp, eye, opts) -> None:
        """The particles or springs debug view."""
        ctx = self.ctx
        if view == "particles":
            if self._dirty_particles:
                self.vbo_particles.write(np.ascontiguousarray(self._all_positions(), dtype=np.float32))
                self._dirty_particles = False
            p = self.programs["points"]
            _set(p, "u_viewproj", vp)
            _set(p, "u_point_size", float(opts.point_size))
            ctx.enable(moderngl.PROGRAM_POINT_SIZE)
            self.vao_points.render(moderngl.POINTS)
            ctx.disable(moderngl.PROGRAM_POINT_SIZE)
        elif view == "springs":
            if self.springs is not None:
                if self._dirty_springs:
                    allp = self._all_positions()
                    self.vbo_spring_pos.write(np.ascontiguousarray(allp[self.springs.ravel()], dtype=np.float32))
                    self._dirty_springs = False
                self._draw_lines(self.vao_springs, vp, eye, opts, lift=0.0)
            else:  # nothing to show: fall back to the mesh edges
                self._draw_lines(self.vao_wire, vp, eye, opts, lift=0.0, colour=(0.2, 0.4, 0.9))

    def _draw_ground(self, opts, vp, L, gz, rect) -> None:
        """The ground: with a shadow mask, first only the mask's rectangle with the shadow,
        then the whole ground quad (7 leaf radii, fading into the background) pushed back by a
        polygon offset, so it fails the depth test where the rectangle was drawn.  Every
        visible ground pixel is shaded once and the mask is fetched on a fraction of them."""
        gcol = np.asarray(opts.ground_colour, np.float64)
        sky, sun = np.asarray(opts.sky_colour, np.float64), np.asarray(opts.light_colour, np.float64)
        lit = gcol * (sky + sun * max(L[2], 0.0))
        shade = gcol * sky * 0.95  # the leaf also hides a little of the sky
        cx, cy = float(self.center[0]), float(self.center[1])
        ext = 7.0 * self.radius
        quads = [(0, (cx, cy, ext, ext))]
        if rect is not None:
            quads.insert(0, (1, ((rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2, (rect[2] - rect[0]) / 2, (rect[3] - rect[1]) / 2)))
        for sh, quad in quads:
            g = self._variant("ground", LS_SHADOW=sh)
            for k, v in dict(u_viewproj=vp, u_center=(cx, cy, gz), u_quad=tuple(float(x) for x in quad), u_ground_z=gz,
                             u_fade0=2.0 * self.radius, u_fade1=ext, u_lit_srgb=_srgb(lit), u_shade_srgb=_srgb(shade),
                             u_bg=tuple(opts.background), u_mask=2,
                             u_rect=tuple(float(v) for v in (rect or (0.0, 0.0, 1.0, 1.0)))).items():
                _set(g, k, v)
            self.ctx.polygon_offset = (2.0, 4.0) if (sh == 0 and rect is not None) else (0.0, 0.0)
            self._ground_vaos[sh].render(moderngl.TRIANGLE_STRIP)
        self.ctx.polygon_offset = (0.0, 0.0)

    def _draw_blade(self, opts, vp, light, light_mat, heat, self_shadow):
        if heat:
            mode, cmap = 3, 0 if opts.colormap == "turbo" else 1
        else:
            mode, cmap = self._albedo_mode(opts), 0
        mottle = not heat and self._mottle_on()
        crinkle = not heat and self._crinkle_on()
        defs = dict(LS_MODE=mode, LS_CMAP=cmap, LS_SHADOW=int(self_shadow and not heat),
                    LS_CUTOUT=int(bool(opts.texture_cutout) and mode == 1), LS_MOTTLE=int(mottle),
                    LS_CRINKLE=int(crinkle))
        b = self._variant("blade", **defs)
        if mottle:
            self._mottle_uniforms(b)
        if crinkle:
            self._crinkle_uniforms(b)
        if heat:
            if self._scalar_name != opts.view:
                self.vbo_scalar.write(self.scalars[opts.view])
                self._scalar_name = opts.view
            _set(b, "u_range", tuple(float(v) for v in self.scalar_range(opts)))
        _set(b, "u_viewproj", vp)
        _set(b, "u_tex", 0)
        _set(b, "u_tex_mean", self.tex_mean)
        for k, v in light.items():
            _set(b, k, v)
        _set(b, "u_shadow", 1)
        _set(b, "u_light_mat", light_mat)
        _set(b, "u_shadow_offset", 12.0 * 2.3 * self.radius / opts.shadow_size)
        self._variant_vao("blade", **defs).render(moderngl.TRIANGLES)

    def _mottle_on(self) -> bool:
        return self.mottle_size > 0.0 and self.mottle_amount > 0.0 and self.has_rest

    def _crinkle_on(self) -> bool:
        return self.crinkle_size > 0.0 and self.crinkle_peak > 0.0 and self.has_rest

    def _crinkle_uniforms(self, prog) -> None:
        self._crinkle_texture().use(location=4)
        _set(prog, "u_crinkle_grad", 4)
        _set(prog, "u_crinkle_scale", mottle_scale(self.crinkle_size))
        _set(prog, "u_crinkle_offset", CRINKLE_OFFSET)
        _set(prog, "u_crinkle_norm", 1.0 / crinkle_gradient_rms())
        if "u_crinkle_oriented" in prog:
            prog["u_crinkle_oriented"].write(np.asarray(CRINKLE_ORIENTED_OFFSETS, np.float32).tobytes())

    def _crinkle_texture(self):
        """The mottle field's central differences (:func:`leafsim.appearance.mottle.crinkle_gradient`)
        as a two-channel half-float texture, repeated and mipmapped (made once per renderer): one
        fetch a pixel for the crinkle's gradient, and a minified leaf averages it away."""
        if self._crinkle_grad is None:
            g = crinkle_gradient()
            t = self.ctx.texture((g.shape[1], g.shape[0]), 2, g.astype(np.float16).tobytes(), dtype="f2")
            t.build_mipmaps()
            t.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = True
            self._crinkle_grad = t
        return self._crinkle_grad

    def _mottle_uniforms(self, prog) -> None:
        self._mottle_texture().use(location=3)
        _set(prog, "u_noise", 3)
        _set(prog, "u_mottle_scale", mottle_scale(self.mottle_size))
        _set(prog, "u_mottle", self.mottle_amount)
        _set(prog, "u_absorb", [tuple(float(v) for v in row) for row in ABSORPTION])
        _set(prog, "u_base", tuple(float(v) for v in BASE_REFLECTANCE))

    def _mottle_texture(self):
        """The periodic mottle field (:func:`leafsim.appearance.mottle.mottle_field`) as a
        single-channel 8-bit texture of its levels (the shaders decode n = (2k + 1)/256 − 1),
        repeated and mipmapped (made once per renderer): a minified leaf averages the flecks out
        instead of shimmering."""
        if self._noise is None:
            f = mottle_levels()
            t = self.ctx.texture((f.shape[1], f.shape[0]), 1, np.ascontiguousarray(f).tobytes(), dtype="f1")
            t.build_mipmaps()
            t.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = True
            self._noise = t
        return self._noise

    def scalar_range(self, opts) -> tuple[float, float]:
        """The (lo, hi) a heat map of ``opts.view`` is drawn with (what a colour bar must show):
        ``opts.scalar_range``, or the field's 2nd..98th percentile, so that a few nearly dry
        margin particles do not squeeze the rest of the leaf into one colour."""
        if opts.scalar_range is not None:
            return float(opts.scalar_range[0]), float(opts.scalar_range[1])
        f = self.scalars[opts.view]
        f = f[np.isfinite(f)]
        if not f.size:
            return 0.0, 1.0
        lo, hi = (float(v) for v in np.percentile(f, [2.0, 98.0]))
        if hi <= lo:
            lo, hi = float(f.min()), float(f.max())
        # a field (nearly) the same everywhere, as the water of a fresh leaf or a pigment not made
        # yet, is drawn on its full scale: fitted to itself it was the lowest colour, a fresh leaf
        # black, with every tick of the bar reading the same value
        fraction = opts.view != "mass"  # every other view is a share, 0..1
        if hi - lo <= (1e-4 if fraction else 1e-6 * max(abs(lo), abs(hi), 1e-300)):
            c = 0.5 * (lo + hi)
            if fraction:
                return min(0.0, c), max(1.0, c)
            return (0.5 * c, 1.5 * c) if c > 0.0 else (c - 1.0, c + 1.0)
        return lo, hi

    def _albedo_mode(self, opts) -> int:
        if opts.albedo == "colours":
            return 0
        if self.texture is None or not self.has_uv:
            if opts.albedo in ("texture", "detail"):
                raise LeafsimError(f"render options: albedo={opts.albedo!r} needs a mesh with texture_rgba and texcoords")
            return 0
        return {"auto": 1, "texture": 1, "detail": 2}[opts.albedo]

    def _draw_veins(self, opts, vp, light, width, height, light_mat, self_shadow):
        mode = self._albedo_mode(opts)
        mottle = mode > 0 and self._mottle_on()  # the ribbon redraws the blade's photo under it
        defs = dict(LS_TEX=mode, LS_CUTOUT=int(mode == 1 and bool(opts.texture_cutout)),
                    LS_SHADOW=int(self_shadow), LS_MOTTLE=int(mottle))
        v = self._variant("vein", **defs)
        if mottle:
            self._mottle_uniforms(v)
        _set(v, "u_shadow", 1)
        _set(v, "u_light_mat", light_mat)
        _set(v, "u_shadow_offset", 12.0 * 2.3 * self.radius / opts.shadow_size)
        _set(v, "u_viewproj", vp)
        _set(v, "u_viewport", (float(width), float(height)))
        _set(v, "u_lift", 3e-4 * self.radius)
        _set(v, "u_pull_max", VEIN_PULL_MAX)
        _set(v, "u_min_px", float(opts.vein_min_px))
        _set(v, "u_width_scale", float(opts.vein_width_scale))
        _set(v, "u_absolute", int(opts.vein_absolute))
        _set(v, "u_opacity", float(min(max(opts.vein_opacity, 0.0), 1.0)))
        _set(v, "u_tex", 0)
        # sides at their own coordinates: the blade's sampling; the centre's on both sides (no
        # rest positions): 1.5 mip levels coarser, against bands across the vein
        _set(v, "u_uv_blur", 0.0 if self.veins.across_uv else 1.5)
        if mode == 2:
            _set(v, "u_tex_mean", self.tex_mean)
        cols = list(opts.vein_colours)[:4]
        cols += [cols[-1]] * (4 - len(cols))
        _set(v, "u_vein_cols", [tuple(float(x) for x in c) for c in cols])
        for k, val in light.items():
            _set(v, k, val)
        ctx = self.ctx
        ctx.enable(moderngl.BLEND)
        # colour blended, coverage kept: the target's alpha stays 1 under a vein (blended like the
        # colour it fell to a² + 1 − a, and the GUI's half-size view, drawn as a texture over the
        # window, showed the veins pale and dashed)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
        self._target.depth_mask = False
        self._variant_vao("vein", **defs).render(moderngl.TRIANGLES)
        self._target.depth_mask = True
        ctx.disable(moderngl.BLEND)

    def _draw_lines(self, vao, vp, eye, opts, lift, colour=(0.0, 0.0, 0.0)):
        p = self.programs["lines"]
        _set(p, "u_viewproj", vp)
        _set(p, "u_eye", tuple(eye))
        _set(p, "u_lift", float(lift))
        _set(p, "u_colour", tuple(float(c) for c in colour))
        _set(p, "u_kind_cols", [tuple(float(x) for x in c) for c in opts.spring_colours[:4]])
        vao.render(moderngl.LINES)

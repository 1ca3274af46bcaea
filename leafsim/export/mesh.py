"""Mesh export of a simulated leaf: glTF 2.0 (.glb / .gltf + .bin), OBJ + MTL, PLY (core: no OpenGL).

The blade is written either as a **closed thin shell** (``layers="shell"``: the bottom layer T,
a top surface at the current layer separation measured from the V particles, and a side wall
along the margin — watertight) or as the **mid-surface** (``layers="mid"``: one sheet halfway
between the layers, with the local thickness as a vertex attribute).  Colours are the baked
pigment colours (linear RGB per vertex) or the species photo as a texture.  Veins are an
optional second mesh (flat ribbons of the vein width on the upper surface).  ``texture="baked"``
writes one state's blade colour as a texture instead (:mod:`leafsim.export.bake`: the window's
albedo per texel, the sub-grid mottle and a photo's detail included, which per-vertex colours
cannot carry); the veins keep their vertex colours, or over a photo take the texture (the
main veins and laterals only, as the window draws them there).  Several states
become a glTF animation: one morph target per key frame and an animation channel driving
their weights (static formats take one state).  Every file is written atomically.

Coordinates: leafsim is z-up; every format gets glTF's y-up convention ``(x, z, −y)``, metres.

Example
-------
>>> export_mesh(model, [state], "leaf.glb", view=LeafView(model), params=params)   # doctest: +SKIP
>>> export_mesh(model, states, "drying.glb", params=params, times=[s.time for s in states])  # doctest: +SKIP
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes
from leafsim.base.geometry import boundary_edges
from leafsim.sim.checkpoint import check_state, model_fingerprint
from leafsim.sim.frame import _unit, blade_frame
from leafsim.sim.model import Model, State

FORMATS = ("glb", "gltf", "obj", "ply")
LAYERS = ("shell", "mid")
TEXTURES = ("colours", "photo", "baked")
#: the ageing factor on a photo texture is clipped to this (a green pixel needs × 10 and more
#: to turn red; the app's photo albedo clips at 64)
MAX_AGEING = 64.0
#: largest photo side embedded as a texture (pixels)
TEXTURE_MAX = 1024


@dataclass
class Surface:
    """One exported triangle mesh.

    positions, normals : (n, 3) float32 (y-up); uv : (n, 2) float32 or None;
    colours : (n, 3) float32 linear RGB or None; thickness : (n,) float32 or None (mid-surface);
    ageing : (n, 3) float32 or None: with the photo as texture, the factor rgb(now) / rgb(young)
        the ageing multiplies it by (above 1 where green turns red or yellow);
    triangles : (m, 3) uint32, counter-clockwise seen from outside;
    lower : (n,) bool or None: the vertices of a shell's lower face (the glTF writer turns their
        normal-map frame by 180° about the normal, :meth:`leafsim.export.gltf.GltfBuilder.mesh`).
    """

    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray | None = None
    colours: np.ndarray | None = None
    thickness: np.ndarray | None = None
    ageing: np.ndarray | None = None
    lower: np.ndarray | None = None  # (n,) bool: the vertex is on a shell's lower face (the blade's)


def to_y_up(p: np.ndarray) -> np.ndarray:
    """(n, 3) z-up → y-up: (x, y, z) → (x, z, −y)."""
    p = np.asarray(p, np.float64)
    return np.column_stack([p[:, 0], p[:, 2], -p[:, 1]])


def _surface(pos, nrm, tri, uv, col, thick=None) -> Surface:
    return Surface(positions=to_y_up(pos).astype(np.float32), normals=_unit(to_y_up(nrm)).astype(np.float32),
                   triangles=np.ascontiguousarray(tri, np.uint32), uv=None if uv is None else uv.astype(np.float32),
                   colours=None if col is None else np.clip(col, 0.0, 1.0).astype(np.float32),
                   thickness=None if thick is None else thick.astype(np.float32))


def blade_surface(model, state, T, remap, layers, uv, col) -> tuple[Surface, np.ndarray, np.ndarray, np.ndarray]:
    """The blade as a :class:`Surface`; also the upper- and lower-surface points and the
    normals (z-up) the veins lie on."""
    p, tri, n, h = blade_frame(model, state, T, remap)
    if layers == "mid":
        mid = p + 0.5 * h[:, None] * n
        return _surface(mid, n, tri, uv, col, h), mid + 0.5 * h[:, None] * n, n, mid - 0.5 * h[:, None] * n
    top = p + h[:, None] * n
    nT = len(p)
    be = boundary_edges(tri)
    a, b = be[:, 0], be[:, 1]
    sides = np.concatenate([np.column_stack([a, b, b + nT]), np.column_stack([a, b + nT, a + nT])])
    faces = np.concatenate([tri[:, ::-1], tri + nT, sides])
    twice = lambda x: None if x is None else np.concatenate([x, x])
    shell = _surface(np.concatenate([p, top]), np.concatenate([-n, n]), faces, twice(uv), twice(col))
    shell.lower = np.arange(2 * nT) < nT
    return shell, top, n, p


def split_surface(s: Surface, on: np.ndarray, colours: np.ndarray) -> tuple[Surface, Surface]:
    """``s`` cut in two along the faces that touch a vertex of ``on`` (n,) bool: (the rest, with
    ``s``'s attributes; those faces, with the vertex colours ``colours`` (n, 3) linear RGB and no
    texture coordinates).  Each keeps only the vertices its faces use, so the vertices on the cut
    are in both (a seam in the texture, not in the surface)."""
    cut = on[s.triangles].any(axis=1)

    def part(faces, uv, col) -> Surface:
        used = np.unique(faces)
        new = np.full(len(s.positions), -1, np.int64)
        new[used] = np.arange(len(used))
        pick = lambda x: None if x is None else x[used]  # noqa: E731
        return Surface(positions=s.positions[used], normals=s.normals[used],
                       triangles=new[faces].astype(np.uint32), uv=pick(uv),
                       colours=None if col is None else np.clip(col[used], 0.0, 1.0).astype(np.float32),
                       thickness=pick(s.thickness), ageing=pick(s.ageing), lower=pick(s.lower))

    return part(s.triangles[~cut], s.uv, s.colours), part(s.triangles[cut], None, colours)


def _ribbons(model: Model, remap: np.ndarray, sheet: np.ndarray, n: np.ndarray, up: float, uv, col,
             max_order: int | None, base: int, without: np.ndarray | None = None) -> tuple:
    """The vein ribbons on one face of the blade: ``sheet`` (nT, 3) its points, ``up`` +1 on the
    upper face (normals ``n``), −1 on the lower one (normals −n, the winding turned); vertex
    numbers from ``base``; a vein with over half its points in ``without`` (particles, bool) is
    left out.  Returns the lists (positions, normals, triangles, uvs, colours) and the next free
    vertex number."""
    pos, nrm, tris, uvs, cols = [], [], [], [], []
    for k, (idx, width, order) in enumerate(model.vein_polylines()):
        if len(idx) < 2 or (max_order is not None and order > max_order):
            continue
        if without is not None and 2 * int(without[idx].sum()) > len(idx):
            continue
        # each ribbon a hair off the blade at its own height, the main veins farthest: where
        # ribbons met at one height (a branch point), Cycles drew the coplanar faces black
        lift = (0.02 + 0.03 * (3 - min(int(order), 3)) + 0.002 * (k % 5)) * model.thickness
        i = remap[idx]
        out = up * n[i]
        c = sheet[i] + lift * out
        t = np.gradient(c, axis=0)
        side = _unit(np.cross(n[i], t), fallback=(1.0, 0.0, 0.0)) * (0.5 * np.asarray(width))[:, None]
        pos.append(np.concatenate([c - side, c + side]))
        nrm.append(np.concatenate([out, out]))
        m = len(i)
        s = np.arange(m - 1)
        l0, l1, r0, r1 = s, s + 1, s + m, s + m + 1
        # side = n × t puts r to the right of the walk seen from n: (l0, r1, r0), (l0, l1, r1) turn
        # counter-clockwise about n, so the faces agree with their normals (clients light by
        # winding); seen from −n the other way round
        if up > 0:
            tris.append(base + np.concatenate([np.column_stack([l0, r1, r0]), np.column_stack([l0, l1, r1])]))
        else:
            tris.append(base + np.concatenate([np.column_stack([l0, r0, r1]), np.column_stack([l0, r1, l1])]))
        if uv is not None:
            uvs.append(np.concatenate([uv[i], uv[i]]))
        if col is not None:
            cols.append(np.concatenate([col[i], col[i]]))
        base += 2 * m
    return (pos, nrm, tris, uvs, cols), base


def vein_surface(model: Model, remap: np.ndarray, top: np.ndarray, n: np.ndarray, uv, col,
                 max_order: int | None = None, bottom: np.ndarray | None = None,
                 without: np.ndarray | None = None) -> Surface | None:
    """Flat ribbons of the vein widths on the upper surface ``top`` (nT, 3) with normals ``n``,
    and with ``bottom`` (nT, 3) the same on the lower surface (the window draws the veins from
    either side; on a real leaf they stand out below most); 2 vertices per vein point, 2
    triangles per segment, coloured ``col`` (nT, 3) (the vein tissue's own albedo, as the
    renderer draws it); a vein with over half its points in ``without`` (particles, bool) is
    left out.  None when the model has no veins."""
    parts, base = _ribbons(model, remap, top, n, 1.0, uv, col, max_order, 0, without)
    if bottom is not None and base:
        below, _ = _ribbons(model, remap, bottom, n, -1.0, uv, col, max_order, base, without)
        parts = tuple(a + b for a, b in zip(parts, below))
    pos, nrm, tris, uvs, cols = parts
    if not pos:
        return None
    cat = lambda x: np.concatenate(x) if x else None
    return _surface(cat(pos), cat(nrm), cat(tris), cat(uvs), cat(cols))


class MeshSource:
    """What an export needs from one leaf: the model, its :class:`~leafsim.appearance.view.LeafView` (the
    colours from the pigments, the photo) and the options; :meth:`surfaces` gives the meshes
    of one state (same topology for every state of the model)."""

    def __init__(self, model: Model, params, view=None, layers: str = "shell", veins: bool = False,
                 texture: str = "colours", albedo: str = "detail"):
        from leafsim.appearance.view import LeafView

        if layers not in LAYERS:
            raise LeafsimError(f"export: layers {layers!r}: expected one of {', '.join(LAYERS)}")
        if texture not in TEXTURES:
            raise LeafsimError(f"export: texture {texture!r}: expected one of {', '.join(TEXTURES)}")
        from leafsim.export.bake import ALBEDOS

        if albedo not in ALBEDOS:
            raise LeafsimError(f"export: albedo {albedo!r}: expected one of {', '.join(ALBEDOS)} (what a baked texture draws "
                               "on a photo species)")
        self.albedo = albedo
        if view is not None:  # another build's view indexed this model's particles with its own
            if not isinstance(view, LeafView):
                raise LeafsimError(f"export: view is a {type(view).__name__}, expected a LeafView(model, photo_rgba) "
                                   "or None")
            if view.model is not model and model_fingerprint(view.model) != model_fingerprint(model):
                raise LeafsimError("export: view was made for another model (expected LeafView(model, ...) of the model "
                                   "exported)")
            photo = view.photo_rgba
            if photo is not None and not (isinstance(photo, np.ndarray) and photo.ndim == 3 and photo.shape[2] == 4
                                          and photo.dtype == np.uint8 and min(photo.shape[:2]) > 0):
                got = f"{photo.dtype} {photo.shape}" if isinstance(photo, np.ndarray) else type(photo).__name__
                raise LeafsimError(f"export: the view's photo_rgba is {got}, expected an (H, W, 4) uint8 photo "
                                   "(species_photo_rgba) or None")
        self.model, self.params = model, params
        self.view = view if view is not None else LeafView(model)
        if texture == "photo" and self.view.photo_rgba is None:
            raise LeafsimError("export: texture 'photo' needs the leaf's photo in the view: view=LeafView.of_species(sp, "
                               "model, params) of a species with a photo")
        self.layers, self.veins, self.texture = layers, bool(veins), texture
        self.uv = model.particle_texcoord[self.view.T].astype(np.float64)

    def surfaces(self, state: State) -> dict[str, Surface]:
        """``{"blade": Surface, "veins": Surface}`` (veins only when asked for and present)."""
        col = None
        if self.texture in ("colours", "baked"):
            col = np.asarray(self.view.colours(state, self.params)[0], np.float64)
        baked = self.texture == "baked"  # the blade's colour is the texture
        # over a photo the window draws the veins as the photo under them (the photo shows its
        # own veins): their ribbons take the baked texture too; otherwise their own colour per vertex
        veins_textured = baked and self.view.use_texture(self.params) and self.albedo != "colours"
        blade, top, n, bottom = blade_surface(self.model, state, self.view.T, self.view.remap, self.layers, self.uv,
                                      None if baked else col)
        out = {"blade": blade}
        stalk_v = ~self.model.blade_particles[self.view.T]  # the view's vertices on the stalk
        if baked and stalk_v.any():
            # the stalk's texture coordinates lie on the blade's midrib, whose texels the blade's
            # colour fills: it takes the window's albedo per vertex instead (its own pigments)
            from leafsim.export.bake import vertex_albedo

            tri = self.view.remap[self.model.tri_T]
            need = np.unique(tri[stalk_v[tri].any(axis=1)])  # the stalk's faces' vertices, the blade's on the cut too
            alb = np.zeros((len(stalk_v), 3), np.float64)
            alb[need] = vertex_albedo(self, state, need)
            out["blade"], out["stalk"] = split_surface(blade, np.tile(stalk_v, len(blade.positions) // len(stalk_v)),
                                                       np.tile(alb, (len(blade.positions) // len(stalk_v), 1)))
        if self.veins:
            vcol = None if col is None or veins_textured else self.view.vein_colours(state, self.params, col)
            # (and only the main veins and laterals, as the window draws over a photo: the finer
            # orders it grew would cross the photo's areoles as a second pattern)
            v = vein_surface(self.model, self.view.remap, top, n, None if baked and not veins_textured else self.uv,
                             None if veins_textured else (col if vcol is None else np.asarray(vcol, np.float64)),
                             max_order=1 if veins_textured else None, bottom=bottom,
                             # (the stalk's own vein would take the blade's texels at the midrib's base)
                             without=~self.model.blade_particles if veins_textured else None)
            if v is not None:
                out["veins"] = v
        if self.texture == "photo":  # the ageing as a factor on the photo, per vertex of each surface
            _, tint = self.view.colours(state, self.params)
            f = np.ones((len(self.view.T), 3)) if tint is None else np.clip(np.asarray(tint, np.float64), 0.0, MAX_AGEING)
            blade.ageing = (f if self.layers == "mid" else np.concatenate([f, f])).astype(np.float32)
            if "veins" in out:
                one = np.concatenate([np.concatenate([f[self.view.remap[i]], f[self.view.remap[i]]])
                                      for i, _, _ in self.model.vein_polylines() if len(i) >= 2])
                out["veins"].ageing = np.concatenate([one, one]).astype(np.float32)  # the upper and lower ribbons
        return out

    def texture_png(self, state: State) -> bytes | None:
        """The texture of an export of ``state`` as PNG bytes: the photo (:meth:`photo_png`), the
        blade's colour baked at ``state`` (:func:`~leafsim.export.bake.bake_png`), or None for
        vertex colours."""
        return self.texture_pngs(state, normals=False)[0]

    def texture_pngs(self, state: State, normals: bool = True) -> tuple[bytes | None, bytes | None]:
        """(:meth:`texture_png`, the blade's crinkle as a normal map of the same texture space, or
        None): a baked texture carries the crinkle (``render.crinkle``,
        :func:`~leafsim.export.bake.bake_normals`) where the blade has one."""
        if self.texture == "baked":
            from leafsim.export.bake import bake_pngs

            return bake_pngs(self, state, normals)
        return self.photo_png(), None

    def photo_png(self) -> bytes | None:
        """The photo (RGB, at most TEXTURE_MAX px a side; the blade's colour carried past its margin,
        :func:`~leafsim.appearance.texture.clean_texture`) as PNG bytes, or None for vertex colours."""
        if self.texture != "photo":
            return None
        import cv2

        from leafsim.appearance.texture import clean_texture

        rgba = clean_texture(np.asarray(self.view.photo_rgba))  # no background fringe at the margin or past it
        h, w = rgba.shape[:2]
        f = min(1.0, TEXTURE_MAX / max(h, w))
        bgr = cv2.cvtColor(np.ascontiguousarray(rgba[:, :, :3]), cv2.COLOR_RGB2BGR)
        if f < 1.0:
            bgr = cv2.resize(bgr, (max(1, round(w * f)), max(1, round(h * f))), interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".png", bgr)
        if not ok:
            raise LeafsimError("export: cannot encode the photo texture as PNG")
        return buf.tobytes()


def format_of(path, fmt: str | None, flag: str = "format") -> str:
    """The export format: ``fmt`` when given, else the file's suffix; LeafsimError otherwise
    (naming ``flag``: the API's ``format``, the CLI's ``--format``)."""
    suffix = Path(path).suffix.lstrip(".").lower()
    if fmt and fmt not in FORMATS:
        raise LeafsimError(f"{path}: {flag} {fmt!r}: unknown mesh format (expected one of {', '.join(FORMATS)})")
    if fmt and suffix in FORMATS and suffix != fmt:
        raise LeafsimError(f"{path}: the name says {suffix}, {flag} says {fmt} (a {fmt} file named .{suffix} "
                           f"would not open as one): name it .{fmt} or leave {flag} out")
    fmt = fmt or suffix
    if fmt not in FORMATS:
        raise LeafsimError(f"{path}: unknown mesh format {fmt!r} (expected one of {', '.join(FORMATS)})")
    return fmt


def export_mesh(model: Model, states, path, format: str | None = None, params=None, view=None,
                layers: str = "shell", veins: bool = False, texture: str = "colours", times=None,
                albedo: str = "detail", name: str = "leaf", extras: dict | None = None, keep=()) -> dict:
    """Write the leaf ``model`` in ``states`` (a State or a list; several = a glTF animation with
    one morph target per state after the first) to ``path``.

    Parameters
    ----------
    format : "glb", "gltf", "obj" or "ply" (default: from the suffix of ``path``).
    params : the ParamSet the colours are made with (default: the declared defaults).
    view : a :class:`~leafsim.appearance.view.LeafView` (carries the photo); default a photo-less one.
    layers : "shell" (closed thin shell from both layers) or "mid" (mid-surface + thickness).
    veins : add the veins as a second mesh.
    texture : "colours" (baked pigment colours), "photo" (the species photo, glTF/OBJ) or
        "baked" (one state's blade colour as a texture, mottle and photo detail included, glTF/OBJ).
    times : key times [s] of the states (default: their simulated times).
    albedo : with ``texture="baked"`` on a photo species, the window's albedo the texture holds:
        "detail" (the pigment colour with the photo's detail, the window's default), "texture"
        (the photo tinted by the pigment change) or "colours" (the pigment colour alone).
    name, extras : a glTF's root node, whose children the surfaces are: its name (``leafsim
        export`` gives the species and seed, a scene the leaf's name) and JSON-able facts about
        the leaf (species, seed, frame, ...) as its ``extras``.
    keep : files never removed as an earlier OBJ export's leftovers (the species' config and
        photos: :func:`_remove_stale`).

    Returns a summary: format, path, files written, vertex and triangle counts per mesh, targets,
    and ``removed``: the textures an earlier OBJ export to ``path`` wrote that this one did not.
    """
    from leafsim.config.params import ParamSet, as_params

    # every argument checked before anything is computed or written: a state of another model
    # ended in an IndexError, or (a larger one) wrote a file of that leaf's positions on this
    # one's triangles; NaN positions or colours were written into the file
    if not isinstance(path, (str, os.PathLike)):
        raise LeafsimError(f"export: path {path!r:.60}: expected a file name (str or Path) ending in .glb, .gltf, .obj or .ply")
    if not isinstance(model, Model):
        hint = " (pass leaf.model, the model of build_leaf's result)" if hasattr(model, "model") else ""
        raise LeafsimError(f"export: model is a {type(model).__name__}, expected a Model{hint}")
    if isinstance(states, State):
        states = [states]
    elif isinstance(states, (list, tuple)) or (hasattr(states, "__iter__") and not isinstance(states, (str, bytes, dict))):
        states = list(states)
    else:
        raise LeafsimError(f"export: states is a {type(states).__name__}, expected a State or a list of States")
    if not states:
        raise LeafsimError("export: no state to write")
    for k, s in enumerate(states):
        check_state(s, model, f"export: state {k}", physical=False)
    if params is not None:
        from leafsim.sim.simulator import check_built_with

        params = as_params(params, "export")
        check_built_with(model, params, "export")  # another leaf's params: its colours on this model, silently
    else:
        params = ParamSet()
    if extras is not None:
        import json

        try:  # (a NaN became the token NaN in the glTF's JSON, which strict parsers refuse)
            json.dumps(extras, allow_nan=False)
        except (TypeError, ValueError) as e:
            raise LeafsimError(f"export: extras: expected JSON values (strings, finite numbers, lists, dicts): {e}") from None
    if times is not None:
        try:
            times = [float(t) for t in times]
        except (TypeError, ValueError):
            raise LeafsimError(f"export: times {times!r:.60}: expected one number [s] per state") from None
        if len(times) != len(states) or not all(np.isfinite(times)):
            raise LeafsimError(f"export: times: expected {len(states)} finite key times [s], one per state, got "
                               f"{len(times)}{' (not all finite)' if not all(np.isfinite(times)) else ''}")
    fmt = format_of(path, format)
    if fmt in ("obj", "ply") and len(states) > 1:
        raise LeafsimError(f"{path}: {fmt.upper()} holds one static shape; use glb or gltf for the drying animation")
    if fmt == "ply" and texture in ("photo", "baked"):
        raise LeafsimError(f"{path}: PLY carries vertex colours, not a {texture} texture (use texture='colours')")
    if texture == "baked" and len(states) > 1:
        raise LeafsimError(f"{path}: texture 'baked' holds one state's colour, and a glTF texture cannot change with "
                           f"the key frames: export one state, or texture='colours' for the animation")
    from leafsim.base.fileio import output_target

    for side, what in side_files(path, fmt, texture):  # a folder or device in the way: now, not after the bake
        output_target(side, what)
    src = MeshSource(model, params, view, layers, veins, texture, albedo)
    frames = [src.surfaces(s) for s in states]
    times = [s.time for s in states] if times is None else times
    png, normal_png = src.texture_pngs(states[-1], normals=fmt in ("glb", "gltf", "obj"))
    earlier = _mtl_maps(path) if fmt == "obj" else []  # (read before the new MTL replaces it)
    if fmt in ("glb", "gltf"):
        from leafsim.export.gltf import write_gltf

        counts = {}
        files = write_gltf(Path(path), frames, times, png, binary=fmt == "glb", image_name=texture, normal_png=normal_png,
                           name=name, extras=extras, counts=counts)
    elif fmt == "obj":
        files = write_obj(Path(path), frames[0], png, texture_file(path, texture), normal_png, normal_file(path))
    else:
        files = write_ply(Path(path), frames[0])
    if fmt not in ("glb", "gltf"):  # OBJ and PLY write the surfaces' vertices as they are
        counts = {k: {"vertices": len(s.positions), "triangles": len(s.triangles)} for k, s in frames[0].items()}
    removed = _remove_stale(path, earlier, files, keep)
    return {"format": fmt, "path": str(path), "files": [str(f) for f in files], "targets": len(states) - 1,
            "meshes": counts, "removed": [str(f) for f in removed]}


#: the first line of every MTL leafsim writes (:func:`write_obj`)
MTL_HEADER = "# leafsim materials"


def _mtl_maps(path) -> list[Path]:
    """The texture files the MTL beside ``path`` names (``map_Kd``, ``map_Bump``) when that MTL is
    a regular file leafsim wrote (its first line :data:`MTL_HEADER`), else []: what an earlier
    export to ``path`` wrote beside it."""
    mtl = Path(path).with_suffix(".mtl")
    try:
        if mtl.is_symlink() or not mtl.is_file() or mtl.stat().st_size > 1 << 20:
            return []
        lines = mtl.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return []
    if not lines or lines[0].strip() != MTL_HEADER:
        return []
    out = []
    for ln in lines:
        parts = ln.split()
        if len(parts) >= 2 and parts[0] in ("map_Kd", "map_Bump"):
            out.append(Path(path).parent / parts[-1])
    return out


def _remove_stale(path, earlier, written, keep=()) -> list[Path]:
    """Remove the textures an earlier OBJ export to ``path`` wrote (``earlier``: what its MTL
    named, :func:`_mtl_maps`) that this one did not (``written``): a fresh leaf's export writes no
    normal map, a baked export no photo, and a folder zipped for a client shipped the old ones
    beside the new MTL.  Only regular files in ``path``'s folder with a name an export to ``path``
    writes (:func:`side_files`), never one of ``keep`` (the species' inputs); a file that cannot
    be removed is left.  Returns the removed files."""
    ours = {Path(p).name for texture in ("photo", "baked") for p, _ in side_files(path, "obj", texture)}
    mine = {os.path.realpath(f) for f in written}
    kept = {os.path.realpath(f) for f in keep if f is not None}
    removed = []
    for old in dict.fromkeys(earlier):
        old = Path(old)
        real = os.path.realpath(old)
        if (old.name not in ours or real in mine or real in kept or old.is_symlink() or not old.is_file()
                or not same_folder(old.parent, Path(path).parent)):
            continue
        try:
            old.unlink()
        except OSError:
            continue
        removed.append(old)
    return removed


def same_folder(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


# ------------------------------------------------------------------ static formats

def _srgb8(c: np.ndarray) -> np.ndarray:
    from leafsim.appearance.reflectance import linear_to_srgb

    return np.clip(np.round(np.asarray(linear_to_srgb(np.clip(c, 0, 1)), np.float64) * 255.0), 0, 255).astype(np.uint8)


def side_files(path, fmt: str, texture: str = "colours") -> list:
    """(path, what) of the files an export to ``path`` writes beside it: a glTF's buffer, an
    OBJ's material and texture."""
    path = Path(path)
    png = [(texture_file(path, texture), "texture")] if texture != "colours" else []
    if texture == "baked":  # (written only when the blade has a crinkle)
        png.append((normal_file(path), "normal map"))
        if fmt == "obj":  # the lower face's turned copies (written with the normal map)
            png += [(lower_file(texture_file(path, texture)), "lower face's texture"),
                    (lower_file(normal_file(path)), "lower face's normal map")]
    return {"gltf": [(path.with_suffix(".bin"), "glTF buffer")],
            "obj": [(path.with_suffix(".mtl"), "material"), *png]}.get(fmt, [])


def texture_file(path, texture: str) -> Path:
    """The PNG an OBJ export of ``path`` writes beside it with ``texture`` "photo" or "baked"."""
    path = Path(path)
    return path.with_name(f"{path.stem}_{texture}.png")


def normal_file(path) -> Path:
    """The PNG an OBJ export of ``path`` with ``texture`` "baked" writes beside it for the blade's
    crinkle (the glTF's normalTexture), when the blade has one."""
    path = Path(path)
    return path.with_name(f"{path.stem}_baked_normal.png")


def lower_file(png) -> Path:
    """The copy of an OBJ's texture ``png`` turned by 180° for the blade's lower face."""
    png = Path(png)
    return png.with_name(f"{png.stem}_lower.png")


def _turned_png(png: bytes) -> bytes:
    """A PNG turned by 180° (pixel for pixel: the same texels, read from the other corner)."""
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    ok, buf = (False, None) if img is None else cv2.imencode(".png", cv2.rotate(img, cv2.ROTATE_180))
    if not ok:
        raise LeafsimError("export: cannot turn the texture for the OBJ's lower face")
    return buf.tobytes()


#: the MTL's specular colour and exponent, as Blender's OBJ importer turns them into the glTF
#: export's material (Principled BSDF: Specular IOR Level = mean Ks, the dielectric default
#: 0.5; Roughness = 1 − √(Ns / 1000) = 0.75, the glTF's roughnessFactor)
MTL_GLOSS = ("Ks 0.5 0.5 0.5", "Ns 62.5")


def _diffuse(colours) -> np.ndarray:
    """An MTL material's Kd: 1 under a texture (readers that multiply map_Kd by Kd keep the
    texture's colour); the mean of the mesh's vertex colours (linear) without one, so a reader
    that does not draw vertex colours shows the mesh in its mean colour, not grey."""
    if colours is None or not len(colours):
        return np.ones(3)
    return np.clip(np.asarray(colours, np.float64).mean(axis=0), 0.0, 1.0)


def write_obj(path: Path, surfaces: dict[str, Surface], photo_png: bytes | None = None, png: Path | None = None,
              normal_png: bytes | None = None, normal: Path | None = None) -> list[Path]:
    """OBJ + MTL (+ the texture PNG, ``png``, default ``<stem>_photo.png``): one object per mesh,
    ``v x y z r g b`` vertex colours (sRGB, the common extension trimesh, Blender and MeshLab
    read), ``vt``, ``vn``; a mesh without texture coordinates is not textured.

    ``normal_png`` (the baked crinkle, :func:`~leafsim.export.bake.bake_normals`) goes to
    ``normal`` (default ``<stem>_baked_normal.png``) and onto the blade's material as
    ``map_Bump -bm 1``: MTL has no normal-map statement of its own, and ``map_Bump`` is the one
    Blender's importer (and its exporter) read as a tangent-space normal map, tangents from the
    texture coordinates (MikkTSpace, as a glTF client without TANGENT makes them).  Its y is up
    the image, the increasing OBJ ``vt``; a reader that takes ``map_Bump`` as a height map
    shades it wrongly, one that ignores it draws the blade smooth.

    With the normal map, the shell's lower face (``Surface.lower``) takes a material of its own,
    ``blade_lower``, whose two images are the texture and the map turned by 180°
    (:func:`lower_file`), and texture coordinates (1 − u, 1 − v) of its own: it reads the same
    texels as the upper face, in a frame turned by 180° about its normal, as the glTF's lower
    face does with negated coordinates and a mirrored sampler (MTL has no mirrored wrap; with
    the upper face's coordinates, as before, a reader drew the underside's relief mirrored).
    The rim keeps the upper face's coordinates."""
    mtl = path.with_suffix(".mtl")
    png = png if png is not None else texture_file(path, "photo")
    normal = normal if normal is not None else normal_file(path)
    lines = ["# leafsim mesh export", f"mtllib {mtl.name}"]
    mat = [MTL_HEADER]
    base = vt_base = 0
    turned = False
    for name, s in surfaces.items():
        lines.append(f"o {name}")
        lines.append(f"usemtl {name}")
        textured = photo_png is not None and s.uv is not None
        mapped = normal_png is not None and s.uv is not None and name == "blade"
        kd = _diffuse(None if textured else s.colours)
        material = ["Ka 0 0 0", f"Kd {kd[0]:.4f} {kd[1]:.4f} {kd[2]:.4f}", *MTL_GLOSS, "d 1", "illum 2"]
        mat += [f"newmtl {name}", *material]
        if textured:
            mat.append(f"map_Kd {png.name}")
        if mapped:
            mat.append(f"map_Bump -bm 1 {normal.name}")
        rgb = None if s.colours is None else _srgb8(s.colours) / 255.0
        for i, p in enumerate(s.positions):
            lines.append(f"v {p[0]:.7g} {p[1]:.7g} {p[2]:.7g}" + ("" if rgb is None else f" {rgb[i, 0]:.4f} {rgb[i, 1]:.4f} {rgb[i, 2]:.4f}"))
        uv = s.uv if s.uv is not None else np.zeros((len(s.positions), 2), np.float32)
        lines += [f"vt {u:.7g} {1.0 - v:.7g}" for u, v in uv]
        lines += [f"vn {n[0]:.6f} {n[1]:.6f} {n[2]:.6f}" for n in s.normals]
        tri = s.triangles.astype(np.int64)
        low = np.zeros(len(tri), bool)
        extra = 0  # the lower face's own vt lines
        if mapped and textured and s.lower is not None:  # the lower face: its own material and coordinates
            low = s.lower[tri].all(axis=1)
            lo = np.flatnonzero(s.lower)
            lines += [f"vt {1.0 - u:.7g} {v:.7g}" for u, v in uv[lo]]  # (1 − u, 1 − v) in the image's terms
            extra = len(lo)
            at = np.full(len(uv), -1, np.int64)
            at[lo] = len(uv) + np.arange(len(lo))
            mat += ["newmtl blade_lower", *material, f"map_Kd {lower_file(png).name}",
                    f"map_Bump -bm 1 {lower_file(normal).name}"]
            turned = True
        f = tri + base + 1
        ft = tri + vt_base + 1
        lines += [f"f {a}/{at_}/{a} {b}/{bt}/{b} {c}/{ct}/{c}" for (a, b, c), (at_, bt, ct) in zip(f[~low], ft[~low])]
        if low.any():
            lines.append("usemtl blade_lower")
            fl = at[tri[low]] + vt_base + 1
            lines += [f"f {a}/{at_}/{a} {b}/{bt}/{b} {c}/{ct}/{c}" for (a, b, c), (at_, bt, ct) in zip(f[low], fl)]
        base += len(s.positions)
        vt_base += len(uv) + extra
    written = []
    if photo_png is not None:
        written.append(atomic_write_bytes(png, photo_png, "texture"))
    if normal_png is not None:
        written.append(atomic_write_bytes(normal, normal_png, "normal map"))
    if turned:
        written.append(atomic_write_bytes(lower_file(png), _turned_png(photo_png), "lower face's texture"))
        written.append(atomic_write_bytes(lower_file(normal), _turned_png(normal_png), "lower face's normal map"))
    written.append(atomic_write_bytes(mtl, ("\n".join(mat) + "\n").encode(), "material"))
    written.append(atomic_write_bytes(path, ("\n".join(lines) + "\n").encode(), "mesh"))
    return written


def write_ply(path: Path, surfaces: dict[str, Surface]) -> list[Path]:
    """Binary little-endian PLY of every mesh merged (positions, normals, s/t, 8-bit sRGB colours,
    and ``thickness`` [m] for a mid-surface)."""
    ss = list(surfaces.values())
    pos = np.concatenate([s.positions for s in ss])
    nrm = np.concatenate([s.normals for s in ss])
    uv = np.concatenate([s.uv if s.uv is not None else np.zeros((len(s.positions), 2), np.float32) for s in ss])
    col = np.concatenate([s.colours if s.colours is not None else np.full((len(s.positions), 3), 0.5, np.float32) for s in ss])
    thick = None if ss[0].thickness is None else np.concatenate(
        [s.thickness if s.thickness is not None else np.zeros(len(s.positions), np.float32) for s in ss])
    offs = np.cumsum([0] + [len(s.positions) for s in ss])[:-1]
    tri = np.concatenate([s.triangles.astype(np.int64) + o for s, o in zip(ss, offs)])
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
              ("s", "<f4"), ("t", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if thick is not None:
        fields.append(("thickness", "<f4"))
    v = np.zeros(len(pos), dtype=fields)
    for k, name in enumerate("xyz"):
        v[name], v["n" + name] = pos[:, k], nrm[:, k]
    v["s"], v["t"] = uv[:, 0], 1.0 - uv[:, 1]
    c8 = _srgb8(col)
    v["red"], v["green"], v["blue"] = c8[:, 0], c8[:, 1], c8[:, 2]
    if thick is not None:
        v["thickness"] = thick
    f = np.zeros(len(tri), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    f["n"], f["i"] = 3, tri
    ptype = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment leafsim mesh export (y up, metres)",
              f"element vertex {len(v)}", *[f"property {ptype[t]} {n}" for n, t in fields],
              f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    data = ("\n".join(header) + "\n").encode() + v.tobytes() + f.tobytes()
    return [atomic_write_bytes(path, data, "mesh")]

"""Headless rendering: an EGL context, a 4x MSAA framebuffer, and atomic PNG output."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import write_png_atomic as _write_png
from leafsim.base.resources import shader_dir as default_shader_dir
from leafsim.render.camera import OrbitCamera


def write_png_atomic(rgb: np.ndarray, path) -> Path:
    """Write ``rgb (H, W, 3) uint8`` to ``path`` via a temp file + ``os.replace``.

    Raises :class:`LeafsimError` naming the path if the folder is missing or not writable;
    no partial file is left behind.
    """

    path = Path(path)
    return _write_png(path, np.asarray(rgb), rgb=True)


def default_camera(points, pitch: float = 55.0, yaw: float = -90.0, aspect: float | None = None) -> OrbitCamera:
    """An orbit camera framing ``points`` from the base side, apex up on screen; with the
    picture's ``aspect`` (width / height) the leaf fills it (see :meth:`OrbitCamera.frame_bounds`)."""
    cam = OrbitCamera(yaw=yaw, pitch=pitch)
    cam.frame_bounds(points, margin=1.15 if aspect is None else 1.08, aspect=aspect)
    return cam


class OffscreenRenderer:
    """A :class:`~leafsim.render.renderer.Renderer` on its own EGL context.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    samples : int
        MSAA samples (clamped to what the driver offers; 0 = none).
    shader_dir : path, optional
    """

    def __init__(self, width: int, height: int, samples: int = 4, shader_dir=None):
        import moderngl

        from leafsim.render.renderer import Renderer

        self.width, self.height = int(width), int(height)
        try:
            self.ctx = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as exc:
            raise LeafsimError(f"cannot create a headless OpenGL (EGL) context: {exc}") from None
        samples = min(int(samples), self.ctx.max_samples) if samples else 0
        size = (self.width, self.height)
        self.samples = samples
        self._colour = self.ctx.renderbuffer(size, 4, samples=samples)
        self._depth = self.ctx.depth_renderbuffer(size, samples=samples)
        self.fbo = self.ctx.framebuffer(self._colour, self._depth)
        if samples:
            self._resolve_rb = self.ctx.renderbuffer(size, 4)
            self.resolve = self.ctx.framebuffer(self._resolve_rb)
        else:
            self._resolve_rb, self.resolve = None, self.fbo
        self.renderer = Renderer(self.ctx, default_shader_dir() if shader_dir is None else shader_dir)
        self._mesh = None

    def _prepare(self, mesh_or_update):
        """A mesh object: populate (new object) or update from it (same object).
        A dict: ``Renderer.update(**dict)``. None: draw the current state."""
        if mesh_or_update is None:
            if self.renderer.mesh is None:
                raise LeafsimError("offscreen render: nothing populated yet")
        elif isinstance(mesh_or_update, dict):
            self.renderer.update(**mesh_or_update)
        elif mesh_or_update is self._mesh and self.renderer.mesh is mesh_or_update:
            m = mesh_or_update
            self.renderer.update(m.positions, colours=getattr(m, "colours", None),
                                 scalar=getattr(m, "scalars", None) or None, tint=getattr(m, "tint", None),
                                 top_positions=getattr(m, "top_positions", None), chroma=getattr(m, "chroma", None),
                                 vein_colours=getattr(m, "vein_colours", None), mottle=getattr(m, "mottle", None),
                                 mottle_size=(getattr(m, "mottle_size", 0.0) or 0.0) if getattr(m, "mottle", None) is not None else None,
                                 mottle_amount=(getattr(m, "mottle_amount", 0.0) or 0.0) if getattr(m, "mottle", None) is not None else None,
                                 crinkle=getattr(m, "crinkle", None),
                                 crinkle_size=(getattr(m, "crinkle_size", 0.0) or 0.0) if getattr(m, "crinkle", None) is not None else None)
        else:
            self.renderer.populate(mesh_or_update)
            self._mesh = mesh_or_update

    def render_array(self, mesh_or_update=None, camera=None, options=None) -> np.ndarray:
        """Render and read back: ``(H, W, 3) uint8`` RGB, row 0 at the top."""
        with self.ctx:  # make this context current (several offscreen renderers may coexist)
            self._prepare(mesh_or_update)
            r = self.renderer
            if camera is None:
                camera = default_camera(np.stack([r.lo, r.hi]), aspect=self.width / self.height)
            r.render(camera, self.width, self.height, options, framebuffer=self.fbo)
            if self.resolve is not self.fbo:
                self.ctx.copy_framebuffer(self.resolve, self.fbo)
            data = self.resolve.read(components=3, alignment=1)
        img = np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width, 3)
        return np.ascontiguousarray(img[::-1])

    def render_png(self, mesh_or_update, path, camera=None, options=None) -> Path:
        """Render and write a PNG atomically; returns the path."""
        path = Path(path)
        folder = path.parent if str(path.parent) else Path(".")
        if not folder.is_dir():
            raise LeafsimError(f"cannot write PNG {path}: folder {folder} does not exist")
        return write_png_atomic(self.render_array(mesh_or_update, camera, options), path)

    def populate(self, mesh) -> None:
        """``Renderer.populate`` with this renderer's context current."""
        with self.ctx:
            self.renderer.populate(mesh)
            self._mesh = mesh

    def update(self, positions, **kwargs) -> None:
        """``Renderer.update`` with this renderer's context current."""
        with self.ctx:
            self.renderer.update(positions, **kwargs)

    def release(self) -> None:
        if self.ctx is None:
            return
        with self.ctx:
            self.renderer.release()
            for o in (self.fbo, self._colour, self._depth, self.resolve, self._resolve_rb):
                if o is not None:
                    try:
                        o.release()
                    except Exception:
                        pass
        self.ctx.release()
        self.ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

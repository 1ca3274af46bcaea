"""PNG frames of one leaf as it dries, rendered offscreen (``leafsim run --every K``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from leafsim.appearance.view import LeafView
from leafsim.render.offscreen import OffscreenRenderer, default_camera
from leafsim.render.options import RenderOptions


class FrameWriter:
    """Offscreen PNG frames of one leaf (photo species: the pigment colour carrying the photo's
    detail, as the GUI shows it); the camera is fixed by the rest leaf, so every frame of a
    run (and of a resumed run) is framed alike.

    Parameters
    ----------
    model, params : the leaf and its parameters.
    photo : (H, W, 4) uint8 species photo or None.
    out : folder of the ``frame_NNNNN.png`` files.
    rest_state : the fresh leaf (frames the camera; its pigments are the young colour).
    photo_colour : the species' photo shows the young leaf's colour.
    """

    def __init__(self, model, params, photo, out: Path, rest_state, photo_colour: bool = False):
        self.view = LeafView(model, photo, rest_state.pigments.copy(), photo_tint=False, photo_colour=photo_colour)
        self.params, self.out = params, Path(out)
        self.rest = rest_state
        self.renderer = self.camera = None
        self.written = 0

    def write(self, k: int, state) -> Path:
        """Render ``state`` as ``frame_{k:05d}.png`` (atomically)."""
        opts = RenderOptions.of_params(self.params, albedo="detail" if self.view.use_texture(self.params) else "colours")
        path = self.out / f"frame_{k:05d}.png"
        if self.renderer is None:
            self.renderer = OffscreenRenderer(960, 720)
            box = _room_to_curl(self.view.mesh(self.rest, self.params).positions)
            if self.params["dynamics.scene"] == "hanging":
                box = _room_to_hang(box, self.view.model)
            self.camera = default_camera(box, aspect=960 / 720)
            self.renderer.render_png(self.view.mesh(state, self.params), path, camera=self.camera, options=opts)
        else:
            self.renderer.render_png(self.view.update(state, self.params), path, camera=self.camera, options=opts)
        self.written += 1
        return path


def _room_to_hang(box: np.ndarray, model) -> np.ndarray:
    """``box`` grown down to where a leaf hanging from its pinned particles can reach."""
    pins = model.particle_rest[model.particle_pinned]
    if not len(pins):
        return box
    c = pins.mean(0)
    reach = float(np.linalg.norm(model.particle_rest - c, axis=1).max())
    out = box.copy()
    out[0, 2] = min(out[0, 2], c[2] - 1.05 * reach)
    return out


def _room_to_curl(points: np.ndarray) -> np.ndarray:
    """The fresh leaf's box with room above (margins curl up by up to ≈ 0.35 L) and a little
    below, so a camera fixed by it keeps the drying leaf in the picture."""
    lo, hi = points.min(0), points.max(0)
    span = float(np.max(hi - lo))
    return np.array([[lo[0], lo[1], lo[2] - 0.1 * span], [hi[0], hi[1], hi[2] + 0.35 * span]])

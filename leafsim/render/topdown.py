"""Top-down orthographic pictures of a leaf in a :class:`leafsim.compare.metrics.Frame` (``leafsim compare``).

The camera looks straight down (apex up on the canvas, world x to the right) with the frame's
scale, so a model pixel and a photo pixel of the comparison frame are the same point.  The
light is a scanner's: half from straight above, half diffuse sky, no highlight, no
translucency, no ground, no shadow — a flat blade facing up is drawn in exactly its albedo.
The picture is rendered at twice the size without multisampling and averaged down: the
silhouette is the share of covered sub-pixels (≥ ½), the colours are anti-aliased.
"""

from __future__ import annotations

import numpy as np

from leafsim.render.camera import OrbitCamera

#: render options of a scanner-like top-down picture (a flat blade shows its albedo)
SCANNER = dict(light_dir=(0.0, 0.0, 1.0), light_colour=(0.5, 0.5, 0.5), sky_colour=(0.5, 0.5, 0.5), specular=0.0,
               translucency=0.0, ground=False, shadows=False, background=(1.0, 0.0, 1.0))
_KEY = np.array([255, 0, 255], np.uint8)


def topdown_camera(frame, height_above: float = 1.0) -> OrbitCamera:
    """An orthographic camera straight down on ``frame`` (its view height = the frame's)."""
    cam = OrbitCamera(yaw=-90.0, pitch=90.0, ortho=True, fov=35.0)
    c = frame.centre
    cam.target = np.array([c[0], c[1], 0.0])
    cam.distance = float(height_above)
    half = 0.5 * frame.height / frame.scale
    cam.fov = float(np.degrees(2.0 * np.arctan(half / cam.distance)))
    return cam


class TopDown:
    """Offscreen top-down renders of one leaf view in one frame.

    ``render(mesh_or_update, options)`` → (rgb (H, W, 3) uint8 on white, silhouette (H, W) bool).
    """

    def __init__(self, frame, supersample: int = 2):
        from leafsim.render.offscreen import OffscreenRenderer

        self.frame, self.k = frame, int(supersample)
        self.off = OffscreenRenderer(frame.width * self.k, frame.height * self.k, samples=0)
        self.camera = topdown_camera(frame)

    def render(self, mesh_or_update=None, options=None) -> tuple[np.ndarray, np.ndarray]:
        from leafsim.render.options import RenderOptions

        opts = RenderOptions.coerce({**SCANNER, **(options or {})})
        big = self.off.render_array(mesh_or_update, self.camera, opts)
        cover = np.any(big != _KEY, axis=2).astype(np.float32)
        k, H, W = self.k, self.frame.height, self.frame.width
        cov = cover.reshape(H, k, W, k).mean(axis=(1, 3))
        col = (big.astype(np.float32) * cover[..., None]).reshape(H, k, W, k, 3).sum(axis=(1, 3))
        col = col / np.maximum(cov[..., None] * k * k, 1e-6)
        rgb = col * cov[..., None] + 255.0 * (1.0 - cov[..., None])
        return np.clip(rgb + 0.5, 0, 255).astype(np.uint8), cov >= 0.5

    def release(self) -> None:
        self.off.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

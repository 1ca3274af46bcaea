"""Scene overview: many placed leaves in one offscreen image (ground, shadows).

The renderer draws one :class:`~leafsim.appearance.mesh.RenderMesh` per ``populate``; a scene is
drawn by merging every placed leaf into one mesh (:func:`leafsim.scene.placement.merge_views`: positions transformed,
triangle and vein indices offset, per-vertex pigment colours).  One populate, one shadow map
over the whole scene, no change to the renderer itself.  Leaves are drawn with their baked
pigment colours (one mesh holds one texture, so photos are not used here).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from leafsim.appearance.mesh import RenderMesh


def render_overview(mesh: RenderMesh, layout: dict, overview: dict, path: Path) -> Path:
    """Render the placed leaves (one merged mesh, :func:`leafsim.scene.placement.merge_views`)
    on the ground with shadows into ``path`` (PNG, atomic)."""
    from leafsim.render.offscreen import OffscreenRenderer, default_camera
    from leafsim.render.options import RenderOptions

    pts = mesh.positions
    if layout["kind"] == "canopy":  # frame the crown together with the ground under it
        lo, hi = pts.min(0), pts.max(0)
        pts = np.vstack([pts, [[lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0]]])
    cam = default_camera(pts, pitch=overview["pitch"], yaw=overview["yaw"])
    cam.frame_bounds(pts, margin=1.04, aspect=overview["width"] / overview["height"])
    # the ground just under the lowest leaf (the renderer's default; z = 0 exactly would
    # z-fight with leaves lying flat on it), at z = 0 under a canopy
    ground = 0.0 if layout["kind"] == "canopy" else None
    opts = RenderOptions(albedo="colours", ground_z=ground, shadow_size=4096, vein_min_px=0.5)
    with OffscreenRenderer(overview["width"], overview["height"]) as r:
        return r.render_png(mesh, path, camera=cam, options=opts)

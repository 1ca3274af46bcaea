"""Orbit camera (z up) and the small matrix helpers the renderer needs. No OpenGL here.

Matrices are row-major numpy (``clip = P @ V @ p``); the renderer transposes on upload.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def look_at(eye, target, up) -> np.ndarray:
    """(4, 4) float64 view matrix."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    sn = np.linalg.norm(s)
    if sn < 1e-9:  # up parallel to the view direction
        s = np.cross(f, [0.0, 1.0, 0.0] if abs(f[1]) < 0.9 else [1.0, 0.0, 0.0])
        sn = np.linalg.norm(s)
    s /= sn
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fovy_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(math.radians(fovy_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(left, right, bottom, top, near, far) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = 2.0 / (right - left)
    m[1, 1] = 2.0 / (top - bottom)
    m[2, 2] = -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


@dataclass
class OrbitCamera:
    """Camera orbiting ``target`` (z up).

    Parameters
    ----------
    yaw : float
        Degrees around +z; the eye sits at azimuth ``yaw`` (-90 = on the -y side, looking
        towards the apex, so the apex points up on screen).
    pitch : float
        Elevation in degrees, clamped to [-89, 89] by :meth:`drag` (90 = straight down
        is allowed when set directly).
    distance : float
        Eye to target, metres.
    target : (3,) float
        Orbit centre, metres.
    fov : float
        Vertical field of view in degrees (perspective).
    ortho : bool
        Orthographic projection; the view height is ``2 * distance * tan(fov / 2)``.
    """

    yaw: float = -90.0
    pitch: float = 55.0
    distance: float = 0.35
    target: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.06, 0.0]))
    fov: float = 35.0
    ortho: bool = False

    def __post_init__(self):
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3)

    # --- geometry -------------------------------------------------------------------------
    def _dirs(self):
        y, p = math.radians(self.yaw), math.radians(self.pitch)
        back = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p)])
        up = np.array([-math.sin(p) * math.cos(y), -math.sin(p) * math.sin(y), math.cos(p)])
        return back, up

    @property
    def eye(self) -> np.ndarray:
        return self.target + self.distance * self._dirs()[0]

    def view(self) -> np.ndarray:
        """(4, 4) float64 world -> eye matrix."""
        back, up = self._dirs()
        return look_at(self.target + self.distance * back, self.target, up)

    def proj(self, aspect: float) -> np.ndarray:
        """(4, 4) float64 projection for the viewport aspect ratio (width / height)."""
        near, far = self.distance * 0.01, self.distance * 100.0
        if self.ortho:
            h = self.distance * math.tan(math.radians(self.fov) / 2.0)
            return orthographic(-h * aspect, h * aspect, -h, h, near, far)
        return perspective(self.fov, aspect, near, far)

    # --- interaction ----------------------------------------------------------------------
    def drag(self, dx: float, dy: float, speed: float = 0.3) -> None:
        """Orbit by a mouse drag of (dx, dy) pixels (dy > 0 = mouse moved down)."""
        self.yaw -= dx * speed
        self.pitch = float(np.clip(self.pitch + dy * speed, -89.0, 89.0))

    def zoom(self, wheel: float) -> None:
        """Wheel steps (> 0 zooms in)."""
        self.distance = float(np.clip(self.distance * 0.88 ** wheel, 1e-4, 1e4))

    def pan(self, dx: float, dy: float, viewport_height: float = 800.0) -> None:
        """Move the target in the screen plane by (dx, dy) pixels."""
        back, up = self._dirs()
        right = np.cross(up, back)
        k = 2.0 * self.distance * math.tan(math.radians(self.fov) / 2.0) / max(viewport_height, 1.0)
        self.target = self.target + (-dx * right + dy * up) * k

    def frame_bounds(self, points, margin: float = 1.15, aspect: float | None = None) -> None:
        """Aim at the bounding box of ``points (n, 3)`` and back off until it all fits.

        Without ``aspect`` the box's bounding sphere fits the vertical field of view (any
        orbit keeps it in view).  With the viewport's ``aspect`` (width / height) the box's
        eight corners, as this camera sees them, fill the view to within ``margin`` on the
        tighter axis, centred: a flat leaf seen from above fills the picture instead of half
        of it."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        self.target = (lo + hi) / 2.0
        radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-4)
        self.distance = radius * margin / math.sin(math.radians(self.fov) / 2.0)
        if aspect is None:
            return
        corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
        back, up = self._dirs()
        right = np.cross(up, back)
        ty = math.tan(math.radians(self.fov) / 2.0) / margin
        tx = ty * float(aspect)
        for _ in range(4):  # centre the projected box, then fit it; converges in a few rounds
            r = corners - self.target
            x, y, z = r @ right, r @ up, r @ back
            if self.ortho:
                self.target = self.target + 0.5 * (x.max() + x.min()) * right + 0.5 * (y.max() + y.min()) * up
                r = corners - self.target
                self.distance = max(float(np.max(np.abs(r @ right)) / tx), float(np.max(np.abs(r @ up)) / ty), 1e-4)
                return
            depth = np.maximum(self.distance - z, 1e-9)
            u, v = x / depth, y / depth
            shift = 0.5 * (u.max() + u.min()) * right + 0.5 * (v.max() + v.min()) * up
            self.target = self.target + shift * self.distance
            r = corners - self.target
            x, y, z = r @ right, r @ up, r @ back
            self.distance = max(float(np.max(np.abs(x) / tx + z)), float(np.max(np.abs(y) / ty + z)), 1e-4)

"""Renderer (moderngl). ``RenderMesh``, ``OrbitCamera`` and ``RenderOptions`` import no OpenGL;
``Renderer`` and ``OffscreenRenderer`` load moderngl on first use."""

from leafsim.appearance.mesh import RenderMesh
from leafsim.render.camera import OrbitCamera
from leafsim.render.options import RenderOptions

__all__ = ["OrbitCamera", "RenderMesh", "RenderOptions", "Renderer", "OffscreenRenderer"]


def __getattr__(name):
    if name == "Renderer":
        from leafsim.render.renderer import Renderer
        return Renderer
    if name == "OffscreenRenderer":
        from leafsim.render.offscreen import OffscreenRenderer
        return OffscreenRenderer
    raise AttributeError(name)

"""What a renderer needs from one simulated leaf (core: no OpenGL, no imgui).

:class:`LeafView` turns a model + state into a :class:`leafsim.render.mesh.RenderMesh` once
(:meth:`LeafView.mesh`) and into the per-frame arrays of ``Renderer.update`` afterwards
(:meth:`LeafView.update`).  The GUI's session, ``leafsim run`` frames and scene overviews all
use it, so every picture of a leaf is made the same way.

Example
-------
>>> view = LeafView(model, photo_rgba=None)               # doctest: +SKIP
>>> renderer.populate(view.mesh(state, params))           # doctest: +SKIP
>>> renderer.update(**view.update(state, params))         # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np

from .sim.model import LAYER_T, SPRING_LINK, SPRING_SURFACE, SPRING_V, SPRING_VEIN, Model, State

#: pigment fields offered as heat-map debug views
PIGMENT_VIEWS = ("chlorophyll", "carotenoid", "anthocyanin", "browning")


class LeafView:
    """Render data of one model.

    Parameters
    ----------
    model : Model
    photo_rgba : (H, W, 4) uint8 photo with alpha = leaf mask, or None (drawn species).
    pigments0 : the young :class:`~leafsim.sim.colour.PigmentState` (for the photo tint), or None.
    photo_tint : with a photo as albedo, tint it by the pigment change (True) or leave the tint
        at 1 (renderers that take the pigment colour with the photo's detail).
    """

    def __init__(self, model: Model, photo_rgba=None, pigments0=None, photo_tint: bool = True):
        self.model = model
        self.photo_rgba = photo_rgba
        self.pigments0 = pigments0
        self.photo_tint = photo_tint
        T = np.flatnonzero(model.particle_layer == LAYER_T)
        V = np.flatnonzero(model.particle_layer != LAYER_T)
        remap = np.empty(model.particle_count, np.int64)
        remap[T] = np.arange(len(T))
        remap[V] = len(T) + np.arange(len(V))
        self.T, self.V, self.remap = T, V, remap

    def use_texture(self, params) -> bool:
        return bool(params["render.texture"]) and self.photo_rgba is not None

    def colours(self, state: State, params):
        """(colours (nT, 3) linear RGB, tint (nT, 3) or None) of layer T from the pigments.
        The tint (photo species only) is rgb(now) / rgb(young), clipped to [0, 4], or ones
        when :attr:`photo_tint` is False."""
        from .sim.colour import pigments_to_rgb, tint_for_texture

        T = self.T
        pig = state.pigments
        if pig is None:
            rgb = np.tile(np.float32([0.18, 0.35, 0.08]), (len(T), 1))
        else:
            rgb = pigments_to_rgb(pig, params)[T]
        if not self.use_texture(params):
            return rgb, None
        if self.photo_tint and pig is not None and self.pigments0 is not None:
            return rgb, np.clip(tint_for_texture(pig, self.pigments0, params)[T], 0.0, 4.0)
        return rgb, np.ones_like(rgb)

    def scalar_fields(self, state: State) -> dict:
        """Per layer-T vertex heat-map fields: ``mass`` [mg] now, ``water`` (now / initial) and
        the pigment fields (relative to the summer content)."""
        m, T = self.model, self.T
        w = state.particle_water[T]
        out = {"mass": (m.particle_cytosol[T] + w).astype(np.float32),
               "water": (w / np.maximum(m.particle_water0[T], 1e-300)).astype(np.float32)}
        if state.pigments is not None:
            for name in PIGMENT_VIEWS:
                out[name] = np.asarray(getattr(state.pigments, name), np.float32)[T]
        return out

    def mesh(self, state: State, params):
        """A :class:`leafsim.render.mesh.RenderMesh` of the model in ``state`` (populate once)."""
        from .render.mesh import SPRING_LINK as R_LINK, SPRING_SURFACE_T, SPRING_SURFACE_V, SPRING_VEIN as R_VEIN, RenderMesh

        m, T, V, remap = self.model, self.T, self.V, self.remap
        kind_map = np.zeros(4, np.int8)
        kind_map[SPRING_SURFACE], kind_map[SPRING_V] = SPRING_SURFACE_T, SPRING_SURFACE_V
        kind_map[SPRING_LINK], kind_map[SPRING_VEIN] = R_LINK, R_VEIN
        colours, tint = self.colours(state, params)
        veins = [(remap[idx].astype(np.int64), np.asarray(w, np.float64), order) for idx, w, order in m.vein_polylines()]
        return RenderMesh(
            positions=state.particle_q[T].astype(np.float32),
            triangles=remap[m.tri_T].astype(np.int32),
            texcoords=m.particle_texcoord[T].astype(np.float32),
            colours=colours,
            texture_rgba=self.photo_rgba if self.use_texture(params) else None,
            tint=tint,
            vein_lines=veins,
            springs=remap[m.spring_ij].astype(np.int32),
            spring_kind=kind_map[m.spring_type],
            top_positions=state.particle_q[V].astype(np.float32),
            scalars=self.scalar_fields(state),
        )

    def update(self, state: State, params) -> dict:
        """Keyword arguments for ``Renderer.update`` with ``state``."""
        colours, tint = self.colours(state, params)
        out = {"positions": state.particle_q[self.T], "colours": colours, "scalar": self.scalar_fields(state),
               "top_positions": state.particle_q[self.V]}
        if tint is not None:
            out["tint"] = tint
        return out

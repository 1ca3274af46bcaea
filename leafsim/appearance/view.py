"""What a renderer needs from one simulated leaf (core: no OpenGL, no imgui).

:class:`LeafView` turns a model + state into a :class:`leafsim.appearance.mesh.RenderMesh` once
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

from leafsim.sim.model import LAYER_T, SPRING_LINK, SPRING_SURFACE, SPRING_V, SPRING_VEIN, Model, State

#: pigment fields offered as heat-map debug views
PIGMENT_VIEWS = ("chlorophyll", "carotenoid", "anthocyanin", "browning", "necrosis")


class LeafView:
    """Render data of one model.

    Parameters
    ----------
    model : Model
    photo_rgba : (H, W, 4) uint8 photo with alpha = leaf mask, or None (drawn species).
    pigments0 : the young :class:`~leafsim.sim.pigments.PigmentState` (for the photo tint), or None.
    photo_tint : with a photo as albedo, tint it by the pigment change (True) or leave the tint
        at 1 (renderers that take the pigment colour with the photo's detail).
    blade_only : leave the petiole out of the triangles and vein lines (the blade against its photo).
    photo_colour : the photo shows the young leaf: its colour is the young colour (see
        :meth:`colours`).  False for a photo of a senescent leaf (its outline and detail are
        used, the young colour is the palette's).
    """

    def __init__(self, model: Model, photo_rgba=None, pigments0=None, photo_tint: bool = True, photo_colour: bool = False,
                 blade_only: bool = False):
        self.model = model
        self.blade_only = blade_only  # draw the blade without its petiole (the photo comparison)
        self.photo_rgba = photo_rgba
        self.pigments0 = pigments0
        self.photo_tint = photo_tint
        self.photo_colour = bool(photo_colour) and photo_rgba is not None
        T = np.flatnonzero(model.particle_layer == LAYER_T)
        V = np.flatnonzero(model.particle_layer != LAYER_T)
        remap = np.empty(model.particle_count, np.int64)
        remap[T] = np.arange(len(T))
        remap[V] = len(T) + np.arange(len(V))
        self.T, self.V, self.remap = T, V, remap
        self._young = None   # (photo colour per particle (n, 3) linear, luminance normaliser (nT,))
        self._dead = None    # tissue the young photo shows dead already, 0..1 per layer-T particle
        self._fit = None     # (vein_pallor, fitted contents)
        self._pure_vein = None  # ones (n,): m̂ of pure vein tissue (vein_colours)
        self._crinkle = {}  # the lamina compression's per-mesh data and prolongations (leafsim.sim.crinkle)

    @classmethod
    def of_species(cls, sp, model: Model, params, seed: int = 0, pigments0=None, **kw) -> "LeafView":
        """The view every path draws and exports a species' leaf with (``leafsim export``, scenes,
        the window): the species' photo if it has one, the young pigments (``pigments0``, or the
        fresh leaf's of ``model``, ``params`` and ``seed``: :func:`leafsim.sim.simulator.young_state`)
        and the photo as the young colour where the species says so (``photo_colour``).  Other
        keywords go to the constructor (``photo_tint``, ``blade_only``)."""
        from leafsim.appearance.photo import species_photo_rgba
        from leafsim.base.errors import LeafsimError
        from leafsim.config.params import as_params
        from leafsim.config.species import Species
        from leafsim.sim.simulator import check_built_with, young_state

        if not isinstance(sp, Species):
            raise LeafsimError(f"LeafView.of_species: sp is a {type(sp).__name__}, expected a Species (get_species(key))")
        if not isinstance(model, Model):
            hint = " (pass leaf.model, the model of build_leaf's result)" if hasattr(model, "model") else ""
            raise LeafsimError(f"LeafView.of_species: model is a {type(model).__name__}, expected a Model{hint}")
        params = as_params(params, "LeafView.of_species")
        check_built_with(model, params, "LeafView.of_species")
        photo = species_photo_rgba(sp, params) if sp.image is not None else None
        if pigments0 is None:
            pigments0 = young_state(model, params, seed).pigments
        return cls(model, photo, pigments0, photo_colour=sp.photo_colour, **kw)

    def use_texture(self, params) -> bool:
        return bool(params["render.texture"]) and self.photo_rgba is not None

    def young_photo_colour(self) -> np.ndarray:
        """(n, 3) linear RGB of the photo at every particle: the photo blurred over half a mesh
        spacing (blade pixels only), sampled at the particle's texture coordinates."""
        if self._young is None:
            self._young = _photo_at_particles(self.model, self.photo_rgba)
        return self._young[0]

    def dead_in_photo(self) -> np.ndarray:
        """(nT,) how far each layer-T particle's tissue is dead already in the young photo, 0..1
        (:func:`dead_in_photo`); zeros without a young photo."""
        if self._dead is None:
            T = self.T
            self._dead = (dead_in_photo(self.young_photo_colour()[T]) if self.photo_colour
                          else np.zeros(len(T), np.float32))
        return self._dead

    def photo_contents(self, params) -> tuple:
        """Pigment contents fitted to the photo's young colour (cached per ``colour.vein_pallor``)."""
        from leafsim.appearance.reflectance import fit_photo_contents

        key = float(params["colour.vein_pallor"])
        if self._fit is None or self._fit[0] != key:
            m = self.model
            sel = m.particle_layer == LAYER_T
            self._fit = (key, fit_photo_contents(self.young_photo_colour(), self.pigments0, params, m.particle_area, sel))
        return self._fit[1]

    def colours(self, state: State, params):
        """(colours (nT, 3) linear RGB, tint (nT, 3) or None) of layer T from the pigments.

        Photo species whose photo shows the young leaf (``photo_colour``): the young colour is
        the photo's, per particle; aging multiplies it by the model's reflectance change
        rgb(now) / rgb(young), both with pigment contents fitted to the photo
        (:func:`~leafsim.sim.pigments.fit_photo_contents`), so the photo's hue is the start and
        the pigments move it.  The tint (photo as albedo) is that change; the vertex colours
        carry the mean luminance of the photo (the "detail" albedo multiplies it by the pixel's
        luminance over the mean: the photo's own pixel brightness, not twice its shading).
        Otherwise: the palette's pigment colour, and the tint rgb(now) / rgb(young) clipped to
        [0, 4] (ones when :attr:`photo_tint` is False)."""
        from leafsim.appearance.reflectance import pigments_to_rgb, tint_for_texture

        T = self.T
        pig = state.pigments
        if pig is None:
            rgb = np.tile(np.float32([0.18, 0.35, 0.08]), (len(T), 1))
        elif self.photo_colour and self.pigments0 is not None:
            return self._photo_colours(pig, params)
        else:
            rgb = pigments_to_rgb(pig, params)[T]
        if not self.use_texture(params):
            return rgb, None
        if self.photo_tint and pig is not None and self.pigments0 is not None:
            return rgb, np.clip(tint_for_texture(pig, self.pigments0, params)[T], 0.0, 4.0)
        return rgb, np.ones_like(rgb)

    def vein_colours(self, state: State, params, blade: np.ndarray | None = None):
        """(nT, 3) linear RGB of the vein tissue at each layer-T particle, or None without pigments.

        A drawn vein is the vein itself, not the blade under it: the pigment model's colour of
        pure vein tissue (m̂ = 1: ``colour.vein_pallor`` less chlorophyll, ``colour.vein_browning``
        less browning), so a fresh leaf's veins are paler green and a dried leaf's a paler tan,
        as the parameters say.  A species whose young colour is its photo's gets the photo's
        colour there (``blade``, :meth:`colours`' first array, computed when not given) times
        the same change, pure vein tissue over the particle's tissue.  Where the photo itself is
        drawn (the renderer's texture and detail albedos, an export's photo texture) the veins
        take the photo's colour under them instead: the photo shows its own veins."""
        from leafsim.appearance.reflectance import pigments_to_rgb

        pig = state.pigments
        if pig is None:
            return None
        if self._pure_vein is None or len(self._pure_vein) != pig.n:
            self._pure_vein = np.ones(pig.n, np.float32)
        T = self.T
        if not (self.photo_colour and self.pigments0 is not None):
            return pigments_to_rgb(pig, params, vein=self._pure_vein)[T]
        contents = self.photo_contents(params)
        ratio = pigments_to_rgb(pig, params, contents, vein=self._pure_vein)[T] / np.maximum(pigments_to_rgb(pig, params, contents)[T], 1e-4)
        blade = self.colours(state, params)[0] if blade is None else blade
        return (np.asarray(blade, np.float32) * np.clip(ratio, 0.0, 4.0)).astype(np.float32)

    def _photo_colours(self, pig, params):
        from leafsim.appearance.reflectance import pigments_to_rgb

        T = self.T
        contents = self.photo_contents(params)
        now = pigments_to_rgb(pig, params, contents)[T]
        young = self.young_photo_colour()[T]
        # the photo's own cast (what the fitted pigments do not explain: white balance, hairs)
        # fades with the living tissue: colour = model(now) × (photo / model(young))^C, so the
        # young leaf is the photo and dead tissue the species' colour (never a tinted brown)
        cast = np.maximum(young, 1e-4) / np.maximum(pigments_to_rgb(self.pigments0, params, contents)[T], 1e-4)
        live = np.clip(pig.chlorophyll[T], 0.0, 1.0)[:, None]
        change = now * np.power(cast, live) / np.maximum(young, 1e-4)
        # tissue the photo shows dead already (a brown lesion) keeps its photo colour: it has
        # no chlorophyll to lose, and it is already brown (the change above would turn it into
        # the surrounding tissue's dried colour, its edge alone left darker by the detail)
        dead = self.dead_in_photo()
        if dead.any():
            change = (1.0 - dead[:, None]) * change + dead[:, None]
        rgb = (young * self._young[1][:, None] * change).astype(np.float32)
        if not self.use_texture(params):
            return rgb, None
        return rgb, (np.clip(change, 0.0, 64.0).astype(np.float32) if self.photo_tint else np.ones_like(rgb))

    def chroma(self, state: State, params):
        """(nT, 4) float32 for the "detail" albedo (:class:`~leafsim.appearance.mesh.RenderMesh`
        ``chroma``), or None: photo species whose photo shows the young leaf get the photo's
        young colour at each vertex over its luminance, weighted by the chlorophyll the tissue
        keeps (now ÷ young, 0..1), so the renderer lays the photo's own fine hues on living
        tissue and none on dead tissue, whose colour is the model's."""
        pig = state.pigments
        if not (self.photo_colour and self.pigments0 is not None and pig is not None and self.use_texture(params)):
            return None
        T = self.T
        # the γ-2.2 colour the vertex colours are made from: at weight 1 the detail albedo is then
        # exactly the texel as the "photo" albedo draws it (the sampler decodes exact sRGB; taking
        # this ratio against an exact-sRGB blur instead moved the young grapevine from the photo,
        # mean ΔE 0.12 → 0.74, aspen 0.21 → 2.64)
        young = self.young_photo_colour()[T]
        lum = young @ np.float32([0.2126, 0.7152, 0.0722])
        out = np.empty((len(T), 4), np.float32)
        out[:, :3] = young / np.maximum(lum, 1e-4)[:, None]
        c0 = np.asarray(self.pigments0.chlorophyll, np.float64)[T]
        out[:, 3] = np.clip(np.asarray(pig.chlorophyll, np.float64)[T] / np.maximum(c0, 1e-6), 0.0, 1.0)
        return out

    def mottle(self, state: State, params):
        """(the renderer's sub-grid mottle pigments (nT, 10) float32, the field's correlation
        length in metres, ``colour.mottle``), or (None, 0, 0) without pigments
        (:func:`~leafsim.appearance.reflectance.mottle_pigments`, with the photo's fitted pigment
        contents where the young colour is the photo's, as :meth:`colours` has them)."""
        from leafsim.appearance.reflectance import mottle_pigments

        pig = state.pigments
        if pig is None:
            return None, 0.0, 0.0
        contents = self.photo_contents(params) if (self.photo_colour and self.pigments0 is not None) else None
        return mottle_pigments(pig, params, contents)[self.T], float(params["colour.mottle_size"]), float(params["colour.mottle"])

    def compression(self, state: State) -> np.ndarray:
        """(n, 3) the lamina's compression tensor of every particle over the flat rest plane
        (:func:`leafsim.sim.crinkle.lamina_compression`)."""
        from leafsim.sim.crinkle import lamina_compression

        return lamina_compression(self.model, state, self._crinkle)

    def crinkle(self, state: State, params, compression: np.ndarray | None = None):
        """((nT, 3) float32 slope tensor of the sub-grid crinkle over the rest plane,
        ``render.crinkle``² × 2K with K the lamina's compression (:meth:`compression`, or
        ``compression`` when given; :func:`leafsim.sim.crinkle.crinkle_slopes`), the field's
        correlation length in metres), or (None, 0) with ``render.crinkle`` 0."""
        from leafsim.sim.crinkle import crinkle_slopes

        gain = float(params["render.crinkle"])
        if gain <= 0.0:
            return None, 0.0
        K = self.compression(state) if compression is None else compression
        return crinkle_slopes(np.asarray(K)[self.T], gain).astype(np.float32), float(params["render.crinkle_size"])

    def mottle_rest(self, state: State) -> np.ndarray:
        """(nT, 2) float32: where each vertex samples the mottle field, its rest position in
        metres shifted by the leaf's own offset (from its pigment seed)."""
        from leafsim.appearance.mottle import leaf_offset

        seed = state.pigments.seed if state.pigments is not None else 0
        return (self.model.particle_rest[self.T][:, :2] + leaf_offset(seed)).astype(np.float32)

    def scalar_fields(self, state: State, compression: np.ndarray | None = None) -> dict:
        """Per layer-T vertex heat-map fields: ``mass`` per area [kg/m²] now, ``water`` (now / initial),
        the pigment fields (relative to the summer content) and ``crinkle``, the lamina's excess
        length ½ tr K (K: :meth:`compression`, or ``compression`` when given; 0.01 = 1 %)."""
        from leafsim.sim.crinkle import excess_of

        m, T = self.model, self.T
        w = state.particle_water[T]
        out = {"mass": ((m.particle_cytosol[T] + w) / np.maximum(m.particle_area[T], 1e-300)).astype(np.float32),
               "water": (w / np.maximum(m.particle_water0[T], 1e-300)).astype(np.float32),
               "crinkle": excess_of(self.compression(state) if compression is None else compression)[T].astype(np.float32)}
        if state.pigments is not None:
            for name in PIGMENT_VIEWS:
                out[name] = np.asarray(getattr(state.pigments, name), np.float32)[T]
        return out

    def mesh(self, state: State, params):
        """A :class:`leafsim.appearance.mesh.RenderMesh` of the model in ``state`` (populate once)."""
        from leafsim.appearance.mesh import SPRING_LINK as R_LINK
        from leafsim.appearance.mesh import SPRING_SURFACE_T, SPRING_SURFACE_V, RenderMesh
        from leafsim.appearance.mesh import SPRING_VEIN as R_VEIN

        m, T, V, remap = self.model, self.T, self.V, self.remap
        kind_map = np.zeros(4, np.int8)
        kind_map[SPRING_SURFACE], kind_map[SPRING_V] = SPRING_SURFACE_T, SPRING_SURFACE_V
        kind_map[SPRING_LINK], kind_map[SPRING_VEIN] = R_LINK, R_VEIN
        colours, tint = self.colours(state, params)
        vein_colours = self.vein_colours(state, params, colours)
        mottle, mottle_size, mottle_amount = self.mottle(state, params)
        K = self.compression(state)
        crinkle, crinkle_size = self.crinkle(state, params, K)
        stalk = ~m.blade_particles
        veins = [(remap[idx].astype(np.int64), np.asarray(w, np.float64), order) for idx, w, order in m.vein_polylines()
                 if not (self.blade_only and stalk[idx].any())]
        return RenderMesh(
            positions=state.particle_q[T].astype(np.float32),
            triangles=remap[m.blade_tri_T if self.blade_only else m.tri_T].astype(np.int32),
            texcoords=m.particle_texcoord[T].astype(np.float32),
            colours=colours,
            texture_rgba=self.photo_rgba if self.use_texture(params) else None,
            tint=tint,
            chroma=self.chroma(state, params),
            vein_colours=vein_colours,
            vein_lines=veins,
            springs=remap[m.spring_ij].astype(np.int32),
            spring_kind=kind_map[m.spring_type],
            top_positions=state.particle_q[V].astype(np.float32),
            scalars=self.scalar_fields(state, K),
            mottle=mottle,
            mottle_rest=self.mottle_rest(state),
            mottle_size=mottle_size,
            mottle_amount=mottle_amount,
            crinkle=crinkle,
            crinkle_size=crinkle_size,
        )

    def update(self, state: State, params) -> dict:
        """Keyword arguments for ``Renderer.update`` with ``state``."""
        colours, tint = self.colours(state, params)
        K = self.compression(state)
        out = {"positions": state.particle_q[self.T], "colours": colours, "scalar": self.scalar_fields(state, K),
               "top_positions": state.particle_q[self.V]}
        if tint is not None:
            out["tint"] = tint
        chroma = self.chroma(state, params)
        if chroma is not None:
            out["chroma"] = chroma
        vein = self.vein_colours(state, params, colours)
        if vein is not None:
            out["vein_colours"] = vein
        mottle, size, amount = self.mottle(state, params)
        if mottle is not None:
            out["mottle"], out["mottle_size"], out["mottle_amount"] = mottle, size, amount
        crinkle, crinkle_size = self.crinkle(state, params, K)
        out["crinkle"] = crinkle if crinkle is not None else np.zeros((len(self.T), 3), np.float32)
        out["crinkle_size"] = crinkle_size
        return out


#: tissue is dead in a young photo when it is redder (CIELAB a*) than the blade's median by more
#: than the first and darker (L*) by more than the second, fully so by twice each: a brown lesion
#: on a green blade (a* +20 to +30 above it), not a pale pink vein line (lighter), a shadow or a
#: dark green spot (no redder), nor yellowing tissue (lighter)
DEAD_REDDER, DEAD_DARKER = 6.0, 5.0


def dead_in_photo(young: np.ndarray) -> np.ndarray:
    """(n,) 0..1: how far the tissue at each particle is dead already in a young photo, from its
    photo colour ``young`` (linear RGB) against the blade's median (:data:`DEAD_REDDER`,
    :data:`DEAD_DARKER`).  The shipped young photos have next to none (oak: 8 margin particles of
    971 at most 0.001, grapevine one at 0.02); a synthetic blade with a brown lesion has it under
    the lesion."""
    import cv2

    if not len(young):
        return np.zeros(0, np.float32)
    srgb = np.clip(np.asarray(young, np.float32), 0.0, 1.0) ** (1.0 / 2.2)
    lab = cv2.cvtColor(srgb[:, None, ::-1].copy(), cv2.COLOR_BGR2Lab).reshape(-1, 3)
    L, a = lab[:, 0], lab[:, 1]
    redder = np.clip((a - np.median(a) - DEAD_REDDER) / DEAD_REDDER, 0.0, 1.0)
    darker = np.clip((np.median(L) - L - DEAD_DARKER) / DEAD_DARKER, 0.0, 1.0)
    return (redder * darker).astype(np.float32)


def _photo_at_particles(model: Model, rgba: np.ndarray):
    """(linear RGB of the photo at every particle (n, 3), mean luminance / particle luminance
    for layer T (nT,)): blade pixels blurred over half a mesh spacing, bilinear at the
    particles' texture coordinates; the mean is the texture's leaf-area mean (the renderer's)."""
    import cv2

    h, w = rgba.shape[:2]
    lin = (rgba[..., :3].astype(np.float32) / 255.0) ** 2.2
    a = (rgba[..., 3] >= 128).astype(np.float32)
    uv = model.particle_texcoord
    b = model.blade_T  # the petiole's texture coordinates sit on the midrib, off the blade's map
    span = np.ptp(model.particle_rest[b, :2], axis=0).max()
    px_per_m = float(np.ptp(uv[b, 1] * h) + np.ptp(uv[b, 0] * w)) / max(float(np.ptp(model.particle_rest[b, 1]) + np.ptp(model.particle_rest[b, 0])), 1e-12)
    sigma = max(0.5 * model.spacing * px_per_m, 0.7) if span > 0 else 1.0
    num = cv2.GaussianBlur(lin * a[..., None], (0, 0), sigma)
    den = cv2.GaussianBlur(a, (0, 0), sigma)
    mx, my = (uv[:, 0] * w - 0.5).astype(np.float32), (uv[:, 1] * h - 0.5).astype(np.float32)
    n_ = cv2.remap(num, mx.reshape(-1, 1), my.reshape(-1, 1), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1, 3)
    d_ = cv2.remap(den, mx.reshape(-1, 1), my.reshape(-1, 1), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1)
    mean = lin[a > 0].mean(axis=0) if a.any() else np.full(3, 0.1, np.float32)
    young = np.where(d_[:, None] > 1e-3, n_ / np.maximum(d_[:, None], 1e-3), mean).astype(np.float32)
    lum = young @ np.float32([0.2126, 0.7152, 0.0722])
    T = model.particle_layer == LAYER_T
    norm = float(mean @ np.float32([0.2126, 0.7152, 0.0722])) / np.maximum(lum[T], 1e-4)
    return young, norm.astype(np.float32)

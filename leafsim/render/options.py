"""Render options: one strict dataclass (unknown keys are rejected). No OpenGL here."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from leafsim.base.errors import LeafsimError

#: Views that are not scalar heat maps; any other view name must be a key of ``mesh.scalars``.
BASIC_VIEWS = ("shaded", "particles", "springs", "wireframe")
#: render.translucency (default 0.35) × this is the shader's translucency (default 0.65)
TRANSLUCENCY_SCALE = 0.65 / 0.35


@dataclass
class RenderOptions:
    """How to draw the leaf.

    Parameters
    ----------
    view : str
        "shaded", "wireframe" (shaded + edges), "particles", "springs", or the name of a
        scalar field in ``mesh.scalars`` ("mass", "water", ...) drawn as a heat map.
    albedo : str
        "auto" (photo if the mesh has one, else colours), "colours", "texture", or
        "detail" (vertex colour times the photo's normalised brightness: pigment colour
        with the photo's detail).
    texture_cutout : bool
        With the photo as albedo, cut the blade where the photo's alpha (leaf mask) is 0, so
        the photo's own outline shows even on a coarser mesh.
    veins, ground, shadows, ground_shadow, self_shadow, wireframe : bool
        Draw the vein ribbons / ground plane / shadows at all / the soft shadow on the ground /
        leaf self-shadowing / a wireframe overlay in any view.
    background : (3,) float
        Clear colour, display (sRGB) values 0..1.
    ground_colour : (3,) float
        Linear RGB albedo of the ground.
    ground_z : float or None
        Ground height in metres; None = just below the lowest vertex.
    light_dir : (3,) float
        Direction towards the sun (normalised by the renderer).
    light_colour, sky_colour : (3,) float
        Linear radiance of the sun and of the ambient sky.
    translucency : float
        Strength of light transmitted through the blade (back-lit glow).
    specular, shininess : float
        Blinn-Phong highlight strength and exponent.
    vein_colours : tuple of (3,) float
        Per vein order (0 main, 1 lateral, 2 sublateral, 3+ tertiary): a multiplier of the
        vein's albedo (the vein tissue's own colour from the pigments when the mesh carries
        ``vein_colours``, else the blade's under it), or absolute linear RGB when
        ``vein_absolute``.  Ones by default: the veins' colour is the pigment model's, not painted
        (a fixed × 1.7 made a dried tan leaf's veins and stalk glow orange).  With a photo albedo
        ("texture", "detail") orders 2 and finer are not drawn: the photo shows its own veins.
    vein_absolute : bool
        Interpret ``vein_colours`` as absolute linear RGB.
    vein_width_scale : float
        Multiplier of the vein widths.
    vein_min_px : float
        Veins thinner than this on screen are drawn this wide but faded (anti-aliasing).
    vein_opacity : float
        The drawn veins' opacity over the blade (``render.vein_alpha``), 0..1.
    point_size : float
        Particle size in pixels.
    spring_colours : tuple of (3,) float
        sRGB colour per spring kind (surface T, surface V, link, vein).
    colormap : str
        "turbo" or "viridis" for heat maps.
    scalar_range : (float, float) or None
        Heat-map range; None = min/max of the field.
    wire_colour : (3,) float
        sRGB colour of the wireframe overlay.
    shadow_size : int
        Shadow-map resolution (the leaf's self-shadowing).
    ground_shadow_size : int
        Resolution of the ground-shadow mask (the leaf projected onto the ground along the
        sun direction and blurred), sampled once per ground pixel.
    clear : bool
        Clear the target framebuffer first.
    """

    view: str = "shaded"
    albedo: str = "auto"
    texture_cutout: bool = False
    veins: bool = True
    ground: bool = True
    shadows: bool = True
    ground_shadow: bool = True
    self_shadow: bool = True
    wireframe: bool = False
    background: tuple = (0.80, 0.84, 0.88)
    ground_colour: tuple = (0.42, 0.40, 0.36)
    ground_z: float | None = None
    light_dir: tuple = (0.35, -0.45, 0.82)
    light_colour: tuple = (1.0, 0.98, 0.92)
    sky_colour: tuple = (0.32, 0.36, 0.42)
    translucency: float = 0.65
    specular: float = 0.25
    shininess: float = 40.0
    vein_colours: tuple = ((1.0, 1.0, 1.0),) * 4
    vein_absolute: bool = False
    vein_width_scale: float = 1.0
    vein_min_px: float = 1.0
    vein_opacity: float = 1.0
    point_size: float = 4.0
    spring_colours: tuple = ((0.15, 0.45, 0.95), (0.95, 0.35, 0.15), (0.6, 0.6, 0.6), (0.1, 0.75, 0.2))
    colormap: str = "turbo"
    scalar_range: tuple | None = None
    wire_colour: tuple = (0.12, 0.2, 0.1)
    shadow_size: int = 1024
    ground_shadow_size: int = 256
    clear: bool = True

    @classmethod
    def of_params(cls, params, **kw) -> "RenderOptions":
        """The options the ``render.*`` parameters set (the window and rendered frames alike; they
        acted in the window only, a ``--set`` of them did nothing to ``run --every``'s frames):
        ``render.translucency`` (scaled so its default gives the default 0.65),
        ``render.specular`` and ``render.vein_alpha`` (the veins' opacity; hidden below 0.02),
        then ``kw``."""
        alpha = float(params["render.vein_alpha"])
        return replace(cls(), translucency=float(params["render.translucency"]) * TRANSLUCENCY_SCALE,
                       specular=float(params["render.specular"]), veins=alpha > 0.02, vein_opacity=alpha, **kw)

    @classmethod
    def coerce(cls, options) -> "RenderOptions":
        """Accept None, a RenderOptions or a dict of field values (unknown keys rejected)."""
        if options is None:
            return cls()
        if isinstance(options, cls):
            return options
        if isinstance(options, dict):
            known = {f.name for f in fields(cls)}
            bad = sorted(set(options) - known)
            if bad:
                raise LeafsimError(f"render options: unknown key {bad[0]!r} (known: {', '.join(sorted(known))})")
            opts = replace(cls(), **options)
        else:
            raise LeafsimError(f"render options: expected RenderOptions or dict, got {type(options).__name__}")
        return opts

    def check(self) -> None:
        if self.albedo not in ("auto", "colours", "texture", "detail"):
            raise LeafsimError(f"render options: albedo must be auto/colours/texture/detail, got {self.albedo!r}")
        if self.colormap not in ("turbo", "viridis"):
            raise LeafsimError(f"render options: colormap must be turbo or viridis, got {self.colormap!r}")

"""Side views of a leaf hanging from its petiole as it wilts and dries (docs/drying/wilting.png).

    python tools/wilting_pictures.py maple docs/drying/wilting.png material.turgor_share=0.8 material.stiffening_power=3

The leaf (draft quality, scene hanging) first settles under its weight with the drying off,
then dries to 0.5 % water and rests 300 frames; pictures of the settled fresh leaf, the
turgor-loss point (RWC 0.85), its lowest apex and the dried leaf, from one side camera.
Extra arguments are parameter overrides KEY=VALUE.  Prints the apex height / L at each.
"""
import sys

import cv2
import numpy as np

from leafsim.config.species import get_species
from leafsim.config.presets import QUALITY
from leafsim.pipeline import build_leaf
from leafsim.sim.simulator import Simulator
from leafsim.appearance.view import LeafView
from leafsim.render.offscreen import OffscreenRenderer, default_camera
from leafsim.render.options import RenderOptions
species = sys.argv[1]
extra = {}
for a in sys.argv[3:]:
    k, v = a.split("=", 1)
    try:
        extra[k] = float(v)
    except ValueError:
        extra[k] = v
sp = get_species(species)
p = sp.params.with_overrides({**QUALITY["draft"], "dynamics.scene": "hanging", **extra})
m = build_leaf(sp, p, 0).model
apex = int(np.argmax(m.particle_rest[:, 1]))
L = m.length
settle = Simulator(m, p.with_overrides({"effects.osmosis": False}))
st = settle.state()
for _ in range(600):
    settle.step(st)
snaps = [("fresh, settled", st.copy())]
sim = Simulator(m, p)
w0 = m.particle_water0.sum()
low, lowst, tlp = 9, None, None
while m.water_fraction(st.particle_water) > 0.005:
    sim.step(st)
    z = st.particle_q[apex, 2] / L
    if tlp is None and m.water_fraction(st.particle_water) <= 0.85:
        tlp = st.copy()
    if z < low:
        low, lowst = z, st.copy()
for _ in range(300):
    sim.step(st)
snaps += [("RWC 0.85", tlp), (f"lowest (RWC {m.water_fraction(lowst.particle_water):.2f})", lowst), ("dried", st.copy())]
for t, s in snaps:
    print(t, round(s.particle_q[apex, 2] / L, 3))
view = LeafView(m, None, snaps[0][1].pigments.copy())
r = OffscreenRenderer(480, 480)
allp = np.vstack([s.particle_q for _, s in snaps])
cam = default_camera(allp, pitch=5.0, yaw=0.0)
imgs = []
for t, s in snaps:
    img = r.render_array(view.mesh(s, p), camera=cam, options=RenderOptions(albedo="colours"))
    img = np.ascontiguousarray(img[..., :3][:, :, ::-1])
    cv2.putText(img, t, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 2)
    imgs.append(img)
cv2.imwrite(sys.argv[2], np.hstack(imgs))

"""Where a dried leaf's midrib fold sits: the curvature of the hinges on the midrib's edges
against the lamina's beside it, by direction, and cross-sections of the dried shape
(docs/drying/README.md, "Guo's midvein regime").

    .venv/bin/python tools/midrib_crease.py --species hornbeam --set mesh.spacing=0.0199 \\
        --set material.vein_modulus=5e9 --set shrink.sigma_vein=0.002 --set material.dry_stiffening=2 \\
        --set dynamics.integrator=static --set dynamics.static_every=32 [--npz OUT.npz]
    .venv/bin/python tools/midrib_crease.py --sections a.npz b.npz c.npz --png sections.png

Dries the leaf on the ground to 2 % of its water and on to 1.15 × that time (the protocol of
tools/drying_report.py) and prints one JSON line: the dried shape's measures
(leafsim.sim.curl), and the mean |dihedral angle| / spacing [°/mm] of the hinges on the
midrib's edges (in the middle half of the length) and of the lamina's hinges there whose edge
runs along the midrib (within 30°: the blade bends across it) or across it (bending along the
length).  A crease one element wide keeps its angle as the mesh refines; a curvature's angle
shrinks with the spacing.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.curl import dried_shape
from leafsim.sim.kernels.pbd import dihedral_angles
from leafsim.sim.run import Run

DRY, SETTLE = 0.02, 1.15


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def dry(species: str, overrides: dict) -> tuple:
    sp = get_species(species)
    p = sp.params.with_overrides({**overrides, "dynamics.scene": "ground"})
    _, _, m = build_leaf(sp, p, 0)
    run = Run(m, p, seed=0, name=species)
    st, t_dry = run.state, None

    def done(st) -> bool:
        nonlocal t_dry
        if t_dry is None and m.water_fraction(st.particle_water) < DRY:
            t_dry = st.time
        return t_dry is not None and st.time >= SETTLE * t_dry

    t0 = time.perf_counter()
    for _ in run.frames(until=done):
        pass
    return m, st, time.perf_counter() - t0


def crease(m, q: np.ndarray) -> dict:
    rest = m.particle_rest
    T = m.blade_T
    L = float(np.ptp(rest[T, 1]))
    y0 = rest[T, 1].min()
    a, b = m.hinge_idx[:, 2], m.hinge_idx[:, 3]
    mid = (m.particle_vein_order == 0) & T & (np.abs(rest[:, 0]) < 0.03 * L)
    ym = 0.5 * (rest[a, 1] + rest[b, 1])
    band = (ym > y0 + 0.25 * L) & (ym < y0 + 0.75 * L)
    on = mid[a] & mid[b] & band
    lam = band & ~on & T[a] & T[b] & T[m.hinge_idx[:, 0]] & T[m.hinge_idx[:, 1]]
    e = rest[b, :2] - rest[a, :2]
    e /= np.linalg.norm(e, axis=1)[:, None]
    ang = np.abs(np.degrees(dihedral_angles(q, m.hinge_idx)))
    mm = m.spacing * 1e3
    per_mm = lambda sel: round(float(ang[sel].mean() / mm), 3) if sel.any() else None  # noqa: E731
    return {"spacing_mm": round(mm, 3), "midrib_hinges": int(on.sum()),
            "midrib_deg_per_mm": per_mm(on),
            "lamina_across_midrib_deg_per_mm": per_mm(lam & (np.abs(e[:, 1]) > np.cos(np.pi / 6))),
            "lamina_along_length_deg_per_mm": per_mm(lam & (np.abs(e[:, 0]) > np.cos(np.pi / 6)))}


def sections(files: list[str], png: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharey=True)
    for frac, ax in zip((0.3, 0.5, 0.7), axes):
        for f in files:
            d = np.load(f)
            q, rest, L, y0 = d["q"], d["rest"], float(d["length"]), float(d["base"])
            near = np.abs(rest[:, 1] - (y0 + frac * L)) < 0.015 * L
            order = np.argsort(rest[near, 0])
            ax.plot(rest[near, 0][order] / L, q[near, 2][order] / L, ".", ms=3, label=str(d["label"]))
        ax.set_title(f"{frac:.0%} of the length from the base")
        ax.set_xlabel("rest x / L (midrib at 0)")
    axes[0].set_ylabel("height z / L")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--species", default="hornbeam")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--npz", help="save the dried positions here (for --sections)")
    ap.add_argument("--sections", nargs="+", metavar="NPZ", help="plot cross-sections of saved shapes and stop")
    ap.add_argument("--png", default="sections.png")
    args = ap.parse_args()
    if args.sections:
        sections(args.sections, args.png)
        return
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in args.set)}
    m, st, secs = dry(args.species, overrides)
    spacing = overrides.get("mesh.spacing", get_species(args.species).params["mesh.spacing"])
    q = st.particle_q
    out = {"species": args.species, "set": args.set, "particles": int(m.particle_count), "seconds": round(secs, 1),
           **dried_shape(m, st), **crease(m, q)}
    if args.npz:
        T = m.blade_T
        np.savez(args.npz, q=q, rest=m.particle_rest, length=float(np.ptp(m.particle_rest[T, 1])),
                 base=float(m.particle_rest[T, 1].min()), label=f"{spacing} L")
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""Where a dried leaf keeps its drying strain: the in-plane strain of the lamina and the veins
against the rest lengths the shrink has left them (docs/drying/README.md, "Where the dried blade
keeps its strain").

    .venv/bin/python tools/lamina_strain.py --species maple [--set mesh.spacing=0.0141] [--png map.png]

Dries the leaf on the ground to 2 % of its water and on to 1.15 × that time (the protocol of
tools/drying_report.py) and prints one JSON line:

* ``spring_strain``: percentiles (1, 10, 50, 90, 99) of length / rest length − 1 of the blade's
  layer-T surface springs, layer-V springs and vein springs, and the share compressed by more
  than 0.5 %;
* ``principal``: the smaller and larger principal stretch of every blade triangle of layer T
  against the triangle its three springs' current rest lengths make (1 = unstrained), split
  into the triangles between the veins (no vein particle) and those on a vein.

A thin sheet cannot carry compression: where the smaller stretch is below 1 a real lamina would
wrinkle, at whatever wavelength its stiffness sets, and the excess length is what the wrinkles
take up.  Where both stretches are at or above 1 the lamina is a drum between its veins.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from midrib_crease import _value, dry  # the same protocol and --set parsing (tools/ is on sys.path)

from leafsim.sim.model import SPRING_SURFACE, SPRING_V, SPRING_VEIN

PCT = (1, 10, 50, 90, 99)


def spring_strain(m, q: np.ndarray, rest: np.ndarray) -> dict:
    ij = m.spring_ij
    eps = np.linalg.norm(q[ij[:, 0]] - q[ij[:, 1]], axis=1) / rest - 1.0
    blade = m.blade_particles[ij].all(1)
    kinds = {"surface_T": (m.spring_type == SPRING_SURFACE) & (m.spring_layer == 0),
             "surface_V": m.spring_type == SPRING_V, "vein": m.spring_type == SPRING_VEIN}
    out = {}
    for name, sel in kinds.items():
        e = eps[sel & blade]
        out[name] = {"n": int(e.size), "pct": [round(100 * float(v), 2) for v in np.percentile(e, PCT)] if e.size else None,
                     "compressed": round(float(np.mean(e < -0.005)), 3) if e.size else None}
    return out


def principal_stretches(m, q: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(smaller, larger) principal stretch of each blade T triangle against the triangle of its
    springs' rest lengths, and the triangles kept (non-degenerate rest triangles)."""
    tri = m.blade_tri_T
    index = {(int(min(a, b)), int(max(a, b))): s for s, (a, b) in enumerate(m.spring_ij)}

    def rest_of(u, v):
        return rest[np.array([index[(min(x, y), max(x, y))] for x, y in zip(u.tolist(), v.tolist())])]

    a, b, c = tri.T
    lab, lbc, lca = rest_of(a, b), rest_of(b, c), rest_of(c, a)
    cx = (lab ** 2 + lca ** 2 - lbc ** 2) / (2.0 * lab)
    cy = np.sqrt(np.maximum(lca ** 2 - cx ** 2, 0.0))
    Dm = np.zeros((len(tri), 2, 2))
    Dm[:, 0, 0], Dm[:, 0, 1], Dm[:, 1, 1] = lab, cx, cy
    ok = np.abs(np.linalg.det(Dm)) > 1e-14
    Ds = np.stack([q[b] - q[a], q[c] - q[a]], 2)[ok]
    F = Ds @ np.linalg.inv(Dm[ok])
    w = np.linalg.eigvalsh(np.transpose(F, (0, 2, 1)) @ F)
    return np.sqrt(w[:, 0]), np.sqrt(w[:, 1]), ok


def principal(m, q: np.ndarray, rest: np.ndarray) -> dict:
    s1, s2, ok = principal_stretches(m, q, rest)
    on_vein = (m.particle_vein_order[m.blade_tri_T] >= 0).any(1)[ok]
    out = {}
    for name, sel in (("between_veins", ~on_vein), ("on_veins", on_vein)):
        if not sel.any():  # a coarse mesh may have no triangle off the veins
            out[name] = {"n": 0}
            continue
        out[name] = {"n": int(sel.sum()),
                     "smaller_pct": [round(float(v), 4) for v in np.percentile(s1[sel], PCT)],
                     "larger_pct": [round(float(v), 4) for v in np.percentile(s2[sel], PCT)],
                     "compressed_1pct": round(float(np.mean(s1[sel] < 0.99)), 3),
                     "drum": round(float(np.mean(s1[sel] >= 1.0)), 3)}
    return out


def picture(m, q: np.ndarray, rest: np.ndarray, png: str, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s1, _, ok = principal_stretches(m, q, rest)
    tri = m.blade_tri_T[ok]
    R = m.particle_rest[:, :2]
    fig, ax = plt.subplots(figsize=(7, 7))
    pc = ax.tripcolor(R[:, 0], R[:, 1], tri, facecolors=np.clip(1.0 - s1, 0.0, 0.1), cmap="magma_r", vmin=0, vmax=0.1)
    for k in range(len(m.vein_start) - 1):
        if m.vein_order[k] <= 1:
            idx = m.vein_particles[m.vein_start[k]:m.vein_start[k + 1]]
            ax.plot(R[idx, 0], R[idx, 1], "-", color="tab:green", lw=0.6)
    ax.set_aspect("equal")
    ax.set_axis_off()
    fig.colorbar(pc, ax=ax, shrink=0.7, label="compression: 1 − smaller principal stretch")
    ax.set_title(title, fontsize=9)
    fig.savefig(png, dpi=100, bbox_inches="tight")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--species", default="maple")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--png", help="map of the compression over the rest shape")
    args = ap.parse_args()
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in args.set)}
    m, st, secs = dry(args.species, overrides)
    q, rest = st.particle_q, st.spring_rest
    out = {"species": args.species, "set": args.set, "particles": int(m.particle_count), "seconds": round(secs, 1),
           "spring_strain": spring_strain(m, q, rest), "principal": principal(m, q, rest)}
    if args.png:
        picture(m, q, rest, args.png, f"{args.species} {' '.join(args.set)}: dried, ground")
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""How far a drying leaf's XPBD state lags its static equilibrium, and what a drying path on a
coarser mesh (two-grid) gives: the measurements behind docs/performance.md ("How far the
drying lags its equilibrium").

    python tools/equilibrium_lag.py lag maple fine                  # dry to 2 %, then 800 frames with and without drying
    python tools/equilibrium_lag.py direct maple fine fine.pkl      # the accuracy protocol's run, probe fields pickled
    python tools/equilibrium_lag.py twogrid maple draft 0.15 fine.pkl ref.pkl   # draft-mesh path to 15 % water

``lag``: the leaf at the defaults is dried to 2 % water; from that state it runs on twice,
800 frames each: with osmosis off (the shape creeps towards the equilibrium of that water
state) and on (the last water leaves).  ``twogrid``: the water, rest lengths and plastic
angles come from osmosis and shrink on the default mesh (no mechanics); the mechanics runs
on the coarse mesh of quality LEVEL until the default mesh is dry; its positions and
velocities are then carried to the default mesh by a moving-least-squares affine fit over
the 12 nearest coarse particles (a fixed sparse matrix from the rest positions), and the
default mesh runs the rest of the accuracy protocol (to 1.15 × the time to dry).  Both print
the probe scalars (leafsim.sim.metrics) and CPU seconds.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import scipy.sparse as sps
from scipy.spatial import cKDTree

from leafsim.config.presets import QUALITY
from leafsim.config.species import get_species
from leafsim.measure.accuracy import DRY_WATER, SETTLE
from leafsim.pipeline import build_leaf, leaf_shape
from leafsim.sim.metrics import Probe, field_errors
from leafsim.sim.run import Run


def prolongation(coarse, fine, k: int = 12) -> sps.csr_matrix:
    """(n_fine, n_coarse) matrix P with x_fine = P x_coarse: per fine particle the value at its
    rest position of the affine least-squares fit (Gaussian weights) over its k nearest coarse
    particles in the rest state (both layers, so the fit spans the thickness)."""
    Xc, Xf = coarse.particle_rest, fine.particle_rest
    d, idx = cKDTree(Xc).query(Xf, k=k)
    h = d[:, -1:] + 1e-12
    w = np.exp(-(d / (0.5 * h)) ** 2)
    vals = np.empty((len(Xf), k))
    for i in range(len(Xf)):
        A = np.column_stack([np.ones(k), (Xc[idx[i]] - Xf[i]) / h[i, 0]])
        AtW = A.T * w[i]
        vals[i] = np.linalg.solve(AtW @ A + 1e-9 * np.eye(4), AtW)[0]
    return sps.csr_matrix((vals.ravel(), (np.repeat(np.arange(len(Xf)), k), idx.ravel())), shape=(len(Xf), len(Xc)))


def _line(tag: str, f: dict, ref: dict | None, L: float, extra: str = "") -> str:
    s = f"{tag:34s} lift {f['margin_lift']:.4f}  3D {f['area_3d']:.4f}  top {f['area_top']:.4f}"
    if ref is not None:
        e = field_errors(f, ref, L)
        s += f"  | against {ref['_name']}: position {e['position_rms']:.4f} L, lift {e['r_margin_lift']:.3f}, top {e['r_area_top']:.3f}"
    return s + extra


def _dry(run: Run, w0: float) -> int:
    n = 0
    while run.model.water_fraction(run.state.particle_water) > DRY_WATER:
        run.step()
        n += 1
    return n


def lag(species: str, level: str, frames: int = 800) -> None:
    sp = get_species(species)
    base = sp.params.with_overrides({"effects.colour": False})
    p = base.with_overrides(QUALITY[level])
    m = build_leaf(sp, p, 0).model
    probe = Probe(leaf_shape(sp, base))
    w0 = float(m.particle_water0.sum())
    r = Run(m, p, seed=0)
    t0 = time.process_time()
    n = _dry(r, w0)
    f0 = dict(probe.fields(m, r.state), _name="the state at 2 %")
    print(_line(f"{level}, dry after {n} frames", f0, None, probe.length, f"  cpu {time.process_time() - t0:.1f} s"))
    for tag, over in (("drying stopped", {"effects.osmosis": False}), ("drying on", {})):
        st = r.state.copy()
        rr = Run(m, p.with_overrides(over), state=st, seed=0)
        for j in range(1, frames + 1):
            rr.step()
            if j % 100 == 0:
                print(_line(f"{tag} +{j} (water {st.particle_water.sum() / w0:.4f})", probe.fields(m, st), f0, probe.length))


def direct(species: str, level: str, out: str) -> None:
    """The accuracy protocol's run (dry to 2 %, on to 1.15 × that time) at quality ``level``
    (or ``reference``: leafsim accuracy's reference setting); probe fields pickled to ``out``."""
    import pickle

    from leafsim.measure.accuracy import reference_setting

    sp = get_species(species)
    base = sp.params.with_overrides({"effects.colour": False})
    over = reference_setting(base).overrides if level == "reference" else QUALITY[level]
    p = base.with_overrides(over)
    m = build_leaf(sp, p, 0).model
    probe = Probe(leaf_shape(sp, base))
    r = Run(m, p, seed=0)
    w0 = float(m.particle_water0.sum())
    t0 = time.process_time()
    n = _dry(r, w0)
    at_dry = probe.fields(m, r.state)
    cpu_dry = time.process_time() - t0
    for _ in range(int(np.ceil(SETTLE * n)) - n):
        r.step()
    end = probe.fields(m, r.state)
    cpu = time.process_time() - t0
    with open(out, "wb") as f:
        pickle.dump({"species": species, "level": level, "particles": m.particle_count, "dry_frames": n,
                     "cpu_dry": cpu_dry, "cpu": cpu, "dry": at_dry, "end": end}, f)
    print(_line(f"{level}: {m.particle_count} particles, cpu {cpu_dry:.0f} / {cpu:.0f} s", end, None, probe.length))


def _relative(f: dict, ref: dict, probe) -> str:
    """Position and height error relative to the reference's own deformation, as leafsim accuracy."""
    L = probe.length
    e = field_errors(f, ref, L)
    deform = float(np.sqrt(((ref["q_own"] - probe.rest3) ** 2).sum(1).mean())) / L
    height = float(np.sqrt(((ref["q"][:, 2] - ref["q"][:, 2].min()) ** 2).mean())) / L
    return (f"position {e['position_rms'] / deform:.1%}, height {e['height_rms'] / height:.1%}, "
            f"lift {e['r_margin_lift']:.1%}, 3D {e['r_area_3d']:.1%}, top {e['r_area_top']:.1%}")


def twogrid(species: str, level: str, handover: float = DRY_WATER, against=()) -> None:
    """Mechanics on the ``level`` mesh until the default mesh's water falls to ``handover``,
    then on the default mesh to the protocol's end; errors against the pickled runs of
    :func:`direct` (``against``: paths)."""
    import pickle

    sp = get_species(species)
    base = sp.params.with_overrides({"effects.colour": False})
    pc = base.with_overrides(QUALITY[level])
    mc, mf = build_leaf(sp, pc, 0).model, build_leaf(sp, base, 0).model
    probe = Probe(leaf_shape(sp, base))
    refs = []
    for path in against:
        with open(path, "rb") as f:
            refs.append(pickle.load(f))
    P = prolongation(mc, mf)
    w0 = float(mf.particle_water0.sum())
    rf = Run(mf, base, effects=["osmosis", "shrink"], seed=0)
    rc = Run(mc, pc, seed=0)
    t0 = time.process_time()
    n = 0
    while mf.water_fraction(rf.state.particle_water) > handover:
        rf.step()
        rc.step()
        n += 1
    t_path = time.process_time() - t0
    st = rf.state
    st.particle_q[:] = P @ rc.state.particle_q
    st.particle_qd[:] = P @ rc.state.particle_qd
    run = Run(mf, base, state=st, seed=0)
    t0 = time.process_time()
    while mf.water_fraction(st.particle_water) > DRY_WATER:
        run.step()
    n_dry = st.frame
    at_dry, t_dry = probe.fields(mf, st), time.process_time() - t0
    for _ in range(int(np.ceil(SETTLE * n_dry)) - n_dry):
        run.step()
    end, t_end = probe.fields(mf, st), time.process_time() - t0
    print(f"{species}: path on the {level} mesh for {n} frames (water {handover:g}), {t_path:.1f} s; "
          f"default mesh to dry (frame {n_dry}) {t_dry:.1f} s, to the protocol end {t_end:.1f} s")
    print(_line("two-grid at dry", at_dry, None, probe.length) + f"  cpu {t_path + t_dry:.1f} s")
    print(_line("two-grid at the protocol end", end, None, probe.length) + f"  cpu {t_path + t_end:.1f} s")
    for ref in refs:
        print(f"  against {ref['level']} at dry ({ref['cpu_dry']:.0f} s): {_relative(at_dry, ref['dry'], probe)}")
        print(f"  against {ref['level']} at the end ({ref['cpu']:.0f} s): {_relative(end, ref['end'], probe)}")


if __name__ == "__main__":
    a = sys.argv[1:]
    if len(a) >= 3 and a[0] == "lag":
        lag(a[1], a[2])
    elif len(a) == 4 and a[0] == "direct":
        direct(a[1], a[2], a[3])
    elif len(a) >= 3 and a[0] == "twogrid":
        twogrid(a[1], a[2], float(a[3]) if len(a) > 3 else DRY_WATER, a[4:])
    else:
        sys.exit("usage: python tools/equilibrium_lag.py lag SPECIES LEVEL | direct SPECIES LEVEL OUT.pkl | "
                 "twogrid SPECIES LEVEL [HANDOVER_WATER [RUN.pkl ...]]")

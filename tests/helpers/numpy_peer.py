"""A stand-in peer engine for the spring race (:mod:`leafsim.measure.peers`), so that the
bench's peer plumbing is tested where warp and Taichi are not installed: a numpy coloured
Gauss–Seidel sweep following the peers' protocol — float32, the bench's own springs and colour
order, ``Peer(q0, ij, rec, colour_start)`` with ``reset()``, ``run(npass)`` and ``positions()``.
A colour's springs share no particle, so one colour projects as one vectorised step and the
sweep is the serial one's up to float32 round-off."""

from __future__ import annotations

import numpy as np


class Peer:
    def __init__(self, q0, ij, rec, colour_start):
        self.q0 = np.ascontiguousarray(q0, np.float32)
        self.q = self.q0.copy()
        self.ij = np.ascontiguousarray(ij, np.int64)
        self.rec = np.ascontiguousarray(rec, np.float32)
        self.lam = np.zeros(len(ij), np.float32)
        self.cs = [int(c) for c in colour_start]

    def reset(self):
        self.q[:] = self.q0
        self.lam[:] = 0.0

    def run(self, npass):
        q, lam = self.q, self.lam
        for _ in range(npass):
            for lo, hi in zip(self.cs[:-1], self.cs[1:]):
                a, b, r = self.ij[lo:hi, 0], self.ij[lo:hi, 1], self.rec[lo:hi]
                d = q[a] - q[b]
                ln = np.sqrt((d * d).sum(1))
                ok = ln >= 1e-12
                dl = np.where(ok, (r[:, 0] - ln - r[:, 1] * lam[lo:hi]) * r[:, 2], np.float32(0.0))
                lam[lo:hi] += dl
                f = d * (dl / np.where(ok, ln, np.float32(1.0)))[:, None]
                q[a] += f * r[:, 3:4]
                q[b] -= f * r[:, 4:5]

    def positions(self):
        return self.q.astype(np.float64)

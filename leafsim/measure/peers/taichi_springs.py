"""Taichi on the CPU: one kernel per pass, the sweep serialised (Gauss–Seidel in colour order,
like ours; taichi would otherwise run the outermost loop's iterations in parallel), float32.
No ``from __future__ import annotations`` here: taichi reads the annotations as types."""


import numpy as np
import taichi as ti

ti.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.WARN)


@ti.kernel
def _passes(q: ti.types.ndarray(dtype=ti.f32, ndim=2), ij: ti.types.ndarray(dtype=ti.i32, ndim=2),
            rec: ti.types.ndarray(dtype=ti.f32, ndim=2), lam: ti.types.ndarray(dtype=ti.f32, ndim=1), npass: ti.i32):
    ti.loop_config(serialize=True)
    for _ in range(npass):
        for s in range(ij.shape[0]):
            a = ij[s, 0]
            b = ij[s, 1]
            d = ti.Vector([q[a, 0] - q[b, 0], q[a, 1] - q[b, 1], q[a, 2] - q[b, 2]])
            ln = d.norm()
            if ln >= 1.0e-12:
                dl = (rec[s, 0] - ln - rec[s, 1] * lam[s]) * rec[s, 2]
                lam[s] += dl
                f = d * (dl / ln)
                for k in ti.static(range(3)):
                    q[a, k] += f[k] * rec[s, 3]
                    q[b, k] -= f[k] * rec[s, 4]


class Peer:
    def __init__(self, q0, ij, rec, colour_start):
        self.q0 = np.ascontiguousarray(q0, np.float32)
        self.q = self.q0.copy()
        self.ij = np.ascontiguousarray(ij, np.int32)
        self.rec = np.ascontiguousarray(rec, np.float32)
        self.lam = np.zeros(len(ij), np.float32)

    def reset(self):
        self.q[:] = self.q0
        self.lam[:] = 0.0

    def run(self, npass):
        _passes(self.q, self.ij, self.rec, self.lam, npass)
        ti.sync()

    def positions(self):
        return self.q.astype(np.float64)

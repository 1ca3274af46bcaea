"""NVIDIA warp on the CPU: one kernel launch per colour per pass (warp's own way of running a
coloured Gauss–Seidel sweep), float32 vec3 positions."""


import numpy as np
import warp as wp

wp.config.quiet = True
wp.init()


@wp.kernel
def _colour(q: wp.array(dtype=wp.vec3), ij: wp.array2d(dtype=wp.int32), rec: wp.array2d(dtype=wp.float32),
            lam: wp.array(dtype=wp.float32), lo: int):
    s = lo + wp.tid()
    a = ij[s, 0]
    b = ij[s, 1]
    d = q[a] - q[b]
    ln = wp.length(d)
    if ln < 1.0e-12:
        return
    dl = (rec[s, 0] - ln - rec[s, 1] * lam[s]) * rec[s, 2]
    lam[s] = lam[s] + dl
    f = d * (dl / ln)
    q[a] = q[a] + f * rec[s, 3]
    q[b] = q[b] - f * rec[s, 4]


class Peer:
    def __init__(self, q0, ij, rec, colour_start):
        self.q0 = np.ascontiguousarray(q0, np.float32)
        self.q = wp.array(self.q0, dtype=wp.vec3, device="cpu")
        self.ij = wp.array(np.ascontiguousarray(ij, np.int32), dtype=wp.int32, device="cpu")
        self.rec = wp.array(np.ascontiguousarray(rec, np.float32), dtype=wp.float32, device="cpu")
        self.lam = wp.zeros(len(ij), dtype=wp.float32, device="cpu")
        self.cs = [int(c) for c in colour_start]

    def reset(self):
        self.q.numpy()[:] = self.q0
        self.lam.zero_()

    def run(self, npass):
        for _ in range(npass):
            for lo, hi in zip(self.cs[:-1], self.cs[1:]):
                wp.launch(_colour, dim=hi - lo, inputs=[self.q, self.ij, self.rec, self.lam, lo], device="cpu")
        wp.synchronize_device("cpu")

    def positions(self):
        return self.q.numpy().astype(np.float64)

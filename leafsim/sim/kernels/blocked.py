"""The production bending and thickness projections, in blocks the CPU runs 8 at a time.

No two constraints of one graph colour share a particle, so the constraints of a colour can
be projected in any order, or all at once.  Each kernel here walks its constraints in
*blocks* of at most :data:`BLOCK` that never cross a colour boundary (:func:`block_starts`),
and each block takes three loops:

1. **gather** (scalar): the particles' coordinate differences and the Lagrange multipliers
   into a small structure-of-arrays buffer ``B`` (one field every :data:`BLOCK` doubles);
2. **compute** (SIMD): the projection itself — normals, angle, gradients, XPBD step, step
   limit — on ``B`` and the per-frame record (rest value, compliance, inverse masses; one
   row per field, :func:`pack_hinges`), written without branches (a degenerate constraint
   takes a zero step through selects), so LLVM vectorises it: 8 doubles per AVX-512
   instruction, 4 with AVX2;
3. **scatter** (scalar): the displacements added to the particles, the multipliers written
   back, the largest change kept.

Every lane does exactly the operations of the one-at-a-time kernel (:mod:`.scalar`) in the
same order (no reassociation, no FMA contraction: :data:`~leafsim.sim.kernels.FASTMATH`), so
the results are bit-identical to it (tests/test_kernels.py), on any CPU, vectorised or not.
Measured on the bench leaf (docs/performance.md): a hinge 43 → 21 ns, a volume 19 → 15 ns.
Springs stay one at a time (:func:`~leafsim.sim.kernels.scalar.spring_pass`): their
projection is one square root and one division between two gathers, and the blocked spring
kernel measured the same 8–9 ns.

The compute loop touches only ``B`` (fields at compile-time-constant offsets, which need no
overlap check) and the record: with one array per field LLVM has to check at run time that
the arrays do not overlap, and above 8 such checks it gives up ("too many memory checks
needed").  ``error_model="numpy"`` drops Python's division-by-zero checks, whose branches
are early exits the vectoriser refuses (every division here is guarded)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from leafsim.sim.kernels import FASTMATH
from leafsim.sim.kernels.scalar import atan2_

#: constraints per block: 32 measured fastest against 16 / 64 / 128 on the bench leaf (a
#: block's buffer, 23 × 32 doubles, stays in L1 next to the particles it touches)
BLOCK = 32
#: fields of the block buffer (hinges: 9 differences, λ, 12 displacements, the change²)
FIELDS = 23


def block_starts(colour_start: np.ndarray, size: int = BLOCK) -> np.ndarray:
    """int64 offsets of blocks of at most ``size`` ≤ :data:`BLOCK` constraints that never cross
    a colour: block k is [starts[k], starts[k + 1])."""
    if not 0 < size <= BLOCK:
        raise ValueError(f"block size {size}: expected 1 … {BLOCK} (the buffer's field stride)")
    cs = np.asarray(colour_start, np.int64)
    parts = [np.arange(a, b, size, dtype=np.int64) for a, b in zip(cs[:-1], cs[1:]) if b > a]
    return np.concatenate(parts + [cs[-1:]]) if parts else cs[-1:].copy()


def block_buffer() -> np.ndarray:
    """A scratch buffer every blocked kernel can use."""
    return np.zeros(FIELDS * BLOCK)


# ----------------------------------------------------------------------------- per-frame records
@njit(cache=True, nogil=True, fastmath=FASTMATH)
def pack_hinges(hidx, invm, hrest, halpha, hrec):
    """hrec[:, e] = (rest angle, compliance / Δt², w1, w2, w3, w4) of one frame: (6, h), one
    row per field, so a block reads each field as one contiguous vector."""
    for e in range(hidx.shape[0]):
        hrec[0, e] = hrest[e]
        hrec[1, e] = halpha[e]
        for k in range(4):
            hrec[2 + k, e] = invm[hidx[e, k]]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def pack_volumes(vidx, invm, vrest, vrec):
    """vrec[:, t] = (6 × rest volume, w_v, w_a, w_b, w_c) of one frame: (5, m), one row per
    field."""
    for t in range(vidx.shape[0]):
        vrec[0, t] = vrest[t]
        for k in range(4):
            vrec[1 + k, t] = invm[vidx[t, k]]


# ----------------------------------------------------------------------------- hinges
# B fields: 0–2 e = x4 − x3; 3–5 a = x1 − x3; 6–8 c = x2 − x4; 9 λ; 10–21 Δx1…Δx4; 22 the
# change²; the record R (:func:`pack_hinges`) is read in place
@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _hinge_block(B, R, lo, omega, n):
    for k in range(n):
        e = lo + k
        ex = B[k]; ey = B[BLOCK + k]; ez = B[2 * BLOCK + k]
        ax = B[3 * BLOCK + k]; ay = B[4 * BLOCK + k]; az = B[5 * BLOCK + k]
        cx = B[6 * BLOCK + k]; cy = B[7 * BLOCK + k]; cz = B[8 * BLOCK + k]
        ha = R[1, e]
        w1 = R[2, e]; w2 = R[3, e]; w3 = R[4, e]; w4 = R[5, e]
        n1x = ey * az - ez * ay; n1y = ez * ax - ex * az; n1z = ex * ay - ey * ax
        n2x = cy * ez - cz * ey; n2y = cz * ex - cx * ez; n2z = cx * ey - cy * ex
        el2 = ex * ex + ey * ey + ez * ez
        l1 = n1x * n1x + n1y * n1y + n1z * n1z
        l2 = n2x * n2x + n2y * n2y + n2z * n2z
        ok = (el2 >= 1e-24) & (l1 >= 1e-30) & (l2 >= 1e-30)
        el2 = el2 if ok else 1.0
        l1 = l1 if ok else 1.0
        l2 = l2 if ok else 1.0
        el = math.sqrt(el2)
        C = atan2_(el * (n2x * ax + n2y * ay + n2z * az), n1x * n2x + n1y * n2y + n1z * n2z) - R[0, e]
        C = C - 2 * math.pi if C > math.pi else C
        C = C + 2 * math.pi if C < -math.pi else C
        il1 = 1.0 / l1
        il2 = 1.0 / l2
        iel = 1.0 / el
        g1 = el * il1
        g2 = el * il2
        p1 = (ax * ex + ay * ey + az * ez - el2) * iel * il1  # (x1 − x4)·e / |e| / |n1|²
        p2 = (cx * ex + cy * ey + cz * ez) * iel * il2  # (x2 − x4)·e / |e| / |n2|²
        u3x = p1 * n1x + p2 * n2x; u3y = p1 * n1y + p2 * n2y; u3z = p1 * n1z + p2 * n2z
        u4x = -(g1 * n1x + g2 * n2x + u3x); u4y = -(g1 * n1y + g2 * n2y + u3y); u4z = -(g1 * n1z + g2 * n2z + u3z)
        s1 = el2 * il1  # |u1|²
        s2 = el2 * il2
        s3 = u3x * u3x + u3y * u3y + u3z * u3z
        s4 = u4x * u4x + u4y * u4y + u4z * u4z
        W = w1 * s1 + w2 * s2 + w3 * s3 + w4 * s4 + ha
        ok = ok & (W > 0.0)
        W = W if ok else 1.0
        dl = omega * (-C - ha * B[9 * BLOCK + k]) / W
        m12 = max(w1 * w1 * s1, w2 * w2 * s2)
        gm2 = max(m12, max(w3 * w3 * s3, w4 * w4 * s4))
        lim = dl * dl * gm2 > 0.25 * el2  # gm2 > 0 where true
        dl = math.copysign(0.5 * el / math.sqrt(gm2 if lim else 1.0), dl) if lim else dl
        dl = dl if ok else 0.0
        B[9 * BLOCK + k] += dl
        f1 = w1 * dl * g1; f2 = w2 * dl * g2; f3 = w3 * dl; f4 = w4 * dl
        B[10 * BLOCK + k] = f1 * n1x; B[11 * BLOCK + k] = f1 * n1y; B[12 * BLOCK + k] = f1 * n1z
        B[13 * BLOCK + k] = f2 * n2x; B[14 * BLOCK + k] = f2 * n2y; B[15 * BLOCK + k] = f2 * n2z
        B[16 * BLOCK + k] = f3 * u3x; B[17 * BLOCK + k] = f3 * u3y; B[18 * BLOCK + k] = f3 * u3z
        B[19 * BLOCK + k] = f4 * u4x; B[20 * BLOCK + k] = f4 * u4y; B[21 * BLOCK + k] = f4 * u4z
        B[22 * BLOCK + k] = dl * dl * m12


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def hinges_blocked(q, hidx, hrec, hlam, omega, blocks, B):
    """One pass over the bending hinges (records of :func:`pack_hinges`), over-relaxed by
    ``omega``, block by block; returns the largest |Δx|.  Bit-identical to
    :func:`~leafsim.sim.kernels.scalar.hinge_pass`, whose docstring derives the formulas."""
    big2 = 0.0
    for b in range(blocks.shape[0] - 1):
        lo = blocks[b]
        n = blocks[b + 1] - lo
        for k in range(n):
            e = lo + k
            i1 = hidx[e, 0]; i2 = hidx[e, 1]; i3 = hidx[e, 2]; i4 = hidx[e, 3]
            B[k] = q[i4, 0] - q[i3, 0]; B[BLOCK + k] = q[i4, 1] - q[i3, 1]; B[2 * BLOCK + k] = q[i4, 2] - q[i3, 2]
            B[3 * BLOCK + k] = q[i1, 0] - q[i3, 0]; B[4 * BLOCK + k] = q[i1, 1] - q[i3, 1]
            B[5 * BLOCK + k] = q[i1, 2] - q[i3, 2]
            B[6 * BLOCK + k] = q[i2, 0] - q[i4, 0]; B[7 * BLOCK + k] = q[i2, 1] - q[i4, 1]
            B[8 * BLOCK + k] = q[i2, 2] - q[i4, 2]
            B[9 * BLOCK + k] = hlam[e]
        _hinge_block(B, hrec, lo, omega, n)
        for k in range(n):
            e = lo + k
            i1 = hidx[e, 0]; i2 = hidx[e, 1]; i3 = hidx[e, 2]; i4 = hidx[e, 3]
            q[i1, 0] += B[10 * BLOCK + k]; q[i1, 1] += B[11 * BLOCK + k]; q[i1, 2] += B[12 * BLOCK + k]
            q[i2, 0] += B[13 * BLOCK + k]; q[i2, 1] += B[14 * BLOCK + k]; q[i2, 2] += B[15 * BLOCK + k]
            q[i3, 0] += B[16 * BLOCK + k]; q[i3, 1] += B[17 * BLOCK + k]; q[i3, 2] += B[18 * BLOCK + k]
            q[i4, 0] += B[19 * BLOCK + k]; q[i4, 1] += B[20 * BLOCK + k]; q[i4, 2] += B[21 * BLOCK + k]
            hlam[e] = B[9 * BLOCK + k]
            if B[22 * BLOCK + k] > big2:
                big2 = B[22 * BLOCK + k]
    return math.sqrt(big2)


# ----------------------------------------------------------------------------- thickness volumes
# B fields: 0–2 b = x_b − x_a; 3–5 c = x_c − x_a; 6–8 v = x_v − x_a; 9–20 Δx_v, Δx_a, Δx_b,
# Δx_c; 21 the change²; the record R (:func:`pack_volumes`) is read in place
@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _volume_block(B, R, lo, n):
    for k in range(n):
        t = lo + k
        bx = B[k]; by = B[BLOCK + k]; bz = B[2 * BLOCK + k]
        cx = B[3 * BLOCK + k]; cy = B[4 * BLOCK + k]; cz = B[5 * BLOCK + k]
        vx = B[6 * BLOCK + k]; vy = B[7 * BLOCK + k]; vz = B[8 * BLOCK + k]
        wv = R[1, t]; wa = R[2, t]; wb = R[3, t]; wc = R[4, t]
        gvx = by * cz - bz * cy; gvy = bz * cx - bx * cz; gvz = bx * cy - by * cx
        gbx = cy * vz - cz * vy; gby = cz * vx - cx * vz; gbz = cx * vy - cy * vx
        gcx = vy * bz - vz * by; gcy = vz * bx - vx * bz; gcz = vx * by - vy * bx
        gax = -(gvx + gbx + gcx); gay = -(gvy + gby + gcy); gaz = -(gvz + gbz + gcz)
        C = vx * gvx + vy * gvy + vz * gvz - R[0, t]
        sv = gvx * gvx + gvy * gvy + gvz * gvz
        sa = gax * gax + gay * gay + gaz * gaz
        sb = gbx * gbx + gby * gby + gbz * gbz
        sc = gcx * gcx + gcy * gcy + gcz * gcz
        W = wv * sv + wa * sa + wb * sb + wc * sc
        ok = W > 1e-300
        W = W if ok else 1.0
        dl = -C / W
        gm2 = max(max(wv * wv * sv, wa * wa * sa), max(wb * wb * sb, wc * wc * sc))
        lim2 = 0.25 * math.sqrt((bx * bx + by * by + bz * bz) * (cx * cx + cy * cy + cz * cz))
        lim = dl * dl * gm2 > lim2  # gm2 > 0 where true
        dl = math.copysign(math.sqrt(lim2 / (gm2 if lim else 1.0)), dl) if lim else dl
        dl = dl if ok else 0.0
        fv = wv * dl; fa = wa * dl; fb = wb * dl; fc = wc * dl
        B[9 * BLOCK + k] = fv * gvx; B[10 * BLOCK + k] = fv * gvy; B[11 * BLOCK + k] = fv * gvz
        B[12 * BLOCK + k] = fa * gax; B[13 * BLOCK + k] = fa * gay; B[14 * BLOCK + k] = fa * gaz
        B[15 * BLOCK + k] = fb * gbx; B[16 * BLOCK + k] = fb * gby; B[17 * BLOCK + k] = fb * gbz
        B[18 * BLOCK + k] = fc * gcx; B[19 * BLOCK + k] = fc * gcy; B[20 * BLOCK + k] = fc * gcz
        B[21 * BLOCK + k] = dl * dl * wv * wv * sv


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def volumes_blocked(q, vidx, vrec, blocks, B):
    """One pass over the thickness constraints (records of :func:`pack_volumes`), block by
    block; returns the largest |Δx|.  Bit-identical to
    :func:`~leafsim.sim.kernels.scalar.volume_pass`."""
    big2 = 0.0
    for b in range(blocks.shape[0] - 1):
        lo = blocks[b]
        n = blocks[b + 1] - lo
        for k in range(n):
            t = lo + k
            iv = vidx[t, 0]; ia = vidx[t, 1]; ib = vidx[t, 2]; ic = vidx[t, 3]
            B[k] = q[ib, 0] - q[ia, 0]; B[BLOCK + k] = q[ib, 1] - q[ia, 1]; B[2 * BLOCK + k] = q[ib, 2] - q[ia, 2]
            B[3 * BLOCK + k] = q[ic, 0] - q[ia, 0]; B[4 * BLOCK + k] = q[ic, 1] - q[ia, 1]
            B[5 * BLOCK + k] = q[ic, 2] - q[ia, 2]
            B[6 * BLOCK + k] = q[iv, 0] - q[ia, 0]; B[7 * BLOCK + k] = q[iv, 1] - q[ia, 1]
            B[8 * BLOCK + k] = q[iv, 2] - q[ia, 2]
        _volume_block(B, vrec, lo, n)
        for k in range(n):
            t = lo + k
            iv = vidx[t, 0]; ia = vidx[t, 1]; ib = vidx[t, 2]; ic = vidx[t, 3]
            q[iv, 0] += B[9 * BLOCK + k]; q[iv, 1] += B[10 * BLOCK + k]; q[iv, 2] += B[11 * BLOCK + k]
            q[ia, 0] += B[12 * BLOCK + k]; q[ia, 1] += B[13 * BLOCK + k]; q[ia, 2] += B[14 * BLOCK + k]
            q[ib, 0] += B[15 * BLOCK + k]; q[ib, 1] += B[16 * BLOCK + k]; q[ib, 2] += B[17 * BLOCK + k]
            q[ic, 0] += B[18 * BLOCK + k]; q[ic, 1] += B[19 * BLOCK + k]; q[ic, 2] += B[20 * BLOCK + k]
            if B[21 * BLOCK + k] > big2:
                big2 = B[21 * BLOCK + k]
    return math.sqrt(big2)


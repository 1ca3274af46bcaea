"""Real inertia for the leaf's rigid motion under ``dynamics.mass_scaling`` (selective mass
scaling, ``dynamics.rigid_inertia``).

The inertia scaling (mass × M, gravity ÷ M) converges the quasi-static drying, but it slows
*every* motion √M-fold, a falling or swinging leaf included.  Selective mass scaling (Olovsson
et al. 2005, "Selective mass scaling for explicit finite element analyses", IJNME 63:1436)
scales only the deformation modes and keeps the real mass on the rigid-body modes:

    M_eff = M·D (I − P) + D P,      P = U (Uᵀ D U)⁻¹ Uᵀ D,

with D the real lumped masses and U the rigid modes (three translations and three rotations
about the centre of mass; for a leaf pinned at its stalk, the three rotations about the pin).
The static forces are the same under any mass matrix, so the equilibrium shapes the drying
converges to do not change.

The Gauss–Seidel substep runs with the uniform scaling as before; this kernel then adds what
the rigid modes are missing.  In one substep the scaled leaf's rigid velocity changes by the
rigid part of the *compliant* impulses (gravity, and for a pinned leaf the elastic moment the
stalk carries about the pin) divided by M; the real leaf's changes M times as much.  So the
kernel measures that change from the substep's displacements, adds (M − 1) times it to every
particle's velocity and the same times h to its position (x_new = x_old + h v_new stays
exact), and rescales the rigid part of the velocity from the internal damping to the air's
(``dynamics.air_damping``).  Hard constraints (the ground, the pins themselves) are not
scaled: their impulses stop a motion whatever its mass.

* Free body (``mode`` 1, the ground and free scenes): with the momentum-conserving substep
  (:func:`~.pbd.remove_rigid`) the internal forces carry no net impulse, so the missing part is
  gravity's alone: (1 − 1/M) g h on every particle.  A leaf that touches the ground is left
  as it is (its contacts hold the weight; tipping over and sliding stay √M slower): only a leaf
  in the air falls at its real speed.
* Pinned (``mode`` 2, the hanging scene): rotations about the pin, driven by the moment of
  gravity and of the internal displacements ``dint`` (the stalk's elastic moment): a leaf
  released beside its pin swings down in its real period, and at rest (no net moment) nothing
  changes.
"""

from __future__ import annotations

import math

from numba import njit

from leafsim.sim.kernels import FASTMATH


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _solve3(a00, a01, a02, a11, a12, a22, bx, by, bz):
    """x = A⁻¹ b for the symmetric 3 × 3 A (adjugate / determinant); zeros when singular."""
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    if abs(det) < 1e-300:
        return 0.0, 0.0, 0.0
    return ((c00 * bx + c01 * by + c02 * bz) / det, (c01 * bx + c11 * by + c12 * bz) / det,
            (c02 * bx + c12 * by + c22 * bz) / det)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def rigid_inertia(q, qd, invm, dint, h, gz, mode, px, py, pz, gain, kratio, ground, eps):
    """After one scaled substep (velocities already updated): give the rigid modes their real
    inertia.  ``gz`` the scaled gravity (−g / M), ``gain`` = M − 1, ``kratio`` the air's
    velocity factor over the internal damping's for one substep, (px, py, pz) the pin
    (``mode`` 2).  With ``ground`` a free body any of whose particles is within ``eps`` of the
    ground is left alone.  Returns 1 when it changed the state, else 0."""
    n = q.shape[0]
    M = 0.0
    cx = 0.0; cy = 0.0; cz = 0.0
    vx = 0.0; vy = 0.0; vz = 0.0
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        if mode == 1 and ground and q[i, 2] <= eps:
            return 0
        m = 1.0 / invm[i]
        M += m
        cx += m * q[i, 0]; cy += m * q[i, 1]; cz += m * q[i, 2]
        vx += m * qd[i, 0]; vy += m * qd[i, 1]; vz += m * qd[i, 2]
    if M <= 0.0:
        return 0
    cx /= M; cy /= M; cz /= M
    vx /= M; vy /= M; vz /= M
    if mode == 2:  # rotations about the pin: no translation
        cx = px; cy = py; cz = pz
        vx = 0.0; vy = 0.0; vz = 0.0
    # angular momentum of the velocity (and, pinned, of the compliant displacement) about c
    Lx = 0.0; Ly = 0.0; Lz = 0.0
    Dx = 0.0; Dy = 0.0; Dz = 0.0
    Ixx = 0.0; Iyy = 0.0; Izz = 0.0; Ixy = 0.0; Ixz = 0.0; Iyz = 0.0
    gd = gz * h * h
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        m = 1.0 / invm[i]
        rx = q[i, 0] - cx; ry = q[i, 1] - cy; rz = q[i, 2] - cz
        ux = qd[i, 0] - vx; uy = qd[i, 1] - vy; uz = qd[i, 2] - vz
        Lx += m * (ry * uz - rz * uy); Ly += m * (rz * ux - rx * uz); Lz += m * (rx * uy - ry * ux)
        if mode == 2:
            dx = dint[i, 0]; dy = dint[i, 1]; dz = dint[i, 2] + gd
            Dx += m * (ry * dz - rz * dy); Dy += m * (rz * dx - rx * dz); Dz += m * (rx * dy - ry * dx)
        Ixx += m * (ry * ry + rz * rz); Iyy += m * (rx * rx + rz * rz); Izz += m * (rx * rx + ry * ry)
        Ixy -= m * rx * ry; Ixz -= m * rx * rz; Iyz -= m * ry * rz
    wx, wy, wz = _solve3(Ixx, Ixy, Ixz, Iyy, Iyz, Izz, Lx, Ly, Lz)       # the rigid part of v
    ex = 0.0; ey = 0.0; ez = 0.0                                          # extra translation
    ox = 0.0; oy = 0.0; oz = 0.0                                          # extra rotation
    if mode == 1:
        ez = gain * gz * h
    else:
        ox, oy, oz = _solve3(Ixx, Ixy, Ixz, Iyy, Iyz, Izz, Dx, Dy, Dz)
        ox *= gain / h; oy *= gain / h; oz *= gain / h
    k1 = kratio - 1.0
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        rx = q[i, 0] - cx; ry = q[i, 1] - cy; rz = q[i, 2] - cz
        # the extra velocity (also moves the particle) and the damping's correction (does not)
        fx = ex + oy * rz - oz * ry
        fy = ey + oz * rx - ox * rz
        fz = ez + ox * ry - oy * rx
        qd[i, 0] += fx + k1 * (vx + wy * rz - wz * ry)
        qd[i, 1] += fy + k1 * (vy + wz * rx - wx * rz)
        qd[i, 2] += fz + k1 * (vz + wx * ry - wy * rx)
        q[i, 0] += h * fx
        q[i, 1] += h * fy
        q[i, 2] += h * fz
    return 1


def air_factor(rate: float, damping_rate: float, h: float) -> float:
    """The rigid velocity's factor that turns the internal damping of one substep into the
    air's: e^(−rate·h) / e^(−damping_rate·h)."""
    return math.exp(-(rate - damping_rate) * h)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def momenta_sums(mass, q, qd, out):
    """The watchdog's sums in two passes: out = (M, centre of mass (3), mean velocity (3),
    angular momentum about the centre of mass (3), its inertia tensor xx, yy, zz, xy, xz, yz,
    kinetic energy) (float64[17])."""
    M = 0.0
    cx = cy = cz = vx = vy = vz = ke = 0.0
    for i in range(q.shape[0]):
        m = mass[i]
        M += m
        cx += m * q[i, 0]
        cy += m * q[i, 1]
        cz += m * q[i, 2]
        vx += m * qd[i, 0]
        vy += m * qd[i, 1]
        vz += m * qd[i, 2]
        ke += m * (qd[i, 0] * qd[i, 0] + qd[i, 1] * qd[i, 1] + qd[i, 2] * qd[i, 2])
    cx /= M
    cy /= M
    cz /= M
    vx /= M
    vy /= M
    vz /= M
    lx = ly = lz = ixx = iyy = izz = ixy = ixz = iyz = 0.0
    for i in range(q.shape[0]):
        m = mass[i]
        r0 = q[i, 0] - cx
        r1 = q[i, 1] - cy
        r2 = q[i, 2] - cz
        u0 = qd[i, 0] - vx
        u1 = qd[i, 1] - vy
        u2 = qd[i, 2] - vz
        lx += m * (r1 * u2 - r2 * u1)
        ly += m * (r2 * u0 - r0 * u2)
        lz += m * (r0 * u1 - r1 * u0)
        ixx += m * (r1 * r1 + r2 * r2)
        iyy += m * (r0 * r0 + r2 * r2)
        izz += m * (r0 * r0 + r1 * r1)
        ixy -= m * r0 * r1
        ixz -= m * r0 * r2
        iyz -= m * r1 * r2
    vals = (M, cx, cy, cz, vx, vy, vz, lx, ly, lz, ixx, iyy, izz, ixy, ixz, iyz, 0.5 * ke)
    for k in range(17):
        out[k] = vals[k]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def internal_motion(mass, q, qd, c, v, w):
    """Kinetic energy of the motion left after the rigid part v + w × (x − c), and the largest
    such speed squared."""
    ke = 0.0
    s2max = 0.0
    for i in range(q.shape[0]):
        r0 = q[i, 0] - c[0]
        r1 = q[i, 1] - c[1]
        r2 = q[i, 2] - c[2]
        a0 = qd[i, 0] - v[0] - (w[1] * r2 - w[2] * r1)
        a1 = qd[i, 1] - v[1] - (w[2] * r0 - w[0] * r2)
        a2 = qd[i, 2] - v[2] - (w[0] * r1 - w[1] * r0)
        s2 = a0 * a0 + a1 * a1 + a2 * a2
        ke += mass[i] * s2
        if s2 > s2max:
            s2max = s2
    return 0.5 * ke, s2max

"""Kernels of the co-rotational (floating-frame) kinematics of a group of deformable bodies (docs/method.md §7),
numba, one call per group and step (no Python loop over bodies).

Per body j of a group (k bodies of one block type, n nodes, d = 2 or 3), in its frame of step i: nodal masses m_a
(lumped M, or row sums of the consistent M), y_a = X_a + q_a, centroid c = Σ m_a y_a / m, r_a = y_a - c, mean
velocity v̄ = Σ m_a u_a / m, angular velocity ω from the angular momentum about c: 2D ω = Σ m_a r_a × u_a / Σ m_a
|r_a|², 3D ω = I(r)⁻¹ Σ m_a r_a × u_a, I(r) = Σ m_a (|r_a|² 1 - r_a r_aᵀ).

`frame_start_*`: c, r, I(r), v̄_i, ω_i, and the velocity that M multiplies in the free-velocity right-hand side,
u_i - h ω_i × (u_i - v̄_i) (the inertial term of the turning frame).

`frame_update_*`: with ω_{i+1}, v̄_{i+1} from u_{i+1} and the same r_a: Δφ = h((1-θ)ω_i + θω_{i+1}), R_{i+1} = R_i
exp([Δφ]×) (2D: R = R0 rot(φ), φ += Δφ; 3D: Rodrigues, then one Newton–Schulz step R <- (3R - R Rᵀ R)/2 that keeps
R orthonormal to rounding), D = u - v̄ - ω × r at i and i+1, q_{i+1} = c + r + h((1-θ)D_i + θD_{i+1}) - X (the
centroid's frame coordinates kept), position_{i+1} = C_{i+1} - R_{i+1} c with the global centroid C_{i+1} = R_i (c +
Δc) + position_i, Δc = h((1-θ)v̄_i + θv̄_{i+1}), and u in the new frame u_{i+1} - v̄_{i+1} + exp(-[Δφ]×) v̄_{i+1}.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def frame_start_2d(m, X, Q, U, h, c, r, Ir, vbar, w, Ueff):
    n = X.shape[0]
    k = Q.shape[1]
    mass = m.sum()
    for j in range(k):
        cx = cy = vx = vy = 0.0
        for a in range(n):
            cx += m[a] * (X[a, 0] + Q[2 * a, j])
            cy += m[a] * (X[a, 1] + Q[2 * a + 1, j])
            vx += m[a] * U[2 * a, j]
            vy += m[a] * U[2 * a + 1, j]
        cx /= mass
        cy /= mass
        vx /= mass
        vy /= mass
        J = L = 0.0
        for a in range(n):
            rx = X[a, 0] + Q[2 * a, j] - cx
            ry = X[a, 1] + Q[2 * a + 1, j] - cy
            r[j, a, 0] = rx
            r[j, a, 1] = ry
            J += m[a] * (rx * rx + ry * ry)
            L += m[a] * (rx * U[2 * a + 1, j] - ry * U[2 * a, j])
        om = L / J
        c[j, 0], c[j, 1], vbar[j, 0], vbar[j, 1], Ir[j], w[j] = cx, cy, vx, vy, J, om
        for a in range(n):  # u - h ω J (u - v̄)
            ux = U[2 * a, j] - vx
            uy = U[2 * a + 1, j] - vy
            Ueff[2 * a, j] = U[2 * a, j] + h * om * uy
            Ueff[2 * a + 1, j] = U[2 * a + 1, j] - h * om * ux


@njit(cache=True)
def frame_update_2d(m, X, r, c, Ir, vbar0, w0, U, Unew, h, th, R0, phi, R, pos, Q):
    n = X.shape[0]
    k = Q.shape[1]
    mass = m.sum()
    for j in range(k):
        vx = vy = L = 0.0
        for a in range(n):
            vx += m[a] * Unew[2 * a, j]
            vy += m[a] * Unew[2 * a + 1, j]
            L += m[a] * (r[j, a, 0] * Unew[2 * a + 1, j] - r[j, a, 1] * Unew[2 * a, j])
        vx /= mass
        vy /= mass
        w1 = L / Ir[j]
        dphi = h * ((1 - th) * w0[j] + th * w1)
        dcx = h * ((1 - th) * vbar0[j, 0] + th * vx)
        dcy = h * ((1 - th) * vbar0[j, 1] + th * vy)
        ccx, ccy = c[j, 0] + dcx, c[j, 1] + dcy
        Cx = R[j, 0, 0] * ccx + R[j, 0, 1] * ccy + pos[j, 0]
        Cy = R[j, 1, 0] * ccx + R[j, 1, 1] * ccy + pos[j, 1]
        phi[j] += dphi
        co, si = np.cos(phi[j]), np.sin(phi[j])
        for i in range(2):
            R[j, i, 0] = R0[j, i, 0] * co + R0[j, i, 1] * si
            R[j, i, 1] = -R0[j, i, 0] * si + R0[j, i, 1] * co
        pos[j, 0] = Cx - (R[j, 0, 0] * c[j, 0] + R[j, 0, 1] * c[j, 1])
        pos[j, 1] = Cy - (R[j, 1, 0] * c[j, 0] + R[j, 1, 1] * c[j, 1])
        cd, sd = np.cos(dphi), np.sin(dphi)
        tx = cd * vx + sd * vy  # exp(-[Δφ]x) v̄_{i+1}
        ty = -sd * vx + cd * vy
        for a in range(n):
            rx, ry = r[j, a, 0], r[j, a, 1]
            d0x = U[2 * a, j] - vbar0[j, 0] + w0[j] * ry
            d0y = U[2 * a + 1, j] - vbar0[j, 1] - w0[j] * rx
            d1x = Unew[2 * a, j] - vx + w1 * ry
            d1y = Unew[2 * a + 1, j] - vy - w1 * rx
            Q[2 * a, j] = c[j, 0] + rx + h * ((1 - th) * d0x + th * d1x) - X[a, 0]
            Q[2 * a + 1, j] = c[j, 1] + ry + h * ((1 - th) * d0y + th * d1y) - X[a, 1]
            U[2 * a, j] = Unew[2 * a, j] - vx + tx
            U[2 * a + 1, j] = Unew[2 * a + 1, j] - vy + ty


@njit(cache=True)
def _solve3(A, b, out):
    """out = A⁻¹ b for a 3x3 A (cofactors)."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    i00, i10, i20 = c00 / det, c01 / det, c02 / det
    i01 = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / det
    i11 = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
    i21 = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
    i02 = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / det
    i12 = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
    i22 = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det
    out[0] = i00 * b[0] + i01 * b[1] + i02 * b[2]
    out[1] = i10 * b[0] + i11 * b[1] + i12 * b[2]
    out[2] = i20 * b[0] + i21 * b[1] + i22 * b[2]


@njit(cache=True)
def _rodrigues(wv, out):
    th = np.sqrt(wv[0] * wv[0] + wv[1] * wv[1] + wv[2] * wv[2])
    if th < 1e-8:
        a, b = 1.0 - th * th / 6.0, 0.5 - th * th / 24.0
    else:
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / (th * th)
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2], K[1, 2] = -wv[2], wv[1], -wv[0]
    K[1, 0], K[2, 0], K[2, 1] = wv[2], -wv[1], wv[0]
    KK = K @ K
    for i in range(3):
        for l in range(3):
            out[i, l] = (1.0 if i == l else 0.0) + a * K[i, l] + b * KK[i, l]


@njit(cache=True)
def frame_start_3d(m, X, Q, U, h, c, r, Ir, vbar, w, Ueff):
    n = X.shape[0]
    k = Q.shape[1]
    mass = m.sum()
    L = np.zeros(3)
    for j in range(k):
        cs = np.zeros(3)
        vs = np.zeros(3)
        for a in range(n):
            for i in range(3):
                cs[i] += m[a] * (X[a, i] + Q[3 * a + i, j])
                vs[i] += m[a] * U[3 * a + i, j]
        cs /= mass
        vs /= mass
        S = np.zeros((3, 3))
        L[:] = 0.0
        for a in range(n):
            for i in range(3):
                r[j, a, i] = X[a, i] + Q[3 * a + i, j] - cs[i]
            x, y, z = r[j, a, 0], r[j, a, 1], r[j, a, 2]
            ux, uy, uz = U[3 * a, j], U[3 * a + 1, j], U[3 * a + 2, j]
            L[0] += m[a] * (y * uz - z * uy)
            L[1] += m[a] * (z * ux - x * uz)
            L[2] += m[a] * (x * uy - y * ux)
            for i in range(3):
                for l in range(3):
                    S[i, l] += m[a] * r[j, a, i] * r[j, a, l]
        tr = S[0, 0] + S[1, 1] + S[2, 2]
        for i in range(3):
            for l in range(3):
                Ir[j, i, l] = (tr if i == l else 0.0) - S[i, l]
            c[j, i] = cs[i]
            vbar[j, i] = vs[i]
        _solve3(Ir[j], L, w[j])
        wx, wy, wz = w[j, 0], w[j, 1], w[j, 2]
        for a in range(n):  # u - h ω × (u - v̄)
            ux, uy, uz = U[3 * a, j] - vs[0], U[3 * a + 1, j] - vs[1], U[3 * a + 2, j] - vs[2]
            Ueff[3 * a, j] = U[3 * a, j] - h * (wy * uz - wz * uy)
            Ueff[3 * a + 1, j] = U[3 * a + 1, j] - h * (wz * ux - wx * uz)
            Ueff[3 * a + 2, j] = U[3 * a + 2, j] - h * (wx * uy - wy * ux)


@njit(cache=True)
def frame_update_3d(m, X, r, c, Ir, vbar0, w0, U, Unew, h, th, R, pos, Q):
    n = X.shape[0]
    k = Q.shape[1]
    mass = m.sum()
    L = np.zeros(3)
    w1 = np.zeros(3)
    v1 = np.zeros(3)
    dphi = np.zeros(3)
    Rd = np.zeros((3, 3))
    for j in range(k):
        v1[:] = 0.0
        L[:] = 0.0
        for a in range(n):
            x, y, z = r[j, a, 0], r[j, a, 1], r[j, a, 2]
            ux, uy, uz = Unew[3 * a, j], Unew[3 * a + 1, j], Unew[3 * a + 2, j]
            v1[0] += m[a] * ux
            v1[1] += m[a] * uy
            v1[2] += m[a] * uz
            L[0] += m[a] * (y * uz - z * uy)
            L[1] += m[a] * (z * ux - x * uz)
            L[2] += m[a] * (x * uy - y * ux)
        v1 /= mass
        _solve3(Ir[j], L, w1)
        Cg = np.zeros(3)
        for i in range(3):
            dphi[i] = h * ((1 - th) * w0[j, i] + th * w1[i])
        for i in range(3):
            for l in range(3):
                Cg[i] += R[j, i, l] * (c[j, l] + h * ((1 - th) * vbar0[j, l] + th * v1[l]))
            Cg[i] += pos[j, i]
        _rodrigues(dphi, Rd)
        Rn = R[j] @ Rd
        Rn = 1.5 * Rn - 0.5 * (Rn @ Rn.T @ Rn)
        for i in range(3):
            pos[j, i] = Cg[i] - (Rn[i, 0] * c[j, 0] + Rn[i, 1] * c[j, 1] + Rn[i, 2] * c[j, 2])
            for l in range(3):
                R[j, i, l] = Rn[i, l]
        t = Rd.T @ v1  # exp(-[Δφ]x) v̄_{i+1}
        a0x, a0y, a0z = w0[j, 0], w0[j, 1], w0[j, 2]
        for a in range(n):
            x, y, z = r[j, a, 0], r[j, a, 1], r[j, a, 2]
            d0x = U[3 * a, j] - vbar0[j, 0] - (a0y * z - a0z * y)
            d0y = U[3 * a + 1, j] - vbar0[j, 1] - (a0z * x - a0x * z)
            d0z = U[3 * a + 2, j] - vbar0[j, 2] - (a0x * y - a0y * x)
            d1x = Unew[3 * a, j] - v1[0] - (w1[1] * z - w1[2] * y)
            d1y = Unew[3 * a + 1, j] - v1[1] - (w1[2] * x - w1[0] * z)
            d1z = Unew[3 * a + 2, j] - v1[2] - (w1[0] * y - w1[1] * x)
            Q[3 * a, j] = c[j, 0] + x + h * ((1 - th) * d0x + th * d1x) - X[a, 0]
            Q[3 * a + 1, j] = c[j, 1] + y + h * ((1 - th) * d0y + th * d1y) - X[a, 1]
            Q[3 * a + 2, j] = c[j, 2] + z + h * ((1 - th) * d0z + th * d1z) - X[a, 2]
            for i in range(3):
                U[3 * a + i, j] = Unew[3 * a + i, j] - v1[i] + t[i]


def start(gr, h):
    """frame_start_* on a framed group `gr` (dynamics._Group): sets gr.c, gr.r, gr.Ir, gr.vbar0, gr.w0 and returns
    u_i - h ω_i × (u_i - v̄_i) (ndof, k)."""
    mp = gr.type.mass_properties
    X = gr.type.mesh.points
    n, d = X.shape
    k = gr.Q.shape[1]
    gr.c, gr.r, gr.vbar0 = np.empty((k, d)), np.empty((k, n, d)), np.empty((k, d))
    Ueff = np.empty_like(gr.U)
    if d == 2:
        gr.Ir, gr.w0 = np.empty(k), np.empty(k)
        frame_start_2d(mp.m, X, gr.Q, gr.U, h, gr.c, gr.r, gr.Ir, gr.vbar0, gr.w0, Ueff)
    else:
        gr.Ir, gr.w0 = np.empty((k, 3, 3)), np.empty((k, 3))
        frame_start_3d(mp.m, X, gr.Q, gr.U, h, gr.c, gr.r, gr.Ir, gr.vbar0, gr.w0, Ueff)
    return Ueff


def update(gr, Unew, h, theta):
    """frame_update_* on a framed group: gr.Q, gr.U, gr.R, gr.pos (and 2D gr.phi) at t_{i+1}, in place."""
    mp = gr.type.mass_properties
    X = gr.type.mesh.points
    Unew = np.ascontiguousarray(Unew)
    if X.shape[1] == 2:
        frame_update_2d(mp.m, X, gr.r, gr.c, gr.Ir, gr.vbar0, gr.w0, gr.U, Unew, h, theta, gr.R0, gr.phi, gr.R,
                        gr.pos, gr.Q)
    else:
        frame_update_3d(mp.m, X, gr.r, gr.c, gr.Ir, gr.vbar0, gr.w0, gr.U, Unew, h, theta, gr.R, gr.pos, gr.Q)

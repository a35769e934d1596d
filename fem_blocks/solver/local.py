"""Single-contact (local) frictional solvers for 3D NLGS, compiled with numba.

Local problem (FCLIB convention, normal first): given the diagonal Delassus block w (3x3) and the local free
velocity q (3,), find r, v with

    v = w r + q,   0 <= r_N ⟂ v_N >= 0,   ‖r_T‖ <= mu r_N,   r_T = -mu r_N v_T/‖v_T‖ if v_T != 0

(equivalently, with the De Saxcé shift ṽ = v + [mu‖v_T‖, 0, 0]:  K* ∋ ṽ ⟂ r ∈ K).

Cases tried in order (thesis §6.3.2.d):
  0 open   r = 0 when q_N >= 0;
  1 stick  r = -w⁻¹ q when it lies in the cone;
  2 slide  Alart–Curnier generalized Newton on the 3 reactions (v eliminated), with an Armijo line search
           on ½‖Φ‖², Φ_N = r_N - max(0, r_N - ρ_N v_N),  Φ_T = r_T - P_{B(0, mu max(0, r_N - ρ_N v_N))}(r_T - ρ_T v_T);
  3 slide  if Newton fails (e.g. strongly non-symmetric w, large mu): exact search on the sliding direction
           e = (cos θ, sin θ): v_N = 0, r = r_N (1, -mu e), r_N = -q_N / a, a = w_NN - mu w_NT e > 0, roots of
           the continuous G(θ) = a v_T × e with v_T · e >= 0 (sampled sign changes refined by bisection);
  4        last resort: projection fixed point r <- P_K(r - ρ (v + [mu‖v_T‖, 0, 0])).
Among the candidates, the one with the smallest local natural-map residual is returned.
"""
from __future__ import annotations

import numpy as np
from numba import njit

NEWTON_MAX_IT = 30
N_THETA = 48


@njit(cache=True, inline="always")
def _proj_cone2(x0, x1, mu):
    """Projection of x on the 2D Coulomb cone K = {|x_T| <= mu x_N}. μ = 0: K is the ray {x_T = 0, x_N >= 0}
    (the test is written so that x_N < 0 with x_T = 0 is not taken as inside: 0 <= 0·x_N holds)."""
    ax1 = abs(x1)
    if ax1 <= mu * x0 and x0 >= 0.0:
        return x0, x1
    if mu * ax1 <= -x0:
        return 0.0, 0.0
    c = (x0 + mu * ax1) / (1.0 + mu * mu)
    return c, c * mu * (1.0 if x1 > 0.0 else -1.0)


@njit(cache=True, inline="always")
def _proj_cone3(x0, x1, x2, mu):
    """Projection of x on the Coulomb cone K = {‖x_T‖ <= mu x_N} (μ = 0: the ray x_T = 0, x_N >= 0)."""
    nt = np.sqrt(x1 * x1 + x2 * x2)
    if nt <= mu * x0 and x0 >= 0.0:
        return x0, x1, x2
    if mu * nt <= -x0:
        return 0.0, 0.0, 0.0
    c = (x0 + mu * nt) / (1.0 + mu * mu)
    if nt > 0.0:
        return c, mu * c * x1 / nt, mu * c * x2 / nt
    return c, 0.0, 0.0


@njit(cache=True)
def local_residual3(w, d, q0, q1, q2, mu, r0, r1, r2):
    """‖F‖ of the local natural map F = r - P_K(r - (v + [mu‖v_T‖, 0, 0])), v = w r + q."""
    v0 = w[d, 0, 0] * r0 + w[d, 0, 1] * r1 + w[d, 0, 2] * r2 + q0
    v1 = w[d, 1, 0] * r0 + w[d, 1, 1] * r1 + w[d, 1, 2] * r2 + q1
    v2 = w[d, 2, 0] * r0 + w[d, 2, 1] * r1 + w[d, 2, 2] * r2 + q2
    p0, p1, p2 = _proj_cone3(r0 - v0 - mu * np.sqrt(v1 * v1 + v2 * v2), r1 - v1, r2 - v2, mu)
    f0 = r0 - p0
    f1 = r1 - p1
    f2 = r2 - p2
    return np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)


@njit(cache=True)
def _ac_eval(w, d, q0, q1, q2, mu, r0, r1, r2, rhoN, rhoT, J):
    """Alart–Curnier function Φ(r) and (if J.size) one element of its generalized Jacobian."""
    u0 = w[d, 0, 0] * r0 + w[d, 0, 1] * r1 + w[d, 0, 2] * r2 + q0
    u1 = w[d, 1, 0] * r0 + w[d, 1, 1] * r1 + w[d, 1, 2] * r2 + q1
    u2 = w[d, 2, 0] * r0 + w[d, 2, 1] * r1 + w[d, 2, 2] * r2 + q2
    pN = r0 - rhoN * u0
    if pN > 0.0:
        F0 = rhoN * u0
        tau = mu * pN
        for j in range(3):
            J[0, j] = rhoN * w[d, 0, j]
        dt0 = mu * (1.0 - rhoN * w[d, 0, 0])
        dt1 = -mu * rhoN * w[d, 0, 1]
        dt2 = -mu * rhoN * w[d, 0, 2]
    else:
        F0 = r0
        tau = 0.0
        J[0, 0] = 1.0
        J[0, 1] = 0.0
        J[0, 2] = 0.0
        dt0 = 0.0
        dt1 = 0.0
        dt2 = 0.0
    x1 = r1 - rhoT * u1
    x2 = r2 - rhoT * u2
    nx = np.sqrt(x1 * x1 + x2 * x2)
    if nx <= tau:
        F1 = rhoT * u1
        F2 = rhoT * u2
        for j in range(3):
            J[1, j] = rhoT * w[d, 1, j]
            J[2, j] = rhoT * w[d, 2, j]
    else:
        n1 = x1 / nx
        n2 = x2 / nx
        F1 = r1 - tau * n1
        F2 = r2 - tau * n2
        c = tau / nx
        # dx_T/dr rows: e_k - rhoT w_k
        a10 = -rhoT * w[d, 1, 0]
        a11 = 1.0 - rhoT * w[d, 1, 1]
        a12 = -rhoT * w[d, 1, 2]
        a20 = -rhoT * w[d, 2, 0]
        a21 = -rhoT * w[d, 2, 1]
        a22 = 1.0 - rhoT * w[d, 2, 2]
        m11 = c * (1.0 - n1 * n1)
        m12 = -c * n1 * n2
        m22 = c * (1.0 - n2 * n2)
        J[1, 0] = -(m11 * a10 + m12 * a20 + n1 * dt0)
        J[1, 1] = 1.0 - (m11 * a11 + m12 * a21 + n1 * dt1)
        J[1, 2] = -(m11 * a12 + m12 * a22 + n1 * dt2)
        J[2, 0] = -(m12 * a10 + m22 * a20 + n2 * dt0)
        J[2, 1] = -(m12 * a11 + m22 * a21 + n2 * dt1)
        J[2, 2] = 1.0 - (m12 * a12 + m22 * a22 + n2 * dt2)
    return F0, F1, F2


@njit(cache=True, inline="always")
def _solve3(J, b0, b1, b2):
    """x = J⁻¹ b by Cramer's rule; ok = False if J is numerically singular."""
    c00 = J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1]
    c01 = J[1, 2] * J[2, 0] - J[1, 0] * J[2, 2]
    c02 = J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]
    det = J[0, 0] * c00 + J[0, 1] * c01 + J[0, 2] * c02
    scale = (abs(J[0, 0]) + abs(J[0, 1]) + abs(J[0, 2])) * (abs(J[1, 0]) + abs(J[1, 1]) + abs(J[1, 2])) * \
        (abs(J[2, 0]) + abs(J[2, 1]) + abs(J[2, 2]))
    if not (abs(det) > 1e-14 * scale):
        return 0.0, 0.0, 0.0, False
    x0 = (c00 * b0 + (J[0, 2] * J[2, 1] - J[0, 1] * J[2, 2]) * b1 + (J[0, 1] * J[1, 2] - J[0, 2] * J[1, 1]) * b2) / det
    x1 = (c01 * b0 + (J[0, 0] * J[2, 2] - J[0, 2] * J[2, 0]) * b1 + (J[0, 2] * J[1, 0] - J[0, 0] * J[1, 2]) * b2) / det
    x2 = (c02 * b0 + (J[0, 1] * J[2, 0] - J[0, 0] * J[2, 1]) * b1 + (J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]) * b2) / det
    return x0, x1, x2, True


@njit(cache=True)
def _newton_ac(w, d, q0, q1, q2, mu, r0, r1, r2, J, tol):
    """Damped Alart–Curnier Newton from (r0, r1, r2). Returns (r0, r1, r2, ok)."""
    rhoN = 1.0 / w[d, 0, 0]
    wt = 0.5 * (w[d, 1, 1] + w[d, 2, 2])
    rhoT = 1.0 / wt if wt > 0.0 else rhoN
    F0, F1, F2 = _ac_eval(w, d, q0, q1, q2, mu, r0, r1, r2, rhoN, rhoT, J)
    phi = F0 * F0 + F1 * F1 + F2 * F2
    for it in range(NEWTON_MAX_IT):
        scale = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + rhoN * np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        if np.sqrt(phi) <= tol * scale:
            return r0, r1, r2, True
        d0, d1, d2, ok = _solve3(J, -F0, -F1, -F2)
        if not ok:
            return r0, r1, r2, False
        t = 1.0
        accepted = False
        for ls in range(30):
            s0 = r0 + t * d0
            s1 = r1 + t * d1
            s2 = r2 + t * d2
            G0, G1, G2 = _ac_eval(w, d, q0, q1, q2, mu, s0, s1, s2, rhoN, rhoT, J)
            phin = G0 * G0 + G1 * G1 + G2 * G2
            if phin <= (1.0 - 1e-4 * t) * phi:
                accepted = True
                break
            t *= 0.5
        if not accepted:
            # J now holds the Jacobian at the last trial point; restore it at r
            _ac_eval(w, d, q0, q1, q2, mu, r0, r1, r2, rhoN, rhoT, J)
            return r0, r1, r2, np.sqrt(phi) <= 1e-10 * scale
        r0, r1, r2 = s0, s1, s2
        F0, F1, F2 = G0, G1, G2
        phi = phin
    scale = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + rhoN * np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
    return r0, r1, r2, np.sqrt(phi) <= 1e-10 * scale


@njit(cache=True, inline="always")
def _slide_g(w, d, q0, q1, q2, mu, th):
    """Sliding along e = (cos θ, sin θ), r = r_N (1, -mu e), v_N = 0, with a = w_NN - mu w_NT e and
    r_N = -q_N / a. Returns the homogeneous (continuous in θ) quantities (a v_T × e, a v_T · e, a)."""
    c = np.cos(th)
    s = np.sin(th)
    a = w[d, 0, 0] - mu * (w[d, 0, 1] * c + w[d, 0, 2] * s)
    v1 = a * q1 - q0 * (w[d, 1, 0] - mu * (w[d, 1, 1] * c + w[d, 1, 2] * s))
    v2 = a * q2 - q0 * (w[d, 2, 0] - mu * (w[d, 2, 1] * c + w[d, 2, 2] * s))
    return v1 * s - v2 * c, v1 * c + v2 * s, a


@njit(cache=True)
def _slide_search(w, d, q0, q1, q2, mu):
    """Exact sliding solution by a search on the sliding direction θ: sign changes of the continuous
    G(θ) = a v_T × e on N_THETA intervals refined by bisection, kept if a > 0 and v_T · e >= 0.
    Returns (r0, r1, r2, found), the root with the smallest local residual."""
    best = np.inf
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    found = False
    dth = 2.0 * np.pi / N_THETA
    gp, dp, ap = _slide_g(w, d, q0, q1, q2, mu, 0.0)
    for k in range(1, N_THETA + 1):
        th = k * dth
        g, dd, a = _slide_g(w, d, q0, q1, q2, mu, th)
        if (g <= 0.0) != (gp <= 0.0) or g == 0.0:
            lo = th - dth
            hi = th
            glo = gp
            for it in range(60):
                mid = 0.5 * (lo + hi)
                gm, dm, am = _slide_g(w, d, q0, q1, q2, mu, mid)
                if (gm <= 0.0) == (glo <= 0.0):
                    lo = mid
                    glo = gm
                else:
                    hi = mid
            th0 = 0.5 * (lo + hi)
            gm, dm, am = _slide_g(w, d, q0, q1, q2, mu, th0)
            if am > 0.0 and dm >= 0.0:
                rm = -q0 / am
                c0 = rm
                c1 = -mu * rm * np.cos(th0)
                c2 = -mu * rm * np.sin(th0)
                res = local_residual3(w, d, q0, q1, q2, mu, c0, c1, c2)
                if res < best:
                    best = res
                    b0, b1, b2 = c0, c1, c2
                    found = True
        gp, dp, ap = g, dd, a
    return b0, b1, b2, found


@njit(cache=True)
def _projection(w, d, q0, q1, q2, mu, r0, r1, r2, n_it):
    """Projected fixed point r <- P_K(r - ρ (v + [mu‖v_T‖, 0, 0])), ρ = 1/‖w‖_1."""
    nrm = 0.0
    for i in range(3):
        s = abs(w[d, i, 0]) + abs(w[d, i, 1]) + abs(w[d, i, 2])
        if s > nrm:
            nrm = s
    rho = 1.0 / nrm
    for it in range(n_it):
        v0 = w[d, 0, 0] * r0 + w[d, 0, 1] * r1 + w[d, 0, 2] * r2 + q0
        v1 = w[d, 1, 0] * r0 + w[d, 1, 1] * r1 + w[d, 1, 2] * r2 + q1
        v2 = w[d, 2, 0] * r0 + w[d, 2, 1] * r1 + w[d, 2, 2] * r2 + q2
        r0, r1, r2 = _proj_cone3(r0 - rho * (v0 + mu * np.sqrt(v1 * v1 + v2 * v2)), r1 - rho * v1, r2 - rho * v2,
                                 mu)
    return r0, r1, r2


@njit(cache=True)
def local_3d(w, d, q0, q1, q2, mu, g0, g1, g2, J):
    """Solve the 3D local problem with block w[d] and free velocity q; (g0, g1, g2) is the warm start
    (current reaction), J a (3, 3) work array. Returns (r_N, r_T1, r_T2, case) — see the module docstring."""
    if q0 >= 0.0:
        return 0.0, 0.0, 0.0, 0
    # stick: w r = -q
    for i in range(3):
        for j in range(3):
            J[i, j] = w[d, i, j]
    s0, s1, s2, ok = _solve3(J, -q0, -q1, -q2)
    if ok and s0 > 0.0 and np.sqrt(s1 * s1 + s2 * s2) <= mu * s0:
        return s0, s1, s2, 1
    if not (w[d, 0, 0] > 0.0):
        return 0.0, 0.0, 0.0, -1
    # slide: Newton from the warm start (or from the frictionless normal reaction)
    if g0 > 0.0:
        x0, x1, x2 = g0, g1, g2
    else:
        x0, x1, x2 = -q0 / w[d, 0, 0], 0.0, 0.0
    r0, r1, r2, ok = _newton_ac(w, d, q0, q1, q2, mu, x0, x1, x2, J, 1e-14)
    if ok:
        return r0, r1, r2, 2
    best = local_residual3(w, d, q0, q1, q2, mu, r0, r1, r2)
    case = 2
    # exact search on the sliding direction
    t0, t1, t2, found = _slide_search(w, d, q0, q1, q2, mu)
    if found:
        # polish with Newton from the search result (it is a root of the same equations)
        p0, p1, p2, okp = _newton_ac(w, d, q0, q1, q2, mu, t0, t1, t2, J, 1e-14)
        rp = local_residual3(w, d, q0, q1, q2, mu, p0, p1, p2)
        rt = local_residual3(w, d, q0, q1, q2, mu, t0, t1, t2)
        if rt < rp:
            p0, p1, p2, rp = t0, t1, t2, rt
        if rp < best:
            r0, r1, r2, best, case = p0, p1, p2, rp, 3
    scale = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) / w[d, 0, 0]
    if not (best <= 1e-10 * scale):
        p0, p1, p2 = _projection(w, d, q0, q1, q2, mu, r0, r1, r2, 500)
        rp = local_residual3(w, d, q0, q1, q2, mu, p0, p1, p2)
        if rp < best:
            r0, r1, r2, best, case = p0, p1, p2, rp, 4
    return r0, r1, r2, case

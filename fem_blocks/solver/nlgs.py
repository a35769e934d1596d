"""Nonlinear block Gauss–Seidel (NLGS) for 2D and 3D frictional contact, compiled with numba.

Problem (FCLIB / Siconos convention, contact α occupies entries [dα, dα+d) = (normal, tangent[, tangent 2])):

    u = W r + q,   r_N >= 0, u_N >= 0, r_N u_N = 0,   |r_T| <= mu r_N,
    u_T = 0 if |r_T| < mu r_N, else r_T = -mu r_N u_T/|u_T|.

Sweep: for α in order, v_loc = q_α + Σ_{β≠α} W_αβ r_β, then the exact 2D local solve of
v = W_αα r + v_loc (thesis §6.3.2.c): the affine line intersected with the Signorini and
Coulomb graphs — open (r = 0 if v_loc,N >= 0), stick (v = 0), slide forward / backward
(v_N = 0, r_T = -s mu r_N, s v_T >= 0) — then relaxation r_α <- ω r_loc + (1-ω) r_α.
3D: local solver of solver/local.py (open, stick, Alart–Curnier Newton with line search, exact search on
the sliding direction, projection fixed point), warm-started from the current r_α.

Measures (both reported): relative change ‖Δr‖/‖r‖ over a sweep, and the FCLIB natural-map
residual ‖F‖/‖q‖ with F_α = r_α - P_K(r_α - (u_α + [mu‖u_T‖, 0])) (README of data/fclib).
The residual reported is always recomputed from the returned reactions.

W is stored as block-CSR arrays (linalg.BlockCSR: indptr, indices, blocks (nnzb, d, d), diag_pos) so the time
stepper calls the kernel without scipy objects.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError
from ..linalg import BlockCSR, matvec_bcsr, to_block_csr
from .local import _proj_cone2, _proj_cone3, _solve3, local_3d
from .problem import SolverResult

ORDERS = {"given": 0, "reversed": 1, "shuffled": 2}


# ----------------------------------------------------------------------------- compiled kernels
@njit(cache=True)
def local_residual_2d(w00, w01, w10, w11, q0, q1, mu, rn, rt):
    """‖F‖ of the local natural map F = r - P_K(r - (v + [mu|v_T|, 0])), v = w r + q (2D)."""
    v0 = w00 * rn + w01 * rt + q0
    v1 = w10 * rn + w11 * rt + q1
    p0, p1 = _proj_cone2(rn - (v0 + mu * abs(v1)), rt - v1, mu)
    return np.sqrt((rn - p0) ** 2 + (rt - p1) ** 2)


@njit(cache=True)
def local_2d(w00, w01, w10, w11, q0, q1, mu):
    """Exact solution of v = w r + q with Signorini + Coulomb (2D). Returns (r_N, r_T, case):
    case 0 open, 1 stick, 2 slide forward (v_T > 0), 3 slide backward, -1 no consistent case (degenerate block,
    e.g. singular or strongly non-symmetric w): the candidate (open, frictionless, either slide, stick projected
    on the cone) with the smallest local natural-map residual."""
    if q0 >= 0.0:
        return 0.0, 0.0, 0
    det = w00 * w11 - w01 * w10
    if det > 0.0:
        rn = -(w11 * q0 - w01 * q1) / det
        rt = -(-w10 * q0 + w00 * q1) / det
        if rn > 0.0 and abs(rt) <= mu * rn:
            return rn, rt, 1
    for k in range(2):
        s = 1.0 if k == 0 else -1.0
        den = w00 - s * mu * w01
        if den > 0.0:
            rn = -q0 / den
            rt = -s * mu * rn
            vt = w10 * rn + w11 * rt + q1
            if rn >= 0.0 and s * vt >= -1e-14 * (abs(q1) + abs(q0) + 1e-300):
                return rn, rt, 2 + k
    # no consistent case: least local residual among the candidates
    best_rn, best_rt = 0.0, 0.0
    best = local_residual_2d(w00, w01, w10, w11, q0, q1, mu, 0.0, 0.0)
    for k in range(4):
        if k < 2:
            s = 1.0 if k == 0 else -1.0
            den = w00 - s * mu * w01
            if not (den > 0.0):
                continue
            rn = -q0 / den
            rt = -s * mu * rn
        elif k == 2:
            if not (w00 > 0.0):
                continue
            rn = -q0 / w00
            rt = 0.0
        else:
            if det == 0.0:
                continue
            x0 = -(w11 * q0 - w01 * q1) / det
            x1 = -(-w10 * q0 + w00 * q1) / det
            ax1 = abs(x1)
            if ax1 <= mu * x0 and x0 >= 0.0:
                rn, rt = x0, x1
            elif mu * ax1 <= -x0:
                continue
            else:
                rn = (x0 + mu * ax1) / (1.0 + mu * mu)
                rt = rn * mu * (1.0 if x1 > 0.0 else -1.0)
        e = local_residual_2d(w00, w01, w10, w11, q0, q1, mu, rn, rt)
        if e < best:
            best, best_rn, best_rt = e, rn, rt
    return best_rn, best_rt, -1


@njit(cache=True, inline="always")
def _local_free(indptr, indices, blocks, q, r, a):
    """v_loc^α = q_α + Σ_{β≠α} W_αβ r_β."""
    v0 = q[2 * a]
    v1 = q[2 * a + 1]
    for k in range(indptr[a], indptr[a + 1]):
        b = indices[k]
        if b != a:
            rb0 = r[2 * b]
            rb1 = r[2 * b + 1]
            v0 += blocks[k, 0, 0] * rb0 + blocks[k, 0, 1] * rb1
            v1 += blocks[k, 1, 0] * rb0 + blocks[k, 1, 1] * rb1
    return v0, v1


@njit(cache=True, inline="always")
def clip_to_cone_2d(rn, rt, mu):
    """(r_N, r_T) brought back into the 2D Coulomb cone after a relaxed or corrected update: r_N <- max(r_N, 0),
    then r_T clipped to [-μ r_N, μ r_N]."""
    if rn < 0.0:
        rn = 0.0
    lim = mu * rn
    if rt > lim:
        rt = lim
    elif rt < -lim:
        rt = -lim
    return rn, rt


@njit(cache=True)
def _sweep(indptr, indices, blocks, diag_pos, q, mu, r, order, omega):
    dr2 = 0.0
    r2 = 0.0
    for ii in range(order.shape[0]):
        a = order[ii]
        v0, v1 = _local_free(indptr, indices, blocks, q, r, a)
        d = diag_pos[a]
        if d < 0:
            rn, rt = 0.0, 0.0
        else:
            rn, rt, case = local_2d(blocks[d, 0, 0], blocks[d, 0, 1], blocks[d, 1, 0], blocks[d, 1, 1], v0, v1, mu[a])
        if omega != 1.0:
            rn = omega * rn + (1.0 - omega) * r[2 * a]
            rt = omega * rt + (1.0 - omega) * r[2 * a + 1]
            rn, rt = clip_to_cone_2d(rn, rt, mu[a])
        e0 = rn - r[2 * a]
        e1 = rt - r[2 * a + 1]
        dr2 += e0 * e0 + e1 * e1
        r2 += rn * rn + rt * rt
        r[2 * a] = rn
        r[2 * a + 1] = rt
    return dr2, r2


@njit(cache=True, inline="always")
def _natural_map_term_2d(r, u, mu, a):
    """‖F_α‖² of the 2D natural map (one contact's term of natural_map_2d)."""
    m = mu[a]
    p0, p1 = _proj_cone2(r[2 * a] - (u[2 * a] + m * abs(u[2 * a + 1])), r[2 * a + 1] - u[2 * a + 1], m)
    f0 = r[2 * a] - p0
    f1 = r[2 * a + 1] - p1
    return f0 * f0 + f1 * f1


@njit(cache=True, inline="always")
def _natural_map_term_3d(r, u, mu, a):
    """‖F_α‖² of the 3D natural map (one contact's term of natural_map_3d)."""
    u1 = u[3 * a + 1]
    u2 = u[3 * a + 2]
    p0, p1, p2 = _proj_cone3(r[3 * a] - (u[3 * a] + mu[a] * np.sqrt(u1 * u1 + u2 * u2)),
                             r[3 * a + 1] - u1, r[3 * a + 2] - u2, mu[a])
    f0 = r[3 * a] - p0
    f1 = r[3 * a + 1] - p1
    f2 = r[3 * a + 2] - p2
    return f0 * f0 + f1 * f1 + f2 * f2


@njit(cache=True)
def natural_map_2d(r, u, mu):
    """‖F‖_2 with F_α = r_α - P_K(r_α - (u_α + [mu |u_T|, 0])) (2D Coulomb cone K): sqrt(Σ_α ‖F_α‖²), the terms
    added in contact order from 0.0."""
    n = mu.shape[0]
    s = 0.0
    for a in range(n):
        s += _natural_map_term_2d(r, u, mu, a)
    return np.sqrt(s)


@njit(cache=True)
def natural_map_3d(r, u, mu):
    """‖F‖_2 with F_α = r_α - P_K(r_α - (u_α + [mu ‖u_T‖, 0, 0])) (3D Coulomb cone K), summed as natural_map_2d."""
    s = 0.0
    for a in range(mu.shape[0]):
        s += _natural_map_term_3d(r, u, mu, a)
    return np.sqrt(s)


@njit(cache=True)
def natural_map_terms(r, u, mu, dim):
    """The terms ‖F_α‖², α = 0..n-1 (n = len(mu)), of the FCLIB natural map for dim = 2 or 3: each computed with
    the arithmetic of natural_map_2d/3d, so that Σ_α in contact order from 0.0 (then sqrt) is natural_map(r, u, mu,
    dim) bitwise, and an exact sum of them (distributed.exact) is the same whatever the order or the ranks."""
    n = mu.shape[0]
    t = np.empty(n)
    for a in range(n):
        t[a] = _natural_map_term_2d(r, u, mu, a) if dim == 2 else _natural_map_term_3d(r, u, mu, a)
    return t


@njit(cache=True)
def natural_map(r, u, mu, dim):
    """‖F‖_2 of the FCLIB natural map for dim = 2 or 3."""
    if dim == 2:
        return natural_map_2d(r, u, mu)
    return natural_map_3d(r, u, mu)


@njit(cache=True)
def _sweep3(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, J, cases):
    """One 3D Gauss–Seidel pass; cases[k] counts the local cases used (k = case + 1)."""
    dr2 = 0.0
    r2 = 0.0
    for ii in range(order.shape[0]):
        a = order[ii]
        i0 = 3 * a
        v0 = q[i0]
        v1 = q[i0 + 1]
        v2 = q[i0 + 2]
        for k in range(indptr[a], indptr[a + 1]):
            b = indices[k]
            if b != a:
                rb0 = r[3 * b]
                rb1 = r[3 * b + 1]
                rb2 = r[3 * b + 2]
                v0 += blocks[k, 0, 0] * rb0 + blocks[k, 0, 1] * rb1 + blocks[k, 0, 2] * rb2
                v1 += blocks[k, 1, 0] * rb0 + blocks[k, 1, 1] * rb1 + blocks[k, 1, 2] * rb2
                v2 += blocks[k, 2, 0] * rb0 + blocks[k, 2, 1] * rb1 + blocks[k, 2, 2] * rb2
        d = diag_pos[a]
        o0 = r[i0]
        o1 = r[i0 + 1]
        o2 = r[i0 + 2]
        if d < 0:
            x0, x1, x2, case = 0.0, 0.0, 0.0, -1
        else:
            x0, x1, x2, case = local_3d(blocks, d, v0, v1, v2, mu[a], o0, o1, o2, J)
        cases[case + 1] += 1
        if omega != 1.0:
            x0, x1, x2 = _proj_cone3(omega * x0 + (1.0 - omega) * o0, omega * x1 + (1.0 - omega) * o1,
                                     omega * x2 + (1.0 - omega) * o2, mu[a])
        e0 = x0 - o0
        e1 = x1 - o1
        e2 = x2 - o2
        dr2 += e0 * e0 + e1 * e1 + e2 * e2
        r2 += x0 * x0 + x1 * x1 + x2 * x2
        r[i0] = x0
        r[i0 + 1] = x1
        r[i0 + 2] = x2
    return dr2, r2


def sweep(indptr, indices, blocks, diag_pos, q, mu, r, order, omega=1.0):
    """One Gauss–Seidel pass over the contacts in `order` (r updated in place); dim = blocks.shape[1].
    Returns the relative change ‖Δr‖/‖r‖ of the pass (‖Δr‖ if r = 0)."""
    order = np.ascontiguousarray(order, dtype=np.int64)
    if blocks.shape[1] == 2:
        dr2, r2 = _sweep(indptr, indices, blocks, diag_pos, q, mu, r, order, float(omega))
    else:
        dr2, r2 = _sweep3(indptr, indices, blocks, diag_pos, q, mu, r, order, float(omega), np.empty((3, 3)),
                          np.zeros(6, dtype=np.int64))
    return float(np.sqrt(dr2 / r2)) if r2 > 0 else float(np.sqrt(dr2))


@njit(cache=True)
def _run(indptr, indices, blocks, diag_pos, q, mu, r, order_kind, omega, tol, max_sweeps, seed,
         use_residual, check_every, qnorm, cases):
    n = mu.shape[0]
    dim = blocks.shape[1]
    order = np.arange(n)
    if order_kind == 1:
        order = order[::-1].copy()
    if order_kind == 2:
        np.random.seed(seed)
    u = np.empty_like(q)
    J = np.empty((3, 3))
    change = np.inf
    res = np.inf
    sweeps = 0
    converged = False
    while sweeps < max_sweeps:
        if order_kind == 2:
            np.random.shuffle(order)
        if dim == 2:
            dr2, r2 = _sweep(indptr, indices, blocks, diag_pos, q, mu, r, order, omega)
        else:
            dr2, r2 = _sweep3(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, J, cases)
        sweeps += 1
        change = np.sqrt(dr2 / r2) if r2 > 0.0 else np.sqrt(dr2)
        if use_residual:
            if sweeps % check_every == 0 or sweeps == max_sweeps or change == 0.0:
                matvec_bcsr(indptr, indices, blocks, r, u)
                for i in range(q.shape[0]):
                    u[i] += q[i]
                res = natural_map(r, u, mu, dim) / qnorm
                if res <= tol:
                    converged = True
                    break
                if change == 0.0 and sweeps > 1:
                    # stationary point: a solution when the local solver is exact (2D); in 3D only if the
                    # residual says so (a failed local solve can also be stationary)
                    converged = dim == 2
                    break
        elif change <= tol:
            converged = True
            break
    return sweeps, change, converged


# ----------------------------------------------------------------------------- public API
def _check(bcsr: BlockCSR, q, mu, tol, max_sweeps, omega, order, check_every):
    n = bcsr.n
    d = bcsr.dim
    if d not in (2, 3):
        raise InputError(f"dim = {d}: expected 2 or 3")
    q = np.ascontiguousarray(q, dtype=np.float64).ravel()
    if q.size != d * n:
        raise InputError(f"q: expected {d * n} entries ({d} per contact), got {q.size}")
    mu_a = np.asarray(mu, dtype=np.float64)
    if mu_a.ndim > 1 or (mu_a.ndim == 1 and mu_a.size not in (1, n)):
        raise InputError(f"mu: expected a scalar or {n} friction coefficients, got shape {mu_a.shape}")
    mu = np.ascontiguousarray(np.broadcast_to(mu_a.ravel() if mu_a.ndim else mu_a, (n,)).copy())
    if np.any(~np.isfinite(mu)) or np.any(mu < 0):
        raise InputError("mu: expected friction coefficients >= 0")
    if not np.all(np.isfinite(q)):
        raise InputError("q: expected finite values")
    if not (tol > 0):
        raise InputError(f"tol = {tol!r}: expected tol > 0")
    if int(max_sweeps) < 1:
        raise InputError(f"max_sweeps = {max_sweeps!r}: expected an integer >= 1")
    if not (0 < omega <= 2):
        raise InputError(f"omega = {omega!r}: expected 0 < omega <= 2")
    if order not in ORDERS:
        raise InputError(f"order = {order!r}: expected one of {list(ORDERS)}")
    if int(check_every) < 1:
        raise InputError(f"check_every = {check_every!r}: expected an integer >= 1")
    return q, mu


def solve_block_csr(W: BlockCSR, q, mu, r0=None, tol: float = 1e-8, max_sweeps: int = 10000,
                    omega: float = 1.0, order: str = "given", seed: int = 0, criterion: str = "change",
                    check_every: int = 1, coarse=None) -> SolverResult:
    """NLGS on block-CSR arrays (2x2 or 3x3 blocks). criterion "change": stop when ‖Δr‖/‖r‖ <= tol over a
    sweep; "residual": stop when the FCLIB residual ‖F‖/‖q‖ <= tol (checked every `check_every` sweeps).

    coarse (2D, fallback "none"): a coarse space (solver/coarse.py, e.g. `InterfaceCoarse`); after every
    `coarse.every` sweeps that did not converge, its Galerkin correction on the sticking contacts (two-level NLGS).
    The stopping test is unchanged; `sweeps` counts the Gauss–Seidel sweeps only.

    The hand-over to the global Newton when Gauss–Seidel stagnates is driver.nlgs_then_newton (options.fallback).
    """
    if criterion not in ("change", "residual"):
        raise InputError(f"criterion = {criterion!r}: expected 'change' or 'residual'")
    q, mu = _check(W, q, mu, tol, max_sweeps, omega, order, check_every)
    if coarse is not None and W.dim != 2:
        raise InputError(f"coarse: the interface coarse space is 2D only (W has {W.dim}x{W.dim} blocks)")
    if coarse is not None and coarse.group.shape[0] != W.n:
        raise InputError(f"coarse: built for {coarse.group.shape[0]} contacts, W has {W.n}")
    n, d = W.n, W.dim
    r = np.zeros(d * n) if r0 is None else np.array(r0, dtype=np.float64).ravel()
    if r.size != d * n:
        raise InputError(f"r0: expected {d * n} entries, got {r.size}")
    if not np.all(np.isfinite(r)):
        raise InputError("r0: expected finite values")
    qnorm = float(np.linalg.norm(q)) or 1.0
    if n == 0:
        return SolverResult(r, q.copy(), 0, True, 0.0, 0.0, 0.0, "no contact")
    cases = np.zeros(6, dtype=np.int64)
    if coarse is None:
        sweeps, change, converged = _run(W.indptr, W.indices, W.blocks, W.diag_pos, q, mu, r, ORDERS[order],
                                         float(omega), float(tol), int(max_sweeps), int(seed),
                                         criterion == "residual", int(check_every), qnorm, cases)
    else:  # two-level: chunks of `every` sweeps, a coarse correction between chunks
        sweeps, chunk = 0, 0
        coarse.start()
        while True:
            n_s, change, converged = _run(W.indptr, W.indices, W.blocks, W.diag_pos, q, mu, r, ORDERS[order],
                                          float(omega), float(tol), min(coarse.every, int(max_sweeps) - sweeps),
                                          int(seed) + chunk, criterion == "residual", int(check_every), qnorm,
                                          cases)
            sweeps += n_s
            chunk += 1
            if converged or sweeps >= max_sweeps:
                break
            coarse.correct(W, q, mu, r)
    u = np.empty_like(q)
    matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
    u += q
    res_abs = float(natural_map(r, u, mu, d))
    res = res_abs / qnorm
    if converged:
        msg = f"converged in {sweeps} sweeps"
    else:
        msg = (f"not converged after {sweeps} sweeps (change {change:.3g}, residual {res:.3g}, "
               f"tolerance {tol:g} on the {criterion})")
    if d == 3 and cases[0]:
        msg += f"; {cases[0]} local solves without a positive diagonal block"
    return SolverResult(r, u, int(sweeps), bool(converged), float(change), res, res_abs, msg,
                      cases if d == 3 else None)


def fclib_residual(W, q, mu, r, dim: int = 2) -> tuple[float, float]:
    """(‖F‖, ‖F‖/‖q‖) of the natural map for reactions r."""
    B = to_block_csr(W, dim)
    q = np.ascontiguousarray(q, dtype=np.float64).ravel()
    r = np.ascontiguousarray(r, dtype=np.float64).ravel()
    mu = np.ascontiguousarray(np.broadcast_to(np.asarray(mu, dtype=np.float64), (B.n,)).copy())
    u = np.empty_like(q)
    matvec_bcsr(B.indptr, B.indices, B.blocks, r, u)
    u += q
    f = float(natural_map(r, u, mu, B.dim))
    return f, f / (float(np.linalg.norm(q)) or 1.0)


# ----------------------------------------------------------------------------- cohesive interfaces
# Change of variables (thesis §6.3.4): with the adhesive impulse P_adh = h (K u + f) linearised at the trial jump
# u = u_eff + h θ v (u_eff = u_i + h(1-θ) v_i - h θ s e_N, s the Signorini shift of the normal velocity),
# P̃ = P + P_adh satisfies Signorini–Coulomb with the exact local operator
#   v = W' P̃ + q',  W' = A⁻¹ W_αα,  q' = A⁻¹ (v_loc - h W_αα (K u_eff + f)),  A = I + h² θ W_αα K.
from ..laws import compression_stiffness as _kcomp, internal_update as _internal_update, linear_part as _linear_part  # noqa: E402,E501
from ..laws import cap_stress as _cap_stress, P_CSS as _P_CSS  # noqa: E402


# ----------------------------------------------------------------------------- elliptic cap (C_ss > 0)
# Admissible impulses at a capped contact (docs/laws.md, "Elliptic cap"): K = E ∩ C with the ellipse
# E = {P_N² + C_ss |P_T|² <= P_c²} (P_c = h f_c(κ) A) and the Coulomb cone C = {|P_T| <= μ P_N}. Flow: Coulomb
# (non-associated: no normal velocity from slip) inside E; associated on the ellipse, v' = -λ (P_N, C_ss P_T),
# λ >= 0 (closure and a tangential slip); at the corner E ∩ ∂C (P_N = P_c/√(1 + C_ss μ²), |P_T| = μ P_N) both,
# v'_N = -λ P_N, v_T = -λ C_ss P_T - γ sgn(P_T), λ, γ >= 0.
@njit(cache=True, inline="always")
def _ell_p2(m00, m01, m10, m11, b0, b1, css, lam):
    """(M + λ G)⁻¹ b, G = diag(1, C_ss) (2×2)."""
    a00 = m00 + lam
    a11 = m11 + lam * css
    det = a00 * a11 - m01 * m10
    return (a11 * b0 - m01 * b1) / det, (a00 * b1 - m10 * b0) / det


@njit(cache=True)
def ell_solve2(m00, m01, m10, m11, b0, b1, css, Pc):
    """Point of the ellipse P_N² + C_ss P_T² <= Pc² of the form P(λ) = (M + λ G)⁻¹ b, G = diag(1, C_ss), λ >= 0:
    the projection of M⁻¹b onto the ellipse in the metric M (optimality M (P - M⁻¹b) = -λ G P). For M symmetric
    positive definite φ(λ) = P(λ)ᵀ G P(λ) decreases strictly from φ(0) to 0 (M = L Lᵀ, z = Lᵀ P: φ = Σ g_i ẑ_i²/(1 +
    λ g_i)² in the eigenbasis of L⁻¹ G L⁻ᵀ), so the root of φ(λ) = Pc² is bracketed by doubling and found by
    bisection to the last bits (λ = 0 and P = M⁻¹b if that is inside). Returns (P_N, P_T, λ); P on the feasible side."""
    p0, p1 = _ell_p2(m00, m01, m10, m11, b0, b1, css, 0.0)
    c2 = Pc * Pc
    if p0 * p0 + css * p1 * p1 <= c2:
        return p0, p1, 0.0
    lo = 0.0
    hi = max(abs(m00) + abs(m11), 1e-300)
    for _ in range(2100):
        p0, p1 = _ell_p2(m00, m01, m10, m11, b0, b1, css, hi)
        if p0 * p0 + css * p1 * p1 <= c2:
            break
        lo = hi
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        x0, x1 = _ell_p2(m00, m01, m10, m11, b0, b1, css, mid)
        if x0 * x0 + css * x1 * x1 <= c2:
            hi, p0, p1 = mid, x0, x1
        else:
            lo = mid
    return p0, p1, hi


@njit(cache=True)
def ellcone_proj2(x0, x1, r0, r1, Pc, css, mu):
    """Π(x) of the Alart–Curnier function F = P - Π(P - R v') on the capped set K = E ∩ C (R = diag(r0, r1) > 0),
    and its derivative J = ∂Π/∂x (a generalized Jacobian: piecewise smooth). Three regions:
    1. y = the Coulomb AC map (y_N = x_N⁺, y_T = x_T clipped to [-μ y_N, μ y_N]) if y ∈ E;
    2. else z = the projection of x onto E in the metric R⁻¹, z = (I + λ R G)⁻¹ x (ell_solve2), if z ∈ C:
       J = B - (B R G z)(zᵀ G B)/(zᵀ G B R G z), B = (I + λ R G)⁻¹ (implicit function of zᵀ G z = Pc²);
    3. else the corner (P_c/√(1 + C_ss μ²))(1, μ sgn x_T), J = 0.
    F = 0 exactly at the solutions of the law (docs/laws.md, "Elliptic cap"). Returns (y0, y1, J00, J01, J10, J11,
    region)."""
    y0 = max(x0, 0.0)
    lim = mu * y0
    y1 = min(max(x1, -lim), lim)
    if y0 * y0 + css * y1 * y1 <= Pc * Pc:
        if x0 <= 0.0:
            return y0, y1, 0.0, 0.0, 0.0, 0.0, 1
        if abs(x1) <= lim:
            return y0, y1, 1.0, 0.0, 0.0, 1.0, 1
        return y0, y1, 1.0, 0.0, mu * (1.0 if x1 > 0.0 else -1.0), 0.0, 1
    z0, z1, lam = ell_solve2(1.0 / r0, 0.0, 0.0, 1.0 / r1, x0 / r0, x1 / r1, css, Pc)
    if z0 > 0.0 and abs(z1) <= mu * z0:
        b0 = 1.0 / (1.0 + lam * r0)
        b1 = 1.0 / (1.0 + lam * r1 * css)
        a0 = b0 * r0 * z0          # B R G z
        a1 = b1 * r1 * css * z1
        c0 = z0 * b0               # zᵀ G B
        c1 = css * z1 * b1
        den = c0 * r0 * z0 + c1 * r1 * css * z1  # zᵀ G B R G z
        if den > 0.0:
            return z0, z1, b0 - a0 * c0 / den, -a0 * c1 / den, -a1 * c0 / den, b1 - a1 * c1 / den, 2
        return z0, z1, b0, 0.0, 0.0, b1, 2
    pc = Pc / np.sqrt(1.0 + css * mu * mu)
    return pc, mu * pc * (1.0 if x1 > 0.0 else -1.0), 0.0, 0.0, 0.0, 0.0, 3


@njit(cache=True)
def _ell_res2(p0, p1, m00, m01, m10, m11, q0, q1, mu, Pc, css):
    """‖P - Π(P - v')‖ (ρ = 1) of a candidate P of the local elliptic-cap problem, v' = M P + q."""
    v0 = m00 * p0 + m01 * p1 + q0
    v1 = m10 * p0 + m11 * p1 + q1
    y0, y1, j0, j1, j2, j3, reg = ellcone_proj2(p0 - v0, p1 - v1, 1.0, 1.0, Pc, css, mu)
    return np.sqrt((p0 - y0) ** 2 + (p1 - y1) ** 2)


@njit(cache=True)
def _cap_ell(pn, pt, m00, m01, m10, m11, q0, q1, mu, capP, css):
    """Elliptic cap (C_ss > 0) of the 2D local problem v' = M P + q (M: the contact's operator W' with the compliance
    on M_NN), (pn, pt) the Signorini–Coulomb solution. Exact by its cases: (pn, pt) if inside the ellipse E; else the
    ellipse face, the M-metric projection of the stick point -M⁻¹q onto E (ell_solve2: v' = M(P - P*) = -λ G P) if it
    lies in the cone; else the corner whose multipliers λ = -v'_N/P_N and γ = -s(v_T + λ C_ss P_T) are >= 0; if no
    case is consistent (never met in the tests), the candidate with the least residual ‖P - Π(P - v')‖."""
    if pn * pn + css * pt * pt <= capP * capP:
        return pn, pt
    z0, z1, lam = ell_solve2(m00, m01, m10, m11, -q0, -q1, css, capP)
    if z0 > 0.0 and abs(z1) <= mu * z0:
        return z0, z1
    pc = capP / np.sqrt(1.0 + css * mu * mu)
    s = 1.0 if z1 > 0.0 else -1.0
    for k in range(2):
        sk = s if k == 0 else -s
        c1 = sk * mu * pc
        v0 = m00 * pc + m01 * c1 + q0
        v1 = m10 * pc + m11 * c1 + q1
        lam = -v0 / pc
        if lam >= 0.0 and -sk * (v1 + lam * css * c1) >= 0.0:
            return pc, c1
    best0, best1 = pc, s * mu * pc
    best = _ell_res2(best0, best1, m00, m01, m10, m11, q0, q1, mu, capP, css)
    for k in range(2):
        c0, c1 = (pc, -s * mu * pc) if k == 0 else (z0, z1)
        if k == 1 and not z0 > 0.0:
            continue
        e = _ell_res2(c0, c1, m00, m01, m10, m11, q0, q1, mu, capP, css)
        if e < best:
            best, best0, best1 = e, c0, c1
    return best0, best1


@njit(cache=True)
def _cap(pn, pt, m10, m11, q1, mu, capP):
    """Compressive cap r̃_N <= capP (impulse h f_c A): at the cap the normal impulse is fixed and the tangential
    one solves v_T = m10 pn + m11 pt + q1 with Coulomb at pn (stick, or slide against v_T)."""
    if capP <= 0.0 or pn <= capP:
        return pn, pt
    pn = capP
    b = m10 * pn + q1
    if m11 > 0.0 and abs(b) <= m11 * mu * pn:
        return pn, -b / m11
    return pn, (-mu * pn if b > 0.0 else mu * pn)


@njit(cache=True)
def _local_cohesive(w00, w01, w10, w11, v0, v1, law, par, st, x, ue0, ue1, area, h, theta):
    """Exact local solve with an adhesive law at a fixed internal variable x (the tension/compression
    branch of tension-only springs is iterated). Returns (P_N, P_T)."""
    c = h * h * theta
    eps = 1e-15  # m: a jump of round-off size is "closed" (compression branch), not tension
    tension = ue0 > eps
    rn = 0.0
    rt = 0.0
    for it in range(4):
        kN, kT, fN, fT, mue = _linear_part(law, par, st, x, tension)
        kN *= area
        kT *= area
        fN *= area
        fT *= area
        a00 = 1.0 + c * w00 * kN
        a01 = c * w01 * kT
        a10 = c * w10 * kN
        a11 = 1.0 + c * w11 * kT
        det = a00 * a11 - a01 * a10
        i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
        g0 = h * (kN * ue0 + fN)
        g1 = h * (kT * ue1 + fT)
        b0 = v0 - (w00 * g0 + w01 * g1)
        b1 = v1 - (w10 * g0 + w11 * g1)
        q0 = i00 * b0 + i01 * b1
        q1 = i10 * b0 + i11 * b1
        m00 = i00 * w00 + i01 * w10
        m01 = i00 * w01 + i01 * w11
        m10 = i10 * w00 + i11 * w10
        m11 = i10 * w01 + i11 * w11
        cmp = 0.0
        if not tension:
            kc = _kcomp(law, par) * area
            if kc > 0.0:
                cmp = 1.0 / (h * h * theta * kc)  # compliant Signorini: v_N + cmp P_N >= 0
        pn, pt, case = local_2d(m00 + cmp, m01, m10, m11, q0, q1, mue)
        capP = h * _cap_stress(par, st) * area
        if par[_P_CSS] > 0.0 and capP > 0.0:
            pn, pt = _cap_ell(pn, pt, m00 + cmp, m01, m10, m11, q0, q1, mue, capP, par[_P_CSS])
        else:
            pn, pt = _cap(pn, pt, m10, m11, q1, mue, capP)
        vn = m00 * pn + m01 * pt + q0
        vtt = m10 * pn + m11 * pt + q1
        uN = ue0 + h * theta * vn
        uT = ue1 + h * theta * vtt
        rn = pn - h * (kN * uN + fN)
        rt = pt - h * (kT * uT + fT)
        if (uN > eps) == tension:
            break
        tension = uN > eps
    return rn, rt


@njit(cache=True)
def _update_internal(law, par, st, ueff, v, h, theta, x):
    """x_α from the jumps u = u_eff + hθ v of a converged NLGS (d = ueff.shape[1] = 2 or 3; in 3D the laws see
    ‖u_T‖ of the tangential 2-vector; the step h enters the rate-dependent laws: Frémond's b, the mixed-mode
    `damage_viscosity`); returns the largest change."""
    dmax = 0.0
    dim = ueff.shape[1]
    for a in range(law.shape[0]):
        if law[a] == 0:
            continue
        uT = ueff[a, 1] + h * theta * v[dim * a + 1]
        if dim == 3:
            uS = ueff[a, 2] + h * theta * v[dim * a + 2]
            uT = np.sqrt(uT * uT + uS * uS)
        xn = _internal_update(law[a], par[a], st[a], ueff[a, 0] + h * theta * v[dim * a], uT, h)
        d = abs(xn - x[a])
        if d > dmax:
            dmax = d
        x[a] = xn
    return dmax


@njit(cache=True)
def _sweep_cohesive(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, law, par, st, trial, ueff, area,
                    h, theta):
    dr2 = 0.0
    r2 = 0.0
    for ii in range(order.shape[0]):
        a = order[ii]
        v0, v1 = _local_free(indptr, indices, blocks, q, r, a)
        d = diag_pos[a]
        w00, w01, w10, w11 = blocks[d, 0, 0], blocks[d, 0, 1], blocks[d, 1, 0], blocks[d, 1, 1]
        if law[a] == 0:
            rn, rt, case = local_2d(w00, w01, w10, w11, v0, v1, mu[a])
            capP = h * _cap_stress(par[a], st[a]) * area[a]
            if par[a, _P_CSS] > 0.0 and capP > 0.0:
                rn, rt = _cap_ell(rn, rt, w00, w01, w10, w11, v0, v1, mu[a], capP, par[a, _P_CSS])
            else:
                rn, rt = _cap(rn, rt, w10, w11, v1, mu[a], capP)
        else:
            rn, rt = _local_cohesive(w00, w01, w10, w11, v0, v1, law[a], par[a], st[a], trial[a], ueff[a, 0],
                                     ueff[a, 1], area[a], h, theta)
        if omega != 1.0:
            rn = omega * rn + (1.0 - omega) * r[2 * a]
            rt = omega * rt + (1.0 - omega) * r[2 * a + 1]
        e0 = rn - r[2 * a]
        e1 = rt - r[2 * a + 1]
        dr2 += e0 * e0 + e1 * e1
        r2 += rn * rn + rt * rt
        r[2 * a] = rn
        r[2 * a + 1] = rt
    return dr2, r2


# ----------------------------------------------------------------------------- cohesive interfaces, 3D
# Same change of variables with u = (u_N, u_T, u_S), K = diag(k_N, k_T, k_T) A (isotropic tangential part: the laws
# see ‖u_T‖), W' = A⁻¹ W_αα = (W_αα⁻¹ + h²θ K)⁻¹ (symmetric when W_αα is), solved by local_3d; the cap fixes P̃_N and
# leaves a 2D friction problem on the disk ‖P̃_T‖ <= μ P̃_N (_cap3).
@njit(cache=True, inline="always")
def _local_free3(indptr, indices, blocks, q, r, a):
    """v_loc^α = q_α + Σ_{β≠α} W_αβ r_β (3D)."""
    v0 = q[3 * a]
    v1 = q[3 * a + 1]
    v2 = q[3 * a + 2]
    for k in range(indptr[a], indptr[a + 1]):
        b = indices[k]
        if b == a:
            continue
        for j in range(3):
            rj = r[3 * b + j]
            v0 += blocks[k, 0, j] * rj
            v1 += blocks[k, 1, j] * rj
            v2 += blocks[k, 2, j] * rj
    return v0, v1, v2


@njit(cache=True)
def _cap3(w, d, pn, p1, p2, q1, q2, mu, capP):
    """Compressive cap P̃_N <= capP (3D). At the cap P̃_N = capP and the tangential impulse solves
    v_T = w_TN capP + w_TT p_T + q_T with Coulomb on the disk ‖p_T‖ <= R = μ capP: stick p_T = -w_TT⁻¹ b
    (b = w_TN capP + q_T) if inside, else slide p_T = -R e, e = (λ I + R w_TT)⁻¹ b, ‖e‖ = 1 (then v_T = λ e, λ >= 0;
    ‖(λ I + R w_TT)⁻¹ b‖ decreases in λ for w_TT SPD: bisection on [0, ‖b‖ + R ‖w_TT‖_1])."""
    if capP <= 0.0 or pn <= capP:
        return pn, p1, p2
    pn = capP
    b1 = w[d, 1, 0] * pn + q1
    b2 = w[d, 2, 0] * pn + q2
    R = mu * pn
    a11 = w[d, 1, 1]
    a12 = w[d, 1, 2]
    a21 = w[d, 2, 1]
    a22 = w[d, 2, 2]
    det = a11 * a22 - a12 * a21
    if det > 0.0:
        s1 = -(a22 * b1 - a12 * b2) / det
        s2 = -(a11 * b2 - a21 * b1) / det
        if np.sqrt(s1 * s1 + s2 * s2) <= R:
            return pn, s1, s2
    nb = np.sqrt(b1 * b1 + b2 * b2)
    if R == 0.0 or nb == 0.0:
        return pn, 0.0, 0.0
    lo = 0.0
    hi = nb + R * (abs(a11) + abs(a12) + abs(a21) + abs(a22))
    e1 = b1 / nb
    e2 = b2 / nb
    for it in range(200):
        lam = 0.5 * (lo + hi)
        m11 = lam + R * a11
        m22 = lam + R * a22
        dm = m11 * m22 - R * a12 * R * a21
        if dm == 0.0:
            lo = lam
            continue
        x1 = (m22 * b1 - R * a12 * b2) / dm
        x2 = (m11 * b2 - R * a21 * b1) / dm
        nx = np.sqrt(x1 * x1 + x2 * x2)
        if nx > 1.0:
            lo = lam
        else:
            hi = lam
            if nx > 0.0:
                e1 = x1 / nx
                e2 = x2 / nx
        if hi - lo <= 1e-15 * hi:
            break
    return pn, -R * e1, -R * e2


@njit(cache=True)
def ellcone_proj3(x0, x1, x2, Pc, css, mu):
    """3D Π(x) (ρ = 1) on K = {P_N² + C_ss ‖P_T‖² <= Pc², ‖P_T‖ <= μ P_N}: the Coulomb AC map if inside the ellipse,
    else the Euclidean projection onto the ellipsoid (isotropic in the tangent plane: the 2D projection of
    (x_N, ‖x_T‖), direction of x_T kept) if in the cone, else the corner circle P_N = Pc/√(1 + C_ss μ²),
    P_T = μ P_N x_T/‖x_T‖ (as ellcone_proj2)."""
    nt = np.sqrt(x1 * x1 + x2 * x2)
    y0 = max(x0, 0.0)
    lim = mu * y0
    f = 1.0 if nt <= lim else lim / nt
    if y0 * y0 + css * (f * nt) ** 2 <= Pc * Pc:
        return y0, f * x1, f * x2
    z0, zt, lam = ell_solve2(1.0, 0.0, 0.0, 1.0, x0, nt, css, Pc)
    if not (z0 > 0.0 and zt <= mu * z0):
        z0 = Pc / np.sqrt(1.0 + css * mu * mu)
        zt = mu * z0
    g = zt / nt if nt > 0.0 else 0.0
    return z0, g * x1, g * x2


@njit(cache=True)
def _ell_p3(w, d, cmp, b0, b1, b2, css, lam):
    """(M' + λ G)⁻¹ b, M' = w[d] + cmp e_N e_Nᵀ, G = diag(1, C_ss, C_ss) (Cramer's rule)."""
    a00 = w[d, 0, 0] + cmp + lam
    a01 = w[d, 0, 1]
    a02 = w[d, 0, 2]
    a10 = w[d, 1, 0]
    a11 = w[d, 1, 1] + lam * css
    a12 = w[d, 1, 2]
    a20 = w[d, 2, 0]
    a21 = w[d, 2, 1]
    a22 = w[d, 2, 2] + lam * css
    c00 = a11 * a22 - a12 * a21
    c01 = a12 * a20 - a10 * a22
    c02 = a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    x0 = (c00 * b0 + (a02 * a21 - a01 * a22) * b1 + (a01 * a12 - a02 * a11) * b2) / det
    x1 = (c01 * b0 + (a00 * a22 - a02 * a20) * b1 + (a02 * a10 - a00 * a12) * b2) / det
    x2 = (c02 * b0 + (a01 * a20 - a00 * a21) * b1 + (a00 * a11 - a01 * a10) * b2) / det
    return x0, x1, x2


@njit(cache=True)
def ell_solve3(w, d, cmp, b0, b1, b2, css, Pc):
    """3D ell_solve2: P(λ) = (M' + λ G)⁻¹ b on the ellipsoid P_N² + C_ss ‖P_T‖² = Pc² (λ >= 0, bisection; λ = 0 if
    M'⁻¹b is inside), the M'-metric projection of M'⁻¹b onto it. Returns (P_N, P_T, P_S, λ)."""
    p0, p1, p2 = _ell_p3(w, d, cmp, b0, b1, b2, css, 0.0)
    c2 = Pc * Pc
    if p0 * p0 + css * (p1 * p1 + p2 * p2) <= c2:
        return p0, p1, p2, 0.0
    lo = 0.0
    hi = max(abs(w[d, 0, 0] + cmp) + abs(w[d, 1, 1]) + abs(w[d, 2, 2]), 1e-300)
    for _ in range(2100):
        p0, p1, p2 = _ell_p3(w, d, cmp, b0, b1, b2, css, hi)
        if p0 * p0 + css * (p1 * p1 + p2 * p2) <= c2:
            break
        lo = hi
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        x0, x1, x2 = _ell_p3(w, d, cmp, b0, b1, b2, css, mid)
        if x0 * x0 + css * (x1 * x1 + x2 * x2) <= c2:
            hi, p0, p1, p2 = mid, x0, x1, x2
        else:
            lo = mid
    return p0, p1, p2, hi


@njit(cache=True)
def _cap3_ell(w, d, cmp, pn, p1, p2, q0, q1, q2, mu, capP, css):
    """Elliptic cap (C_ss > 0) of the 3D local problem v' = M' P + q (M' = w[d] + cmp e_N e_Nᵀ), (pn, p1, p2) the
    Signorini–Coulomb solution: kept if inside the ellipsoid; else the M'-metric projection of the stick point onto
    it (ell_solve3) if in the cone; else the corner circle P_N = P_c/√(1 + C_ss μ²) with the tangential impulse of
    the disk problem of radius μ P_N at that P_N (_cap3's sliding solve); of these two the one with the smaller
    residual ‖P - Π(P - v')‖ when the corner is not consistent."""
    if pn * pn + css * (p1 * p1 + p2 * p2) <= capP * capP:
        return pn, p1, p2
    z0, z1, z2, lam = ell_solve3(w, d, cmp, -q0, -q1, -q2, css, capP)
    if z0 > 0.0 and np.sqrt(z1 * z1 + z2 * z2) <= mu * z0:
        return z0, z1, z2
    pc = capP / np.sqrt(1.0 + css * mu * mu)
    c0, c1, c2 = _cap3(w, d, np.inf, 0.0, 0.0, q1, q2, mu, pc)
    res = np.empty(2)
    for k in range(2):
        a0, a1, a2 = (c0, c1, c2) if k == 0 else (z0, z1, z2)
        v0 = (w[d, 0, 0] + cmp) * a0 + w[d, 0, 1] * a1 + w[d, 0, 2] * a2 + q0
        v1 = w[d, 1, 0] * a0 + w[d, 1, 1] * a1 + w[d, 1, 2] * a2 + q1
        v2 = w[d, 2, 0] * a0 + w[d, 2, 1] * a1 + w[d, 2, 2] * a2 + q2
        y0, y1, y2 = ellcone_proj3(a0 - v0, a1 - v1, a2 - v2, capP, css, mu)
        res[k] = np.sqrt((a0 - y0) ** 2 + (a1 - y1) ** 2 + (a2 - y2) ** 2)
    if res[1] < res[0] and z0 > 0.0:
        return z0, z1, z2
    return c0, c1, c2


@njit(cache=True)
def _local_cohesive3(blocks, dk, v0, v1, v2, law, par, st, x, ue, area, h, theta, o0, o1, o2, wl, J):
    """Exact 3D local solve with an adhesive law at a fixed internal variable x: A = I + h²θ W_αα K,
    W' = A⁻¹ W_αα, q' = A⁻¹(v_loc - h W_αα (K u_eff + f)); P̃ from local_3d on (W' [+ compliance on the normal
    diagonal in compression], q'), capped; P = P̃ - h (K u + f), u = u_eff + hθ (W' P̃ + q'). The tension /
    compression branch of tension-only springs is iterated (as in 2D). o: current impulse (warm start).
    Returns (P_N, P_T, P_S, local case)."""
    c = h * h * theta
    eps = 1e-15
    tension = ue[0] > eps
    # velocity of the current impulse (for the warm start P̃ = o + h(K u + f))
    vc0 = v0 + blocks[dk, 0, 0] * o0 + blocks[dk, 0, 1] * o1 + blocks[dk, 0, 2] * o2
    vc1 = v1 + blocks[dk, 1, 0] * o0 + blocks[dk, 1, 1] * o1 + blocks[dk, 1, 2] * o2
    vc2 = v2 + blocks[dk, 2, 0] * o0 + blocks[dk, 2, 1] * o1 + blocks[dk, 2, 2] * o2
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    case = -1
    for it in range(4):
        kN, kT, fN, fT, mue = _linear_part(law, par, st, x, tension)
        kN *= area
        kT *= area
        fN *= area
        for i in range(3):
            for j in range(3):
                J[i, j] = (1.0 if i == j else 0.0) + c * blocks[dk, i, j] * (kN if j == 0 else kT)
        g0 = h * (kN * ue[0] + fN)
        g1 = h * kT * ue[1]
        g2 = h * kT * ue[2]
        b0 = v0 - (blocks[dk, 0, 0] * g0 + blocks[dk, 0, 1] * g1 + blocks[dk, 0, 2] * g2)
        b1 = v1 - (blocks[dk, 1, 0] * g0 + blocks[dk, 1, 1] * g1 + blocks[dk, 1, 2] * g2)
        b2 = v2 - (blocks[dk, 2, 0] * g0 + blocks[dk, 2, 1] * g1 + blocks[dk, 2, 2] * g2)
        q0, q1, q2, ok = _solve3(J, b0, b1, b2)
        for j in range(3):  # W' = A⁻¹ W_αα column by column
            c0, c1, c2, ok = _solve3(J, blocks[dk, 0, j], blocks[dk, 1, j], blocks[dk, 2, j])
            wl[0, 0, j] = c0
            wl[0, 1, j] = c1
            wl[0, 2, j] = c2
        cmp = 0.0
        if not tension:
            kc = _kcomp(law, par) * area
            if kc > 0.0:
                cmp = 1.0 / (c * kc)  # compliant Signorini: v_N + cmp P̃_N >= 0
        w00 = wl[0, 0, 0]
        wl[0, 0, 0] = w00 + cmp
        s0 = o0 + h * (kN * (ue[0] + h * theta * vc0) + fN)
        s1 = o1 + h * kT * (ue[1] + h * theta * vc1)
        s2 = o2 + h * kT * (ue[2] + h * theta * vc2)
        p0, p1, p2, case = local_3d(wl, 0, q0, q1, q2, mue, s0, s1, s2, J)
        wl[0, 0, 0] = w00
        capP = h * _cap_stress(par, st) * area
        if par[_P_CSS] > 0.0 and capP > 0.0:
            p0, p1, p2 = _cap3_ell(wl, 0, cmp, p0, p1, p2, q0, q1, q2, mue, capP, par[_P_CSS])
        else:
            p0, p1, p2 = _cap3(wl, 0, p0, p1, p2, q1, q2, mue, capP)
        uN = ue[0] + h * theta * (wl[0, 0, 0] * p0 + wl[0, 0, 1] * p1 + wl[0, 0, 2] * p2 + q0)
        uT = ue[1] + h * theta * (wl[0, 1, 0] * p0 + wl[0, 1, 1] * p1 + wl[0, 1, 2] * p2 + q1)
        uS = ue[2] + h * theta * (wl[0, 2, 0] * p0 + wl[0, 2, 1] * p1 + wl[0, 2, 2] * p2 + q2)
        r0 = p0 - h * (kN * uN + fN)
        r1 = p1 - h * kT * uT
        r2 = p2 - h * kT * uS
        if (uN > eps) == tension:
            break
        tension = uN > eps
    return r0, r1, r2, case


@njit(cache=True)
def _sweep_cohesive3(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, law, par, st, trial, ueff, area,
                     h, theta, wl, J, cases):
    """One 3D cohesive Gauss–Seidel pass (impulses r in place); cases[k] counts the local cases (k = case + 1)."""
    dr2 = 0.0
    r2 = 0.0
    for ii in range(order.shape[0]):
        a = order[ii]
        v0, v1, v2 = _local_free3(indptr, indices, blocks, q, r, a)
        d = diag_pos[a]
        i0 = 3 * a
        o0 = r[i0]
        o1 = r[i0 + 1]
        o2 = r[i0 + 2]
        wa = blocks
        if d < 0:  # no diagonal block stored: W_αα = 0 (e.g. both sides driven)
            wa = wl
            d = 1
        if law[a] == 0:
            x0, x1, x2, case = local_3d(wa, d, v0, v1, v2, mu[a], o0, o1, o2, J)
            capP = h * _cap_stress(par[a], st[a]) * area[a]
            if par[a, _P_CSS] > 0.0 and capP > 0.0:
                x0, x1, x2 = _cap3_ell(wa, d, 0.0, x0, x1, x2, v0, v1, v2, mu[a], capP, par[a, _P_CSS])
            else:
                x0, x1, x2 = _cap3(wa, d, x0, x1, x2, v1, v2, mu[a], capP)
        else:
            x0, x1, x2, case = _local_cohesive3(wa, d, v0, v1, v2, law[a], par[a], st[a], trial[a], ueff[a],
                                                area[a], h, theta, o0, o1, o2, wl, J)
        cases[case + 1] += 1
        for i, xi in enumerate((x0, x1, x2)):  # relaxation r <- ω r_loc + (1-ω) r, change and norm
            if omega != 1.0:
                xi = omega * xi + (1.0 - omega) * r[i0 + i]
            dr2 += (xi - r[i0 + i]) ** 2
            r2 += xi * xi
            r[i0 + i] = xi
    return dr2, r2


@njit(cache=True, inline="always")
def residual_scale(indptr, indices, blocks, a, kNA, kTA, h, theta):
    """σ_α = 1 + h²θ max(k_N A W_αα,NN, k_T A W_αα,TT) (3D: the larger tangential diagonal entry), k_N, k_T the
    adhesive stiffnesses of the branch in use: the gain of the transformed impulse P̃ = P + h A r_adh(u(v)),
    v = W P + q, on the contact's own impulse (∂P̃_α/∂P_α = I + h²θ A K W_αα). The natural map of the transformed
    problem measures its impulse components divided by σ_α, i.e. on P itself (σ = 1 without adhesive stiffness)."""
    wn = 0.0
    wt = 0.0
    dd = blocks.shape[1]
    for k in range(indptr[a], indptr[a + 1]):
        if indices[k] == a:
            wn = blocks[k, 0, 0]
            for i in range(1, dd):
                if blocks[k, i, i] > wt:
                    wt = blocks[k, i, i]
    g = h * h * theta * max(kNA * wn, kTA * wt)
    return 1.0 + g if g > 0.0 else 1.0


@njit(cache=True, inline="always")
def _natural_map_cohesive_term3(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area, h, theta, a):
    """‖F_α‖² of the 3D transformed problem (one contact's term of _natural_map_cohesive3), u = W r on the rows."""
    v0 = u[3 * a] + q[3 * a]
    v1 = u[3 * a + 1] + q[3 * a + 1]
    v2 = u[3 * a + 2] + q[3 * a + 2]
    p0 = r[3 * a]
    p1 = r[3 * a + 1]
    p2 = r[3 * a + 2]
    m = mu[a]
    sig = 1.0
    if law[a] != 0:
        uN = ueff[a, 0] + h * theta * v0
        kN, kT, fN, fT, m = _linear_part(law[a], par[a], st[a], trial[a], uN > 0.0)
        p0 += h * area[a] * (kN * uN + fN)
        p1 += h * area[a] * kT * (ueff[a, 1] + h * theta * v1)
        p2 += h * area[a] * kT * (ueff[a, 2] + h * theta * v2)
        sig = residual_scale(indptr, indices, blocks, a, kN * area[a], kT * area[a], h, theta)
        if uN <= 0.0:
            kc = _kcomp(law[a], par[a]) * area[a]
            if kc > 0.0:
                v0 += p0 / (h * h * theta * kc)
    p0 /= sig  # impulse components relative to their gain ∂P̃/∂P (docs/laws.md, "Residual")
    p1 /= sig
    p2 /= sig
    capP = h * _cap_stress(par[a], st[a]) * area[a] / sig
    if capP > 0.0 and par[a, _P_CSS] > 0.0:
        y0, y1, y2 = ellcone_proj3(p0 - v0, p1 - v1, p2 - v2, capP, par[a, _P_CSS], m)
    elif capP > 0.0:
        y0 = min(max(p0 - v0, 0.0), capP)
        x1 = p1 - v1
        x2 = p2 - v2
        nx = np.sqrt(x1 * x1 + x2 * x2)
        lim = m * y0
        if nx > lim:
            x1 *= lim / nx
            x2 *= lim / nx
        y1, y2 = x1, x2
    else:
        y0, y1, y2 = _proj_cone3(p0 - (v0 + m * np.sqrt(v1 * v1 + v2 * v2)), p1 - v1, p2 - v2, m)
    f0 = p0 - y0
    f1 = p1 - y1
    f2 = p2 - y2
    return f0 * f0 + f1 * f1 + f2 * f2


@njit(cache=True)
def _natural_map_cohesive3(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta):
    """3D ‖F‖ of the transformed problem: F = P̃/σ - P_K(P̃/σ - (v + [μ‖v_T‖, 0, 0])), P̃ = P + P_adh(u(v)), σ the
    contact's gain (residual_scale); at a cap
    the Alart–Curnier residual (ρ = 1) with the normal projection onto [0, h f_c A] and the tangential one onto the
    disk of radius μ times it (zero exactly at the solutions). sqrt of Σ_α ‖F_α‖² added in contact order from 0.0."""
    n = mu.shape[0]
    u = np.empty_like(q)
    matvec_bcsr(indptr, indices, blocks, r, u)
    s = 0.0
    for a in range(n):
        s += _natural_map_cohesive_term3(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area, h,
                                         theta, a)
    return np.sqrt(s)


def _check_cohesive3(n, r, law, par, st, ueff, area):
    """Shapes of the 3D cohesive inputs (InputError naming the field)."""
    from ..laws import NPAR, NSTATE3
    if r.size != 3 * n:
        raise InputError(f"r0: expected {3 * n} entries (3 per contact), got {r.size}")
    if law.shape != (n,):
        raise InputError(f"law: expected {n} law codes, got shape {law.shape}")
    if par.shape != (n, NPAR):
        raise InputError(f"par: expected shape ({n}, {NPAR}), got {par.shape}")
    if st.ndim != 2 or st.shape[0] != n or st.shape[1] < NSTATE3:
        raise InputError(f"st: expected the 3D state layout, shape ({n}, {NSTATE3}) (laws.initial_state(law, 3)), "
                         f"got {st.shape}")
    if np.shape(ueff) != (n, 3):
        raise InputError(f"ueff: expected shape ({n}, 3) (u_N, u_T, u_S per contact), got {np.shape(ueff)}")
    if np.shape(area) != (n,):
        raise InputError(f"area: expected {n} tributary areas, got shape {np.shape(area)}")


@njit(cache=True, inline="always")
def _natural_map_cohesive_term2(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area, h, theta, a):
    """‖F_α‖² of the 2D transformed problem (one contact's term of natural_map_cohesive), u = W r on the rows."""
    v0 = u[2 * a] + q[2 * a]
    v1 = u[2 * a + 1] + q[2 * a + 1]
    p0 = r[2 * a]
    p1 = r[2 * a + 1]
    m = mu[a]
    sig = 1.0
    if law[a] != 0:
        uN = ueff[a, 0] + h * theta * v0
        uT = ueff[a, 1] + h * theta * v1
        kN, kT, fN, fT, m = _linear_part(law[a], par[a], st[a], trial[a], uN > 0.0)
        p0 += h * area[a] * (kN * uN + fN)
        p1 += h * area[a] * (kT * uT + fT)
        sig = residual_scale(indptr, indices, blocks, a, kN * area[a], kT * area[a], h, theta)
    if law[a] != 0 and v0 * h * theta + ueff[a, 0] <= 0.0:
        kc = _kcomp(law[a], par[a]) * area[a]
        if kc > 0.0:
            v0 += p0 / (h * h * theta * kc)
    p0 /= sig  # impulse components relative to their gain ∂P̃/∂P (docs/laws.md, "Residual")
    p1 /= sig
    capP = h * _cap_stress(par[a], st[a]) * area[a] / sig
    if capP > 0.0 and par[a, _P_CSS] > 0.0:  # elliptic cap: Π of the Alart–Curnier function (ρ = 1)
        y0, y1, j0, j1, j2, j3, reg = ellcone_proj2(p0 - v0, p1 - v1, 1.0, 1.0, capP, par[a, _P_CSS], m)
        return (p0 - y0) ** 2 + (p1 - y1) ** 2
    if capP > 0.0:  # capped cone: Alart–Curnier residual (rho = 1), zero exactly at the solutions
        y0 = min(max(p0 - v0, 0.0), capP)
        lim = m * y0
        y1 = min(max(p1 - v1, -lim), lim)
        f0 = p0 - y0
        f1 = p1 - y1
        return f0 * f0 + f1 * f1
    y0, y1 = _proj_cone2(p0 - (v0 + m * abs(v1)), p1 - v1, m)
    f0 = p0 - y0
    f1 = p1 - y1
    return f0 * f0 + f1 * f1


@njit(cache=True)
def natural_map_cohesive(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta):
    """‖F‖ of the transformed problem: F = P̃/σ - P_K(P̃/σ - (v + [μ|v_T|, 0])), P̃ = P + P_adh(u(v)), σ the contact's
    gain (residual_scale; 1 for Coulomb contacts) (2D or 3D by the block size): sqrt of Σ_α ‖F_α‖² added in contact
    order from 0.0 (the terms: natural_map_cohesive_terms)."""
    if blocks.shape[1] == 3:
        return _natural_map_cohesive3(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta)
    n = mu.shape[0]
    u = np.empty_like(q)
    matvec_bcsr(indptr, indices, blocks, r, u)
    s = 0.0
    for a in range(n):
        s += _natural_map_cohesive_term2(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area, h,
                                         theta, a)
    return np.sqrt(s)


@njit(cache=True)
def natural_map_cohesive_terms(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta):
    """The terms ‖F_α‖² of natural_map_cohesive (2D or 3D by the block size), one per block row α = 0..n-1,
    n = len(indptr) - 1, each computed with its arithmetic: Σ_α in row order from 0.0, then sqrt, is
    natural_map_cohesive bitwise. The rows may be a subset (a rank's owned contacts, numbered first): r holds the
    impulses of every column index (d per column, owned rows first: r_α is the row's own impulse), q, mu, law, par,
    st, trial, ueff, area at least the n rows' entries; the matrix need not be square."""
    n = indptr.shape[0] - 1
    dd = blocks.shape[1]
    u = np.empty(dd * n)
    matvec_bcsr(indptr, indices, blocks, r, u)
    t = np.empty(n)
    for a in range(n):
        if dd == 3:
            t[a] = _natural_map_cohesive_term3(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area,
                                               h, theta, a)
        else:
            t[a] = _natural_map_cohesive_term2(indptr, indices, blocks, q, u, mu, r, law, par, st, trial, ueff, area,
                                               h, theta, a)
    return t


@njit(cache=True)
def _run_cohesive(indptr, indices, blocks, diag_pos, q, mu, r, order_kind, omega, tol, max_sweeps, seed,
                  law, par, st, trial, ueff, area, h, theta, use_residual, check_every, qnorm, cases):
    n = mu.shape[0]
    dim = blocks.shape[1]
    wl = np.zeros((2, 3, 3))  # 3D: wl[0] the transformed block W', wl[1] a zero block for rows without W_αα
    J = np.empty((3, 3))
    order = np.arange(n)
    if order_kind == 1:
        order = order[::-1].copy()
    if order_kind == 2:
        np.random.seed(seed)
    change = np.inf
    sweeps = 0
    converged = False
    while sweeps < max_sweeps:
        if order_kind == 2:
            np.random.shuffle(order)
        if dim == 2:
            dr2, r2 = _sweep_cohesive(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, law, par, st, trial,
                                      ueff, area, h, theta)
        else:
            dr2, r2 = _sweep_cohesive3(indptr, indices, blocks, diag_pos, q, mu, r, order, omega, law, par, st, trial,
                                       ueff, area, h, theta, wl, J, cases)
        sweeps += 1
        change = np.sqrt(dr2 / r2) if r2 > 0.0 else np.sqrt(dr2)
        if use_residual:
            if sweeps % check_every == 0 or sweeps == max_sweeps:
                res = natural_map_cohesive(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h,
                                           theta) / qnorm
                if res <= tol or (change == 0.0 and sweeps > 1):  # stationary Gauss-Seidel point = solution
                    converged = True
                    break
        elif change <= tol and sweeps > 1:
            converged = True
            break
    return sweeps, change, converged


def solve_cohesive(W: BlockCSR, q, mu, law, par, st, ueff, area, h: float, theta: float, r0=None,
                   tol: float = 1e-8, max_sweeps: int = 10000, omega: float = 1.0, order: str = "given",
                   seed: int = 0, max_outer: int = 100, criterion: str = "change", check_every: int = 10,
                   x0=None):
    """NLGS with interface laws (laws.py) per contact, 2D (2x2 blocks) or 3D (3x3 blocks, u = (u_N, u_T, u_S)).
    Returns (SolverResult, trial internal variables). `q` includes the Signorini shift; `ueff` = u_i + h(1-θ)v_i - hθ
    shift e_N per contact (nc, d); `st` the committed states (nc, NSTATE) in 2D, (nc, NSTATE3) in 3D."""
    if criterion not in ("change", "residual"):
        raise InputError(f"criterion = {criterion!r}: expected 'change' or 'residual'")
    q, mu = _check(W, q, mu, tol, max_sweeps, omega, order, check_every)
    n, d = W.n, W.dim
    r = np.zeros(d * n) if r0 is None else np.array(r0, dtype=np.float64).ravel()
    law = np.ascontiguousarray(law, dtype=np.int64)
    par = np.ascontiguousarray(par, dtype=np.float64)
    st = np.ascontiguousarray(st, dtype=np.float64)
    if d == 3:
        _check_cohesive3(n, r, law, par, st, ueff, area)
    from ..laws import step_start  # committed x_n, or the IMPL-EX extrapolation (held in the step)
    trial = np.ascontiguousarray(step_start(np.ascontiguousarray(law, dtype=np.int64),
                                            np.ascontiguousarray(par, dtype=np.float64), st, float(h))
                                 if x0 is None else np.array(x0, dtype=np.float64))
    ueff = np.ascontiguousarray(ueff, dtype=np.float64)
    area = np.ascontiguousarray(area, dtype=np.float64)
    if n == 0:
        return SolverResult(r, q.copy(), 0, True, 0.0, 0.0, 0.0, "no contact"), trial
    # staggered: NLGS at fixed internal variables (starting from the committed, least damaged state), then
    # update them from the converged jumps, until they stop changing (selects the least damaged solution)
    total = 0
    u = np.empty_like(q)
    cases = np.zeros(6, dtype=np.int64)
    converged = False
    change = np.inf
    for outer in range(max_outer):
        sweeps, change, converged = _run_cohesive(W.indptr, W.indices, W.blocks, W.diag_pos, q, mu, r,
                                                  ORDERS[order], float(omega), float(tol),
                                                  int(max_sweeps) - total, int(seed) + outer, law, par, st, trial,
                                                  ueff, area, float(h), float(theta), criterion == "residual",
                                                  int(check_every), float(np.linalg.norm(q)) or 1.0, cases)
        total += sweeps
        matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
        u += q
        dx = _update_internal(law, par, st, ueff, u, float(h), float(theta), trial)
        if dx <= 1e-12 or total >= max_sweeps:
            converged = converged and dx <= 1e-12
            break
    sweeps = total
    u = np.empty_like(q)
    matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
    u += q
    qnorm = float(np.linalg.norm(q)) or 1.0
    res_abs = float(natural_map_cohesive(W.indptr, W.indices, W.blocks, q, mu, r, law, par, st, trial, ueff, area,
                                         float(h), float(theta)))
    msg = f"converged in {sweeps} sweeps" if converged else \
        f"not converged after {sweeps} sweeps (change {change:.3g}, tolerance {tol:g})"
    return SolverResult(r, u, int(sweeps), bool(converged), float(change), res_abs / qnorm, res_abs, msg,
                      cases if d == 3 else None), trial

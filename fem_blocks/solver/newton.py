"""Global semismooth Newton (Alart–Curnier) for 2D and 3D frictional contact, with NLGS as start and fallback.

Same problem as solver/nlgs.py: u = W r + q, Signorini–Coulomb per contact (normal first). Gauss–Seidel
converges slowly when W couples many contacts strongly (stiff quasi-static steps: W ≈ K⁻¹/h² over a wall of
elastic bricks): its sweeps count grows with the size of the wall. Newton on the Alart–Curnier function
(Alart & Curnier 1991; thesis §6.3) treats all contacts at once:

    F_N = r_N - P_{R+}(r_N - ρ_N u_N),
    F_T = r_T - P_{[-μ x⁺, μ x⁺]}(r_T - ρ_T u_T),   x = r_N - ρ_N u_N,

with ρ_N = 1/W_αα,NN and ρ_T = 1/W_αα,TT. F is piecewise linear in r; a generalized Jacobian is
J = D + E W with 2×2 block-diagonal D, E chosen per contact by its case (open, stick, slip), so J has the
block pattern of W. Each iteration assembles J's blocks in W's pattern (_assemble_jacobian, numba) and solves
J Δr = -F with linalg.BlockLU in 2D below 3000 unknowns (block LU, ordering and fill analysed once per block pattern,
no pivoting between blocks, backward error checked; SuperLU when that check fails), else linalg.lu_solve (SuperLU,
MUMPS above 3000 unknowns),
then a backtracking line search on ½‖F‖² (Armijo). When the line search fails
(Newton's direction is not a descent direction where the cases change), a few NLGS sweeps are taken from the
current iterate and Newton resumes.

Stop: the FCLIB natural-map residual ‖F_nat‖/‖q‖ <= tol (the same measure as NLGS's "residual" criterion).

3D (`solve_newton` on a BlockCSR of 3×3 blocks, plain Signorini–Coulomb): the same iteration on

    F_N = r_N - P_R+(x_N),                 x_N = r_N - ρ_N u_N,
    F_T = r_T - P_{B(0, μ x_N⁺)}(y_T),      y_T = r_T - ρ_T u_T  (2-vector, disk projection),

ρ_N = 1/W_αα,NN, ρ_T = 2/(W_αα,T1T1 + W_αα,T2T2) (one scalar per contact, so that F = 0 is the Coulomb law).
3×3 blocks of J = D + E W per case: open (x_N <= 0): D = I, E = 0; stick (‖y_T‖ <= μ x_N): D = 0,
E = diag(ρ_N, ρ_T, ρ_T); slip: E_NN = ρ_N and, with e = y_T/‖y_T‖, P = μ x_N (I - e eᵀ)/‖y_T‖ (the derivative
of the disk projection), D_TN = -μ e, D_TT = I - P, E_TN = μ ρ_N e, E_TT = ρ_T P. The line search is
non-monotone in 3D (Grippo–Lampariello–Lucidi: Armijo against the largest merit of the last `memory` = 10
iterates, reset after a fallback): on the FCLIB sphere packing (nearly parallel contact constraints, W of rank
566/768) the monotone search stalls near 2e-6 (1000 iterations, 150 fallbacks), the non-monotone one reaches
1e-8 in 26 iterations (docs/benchmarks.md). The regularisation ε of J = D + E (W + ε I) is relaxed (÷10) after
every accepted step with t >= 0.1 (2D: only after full steps): near-parallel contact pairs of that packing (rows of
W with cosine 0.99999994, one of the two must open) need ε below their tiny eigenvalue, and with the 2D rule ε
stayed at 1e-4 W_αα while steps of t = 0.25/0.5 alternated, a plateau at 1.8e-6 from Gauss–Seidel starts of 400+
sweeps (with the 3D rule: 73 iterations from 400 sweeps; from 1000–10000 sweeps still 240–284 iterations, more
than the default max_iter = 200, because that plateau is only left by the restarts below).
Stagnation watch (3D): when 30 iterations have not halved the residual, 20 Gauss–Seidel sweeps and a
restart (ε and the merit memory reset). From r = 0 the non-monotone iteration can wander between cases for
hundreds of iterations (KaplasTower, 570 contacts: residual between 1e-3 and 5e-2 for 400 iterations); with the
watch it reaches 1e-8 in 150. The 2D path keeps its rules (memory = 1, no watch, results unchanged).

Interface laws (2D, `solve_cohesive_newton`): the Alart–Curnier function of the transformed problem
P̃ = P + h A r_adh(u), v' = v + cmp P̃_N e_N (u = u_eff + hθ v; cmp = 1/(h²θ k A) for compliant joints, applied in
tension too so that F is continuous where u_N changes sign: at every solution P̃_N = 0 in tension, the same
solutions as the branch-wise natural map), J = D' + E' W by the chain rule. The mixed-mode damage is evaluated
inside the iteration, D(u) = max(D_committed, D(λ(u))), with its derivative in J (consistent tangent, no outer
staggered loop); Frémond's β is staggered (docs/laws.md, "Integration in the global Newton"). In that coupled pass
the contacts with a compliant normal law (cmp > 0) use `compliant_rows` instead of the Alart–Curnier rows (the
compressive impulse as a function of the jump: F_N = P̃_N - min(k_c⟨-u_N⟩₊/(hθ), cap), no ρ_N), and its fallbacks
and stall restarts take no Gauss–Seidel sweeps (measured on split-brick walls: docs/benchmarks.md, "Split-brick
steps: where the iterations go"); it gives up for the Alart–Curnier retry when it diverges or makes no progress
(GIVE_UP; docs/benchmarks.md, "Split-brick steps: the compliant pass that gives up").
Gain-scaled line search (docs/laws.md, "Residual of the transformed problem"): σ_α,i = 1 + S_α,i W_αα,ii is the
gain of row i of F on the contact's own impulse (S = h²θ A k of the adhesive part at the start of the solve). When
the Armijo search on ½‖F‖² fails, a second one on ½‖Σ⁻¹F‖² (rows divided by σ: measured on P rather than on
P̃ = P + S v + c) along the same direction before falling back to Gauss–Seidel. On a 2-brick prism at μ = 0 (every
closed joint slides, F_T = P̃_T, σ_T ~ 1e5) the first search failed at every iteration (101 fallbacks, residual 1.2
after 200 iterations); the second accepts the full step (5 iterations). Searching on either merit at once cost
470–630 instead of ≤ 99 iterations on some steps of the mixed-mode shear wall.

Choosing the solver (solver.solve, driver.py): `SolverOptions(solver="newton")` (20 NLGS sweeps, then Newton) where W
couples contacts strongly (stacks, packings, stiff walls: Gauss–Seidel stalls or cycles there);
`SolverOptions(criterion="residual", fallback="newton")` keeps Gauss–Seidel where it converges and hands over to this
Newton when a window of 200 sweeps does not halve the residual (driver.nlgs_then_newton). Every 3D FCLIB problem
reaches 1e-8 both ways (tests/test_newton3d.py).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from numba import njit

from ..errors import InputError
from ..laws import MIXED, P_CN, P_CSS, P_CT, P_IMPLEX, S_BETA, S_BROKEN, cap_stress, compression_stiffness, \
    linear_part, mixed_damage_gradient, step_start, viscous_damage
from ..linalg import LU_SMALL, BlockCSR, BlockLU, lu_solve, matvec_bcsr
from . import nlgs
from .problem import SolverResult


COMPLIANT_ROWS = True  # coupled pass: compliant_rows for the compliant contacts (False: Alart–Curnier rows; bench)
RETRY_AC_ROWS = True  # a failed compliant coupled pass is retried with the Alart–Curnier rows before the staggered one
BLOCK_LU = True  # 2D Newton's linear solve: linalg.BlockLU below LU_SMALL unknowns (False: lu_solve only; bench)
# the compliant coupled pass gives up (for the retry) when its residual exceeds GIVE_UP[0] times the residual after its
# first iteration, or when GIVE_UP[1] iterations have not brought it below that value (None: never; measured on the
# split-brick wall, docs/benchmarks.md "Split-brick steps: the compliant pass that gives up")
GIVE_UP = (1e3, 40)


def _rho(W: BlockCSR):
    """ρ_N = 1/W_αα,NN, ρ_T = 1/W_αα,TT (3D: 2/(W_T1T1 + W_T2T2)); 1/max|W| where a diagonal entry vanishes."""
    d = W.blocks[W.diag_pos]
    wn = d[:, 0, 0]
    wt = d[:, 1, 1] if W.dim == 2 else 0.5 * (d[:, 1, 1] + d[:, 2, 2])
    scale = np.max(np.abs(W.blocks)) if W.blocks.size else 1.0
    rn = np.where(wn > 1e-14 * scale, 1.0 / np.where(wn > 0, wn, 1.0), 1.0 / max(scale, 1e-300))
    rt = np.where(wt > 1e-14 * scale, 1.0 / np.where(wt > 0, wt, 1.0), 1.0 / max(scale, 1e-300))
    return rn, rt


@njit(cache=True)
def _ellcone_rows(sel, xN, xT, rN, rT, cap, css, mu):
    """Π and ∂Π/∂x (nlgs.ellcone_proj2) of the contacts `sel` with an elliptic cap: (len(sel), 2), (len(sel), 2, 2)."""
    Y = np.empty((sel.shape[0], 2))
    JP = np.empty((sel.shape[0], 2, 2))
    for k in range(sel.shape[0]):
        a = sel[k]
        y0, y1, j00, j01, j10, j11, reg = nlgs.ellcone_proj2(xN[a], xT[a], rN[a], rT[a], cap[a], css[a], mu[a])
        Y[k, 0], Y[k, 1] = y0, y1
        JP[k, 0, 0], JP[k, 0, 1], JP[k, 1, 0], JP[k, 1, 1] = j00, j01, j10, j11
    return Y, JP


def alart_curnier(r, u, mu, rn, rt, jacobian=False, cap=None, css=None):
    """F (2n,) and, if asked, the 2×2 blocks D, E (n, 2, 2) of J = D + E W (vectorised over contacts).
    `cap` (n,): compressive cap on r_N (inf: none): F_N = r_N - P_[0, cap](x), friction bound μ P_[0, cap](x).
    `css` (n,): the cap's shear term C_ss; where > 0 (elliptic cap) F = r - Π(r - R u), R = diag(ρ_N, ρ_T), Π the map
    of nlgs.ellcone_proj2, D = I - ∂Π/∂x, E = (∂Π/∂x) R."""
    R = r.reshape(-1, 2)
    U = u.reshape(-1, 2)
    xN = R[:, 0] - rn * U[:, 0]
    crushed = np.zeros(len(mu), dtype=bool) if cap is None else xN >= cap
    closed = (xN > 0) & ~crushed
    FN = np.where(crushed, R[:, 0] - (0.0 if cap is None else cap), np.where(closed, rn * U[:, 0], R[:, 0]))
    xT = R[:, 1] - rt * U[:, 1]
    lim = mu * (np.maximum(xN, 0.0) if cap is None else np.clip(xN, 0.0, cap))
    active = closed | crushed
    stick = active & (np.abs(xT) <= lim)
    slip = active & ~stick
    s = np.sign(xT)
    FT = np.where(stick, rt * U[:, 1], np.where(slip, R[:, 1] - lim * s, R[:, 1]))
    F = np.column_stack([FN, FT]).ravel()
    el = np.zeros(0, dtype=np.int64) if css is None or cap is None else np.nonzero((css > 0.0) & (cap < np.inf))[0]
    if el.size:  # elliptic cap
        Y, JP = _ellcone_rows(el, xN, xT, rn, rt, cap, css, mu)
        F.reshape(-1, 2)[el] = R[el] - Y
    if not jacobian:
        return F
    n = len(mu)
    D = np.zeros((n, 2, 2))
    E = np.zeros((n, 2, 2))
    D[~closed, 0, 0] = 1.0  # open: F_N = r_N; crushed: F_N = r_N - cap
    E[closed, 0, 0] = rn[closed]
    D[~active, 1, 1] = 1.0  # open: F_T = r_T
    E[stick, 1, 1] = rt[stick]
    D[slip, 1, 1] = 1.0
    sl = slip & closed  # the friction bound depends on x_N below the cap only
    D[sl, 1, 0] = -(mu * s)[sl]
    E[sl, 1, 0] = (mu * s * rn)[sl]
    if el.size:
        D[el] = np.eye(2)[None] - JP
        E[el] = JP * np.column_stack([rn[el], rt[el]])[:, None, :]
    return F, D, E


def alart_curnier_3d(r, u, mu, rn, rt, jacobian=False):
    """3D Alart–Curnier function F (3n,) and, if asked, the 3×3 blocks D, E (n, 3, 3) of J = D + E W
    (vectorised over contacts; see the module docstring for the cases)."""
    R = r.reshape(-1, 3)
    U = u.reshape(-1, 3)
    xN = R[:, 0] - rn * U[:, 0]
    closed = xN > 0
    y = R[:, 1:] - rt[:, None] * U[:, 1:]
    ny = np.sqrt(y[:, 0] ** 2 + y[:, 1] ** 2)
    tau = mu * np.maximum(xN, 0.0)
    stick = closed & (ny <= tau)
    slip = closed & ~stick
    e = np.zeros_like(y)
    e[slip] = y[slip] / ny[slip, None]
    F = np.empty_like(R)
    F[:, 0] = np.where(closed, rn * U[:, 0], R[:, 0])
    F[:, 1:] = np.where(stick[:, None], rt[:, None] * U[:, 1:],
                        np.where(slip[:, None], R[:, 1:] - tau[:, None] * e, R[:, 1:]))
    F = F.ravel()
    if not jacobian:
        return F
    n = len(mu)
    D = np.zeros((n, 3, 3))
    E = np.zeros((n, 3, 3))
    op = ~closed
    D[op, 0, 0] = D[op, 1, 1] = D[op, 2, 2] = 1.0
    E[closed, 0, 0] = rn[closed]
    E[stick, 1, 1] = E[stick, 2, 2] = rt[stick]
    s = slip
    c = tau[s] / ny[s]
    P = c[:, None, None] * (np.eye(2)[None] - e[s][:, :, None] * e[s][:, None, :])  # d P_B(y)/dy
    D[s, 1:, 0] = -mu[s, None] * e[s]
    E[s, 1:, 0] = (mu[s] * rn[s])[:, None] * e[s]
    D[s, 1:, 1:] = np.eye(2)[None] - P
    E[s, 1:, 1:] = rt[s, None, None] * P
    return F, D, E


def compliant_rows(Pt, v, ueffN, h, theta, cmp, capv, mue, rt, S, T, jacobian=False, css=None):
    """Rows of F for contacts with a compliant normal law (cmp > 0: elastic, mixed), where the compressive normal
    impulse is a function of the jump, not a complementarity: with u_N = u_eff,N + hθ v_N and k_c = 1/cmp = h²θ k A,

        P̃_c = min(k_c ⟨-u_N⟩₊/(hθ), h f_c A)                 (compliant Signorini g̃ + r̃_N/(kA) >= 0 ⊥ r̃_N >= 0,
                                                              solved for r̃_N; the cap),
        F_N = P̃_N - P̃_c,
        F_T = P̃_T - P_[-μ P̃_c, μ P̃_c](P̃_T - ρ_T v_T),

    P̃ = P + S v + c (S, c: the adhesive part of the branch of u_N, tension: u_N > 1e-15 as in _cohesive_terms).
    Same zeros as the Alart–Curnier rows of (P̃, v') (the normal-compliance complementarity has the unique solution
    P̃_N = P̃_c), without their case switch at x_N = P̃_N - ρ_N v'_N = 0, which does not coincide with the switch of
    the adhesive branch at u_N = 0 (docs/laws.md, "Integration in the global Newton"). Returns F (2n,) and, if
    asked, the 2×2 blocks D, E of J = D + E W directly in (P, v) (dP̃/dv = diag(S) + T).
    Elliptic cap (`css` > 0): F = P̃ - Π(x), x = (k_c ⟨-u_N⟩₊/(hθ), P̃_T - ρ_T v_T), Π of nlgs.ellcone_proj2 with
    R = diag(k_c, ρ_T) (x_N is P̃_N - k_c v'_N: on the ellipse v' = -λ (P̃_N, C_ss P̃_T)).
    Vectorised over all contacts; the caller uses the rows where cmp > 0."""
    P2 = Pt.reshape(-1, 2)
    V = v.reshape(-1, 2)
    uN = ueffN + h * theta * V[:, 0]
    comp = ~(uN > 1e-15)
    kc = np.where(cmp > 0.0, 1.0 / np.where(cmp > 0.0, cmp, 1.0), 0.0)
    Pc_raw = np.where(comp, np.maximum(-uN, 0.0) / (h * theta) * kc, 0.0)
    capped = Pc_raw >= capv
    Pc = np.minimum(Pc_raw, capv)
    FN = P2[:, 0] - Pc
    xT = P2[:, 1] - rt * V[:, 1]
    lim = mue * Pc
    stick = (np.abs(xT) <= lim) & (lim > 0.0)
    sgn = np.sign(xT)
    FT = np.where(stick, rt * V[:, 1], P2[:, 1] - lim * sgn)
    F = np.column_stack([FN, FT]).ravel()
    el = np.zeros(0, dtype=np.int64) if css is None else np.nonzero((css > 0.0) & (capv < np.inf) & (kc > 0.0))[0]
    if el.size:  # elliptic cap
        Y, JP = _ellcone_rows(el, Pc_raw, xT, kc, rt, capv, css, mue)
        F.reshape(-1, 2)[el] = P2[el] - Y
    if not jacobian:
        return F
    n = len(cmp)
    dPc = np.where(comp & ~capped & (uN < 0.0), -kc, 0.0)  # dP̃_c/dv_N
    D = np.zeros((n, 2, 2))
    E = np.zeros((n, 2, 2))
    D[:, 0, 0] = 1.0
    E[:, 0, 0] = S[:, 0] + T[:, 0, 0] - dPc
    E[:, 0, 1] = T[:, 0, 1]
    sl = ~stick
    E[stick, 1, 1] = rt[stick]
    D[sl, 1, 1] = 1.0
    E[sl, 1, 0] = T[sl, 1, 0] - (mue * sgn * dPc)[sl]
    E[sl, 1, 1] = S[sl, 1] + T[sl, 1, 1]
    if el.size:  # dF = dP̃ - ∂Π/∂x dx, dx_N = dP_s/dv_N dv_N, dx_T = dP̃_T - ρ_T dv_T
        a, b, c_, d = JP[:, 0, 0], JP[:, 0, 1], JP[:, 1, 0], JP[:, 1, 1]
        dPs = np.where(comp & (uN < 0.0), -kc, 0.0)[el]
        Se, Te, re = S[el], T[el], rt[el]
        gT = Se[:, 1] + Te[:, 1, 1]  # dP̃_T/dv_T
        D[el] = 0.0
        E[el] = 0.0
        D[el, 0, 0] = 1.0
        D[el, 0, 1] = -b
        D[el, 1, 1] = 1.0 - d
        E[el, 0, 0] = Se[:, 0] + Te[:, 0, 0] - a * dPs - b * Te[:, 1, 0]
        E[el, 0, 1] = Te[:, 0, 1] - b * (gT - re)
        E[el, 1, 0] = Te[:, 1, 0] - c_ * dPs - d * Te[:, 1, 0]
        E[el, 1, 1] = gT - d * (gT - re)
    return F, D, E


@njit(cache=True)
def _cohesive_terms(law, par, st, x, ueff, v, area, h, theta, S, c, mue, cmp, capv, inside, T):
    """Per contact at fixed internal variables x: P̃ = P + S v + c (adhesive impulse h A r_adh(u), u = u_eff + hθ v),
    friction coefficient, and compliance cmp of the compliant laws (v'_N = v_N + cmp P̃_N; in tension too, where
    P̃_N = 0 at the solutions, so that v' does not jump when u_N changes sign).
    inside: the mixed-mode damage is a function of the current jump, x_α = D(u) = max(D_committed, D(λ(u))) (set
    here), and T_α = -h A hθ (k_n u_N⁺, k_s u_T)ᵀ ⊗ ∇_u D (2×2, 0 elsewhere) completes the derivative
    dP̃/dv = diag(S) + T (consistent tangent; S v + c stays the secant P_adh at the current D)."""
    n = law.shape[0]
    for a in range(n):
        uN = ueff[a, 0] + h * theta * v[2 * a]
        tension = uN > 1e-15
        if inside:
            T[a, 0, 0] = T[a, 0, 1] = T[a, 1, 0] = T[a, 1, 1] = 0.0
            if law[a] == MIXED and st[a, S_BROKEN] == 0.0 and par[a, P_IMPLEX] != 1.0:  # IMPL-EX: x fixed
                uT = ueff[a, 1] + h * theta * v[2 * a + 1]
                D, gN, gT = mixed_damage_gradient(par[a], st[a, S_BETA], uN, uT)
                D, gN, gT = viscous_damage(par[a], st[a, S_BETA], D, gN, gT, h)  # identity if damage_viscosity = 0
                x[a] = D
                f = -h * area[a] * h * theta
                if tension:
                    T[a, 0, 0] = f * par[a, P_CN] * uN * gN
                    T[a, 0, 1] = f * par[a, P_CN] * uN * gT
                T[a, 1, 0] = f * par[a, P_CT] * uT * gN
                T[a, 1, 1] = f * par[a, P_CT] * uT * gT
        kN, kT, fN, fT, m = linear_part(law[a], par[a], st[a], x[a], tension)
        S[a, 0] = h * area[a] * kN * h * theta
        S[a, 1] = h * area[a] * kT * h * theta
        c[a, 0] = h * area[a] * (kN * ueff[a, 0] + fN)
        c[a, 1] = h * area[a] * (kT * ueff[a, 1] + fT)
        mue[a] = m
        fc = cap_stress(par[a], st[a])
        capv[a] = h * fc * area[a] if fc > 0.0 else np.inf
        cmp[a] = 0.0
        if law[a] != 0:
            kc = compression_stiffness(law[a], par[a]) * area[a]
            if kc > 0.0:
                cmp[a] = 1.0 / (h * h * theta * kc)


@njit(cache=True)
def _assemble_jacobian(indptr, blocks, diag_pos, D, E, eps, Jb):
    """Blocks of J = D + E (W + ε I) in the block pattern of W (D, E block-diagonal, (n, d, d)):
    J_αβ = E_α W_αβ (β ≠ α), J_αα = E_α W_αα + (D_α + ε E_α). The same operations in the same order as
    einsum("kij,kjl->kil", E[rows], W.blocks) followed by J_αα += D_α + ε E_α (bitwise equal)."""
    n = indptr.shape[0] - 1
    d = blocks.shape[1]
    for a in range(n):
        for p in range(indptr[a], indptr[a + 1]):
            for i in range(d):
                for l in range(d):
                    s = 0.0
                    for j in range(d):
                        s += E[a, i, j] * blocks[p, j, l]
                    Jb[p, i, l] = s
        p = diag_pos[a]
        for i in range(d):
            for l in range(d):
                Jb[p, i, l] += D[a, i, l] + eps * E[a, i, l]


def _direction(blu, W, Jb, F, linear=None):
    """Newton's direction Δr = -J⁻¹ F for J of the blocks Jb (pattern of W): the block LU with its symbolic
    analysis done once per solve (linalg.BlockLU, no pivoting between blocks, backward error checked), else — or
    when that check fails — a pivoting LU (linalg.lu_solve: SuperLU below LU_SMALL unknowns, MUMPS above).
    `linear` (e.g. distributed.linear.DistBlockSolver, any object with solve(Jb, rhs) -> x or None): its
    solve(Jb, -F) instead. None if J is singular."""
    if linear is not None:
        return linear.solve(Jb, -F)
    if blu is not None:
        dr = blu.solve_checked(Jb, -F)
        if dr is not None:
            return dr
    n, dim = W.n, W.dim
    return lu_solve(sp.bsr_matrix((Jb, W.indices, W.indptr), shape=(dim * n, dim * n)), -F)


def _newton(W: BlockCSR, q, mu, r, tol, max_iter, gs, max_sweeps_total, coh=None, memory=1, stall_window=0,
            fallback_sweeps=10, stall_sweeps=20, compliant=False, probe=None, give_up=None, linear=None):
    """Core iteration (2D or 3D by W.dim). coh = (law, par, st, x, ueff, area, h, theta, inside) for interface laws
    (2D only), else None: x fixed, except with inside = True, where the mixed-mode damage follows the jump
    (x_α = D(u), consistent tangent, see _cohesive_terms). `gs(r, k)` runs k Gauss–Seidel sweeps from r ->
    (r, sweeps). `memory`: the line search accepts t when ½‖F(r + tΔr)‖² <= max(last `memory` merits)
    - 2e-4 t ½‖F(r)‖² (1: monotone Armijo).
    `stall_window` > 0: when that many iterations have not halved the residual, 20 Gauss–Seidel sweeps and a
    restart (ε and the merit memory reset), counted as a fallback.
    `give_up` = (factor, window): stop (unconverged) when the residual exceeds factor times its value after the
    first iteration, or when `window` iterations have not brought it below that value.
    `probe` (diagnostics, bench/bench_split_step.py): called once per iteration as probe(event) with a dict (the
    iterate, F, J, the step length, the residual after the step, and the function F(r) for finite differences).
    `linear`: the solver of J Δr = -F (see _direction; None: the serial BlockLU / lu_solve).
    Returns (r, u, iterations, sweeps, fallbacks, change, residual)."""
    n = W.n
    dim = W.dim
    Wsp = sp.bsr_matrix((W.blocks, W.indices, W.indptr), shape=(dim * n, dim * n))
    rn, rt = _rho(W)
    qnorm = float(np.linalg.norm(q)) or 1.0
    S = np.zeros((n, 2))
    c = np.zeros((n, 2))
    mue = mu.copy()
    cmp = np.zeros(n)
    capv = np.full(n, np.inf)
    T = np.zeros((n, 2, 2))
    inside = coh is not None and coh[8]

    def transformed(r_, u_):
        """(P̃, v') and the terms used: the plain problem when coh is None."""
        if coh is None:
            return r_, u_
        law, par, st, x, ueff, area, h, th, ins = coh
        _cohesive_terms(law, par, st, x, ueff, u_, area, h, th, S, c, mue, cmp, capv, ins, T)
        Pt = r_.reshape(-1, 2) + S * u_.reshape(-1, 2) + c
        vp = u_.reshape(-1, 2).copy()
        vp[:, 0] += cmp * Pt[:, 0]
        return Pt.ravel(), vp.ravel()

    def residual(r_, u_):
        if coh is None:
            return float(nlgs.natural_map(r_, u_, mu, dim)) / qnorm
        law, par, st, x, ueff, area, h, th, ins = coh
        if ins:  # the damage of the evaluated iterate
            transformed(r_, u_)
        return float(nlgs.natural_map_cohesive(W.indptr, W.indices, W.blocks, q, mu, r_, law, par, st, x, ueff,
                                               area, h, th)) / qnorm

    def ac(r_, u_, jacobian=False):
        if dim == 3:
            return alart_curnier_3d(r_, u_, mue, rn, rt, jacobian=jacobian)
        return alart_curnier(r_, u_, mue, rn, rt, jacobian=jacobian, cap=capv if coh is not None else None,
                             css=coh[1][:, P_CSS] if coh is not None else None)

    def merits_of(F):
        """(½‖F‖², ½‖Σ⁻¹F‖²): the merit and, with interface laws, the merit of the rows divided by their gain σ."""
        f = 0.5 * float(F @ F)
        if sig is None:
            return f, f
        Fs = F / sig.ravel()
        return f, 0.5 * float(Fs @ Fs)


    def fun(r_, u_, jacobian=False):
        """F (and the blocks D, E of J = D + E W in (P, v)) of the iterate (r_, u_)."""
        Pt, vp = transformed(r_, u_)
        out = ac(Pt, vp, jacobian=jacobian)
        if coh is None:
            return out
        F = out[0] if jacobian else out
        D = E = None
        if jacobian:  # chain rule through P̃ = P + S v + c, v' = v + C P̃: J = D' + E' W
            D, E = out[1].copy(), out[2]
            D[:, :, 0] += E[:, :, 0] * cmp[:, None]
            E = D * S[:, None, :] + E
            if inside:  # damage inside: dP̃/dv = diag(S) + T
                E += np.einsum("kij,kjl->kil", D, T)
        cm = cmp > 0.0  # coupled pass: compliant normal laws' rows as functions of the jump (compliant_rows)
        if inside and compliant and np.any(cm):
            o2 = compliant_rows(Pt, u_, coh[4][:, 0], coh[6], coh[7], cmp, capv, mue, rt, S, T, jacobian,
                                css=coh[1][:, P_CSS])
            F2 = o2[0] if jacobian else o2
            F = F.copy()
            F.reshape(-1, 2)[cm] = F2.reshape(-1, 2)[cm]
            if jacobian:
                D[cm], E[cm] = o2[1][cm], o2[2][cm]
        return (F, D, E) if jacobian else F

    def merit(r_, u_):
        return merits_of(fun(r_, u_))

    u = Wsp @ r + q
    sig = None
    if coh is not None:  # scale ρ on the transformed problem: P̃ ≈ (W⁻¹ + S) v, so ρ ≈ 1/W_αα + S_α
        transformed(r, u)
        rn, rt = rn + S[:, 0], rt + S[:, 1]
        # gain of each row of F on the contact's own impulse, σ_α,i = 1 + S_α,i W_αα,ii (i = N, T; ρ W_αα in a
        # stick row, ∂P̃/∂P in a slip or open row). When the line search on ½‖F‖² fails, a second one on the
        # rows divided by it (a merit measured on P, like the residual, nlgs.residual_scale) before the fallback
        # (module docstring, "Interface laws")
        dg = W.blocks[W.diag_pos]
        sig = 1.0 + S * np.column_stack([dg[:, 0, 0], dg[:, 1, 1]])
        if inside and compliant and np.any(cmp > 0.0):  # compliant_rows: a normal row has its compression gain
            kc = np.where(cmp > 0.0, 1.0 / np.where(cmp > 0.0, cmp, 1.0), 0.0)
            sig[:, 0] = 1.0 + np.maximum(S[:, 0], kc) * dg[:, 0, 0]
    res = residual(r, u)
    change = 0.0
    n_it = n_gs = n_fb = 0
    # proximal regularisation of the Jacobian, J = D + E (W + eps I): W is singular for hyperstatic contact
    # sets (more contact points than the boundary dofs they constrain), where the plain Newton direction is
    # meaningless. eps adapts like a Levenberg–Marquardt parameter.
    idx = np.arange(dim)
    wdiag = float(np.mean(np.abs(W.blocks[W.diag_pos][:, idx, idx])))
    eps_min, eps_max = 1e-12 * wdiag, 1e-1 * wdiag
    eps = 1e-6 * wdiag
    merits = []  # merits of the last iterates (non-monotone line search)
    best, last = res, 0  # stagnation watch: residual and iteration of the last halving (or restart)
    # J's pattern is W's: its LU's ordering and fill are analysed once per pattern (2D, dim * n < LU_SMALL). 3D keeps
    # lu_solve: BlockLU took 1.23 s against 0.57 s on FCLIB's KaplasTower (570 contacts; docs/benchmarks.md)
    use_blu = BLOCK_LU and dim == 2 and dim * n < LU_SMALL and res > tol and max_iter > 0 and linear is None
    blu = BlockLU.for_pattern(W.indptr, W.indices, dim) if use_blu else None
    Jb = np.empty_like(W.blocks)
    while res > tol and n_it < max_iter and n_gs < max_sweeps_total:
        r0_it = r
        F, D, E = fun(r, u, jacobian=True)
        f0, f0s = merits_of(F)
        merits.append(f0)
        del merits[:-memory]
        fref = max(merits)
        _assemble_jacobian(W.indptr, W.blocks, W.diag_pos, D, E, float(eps), Jb)
        eps_it = eps
        n_it += 1
        dr = _direction(blu, W, Jb, F, linear)  # None if J is singular
        ok = dr is not None
        accepted = False
        t = 1.0
        if ok:
            du = Wsp @ dr
            scaled = []  # gain-scaled merits of the points tried (the second search tries the same t first)
            for _ in range(30):
                r_t, u_t = r + t * dr, u + t * du
                thr = (1.0 - 2e-4 * t) * f0 if memory == 1 else fref - 2e-4 * t * f0
                m0, m1 = merit(r_t, u_t)
                if m0 <= thr:
                    accepted = True
                    break
                scaled.append(m1)
                t *= 0.5
            if not accepted and sig is not None:  # the same direction, Armijo on the gain-scaled merit
                t = 1.0
                for k in range(30):
                    r_t, u_t = r + t * dr, u + t * du
                    if (scaled[k] if k < len(scaled) else merit(r_t, u_t)[1]) <= (1.0 - 2e-4 * t) * f0s:
                        accepted = True
                        break
                    t *= 0.5
        if accepted:
            change = float(np.linalg.norm(r_t - r) / (np.linalg.norm(r_t) or 1.0))
            r, u = r_t, u_t
            if dim == 2:
                eps = max(eps_min, eps * 0.1) if t == 1.0 else min(eps_max, eps * (10.0 if t < 0.1 else 1.0))
            else:  # 3D: relax eps after any step t >= 0.1 (measured: see the module docstring)
                eps = max(eps_min, eps * 0.1) if t >= 0.1 else min(eps_max, eps * 10.0)
        else:  # not a descent direction here: Gauss–Seidel moves the cases, then Newton again
            eps = min(eps_max, eps * 100.0)
            merits.clear()
            r, k = gs(r, fallback_sweeps) if fallback_sweeps else (r, 0)
            n_gs += k
            n_fb += 1
            u = Wsp @ r + q
        res = residual(r, u)
        if probe is not None:
            J = sp.bsr_matrix((Jb.copy(), W.indices, W.indptr), shape=(dim * n, dim * n))
            probe(dict(it=n_it, r=r0_it, F=F, J=J, t=t if accepted else 0.0, res=res, gs=n_gs, eps=eps_it / wdiag,
                       D=D, E=E, rn=rn, rt=rt, x=None if coh is None else coh[3].copy(),
                       Ffun=lambda r_: fun(r_, Wsp @ r_ + q), restore=lambda: residual(r, u)))
        if give_up is not None:  # diverging, or no progress at all: leave it to the caller's next pass
            if n_it == 1:
                res_1, low = res, np.inf
            low = min(low, res) if n_it > 1 else low
            if res > tol and (res > give_up[0] * res_1 or (n_it >= give_up[1] and low >= res_1)):
                break
        if stall_window:
            if res <= 0.5 * best:
                best, last = res, n_it
            elif n_it - last >= stall_window and res > tol and n_gs < max_sweeps_total:
                # stagnating (wandering between cases): Gauss–Seidel moves them, then restart
                r, k = gs(r, stall_sweeps) if stall_sweeps else (r, 0)
                n_gs += k
                n_fb += 1
                u = Wsp @ r + q
                res = residual(r, u)
                eps = 1e-6 * wdiag
                merits.clear()
                best, last = res, n_it
    return r, u, n_it, n_gs, n_fb, change, res


def solve_newton(W: BlockCSR, q, mu, r0=None, tol: float = 1e-8, max_iter: int = 200,
                 gs_sweeps: int = 20, max_sweeps_total: int = 100000, memory: int | None = None,
                 linear=None) -> SolverResult:
    """Semismooth Newton on the Alart–Curnier function, NLGS-started (`gs_sweeps` sweeps) and NLGS fallback.
    2D or 3D from the blocks of W (2×2 or 3×3). `memory`: length of the non-monotone line search (default 1 in
    2D, 10 in 3D; 1 = monotone Armijo). `linear`: solver of each iteration's J Δr = -F, an object with
    solve(Jb, rhs) -> x or None (distributed.linear.DistBlockSolver on W's pattern; None: serial BlockLU / LU).

    Returns a SolverResult; `sweeps` counts Newton iterations + Gauss–Seidel sweeps (message says which)."""
    q, mu, r = _prepare(W, q, mu, r0, tol, dims=(2, 3))
    if memory is None:
        memory = 1 if W.dim == 2 else 10
    if int(memory) != memory or memory < 1:
        raise InputError(f"memory = {memory!r}: expected an integer >= 1")
    for name, v, lo in (("max_iter", max_iter, 0), ("gs_sweeps", gs_sweeps, 0), ("max_sweeps_total",
                                                                                  max_sweeps_total, 0)):
        if int(v) != v or v < lo:
            raise InputError(f"{name} = {v!r}: expected an integer >= {lo}")
    if W.n == 0:
        return SolverResult(r, q.copy(), 0, True, 0.0, 0.0, 0.0, "no contact", solver="Newton")

    def gs(r_, k):
        res = nlgs.solve_block_csr(W, q, mu, r0=r_, tol=tol, max_sweeps=k, criterion="residual", check_every=k)
        return res.r.copy(), res.sweeps

    n_gs0 = 0
    if gs_sweeps:
        r, n_gs0 = gs(r, gs_sweeps)
    r, u, n_it, n_gs, n_fb, change, res = _newton(W, q, mu, r, tol, max_iter, gs, max_sweeps_total,
                                                  memory=int(memory), stall_window=0 if W.dim == 2 else 30,
                                                  linear=linear)
    return _result(r, u, n_it, n_gs0 + n_gs, n_fb, change, res, tol, q)


def solve_cohesive_newton(W: BlockCSR, q, mu, law, par, st, ueff, area, h: float, theta: float, r0=None,
                          tol: float = 1e-8, max_iter: int = 200, gs_sweeps: int = 20,
                          max_sweeps_total: int = 100000, max_outer: int = 1000, max_total_iter: int | None = None,
                          damage_inside: bool = True, probe=None, linear=None):
    """Newton for the contact problem with interface laws (laws.py), same contract as nlgs.solve_cohesive.
    At fixed internal variables x (β, damage) each law is piecewise linear in the jump u = u_eff + hθ v (tension /
    compression branches), so the transformed problem P̃ = P + S v + c, v' = v + cmp P̃_N e_N keeps the
    Alart–Curnier form and J = D' + E' W.

    Mixed-mode damage (damage_inside = True, the default): D is not staggered but a function of the current jump,
    D(u) = max(D_committed, D(λ(u))) (monotone: never below the committed damage), inside the Alart–Curnier
    function, with the consistent tangent dP̃/dv = diag(S) + T (T: the damage term, laws.mixed_damage_gradient).
    Newton then solves the coupled problem at once; the residual is the natural map at x = D(u). IMPL-EX contacts
    (`damage_integration = "implex"`) start from and keep the extrapolated x (laws.step_start) in every pass, the
    coupled one included (there without a damage term T: a compliant-joint problem at fixed x). Other laws
    (Frémond β) and damage_inside = False: staggered — Newton at fixed x, then x updated from the converged jumps
    (Aitken-relaxed), until x stops changing. The coupled pass writes the rows of compliant contacts as functions
    of the jump (`compliant_rows`), takes no Gauss–Seidel sweeps after a failed line search (the regularisation
    grows) and restarts (regularisation and merit memory reset) when 10 iterations have not halved its residual;
    it gives up (GIVE_UP) when its residual exceeds 1 000 times its value after its first iteration or has not gone
    below that value in 40 iterations; if it ends above the tolerance, a second coupled pass with the Alart–Curnier rows
    (RETRY_AC_ROWS), from the committed damage and the Gauss–Seidel start; if that one fails too, the
    staggered iteration takes over from the committed damage and the Gauss–Seidel start (message says so): it
    selects the least damaged solution where a large step makes the coupled iteration jump between branches of
    the softening law. The whole step is bounded by `max_total_iter` Newton iterations (default 10 x max_iter) and
    `max_sweeps_total` fallback sweeps over all passes; beyond, it reports non-convergence.
    `probe`: diagnostics hook of every Newton iteration (see _newton). `linear`: solver of J Δr = -F (see
    solve_newton).
    Returns (SolverResult, trial internal variables)."""
    q, mu, r = _prepare(W, q, mu, r0, tol)
    law = np.ascontiguousarray(law, dtype=np.int64)
    par = np.ascontiguousarray(par, dtype=np.float64)
    st = np.ascontiguousarray(st, dtype=np.float64)
    x0 = step_start(law, par, st, float(h))  # committed x_n, or the IMPL-EX extrapolation (held in the step)
    x = x0.copy()
    ueff = np.ascontiguousarray(ueff, dtype=np.float64)
    area = np.ascontiguousarray(area, dtype=np.float64)
    if W.n == 0:
        return SolverResult(r, q.copy(), 0, True, 0.0, 0.0, 0.0, "no contact", solver="Newton"), x
    from ..laws import FREMOND
    # the coupled pass (compliant rows, stall restarts, Alart–Curnier retry) also serves IMPL-EX mixed contacts, whose
    # x stays the extrapolated one in it (_cohesive_terms)
    inside = bool(damage_inside) and bool(np.any(law == MIXED))
    n = W.n
    scratch = (np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros((n, 2, 2)))
    mode = {"inside": False}  # damage inside for the Gauss-Seidel fallbacks of the current pass

    def refresh(r_):
        """x_α = D(u(r_)) for the mixed-mode contacts (damage inside)."""
        u_ = np.empty_like(q)
        matvec_bcsr(W.indptr, W.indices, W.blocks, r_, u_)
        u_ += q
        S_, c_, m_, cmp_, cap_, T_ = scratch
        _cohesive_terms(law, par, st, x, ueff, u_, area, float(h), float(theta), S_, c_, m_, cmp_, cap_, True, T_)

    def gs(r_, k):
        if mode["inside"]:
            refresh(r_)
        res, _ = nlgs.solve_cohesive(W, q, mu, law, par, st, ueff, area, h, theta, r0=r_, tol=tol, max_sweeps=k,
                                     max_outer=1, criterion="residual", check_every=k, x0=x)
        return res.r.copy(), res.sweeps

    n_it = n_gs = n_fb = 0
    if gs_sweeps:  # at the committed internal variables
        r, n_gs = gs(r, gs_sweeps)
    r_start = r.copy()
    fell_back = False
    converged_x = False
    # the internal-variable fixed point x <- g(x) (g: Newton at fixed x, then the law update) converges linearly
    # on softening laws (ratio ~0.6 on the shear wall: ~30 outer solves); Aitken's dynamic relaxation
    # (Irons–Tuck) on the staggered continuous variables (Frémond β; mixed-mode D unless inside), kept in their
    # admissible range (β in [0, β_committed], D in [D_committed, 1]), cuts that to a few.
    lo = np.where(law == FREMOND, 0.0, st[:, S_BETA])
    hi = np.where(law == FREMOND, st[:, S_BETA], 1.0)
    omega, res_prev = 1.0, None
    budget = max_total_iter if max_total_iter is not None else 10 * max_iter
    res = np.inf
    rows = "compliant" if COMPLIANT_ROWS else "ac"
    for _ in range(max_outer):  # `budget` Newton iterations and max_sweeps_total sweeps bound the whole step
        if n_it >= budget or n_gs >= max_sweeps_total:
            break
        mode["inside"] = inside
        relax = (law == FREMOND) | ((law == MIXED) & (not inside))
        coh = (law, par, st, x, ueff, area, float(h), float(theta), inside)
        # coupled pass: no Gauss–Seidel sweeps in its fallbacks and restarts (regularisation and merit memory reset
        # only): at fixed trial damage they threw near-converged iterates of split-brick walls back by up to 4
        # orders of magnitude (docs/benchmarks.md, "Split-brick steps")
        r, u, i1, g1, f1, change, res = _newton(W, q, mu, r, tol, min(max_iter, budget - n_it), gs,
                                                max_sweeps_total - n_gs, coh, stall_window=10 if inside else 0,
                                                fallback_sweeps=0 if inside else 10, stall_sweeps=0 if inside else 20,
                                                compliant=rows == "compliant", probe=probe,
                                                give_up=GIVE_UP if inside and rows == "compliant" and RETRY_AC_ROWS
                                                else None, linear=linear)
        n_it, n_gs, n_fb = n_it + i1, n_gs + g1, n_fb + f1
        if inside and res > tol and rows == "compliant" and RETRY_AC_ROWS:
            # a second coupled pass with the Alart–Curnier rows, from the committed damage and the Gauss–Seidel start
            # (measured: the late softening steps where the compliant rows fail, docs/benchmarks.md)
            rows = "ac"
            x[:] = x0
            r = r_start.copy()
            continue
        if inside and res > tol:
            # the coupled iteration did not converge (e.g. a load step large enough to jump onto the softening
            # branch): the staggered iteration from the committed state instead, which selects the least
            # damaged solution
            inside, fell_back, res_prev, omega = False, True, None, 1.0
            x[:] = x0
            r = r_start.copy()
            continue
        x_old = x.copy()
        dx = nlgs._update_internal(law, par, st, ueff, u, float(h), float(theta), x)  # x <- g(x_old)
        converged_x = dx <= 1e-12
        if converged_x:
            break
        res_k = np.where(relax, x - x_old, 0.0)
        if res_prev is not None:
            d = res_k - res_prev
            dd = float(d @ d)
            if dd > 0.0:
                omega = float(np.clip(-omega * float(res_prev @ d) / dd, 0.1, 10.0))
            x[relax] = np.clip(x_old + omega * res_k, lo, hi)[relax]
        res_prev = res_k
    res = float(nlgs.natural_map_cohesive(W.indptr, W.indices, W.blocks, q, mu, r, law, par, st, x, ueff, area,
                                          float(h), float(theta))) / (float(np.linalg.norm(q)) or 1.0)
    out = _result(r, u, n_it, n_gs, n_fb, change, res, tol, q)
    if not converged_x:
        out.converged = False
        out.message += "; internal variables still changing"
    if fell_back:
        out.message += "; coupled damage iteration did not converge, staggered instead"
    return out, x


def _prepare(W, q, mu, r0, tol, dims=(2,)):
    if not isinstance(W, BlockCSR):
        raise InputError(f"W: expected a BlockCSR (linalg.to_block_csr), got {type(W).__name__}")
    if W.dim not in dims:
        raise InputError(f"newton: dim = {W.dim}: expected {' or '.join(map(str, dims))} "
                         f"({'the interface-law Newton solver is 2D' if dims == (2,) else '2×2 or 3×3 blocks'})")
    q, mu = nlgs._check(W, q, mu, tol, 1, 1.0, "given", 1)
    n, d = W.n, W.dim
    if n and np.any(W.diag_pos < 0):
        raise InputError("W: every contact needs a diagonal block (linalg.to_block_csr adds missing ones)")
    r = np.zeros(d * n) if r0 is None else np.array(r0, dtype=np.float64).ravel()
    if r.size != d * n or not np.all(np.isfinite(r)):
        raise InputError(f"r0: expected {d * n} finite values")
    return q, mu, r


def _result(r, u, n_it, n_gs, n_fb, change, res, tol, q):
    converged = res <= tol
    msg = (f"{'converged' if converged else 'not converged'}: {n_it} Newton iterations, {n_gs} Gauss-Seidel "
           f"sweeps ({n_fb} fallbacks), residual {res:.3g} (tolerance {tol:g})")
    qnorm = float(np.linalg.norm(q)) or 1.0
    return SolverResult(r, u, n_it + n_gs, bool(converged), change, res, res * qnorm, msg,
                      solver="Newton + NLGS fallback" if n_fb > 0 else "Newton")

"""Per-contact terms of the NLGS residuals (solver/nlgs.py natural_map_terms, natural_map_cohesive_terms), for exact
sums across ranks.

Expectation (independent of the code under test): the natural maps as they were before the terms were split out,
copied below verbatim from solver/nlgs.py (old_*), on random problems of every interface law code of laws.py,
2D and 3D, with and without (elliptic) caps, broken and intact joints, compressive stiffness: (1) the new functions
return the old values bitwise; (2) the terms added one by one in contact order from 0.0, then sqrt, are those
values bitwise; (3) the terms of a subset of rows (a rank's owned contacts, local numbering: owned then ghosts,
the matrix not square) are the global terms of those contacts, bitwise.

The old functions run as plain Python (their numba decorators removed, the code otherwise verbatim; the kernels they
call are the package's compiled ones): the same IEEE operations in the same order, and compiling them took about
half a minute of every clean CI run.
"""
import numpy as np
import pytest

from fem_blocks import laws
from fem_blocks.distributed import sweep as ds
from fem_blocks.linalg import matvec_bcsr, to_block_csr
from fem_blocks.solver import nlgs
from fem_blocks.solver.local import _proj_cone2, _proj_cone3
from fem_blocks.solver.nlgs import ellcone_proj2, ellcone_proj3, residual_scale
from fem_blocks.laws import compression_stiffness as _kcomp, linear_part as _linear_part
from fem_blocks.laws import cap_stress as _cap_stress, P_CSS as _P_CSS

# ----------------------------------------------------------------------------- verbatim copies (before the split)
def old_natural_map_2d(r, u, mu):
    """‖F‖_2 with F_α = r_α - P_K(r_α - (u_α + [mu |u_T|, 0])) (2D Coulomb cone K)."""
    n = mu.shape[0]
    s = 0.0
    for a in range(n):
        m = mu[a]
        p0, p1 = _proj_cone2(r[2 * a] - (u[2 * a] + m * abs(u[2 * a + 1])), r[2 * a + 1] - u[2 * a + 1], m)
        f0 = r[2 * a] - p0
        f1 = r[2 * a + 1] - p1
        s += f0 * f0 + f1 * f1
    return np.sqrt(s)


def old_natural_map_3d(r, u, mu):
    """‖F‖_2 with F_α = r_α - P_K(r_α - (u_α + [mu ‖u_T‖, 0, 0])) (3D Coulomb cone K)."""
    s = 0.0
    for a in range(mu.shape[0]):
        u1 = u[3 * a + 1]
        u2 = u[3 * a + 2]
        p0, p1, p2 = _proj_cone3(r[3 * a] - (u[3 * a] + mu[a] * np.sqrt(u1 * u1 + u2 * u2)),
                                 r[3 * a + 1] - u1, r[3 * a + 2] - u2, mu[a])
        f0 = r[3 * a] - p0
        f1 = r[3 * a + 1] - p1
        f2 = r[3 * a + 2] - p2
        s += f0 * f0 + f1 * f1 + f2 * f2
    return np.sqrt(s)


def old_natural_map_cohesive3(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta):
    """3D ‖F‖ of the transformed problem: F = P̃/σ - P_K(P̃/σ - (v + [μ‖v_T‖, 0, 0])), P̃ = P + P_adh(u(v)), σ the
    contact's gain (residual_scale); at a cap
    the Alart–Curnier residual (ρ = 1) with the normal projection onto [0, h f_c A] and the tangential one onto the
    disk of radius μ times it (zero exactly at the solutions)."""
    n = mu.shape[0]
    u = np.empty_like(q)
    matvec_bcsr(indptr, indices, blocks, r, u)
    s = 0.0
    for a in range(n):
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
        s += f0 * f0 + f1 * f1 + f2 * f2
    return np.sqrt(s)


def old_natural_map_cohesive(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta):
    """‖F‖ of the transformed problem: F = P̃/σ - P_K(P̃/σ - (v + [μ|v_T|, 0])), P̃ = P + P_adh(u(v)), σ the contact's
    gain (residual_scale; 1 for Coulomb contacts) (2D or 3D by the block size)."""
    if blocks.shape[1] == 3:
        return old_natural_map_cohesive3(indptr, indices, blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta)
    n = mu.shape[0]
    u = np.empty_like(q)
    matvec_bcsr(indptr, indices, blocks, r, u)
    s = 0.0
    for a in range(n):
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
            s += (p0 - y0) ** 2 + (p1 - y1) ** 2
            continue
        if capP > 0.0:  # capped cone: Alart–Curnier residual (rho = 1), zero exactly at the solutions
            y0 = min(max(p0 - v0, 0.0), capP)
            lim = m * y0
            y1 = min(max(p1 - v1, -lim), lim)
            f0 = p0 - y0
            f1 = p1 - y1
            s += f0 * f0 + f1 * f1
            continue
        y0, y1 = _proj_cone2(p0 - (v0 + m * abs(v1)), p1 - v1, m)
        f0 = p0 - y0
        f1 = p1 - y1
        s += f0 * f0 + f1 * f1
    return np.sqrt(s)


# ----------------------------------------------------------------------------- problems


def random_problem(n, dim, seed, codes=tuple(range(6))):
    """A random coupled contact problem with interface laws: W = A Aᵀ/m + 0.1 I (sparse blocks), q, r random of both
    signs; law codes drawn from `codes`; parameters, committed states and trial internal variables drawn so that
    every branch of the natural map occurs (tension/compression, broken, caps plain/elliptic/softening/hardening,
    compliant compression, damage-dependent friction)."""
    rng = np.random.default_rng(seed)
    m = dim * n
    A = np.zeros((m, m))
    for a in range(n):  # each contact coupled to a few others
        for b in rng.choice(n, 3):
            A[dim * a:dim * a + dim, dim * b:dim * b + dim] = rng.normal(size=(dim, dim))
    Wd = A @ A.T / 3 + 0.1 * np.eye(m)
    W = to_block_csr(Wd, dim)
    law = rng.choice(np.array(codes, dtype=np.int64), n)
    par = np.zeros((n, laws.NPAR))
    par[:, laws.P_MU] = rng.uniform(0.2, 0.8, n)
    par[:, laws.P_CN] = 10.0 ** rng.uniform(6, 9, n)
    par[:, laws.P_CT] = 10.0 ** rng.uniform(6, 9, n)
    par[:, laws.P_RC] = rng.uniform(1e3, 1e5, n)
    par[:, laws.P_SC] = np.where(rng.uniform(size=n) < 0.5, rng.uniform(1e3, 1e5, n), 0.0)
    par[:, laws.P_LC] = rng.uniform(1e-5, 1e-3, n)
    par[:, laws.P_W] = rng.uniform(0.5, 5.0, n)
    par[:, laws.P_P] = 1.0
    par[:, laws.P_FT] = rng.uniform(1e4, 1e5, n)
    par[:, laws.P_C] = rng.uniform(1e4, 1e5, n)
    par[:, laws.P_GI] = rng.uniform(5.0, 50.0, n)
    par[:, laws.P_GII] = rng.uniform(10.0, 100.0, n)
    par[:, laws.P_MUKIND] = rng.integers(0, 2, n)
    par[:, laws.P_MUR] = rng.uniform(0.3, 0.7, n)
    capped = rng.uniform(size=n) < 0.5
    par[:, laws.P_FC] = np.where(capped, rng.uniform(5e3, 5e4, n), 0.0)
    par[:, laws.P_CSS] = np.where(rng.uniform(size=n) < 0.5, rng.uniform(1.0, 9.0, n), 0.0)
    par[:, laws.P_GFC] = np.where(rng.uniform(size=n) < 0.5, rng.uniform(1.0, 10.0, n), 0.0)
    par[:, laws.P_KP] = np.where(rng.uniform(size=n) < 0.3, 1e-4, 0.0)
    par[:, laws.P_FCI] = par[:, laws.P_FC] / 3
    st = laws.initial_state(law, dim)
    st[:, laws.S_BROKEN] = rng.uniform(size=n) < 0.2
    st[:, laws.S_UP] = np.where(rng.uniform(size=n) < 0.5, -rng.uniform(0, 2e-4, n), 0.0)
    trial = np.where(rng.uniform(size=n) < 0.2, 0.0, rng.uniform(0, 1, n))
    ueff = rng.normal(size=(n, dim)) * 1e-4
    area = rng.uniform(0.005, 0.02, n)
    q = rng.normal(size=m)
    r = rng.normal(size=m) * np.repeat(rng.uniform(0.1, 2.0, n), dim)
    return W, q, par[:, laws.P_MU].copy(), r, law, par, st, trial, ueff, area


def in_order(t):
    """Σ t[α] added one by one in index order from 0.0 (the serial residual's summation)."""
    s = 0.0
    for i in range(t.shape[0]):
        s += t[i]
    return s


# ----------------------------------------------------------------------------- tests
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_coulomb_terms_sum_to_the_natural_map_bitwise(dim, seed):
    """natural_map_terms in order = natural_map = the old natural_map_2d/3d, bitwise (catches a term computed
    differently from the serial residual's, e.g. mu·u_T without the abs / the norm, or a reordered sum)."""
    rng = np.random.default_rng(seed)
    n = 3000
    r, u, mu = rng.normal(size=dim * n), rng.normal(size=dim * n), rng.uniform(0.0, 0.9, n)
    r[::7] = 0.0  # open contacts
    old = old_natural_map_2d(r, u, mu) if dim == 2 else old_natural_map_3d(r, u, mu)
    t = nlgs.natural_map_terms(r, u, mu, dim)
    assert t.shape == (n,) and np.all(t >= 0.0)
    assert nlgs.natural_map(r, u, mu, dim) == old
    assert np.sqrt(in_order(t)) == old


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("code", range(6))
def test_cohesive_terms_sum_to_the_natural_map_bitwise_per_law(dim, code):
    """Each law code alone (coulomb, elastic, brittle, dugdale, fremond, mixed), 2D and 3D: natural_map_cohesive =
    its old copy and = sqrt of its terms added in order, bitwise (catches a term of one branch computed with other
    arithmetic, e.g. the cap capP without its / σ, or the elliptic cap's squares written another way that rounds
    differently)."""
    for seed in range(3):
        W, q, mu, r, law, par, st, trial, ueff, area = random_problem(60, dim, 100 * code + seed, codes=(code,))
        for h, theta in ((1e-2, 1.0), (3e-3, 0.5)):
            args = (W.indptr, W.indices, W.blocks, q, mu, r, law, par, st, trial, ueff, area, h, theta)
            old = old_natural_map_cohesive(*args)
            assert np.isfinite(old) and old > 0.0
            assert nlgs.natural_map_cohesive(*args) == old
            t = nlgs.natural_map_cohesive_terms(*args)
            assert t.shape == (W.n,) and np.sqrt(in_order(t)) == old


@pytest.mark.parametrize("dim", [2, 3])
def test_cohesive_terms_mixed_laws_and_solver_residual(dim):
    """All the law codes mixed in one coupled problem, and at the impulses the cohesive NLGS returns (residual
    criterion): the solver's residual_abs is sqrt of the terms in order, bitwise (catches natural_map_cohesive and
    its terms diverging, e.g. the loop bound or the u = W r product of the terms taken differently)."""
    W, q, mu, r, law, par, st, trial, ueff, area = random_problem(200, dim, 7)
    args = (W.indptr, W.indices, W.blocks, q, mu)
    for h, theta in ((1e-2, 1.0), (1e-3, 0.5)):
        rest = (law, par, st, trial, ueff, area, h, theta)
        old = old_natural_map_cohesive(*args, r, *rest)
        assert nlgs.natural_map_cohesive(*args, r, *rest) == old
        assert np.sqrt(in_order(nlgs.natural_map_cohesive_terms(*args, r, *rest))) == old
    # at a solver's output (small problem, intact elastic and mixed joints and Coulomb contacts, caps included)
    W, q, mu, r, law, par, st, trial, ueff, area = random_problem(12, dim, 8, codes=(0, 1, 5))
    st[:, laws.S_BROKEN] = 0.0
    res, x = nlgs.solve_cohesive(W, q, mu, law, par, st, ueff, area, 1e-2, 1.0, tol=1e-8, criterion="residual",
                                 check_every=1, max_sweeps=3000)
    assert res.converged and res.residual_abs > 0.0
    args = (W.indptr, W.indices, W.blocks, q, mu, res.r, law, par, st, x, ueff, area, 1e-2, 1.0)
    assert np.sqrt(in_order(nlgs.natural_map_cohesive_terms(*args))) == res.residual_abs
    assert old_natural_map_cohesive(*args) == res.residual_abs


@pytest.mark.parametrize("dim", [2, 3])
def test_terms_of_owned_rows_are_the_global_terms(dim):
    """The rows of a rank (every third contact, local numbering owned then ghosts, W not square, r over owned and
    ghost columns, q and the law arrays of the owned contacts only) give the global terms of those contacts,
    bitwise; and the Coulomb terms likewise (catches the terms assuming a square matrix, e.g. u sized or looped
    over len(r) / len(q) instead of the rows, or σ read from a diagonal block searched by global number)."""
    W, q, mu, r, law, par, st, trial, ueff, area = random_problem(90, dim, 11)
    h, theta = 1e-2, 1.0
    full = nlgs.natural_map_cohesive_terms(W.indptr, W.indices, W.blocks, q, mu, r, law, par, st, trial, ueff, area,
                                           h, theta)
    for rank in range(3):
        owned = np.arange(rank, W.n, 3)
        rows = ds.local_rows(W, q, mu, owned)
        cols = np.concatenate([rows.owned, rows.ghost])
        assert rows.ghost.size > 0
        rl = r.reshape(-1, dim)[cols].ravel()
        t = nlgs.natural_map_cohesive_terms(rows.indptr, rows.indices, rows.blocks, rows.q, rows.mu, rl, law[owned],
                                            par[owned], st[owned], trial[owned], ueff[owned], area[owned], h, theta)
        assert np.array_equal(t, full[owned])
        u = np.empty(dim * W.n)
        matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
        ul = np.empty(dim * owned.size)
        matvec_bcsr(rows.indptr, rows.indices, rows.blocks, rl, ul)
        tc = nlgs.natural_map_terms(rl, ul + rows.q, rows.mu, dim)
        assert np.array_equal(tc, nlgs.natural_map_terms(r, u + q, mu, dim)[owned])

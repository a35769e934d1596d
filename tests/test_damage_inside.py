"""Mixed-mode damage inside the global Newton (solver/newton.py, damage_inside = True): the damage gradient of
laws.mixed_damage_gradient against finite differences of the law itself, the continuity of Newton's normal
function across u_N = 0 for compliant joints, and the coupled Newton against the staggered one on a small
softening problem and along a softening path (the same solutions as the staggered iteration, consistent damage,
natural map below the tolerance), and the fallback to the staggered iteration on a large step."""
import numpy as np
import pytest

from fem_blocks import laws
from fem_blocks.laws import MIXED, NSTATE, S_BETA
from fem_blocks.solver import newton, nlgs
from fem_blocks.linalg import to_block_csr

PAR = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6)


def _par(softening):
    code, p = laws.law_parameters("mixed", dict(PAR, softening=softening), "test")
    assert code == MIXED
    return p


@pytest.mark.parametrize("softening", ["linear", "exponential"])
def test_damage_value_and_gradient(softening):
    """D equals internal_update bitwise; ∂D/∂u matches central differences to 1e-6 (relative) in every mode,
    and vanishes below initiation, in compression (∂/∂u_N), at D = 1 and where the committed D0 governs."""
    p = _par(softening)
    dI, dII = p[laws.P_FT] / p[laws.P_CN], p[laws.P_C] / p[laws.P_CT]
    st = np.zeros(NSTATE)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(400):
        lam = rng.uniform(0.5, 12.0)
        ang = rng.uniform(-np.pi / 2, np.pi)  # u_N < 0 (compression) for ang > pi/2
        uN, uT = lam * np.cos(ang) * dI, lam * np.sin(ang) * dII
        for D0 in (0.0, 0.5):
            st[S_BETA] = D0
            D, gN, gT = laws.mixed_damage_gradient(p, D0, uN, uT)
            assert D == laws.internal_update(MIXED, p, st, uN, uT, 1e-3)  # the same value, to the last bit
            hN, hT = 1e-7 * dI, 1e-7 * dII
            fdN = (laws.internal_update(MIXED, p, st, uN + hN, uT, 1e-3)
                   - laws.internal_update(MIXED, p, st, uN - hN, uT, 1e-3)) / (2 * hN)
            fdT = (laws.internal_update(MIXED, p, st, uN, uT + hT, 1e-3)
                   - laws.internal_update(MIXED, p, st, uN, uT - hT, 1e-3)) / (2 * hT)
            # skip the kinks (initiation λ = 1, D = D0, D = 1, u_N = 0) where one-sided slopes differ
            Dp = [laws.internal_update(MIXED, p, st, uN + s * hN, uT + t * hT, 1e-3) for s in (-1, 1) for t in (-1, 1)]
            smooth = (abs(uN) > 1e-5 * dI and D0 < min(Dp) and max(Dp) < 1.0
                      and (max(uN, 0) / dI) ** 2 + (uT / dII) ** 2 > 1.0 + 1e-5)
            if smooth:
                checked += 1
                scale = abs(fdN) * dI + abs(fdT) * dII
                assert abs(gN - fdN) * dI <= 1e-6 * scale
                assert abs(gT - fdT) * dII <= 1e-6 * scale
            elif D == D0 or D == 1.0:
                assert gN == 0.0 and gT == 0.0
            if uN < 0.0:
                assert gN == 0.0
    assert checked > 150


def test_newton_normal_function_is_continuous_at_closure():
    """One compliant joint held in compression: Newton's function F(P) does not jump when the jump u_N crosses 0
    (the compliance acts on P̃_N in both branches; P̃_N = P_N + h A (1 - D) k_n u_N⁺ is continuous)."""
    p = _par("linear")
    law = np.array([MIXED])
    par = p[None, :].copy()
    st = laws.initial_state(law)
    st[0, S_BETA] = 0.3
    h, th, area = 1e-3, 1.0, np.array([1e-3])
    ueff = np.zeros((1, 2))
    W = to_block_csr(np.array([[2.0, 0.3], [0.3, 1.5]]), 2)
    rn, rt = newton._rho(W)
    P = np.array([5.0, 1.0])

    def terms(vN):
        v = np.array([vN, 0.0])
        S, c, m, cmp, cap, T = np.zeros((1, 2)), np.zeros((1, 2)), np.zeros(1), np.zeros(1), np.zeros(1), \
            np.zeros((1, 2, 2))
        newton._cohesive_terms(law, par, st, st[:, S_BETA].copy(), ueff, v, area, h, th, S, c, m, cmp, cap, True, T)
        return v, S, c, m, cmp, cap

    S0 = terms(1e-3)[1]  # ρ fixed once per solve, as in _newton
    rho_n, rho_t = rn + S0[:, 0], rt + S0[:, 1]

    def F(vN):
        v, S, c, m, cmp, cap = terms(vN)
        Pt = P + S[0] * v + c[0]
        vp = v.copy()
        vp[0] += cmp[0] * Pt[0]
        return newton.alart_curnier(Pt, vp, m, rho_n, rho_t, cap=cap)

    for eps in (1e-6, 1e-9, 1e-12):
        jump = np.abs(F(eps) - F(-eps)).max()
        assert jump <= 1e3 * eps * (1 + np.abs(F(eps)).max())


def _softening_problem(n=24, seed=5, scale=400.0):
    """A small random problem (SPD W, stiff mixed-mode joints: h²θ k A W ≈ 100) loaded in one step hard enough
    to break three joints outright (D: 0 -> 1), where the coupled iteration jumps between softening branches."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((2 * n, 3 * n)) * (rng.random((2 * n, 3 * n)) < 0.1)
    W = A @ A.T + np.diag(1 + rng.random(2 * n))
    law = np.full(n, MIXED)
    par = np.tile(_par("linear"), (n, 1))
    par[:, laws.P_FC] = 0.0
    st = laws.initial_state(law)
    dI = PAR["f_t"] / PAR["k_n"]
    h, th = 1e-3, 1.0
    q = rng.standard_normal(2 * n) * scale * dI / (h * th)
    return to_block_csr(W, 2), q, np.full(n, PAR["tan_phi"]), law, par, st, np.zeros((n, 2)), \
        np.full(n, 1e-3), h, th


def test_large_step_falls_back_to_the_staggered_solution():
    """Coupled pass unconverged -> staggered from the committed state: the staggered solution, reported."""
    W, q, mu, law, par, st, ueff, area, h, th = _softening_problem()
    tol = 1e-10
    a, xa = newton.solve_cohesive_newton(W, q, mu, law, par, st, ueff, area, h, th, tol=tol, damage_inside=True)
    b, xb = newton.solve_cohesive_newton(W, q, mu, law, par, st, ueff, area, h, th, tol=tol, damage_inside=False)
    assert a.converged and b.converged
    assert "staggered instead" in a.message
    assert np.sum(xa == 1.0) == 3
    assert np.linalg.norm(a.r - b.r) <= 1e-9 * np.linalg.norm(b.r)
    assert np.array_equal(xa, xb)
    x = st[:, S_BETA].copy()  # the returned damage is the law's value at the returned jumps
    nlgs._update_internal(law, par, st, ueff, a.u, h, th, x)
    assert np.array_equal(x, xa)
    res = nlgs.natural_map_cohesive(W.indptr, W.indices, W.blocks, q, mu, a.r, law, par, st, x, ueff, area, h, th)
    assert res <= tol * np.linalg.norm(q)


@pytest.mark.parametrize("softening", ["linear", "exponential"])
def test_coupled_and_staggered_damage_give_the_same_path(monkeypatch, softening):
    """A rigid block on a mixed-mode joint, driven along a mixed opening/sliding path through the softening
    branch (test_laws.test_mixed_path_dissipates_between_modes, 400 steps): the coupled iteration converges at
    every step, and the reactions (1e-8 relative to the peak) and damage (1e-8) equal the staggered ones at every
    step up to the first where the staggered iteration misses its stationarity test (none for linear softening)."""
    import functools
    import os
    import sys
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import test_laws as tl
    from fem_blocks.contact.step import ContactStep
    orig = ContactStep.__init__

    def init(self, *a, **k):
        orig(self, *a, **k)
        self.opts.solver = "newton"
    monkeypatch.setattr(ContactStep, "__init__", init)
    prm = dict(tl.MIXED, softening=softening)
    umax = 40 * prm["G_II"] / prm["c"]
    n = 400
    hist = {}
    base_solver = newton.solve_cohesive_newton
    for inside in (True, False):
        monkeypatch.setattr(newton, "solve_cohesive_newton", functools.partial(base_solver, damage_inside=inside))
        blk, base, cs, sim = tl.joint("mixed", prm, h=1.0 / n, drivers=tl.driven({"x": tl.ramp([0, umax], [0, 1]),
                                                                                  "y": tl.ramp([0, umax / 4], [0, 1])}))
        R, D, ok = [], [], []
        for _ in range(n):
            info = sim.step()
            R.append(blk.reaction[:2].copy())
            D.append(cs.state[:, S_BETA].copy())
            ok.append(info.contact["converged"])
        hist[inside] = (np.array(R), np.array(D), np.array(ok))
    (Ra, Da, oka), (Rb, Db, okb) = hist[True], hist[False]
    assert oka.all()  # the coupled iteration converges at every step
    # the staggered one may miss its stationarity test (x change <= 1e-12) on the exponential tail; as long as
    # it converges, the two paths agree
    first_miss = int(np.argmin(okb)) if not okb.all() else n
    assert first_miss >= 100
    Ra, Da, Rb, Db = Ra[:first_miss], Da[:first_miss], Rb[:first_miss], Db[:first_miss]
    assert np.any((Da > 0.05) & (Da < 0.95))  # steps on the softening branch
    assert np.abs(Ra - Rb).max() <= 1e-8 * np.abs(Rb).max()
    assert np.abs(Da - Db).max() <= 1e-8

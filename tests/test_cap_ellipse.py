"""Elliptic cap (`C_ss` > 0 on the mixed law, docs/laws.md "Elliptic cap"): admissible impulses
K = {P_N² + C_ss |P_T|² <= (h f_c A)², |P_T| <= μ P_N, P_N >= 0}, associated flow on the ellipse, Coulomb inside.

Closed forms and independent references: the crushing shear of a joint under a fixed compression
τ = sqrt((f_c² - σ²)/C_ss); the local projection against a brute-force minimisation of the W-metric distance over the
ellipse arc; the corner's multipliers; the Newton rows against finite differences; C_ss -> 0 against today's cap."""
import numpy as np
import pytest
from scipy.optimize import brentq

from fem_blocks.bodies import Driver, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.laws import P_CSS, S_BETA, S_DISS, S_UP, S_UT, law_parameters
from fem_blocks.solver import nlgs
from fem_blocks.solver.newton import alart_curnier, compliant_rows

L, T, H_BLK, RHO = 0.2, 0.1, 0.1, 2000.0
A = L * T
M = RHO * L * H_BLK * T
FC = 1e6
KN, KS = 1e11, 5e10
MIXED = dict(k_n=KN, k_s=KS, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.75)


def couplet(params, solver, sigma, h=1e-2):
    """A rigid block on a fixed base through one mixed-law joint point (tributary area A), pressed by σ A, free
    horizontally (rotation blocked)."""
    forces = {"y": -sigma * A, "x": 0.0}
    blk = RigidBody([(0, 0), (L, 0), (L, H_BLK), (0, H_BLK)], rho=RHO, thickness=T,
                    drivers={"rz": Driver("velocity", 0.0)}, forces=forces)
    fix = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}
    base = RigidBody([(-0.1, -0.1), (0.3, -0.1), (0.3, 0), (-0.1, 0)], drivers=fix, thickness=T)
    cs = ContactStep([InterfaceSpec("j", ("b", "g"), law="mixed", params=dict(MIXED, f_c=FC, **params),
                                   placement="positions", positions=(0.5,))],
                     ["b", "g"], ContactOptions(tol=1e-12, max_sweeps=2000, criterion="residual", solver=solver))
    sim = Simulation([blk, base], h=h, theta=1.0, contact=cs, gravity=(0.0, 0.0), velocity_reset=True)
    return blk, cs, sim


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_joint_crushes_at_the_elliptic_cap_under_shear(solver):
    """σ = 0.9 f_c held, a horizontal force F = τ A: the joint sticks (friction carries τ, |τ| < μσ) and holds
    while σ² + C_ss τ² <= f_c², i.e. up to τ* = sqrt((f_c² - σ²)/C_ss) (0.145 f_c < μσ = 0.675 f_c): no closure at
    τ*(1 - 1e-6) (round-off only: the stick solution's v'_N is a cancellation of two 45 m/s terms), a closure at
    τ*(1 + 1e-6) (≈ 2e-12 m, estimated from the projection). At 1.3 τ* the traction lands on the ellipse and the flow
    is associated: Δu_T/|Δu_p| = C_ss |τ̃|/σ̃, and the dissipation is the cap's work (σ̃ |Δu_p| + |τ̃| Δu_T) A
    (τ̃ = r̃_T/A, the frictional part: r̃_T = r_T + (1 - D) k_s u_T A)."""
    css, sigma = 9.0, 0.9 * FC
    tau_star = np.sqrt((FC ** 2 - sigma ** 2) / css)
    blk, cs, sim = couplet(dict(C_ss=css), solver, sigma)
    for _ in range(6):
        sim.step()
    assert sim.last_contact.stats["converged"]
    assert sim.last_contact.r[0, 0] == pytest.approx(sigma * A, rel=1e-12)
    blk.set_force("x", tau_star * (1 - 1e-6) * A)
    for _ in range(3):
        sim.step()
        assert sim.last_contact.stats["converged"]
    assert abs(cs.state[0, S_UP]) < 1e-15              # below the ellipse: no crushing, stick
    assert abs(sim.last_contact.r[0, 1]) == pytest.approx(tau_star * (1 - 1e-6) * A, rel=1e-10)
    assert blk.q[0] == pytest.approx(0.0, abs=1e-15)
    blk.set_force("x", tau_star * (1 + 1e-6) * A)
    sim.step()
    assert sim.last_contact.stats["converged"]
    assert cs.state[0, S_UP] < -5e-13                   # crushed just above τ*
    up0, x0, diss0 = cs.state[0, S_UP], blk.q[0], cs.state[0, S_DISS]
    blk.set_force("x", 1.3 * tau_star * A)
    sim.step()
    assert sim.last_contact.stats["converged"]
    dup, dx = cs.state[0, S_UP] - up0, blk.q[0] - x0
    assert dup < 0.0 and dx > 0.0
    assert cs.state[0, S_BETA] == 0.0                   # no damage: the slip is below δ_II = c/k_s
    rn, rt = sim.last_contact.r[0]
    rt_tilde = abs(rt + (1 - cs.state[0, S_BETA]) * KS * cs.state[0, S_UT] * A)
    assert rn ** 2 + css * rt_tilde ** 2 == pytest.approx((FC * A) ** 2, rel=1e-8)
    assert dx / abs(dup) == pytest.approx(css * rt_tilde / rn, rel=1e-6)      # associated flow
    assert cs.state[0, S_DISS] - diss0 == pytest.approx(rn * abs(dup) + rt_tilde * dx, rel=1e-6)


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_crushing_shear_lower_pressure(solver):
    """The same couplet at σ = 0.5 f_c: τ* = sqrt(0.75/9) f_c = 0.289 f_c (< μσ = 0.375 f_c): no closure at
    τ*(1 - 1e-6), a closure at τ*(1 + 1e-6); with C_ss = 0 no closure at 1.2 τ* (the cap bounds σ only)."""
    css, sigma = 9.0, 0.5 * FC
    tau_star = np.sqrt((FC ** 2 - sigma ** 2) / css)
    for c, f, crushed in ((css, 1 - 1e-6, False), (css, 1 + 1e-6, True), (0.0, 1.2, False)):
        blk, cs, sim = couplet(dict(C_ss=c), solver, sigma)
        for _ in range(5):
            sim.step()
        blk.set_force("x", tau_star * f * A)
        for _ in range(2):
            sim.step()
            assert sim.last_contact.stats["converged"]
        assert (cs.state[0, S_UP] < -5e-13) == crushed
        if not crushed:
            assert abs(cs.state[0, S_UP]) < 1e-15


# ----------------------------------------------------------------------------- the local solve
def _spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + 0.2 * n * np.eye(n)


def _arc_min(Ms, pstar, Pc, css, mu):
    """Brute force: min over the ellipse arc inside the cone of (P - P*)ᵀ M (P - P*), P(t) = (Pc cos t, Pc sin t/√C_ss),
    |t| <= atan(μ √C_ss): dense sampling, then the zero of the derivative between the best sample's neighbours."""
    tc = np.arctan(mu * np.sqrt(css))
    t = np.linspace(-tc, tc, 200001)
    x, y = Pc * np.cos(t) - pstar[0], Pc * np.sin(t) / np.sqrt(css) - pstar[1]
    d = Ms[0, 0] * x * x + (Ms[0, 1] + Ms[1, 0]) * x * y + Ms[1, 1] * y * y  # (P - P*)ᵀ M (P - P*) written out
    k = int(np.argmin(d))  # (np.einsum's general path took 3 of the test's 4 s; the same minimisers, bit for bit)
    lo, hi = t[max(k - 1, 0)], t[min(k + 1, len(t) - 1)]

    def g(s):  # d/dt of the distance (its zero: the minimiser, to round-off rather than to √ε as by values)
        p = np.array([Pc * np.cos(s), Pc * np.sin(s) / np.sqrt(css)]) - pstar
        dp = np.array([-Pc * np.sin(s), Pc * np.cos(s) / np.sqrt(css)])
        return 2.0 * dp @ Ms @ p
    s = brentq(g, lo, hi, xtol=1e-15, rtol=1e-15) if g(lo) * g(hi) < 0 else t[k]
    return np.array([Pc * np.cos(s), Pc * np.sin(s) / np.sqrt(css)]), k in (0, len(t) - 1)


def test_local_cap_solve_is_the_w_metric_projection_on_the_ellipse_face():
    """Random SPD blocks M and free velocities q whose Signorini–Coulomb solution is outside the ellipse: where the
    solve returns a point of the ellipse strictly inside the cone, it is the minimiser of the M-distance to the stick
    point P* = -M⁻¹q over K (brute force over the arc), to 1e-8; at the corner its multipliers λ, γ are >= 0; and
    every returned P is a zero of the residual ‖P - Π(P - v)‖ (the natural map of nlgs)."""
    rng = np.random.default_rng(7)
    n_face = n_corner = 0
    for _ in range(400):
        Ms = _spd(rng, 2)
        css = float(rng.uniform(0.5, 20.0))
        mu = float(rng.uniform(0.1, 1.2))
        Pc = 1.0
        pstar = np.array([rng.uniform(0.6, 2.5), rng.uniform(-2.0, 2.0)])
        q = -Ms @ pstar
        pn, pt, case = nlgs.local_2d(Ms[0, 0], Ms[0, 1], Ms[1, 0], Ms[1, 1], q[0], q[1], mu)
        if pn * pn + css * pt * pt <= Pc * Pc:
            continue
        p = np.array(nlgs._cap_ell(pn, pt, Ms[0, 0], Ms[0, 1], Ms[1, 0], Ms[1, 1], q[0], q[1], mu, Pc, css))
        v = Ms @ p + q
        y = nlgs.ellcone_proj2(p[0] - v[0], p[1] - v[1], 1.0, 1.0, Pc, css, mu)
        assert np.hypot(p[0] - y[0], p[1] - y[1]) <= 1e-12 * (1 + np.abs(pstar).sum())
        assert p[0] ** 2 + css * p[1] ** 2 == pytest.approx(Pc ** 2, rel=1e-12)
        if abs(p[1]) < mu * p[0] * (1 - 1e-9):
            ref, at_end = _arc_min(Ms, pstar, Pc, css, mu)
            assert not at_end
            assert np.abs(p - ref).max() <= 1e-8 * Pc
            n_face += 1
        else:
            s = np.sign(p[1])
            lam = -v[0] / p[0]
            gam = -s * (v[1] + lam * css * p[1])
            assert lam >= -1e-12 and gam >= -1e-12
            n_corner += 1
    assert n_face >= 50 and n_corner >= 20


def test_local_cap_solve_3d_kkt_and_embedding():
    """3D (_cap3_ell): on the ellipse face the solution satisfies the optimality conditions of the M'-metric
    projection (P on the ellipsoid, M'(P - P*) = -λ G P, λ >= 0: sufficient for the convex set); a 2D problem
    embedded in 3D (s decoupled, q_S = 0) gives the 2D solution."""
    rng = np.random.default_rng(11)
    n_face = 0
    for _ in range(300):
        Ms = _spd(rng, 3)
        css = float(rng.uniform(0.5, 20.0))
        mu = float(rng.uniform(0.1, 1.2))
        pstar = np.array([rng.uniform(0.6, 2.5), rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)])
        q = -Ms @ pstar
        w = Ms[None].copy()
        c = nlgs.local_3d(w, 0, q[0], q[1], q[2], mu, 0.0, 0.0, 0.0, np.zeros((3, 3)))
        if c[0] ** 2 + css * (c[1] ** 2 + c[2] ** 2) <= 1.0:
            continue
        p = np.array(nlgs._cap3_ell(w, 0, 0.0, c[0], c[1], c[2], q[0], q[1], q[2], mu, 1.0, css))
        assert p[0] ** 2 + css * (p[1] ** 2 + p[2] ** 2) == pytest.approx(1.0, rel=1e-12)
        if np.hypot(p[1], p[2]) < mu * p[0] * (1 - 1e-9):
            g = Ms @ (p - pstar)
            G = np.array([1.0, css, css]) * p
            lam = -(g @ G) / (G @ G)
            assert lam >= 0.0
            assert np.abs(g + lam * G).max() <= 1e-9 * np.abs(g).max()
            n_face += 1
        v = Ms @ p + q
        y = nlgs.ellcone_proj3(p[0] - v[0], p[1] - v[1], p[2] - v[2], 1.0, css, mu)
        assert np.abs(p - np.array(y)).max() <= 1e-10 * (1 + np.abs(pstar).sum())
    assert n_face >= 50
    for _ in range(50):
        M2 = _spd(rng, 2)
        css, mu = float(rng.uniform(0.5, 20.0)), float(rng.uniform(0.1, 1.2))
        q = -M2 @ np.array([rng.uniform(0.6, 2.5), rng.uniform(-2.0, 2.0)])
        M3 = np.zeros((1, 3, 3))
        M3[0, :2, :2] = M2
        M3[0, 2, 2] = 1.0
        c2 = nlgs.local_2d(M2[0, 0], M2[0, 1], M2[1, 0], M2[1, 1], q[0], q[1], mu)
        c3 = nlgs.local_3d(M3, 0, q[0], q[1], 0.0, mu, 0.0, 0.0, 0.0, np.zeros((3, 3)))
        assert np.abs(np.array(c2[:2]) - np.array(c3[:2])).max() <= 1e-9 and c3[2] == 0.0
        p2 = nlgs._cap_ell(c2[0], c2[1], M2[0, 0], M2[0, 1], M2[1, 0], M2[1, 1], q[0], q[1], mu, 1.0, css)
        p3 = nlgs._cap3_ell(M3, 0, 0.0, c3[0], c3[1], c3[2], q[0], q[1], 0.0, mu, 1.0, css)
        assert np.abs(np.array(p2) - np.array(p3[:2])).max() <= 1e-9 and p3[2] == 0.0


# ----------------------------------------------------------------------------- Newton rows
def test_newton_rows_of_the_elliptic_cap_against_finite_differences():
    """alart_curnier and compliant_rows with C_ss > 0: J = D + E W of the rows (all three regions of Π) against
    central differences of F in (P, v) (P̃ = P + S v + T v + c for compliant_rows)."""
    rng = np.random.default_rng(3)
    n = 60
    mu = rng.uniform(0.2, 1.0, n)
    css = rng.uniform(1.0, 12.0, n)
    cap = rng.uniform(0.5, 2.0, n)
    rn, rt = rng.uniform(0.5, 3.0, n), rng.uniform(0.5, 3.0, n)
    r = np.column_stack([rng.uniform(0.0, 3.0, n), rng.uniform(-2.0, 2.0, n)]).ravel()
    u = rng.normal(scale=0.5, size=2 * n)
    F, D, E = alart_curnier(r, u, mu, rn, rt, jacobian=True, cap=cap, css=css)
    eps = 1e-7
    for j in range(2):
        e = np.zeros((n, 2))
        e[:, j] = eps
        e = e.ravel()
        dFr = (alart_curnier(r + e, u, mu, rn, rt, cap=cap, css=css)
               - alart_curnier(r - e, u, mu, rn, rt, cap=cap, css=css)) / (2 * eps)
        dFu = (alart_curnier(r, u + e, mu, rn, rt, cap=cap, css=css)
               - alart_curnier(r, u - e, mu, rn, rt, cap=cap, css=css)) / (2 * eps)
        assert np.abs(dFr.reshape(-1, 2) - D[:, :, j]).max() <= 1e-6
        assert np.abs(dFu.reshape(-1, 2) - E[:, :, j]).max() <= 1e-6
    # compliant rows: the jump u_N = u_eff + hθ v_N, k_c = 1/cmp
    h, theta = 0.01, 1.0
    cmp = rng.uniform(0.2, 2.0, n)
    ueffN = rng.normal(scale=0.02, size=n)
    S = rng.uniform(0.0, 1.0, (n, 2))
    Tm = rng.normal(scale=0.2, size=(n, 2, 2))
    c = rng.normal(size=(n, 2))
    P = r.copy()
    v = rng.normal(scale=1.5, size=2 * n)

    def rows(P_, v_, jac=False):
        Pt = P_.reshape(-1, 2) + S * v_.reshape(-1, 2) + np.einsum("kij,kj->ki", Tm, v_.reshape(-1, 2)) + c
        return compliant_rows(Pt.ravel(), v_, ueffN, h, theta, cmp, cap, mu, rt, S, Tm, jac, css=css)
    F, D, E = rows(P, v, True)
    for j in range(2):
        e = np.zeros((n, 2))
        e[:, j] = eps
        e = e.ravel()
        dFP = (rows(P + e, v) - rows(P - e, v)) / (2 * eps)
        dFv = (rows(P, v + e) - rows(P, v - e)) / (2 * eps)
        assert np.abs(dFP.reshape(-1, 2) - D[:, :, j]).max() <= 1e-6
        assert np.abs(dFv.reshape(-1, 2) - E[:, :, j]).max() <= 1e-5 * (1 + np.abs(E).max())


# ----------------------------------------------------------------------------- C_ss -> 0 and C_ss = 0
@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_vanishing_css_gives_todays_cap(solver):
    """A block pressed by 3 f_c A and pushed by 0.9 f_c A (> μ f_c A = 0.75 f_c A: it slides at the cap corner): C_ss = 1e-12
    (the elliptic code) gives today's cap (C_ss = 0) to 1e-9 (the position to the slip of order C_ss μ |u_p| the
    associated flow adds); C_ss = 0 given explicitly is the default, bitwise."""
    out = []
    for c in (None, 0.0, 1e-12):
        blk, cs, sim = couplet({} if c is None else dict(C_ss=c), solver, 3 * FC)
        blk.set_force("x", 0.9 * FC * A)
        for _ in range(4):
            sim.step()
            assert sim.last_contact.stats["converged"]
        out.append((sim.last_contact.r.copy(), cs.state.copy(), blk.q.copy()))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
    assert np.array_equal(out[0][2], out[1][2])
    assert out[0][0][0, 0] == pytest.approx(FC * A, rel=1e-10)
    rt_tilde = abs(out[0][0][0, 1] + (1 - out[0][1][0, S_BETA]) * KS * out[0][1][0, S_UT] * A)
    assert rt_tilde == pytest.approx(0.75 * FC * A, rel=1e-9)   # friction on r̃ at the cap corner: μ f_c A
    np.testing.assert_allclose(out[2][0], out[0][0], rtol=1e-9)
    np.testing.assert_allclose(out[2][1][0, S_UP], out[0][1][0, S_UP], rtol=1e-9)
    np.testing.assert_allclose(out[2][1][0, S_DISS], out[0][1][0, S_DISS], rtol=1e-9)
    # the block's position: the associated flow adds a slip λ C_ss |P̃_T| hθ ≈ C_ss μ |Δu_p| ≈ 3e-12 m per 4 m of closure
    np.testing.assert_allclose(out[2][2], out[0][2], rtol=1e-9, atol=10 * 1e-12 * 0.75 * abs(out[0][1][0, S_UP]))


def test_css_parameter_validated():
    code, p = law_parameters("mixed", dict(MIXED, f_c=1e7, C_ss=9.0), "interfaces.j")
    assert p[P_CSS] == 9.0
    code, p = law_parameters("mixed", dict(MIXED, f_c=1e7), "interfaces.j")
    assert p[P_CSS] == 0.0
    for bad in (-1.0, float("inf"), float("nan")):
        with pytest.raises(InputError, match=r"interfaces\.j\.C_ss"):
            law_parameters("mixed", dict(MIXED, f_c=1e7, C_ss=bad), "interfaces.j")
    with pytest.raises(InputError, match=r"interfaces\.j\.C_ss: needs the compressive strength f_c"):
        law_parameters("mixed", dict(MIXED, C_ss=9.0), "interfaces.j")
    with pytest.raises(InputError, match=r"interfaces\.j\.C_ss: unknown parameter for law 'coulomb'"):
        law_parameters("coulomb", dict(mu=0.5, f_c=1e7, C_ss=9.0), "interfaces.j")

"""NLGS 2D/3D: exact local cases, small closed-form problems, determinism, warm start, input validation.
The FCLIB problems are in test_fclib.py."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.errors import InputError
from fem_blocks.io import fclib
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import ContactProblem, SolverOptions, local as loc, nlgs, solve


def face_solve(W, q, mu, dim=None, r0=None, **options):
    """The public face solve(ContactProblem, SolverOptions) with the defaults of the former nlgs.solve (tol 1e-8,
    10000 sweeps, the residual checked every sweep)."""
    options = {**dict(tol=1e-8, max_sweeps=10000, check_every=1), **options}
    return solve(ContactProblem(W, q, mu, dim), SolverOptions(**options), r0=r0)


@pytest.mark.parametrize("q, mu, expect_case", [
    ((1.0, 0.3), 0.5, 0),      # open: q_N >= 0
    ((-1.0, 0.1), 0.5, 1),     # stick
    ((-1.0, 5.0), 0.5, 2),     # large positive tangential free velocity: slides forward
    ((-1.0, -5.0), 0.5, 2),
])
def test_local_2d_cases(q, mu, expect_case):
    W = np.array([[2.0, 0.3], [0.3, 1.5]])
    rn, rt, case = nlgs.local_2d(W[0, 0], W[0, 1], W[1, 0], W[1, 1], q[0], q[1], mu)
    r = np.array([rn, rt])
    v = W @ r + np.array(q)
    assert rn >= 0 and abs(rt) <= mu * rn * (1 + 1e-14)
    if case == 0:
        assert rn == rt == 0 and v[0] >= 0
    elif case == 1:
        assert np.allclose(v, 0, atol=1e-14)
    else:
        assert abs(v[0]) < 1e-14 and abs(abs(rt) - mu * rn) < 1e-14 and rt * v[1] <= 0
    # slide direction: friction opposes sliding; v_T > 0 is case 2 (forward)
    if case in (2, 3):
        assert (v[1] > 0) == (case == 2)


def test_block_on_two_supports_sum_of_reactions():
    """A rigid bar (mass m, inertia I) on two frictionless contacts at x = -a, +a, pushed down by an impulse
    p at x = c: the reactions sum to p and their moment balances p c (the bar stops)."""
    m, I, a, c, p = 2.0, 0.5, 0.4, 0.1, 3.0
    # contact normal velocity v_N = vy + omega x ; W = G M^-1 G^T
    G = np.array([[0.0, 1.0, -a], [1.0, 0.0, 0.0], [0.0, 1.0, a], [1.0, 0.0, 0.0]])
    Minv = np.diag([1 / m, 1 / m, 1 / I])
    W = G @ Minv @ G.T
    v_free = Minv @ np.array([0.0, -p, -p * c])
    q = G @ v_free
    res = face_solve(W, q, mu=0.0, tol=1e-14, max_sweeps=10000)
    r = res.r.reshape(-1, 2)
    assert res.converged
    assert r[:, 0].sum() == pytest.approx(p, rel=1e-12)
    assert (r[1, 0] - r[0, 0]) * a == pytest.approx(p * c, rel=1e-10)
    assert np.allclose(res.u[0::2], 0.0, atol=1e-12)


def test_incline_one_step_sliding():
    """Particle on a plane inclined by alpha (local frame of the plane), one step h: with mu < tan(alpha) the
    tangential velocity gains h g (sin a - mu cos a); with mu > tan(alpha) it sticks."""
    g, h, m, alpha = 9.81, 1e-2, 3.0, np.deg2rad(30)
    W = np.eye(2) / m * h / h  # impulse in N s: v = v0 + P / m
    q = np.array([-h * g * np.cos(alpha), h * g * np.sin(alpha)])  # free velocity after one step (normal, tangent)
    for mu, vt in ((0.3, h * g * (np.sin(alpha) - 0.3 * np.cos(alpha))), (0.7, 0.0)):
        res = face_solve(W / m * m, q, mu=mu, tol=1e-14)
        assert res.u[1] == pytest.approx(vt, abs=1e-14)
        assert res.u[0] == pytest.approx(0.0, abs=1e-14)
        assert res.r[0] == pytest.approx(m * h * g * np.cos(alpha), rel=1e-14)


def random_problem(n=60, seed=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((2 * n, 3 * n)) * (rng.random((2 * n, 3 * n)) < 0.05)
    W = A @ A.T + np.diag(1 + rng.random(2 * n))
    q = rng.standard_normal(2 * n)
    return W, q


def test_orders_converge_and_are_deterministic():
    W, q = random_problem()
    base = None
    for order in ("given", "reversed", "shuffled"):
        r1 = face_solve(W, q, 0.4, tol=1e-12, order=order, seed=7, criterion="residual")
        r2 = face_solve(W, q, 0.4, tol=1e-12, order=order, seed=7, criterion="residual")
        assert r1.converged and r1.residual <= 1e-12
        assert np.array_equal(r1.r, r2.r)  # bitwise reproducible
        # the solver's reported residual against the independent numpy natural map of io/fclib.residual
        R = fclib.residual(W, q, 0.4, r1.r, dim=2)
        assert R.rel_q <= 1e-12 and r1.residual == pytest.approx(R.rel_q, rel=1e-6, abs=1e-15)
        base = r1.r if base is None else base
        assert np.allclose(r1.r, base, atol=1e-9)  # unique solution here (W SPD, small mu)
    s1 = face_solve(W, q, 0.4, tol=1e-12, order="shuffled", seed=1)
    s2 = face_solve(W, q, 0.4, tol=1e-12, order="shuffled", seed=2)
    assert s1.sweeps != s2.sweeps or not np.array_equal(s1.r, s2.r)


def test_warm_start_and_relaxation():
    W, q = random_problem(seed=5)
    cold = face_solve(W, q, 0.3, tol=1e-10)
    warm = face_solve(W, q, 0.3, tol=1e-10, r0=cold.r)
    assert warm.sweeps <= 2 < cold.sweeps
    relaxed = face_solve(W, q, 0.3, tol=1e-10, omega=0.8, criterion="residual")
    assert relaxed.converged and relaxed.residual <= 1e-10


def test_nonconvergence_reported_not_raised():
    W, q = random_problem(seed=6)
    res = face_solve(W, q, 0.3, tol=1e-15, max_sweeps=3)
    assert not res.converged and res.sweeps == 3 and "not converged after 3 sweeps" in res.message


@pytest.mark.parametrize("kwargs, match", [
    (dict(mu=-0.1), "mu: expected friction coefficients >= 0"),
    (dict(tol=0.0), "tol = 0.0: expected tol > 0"),
    (dict(omega=2.5), "omega = 2.5"),
    (dict(order="random"), "order = 'random'"),
    (dict(max_sweeps=0), "max_sweeps = 0"),
    (dict(dim=4), "dim = 4: expected 2 or 3"),
    (dict(omega=0.0), "omega = 0.0: expected 0 < omega < 2"),
    (dict(criterion="both"), "criterion = 'both'"),
    (dict(check_every=0), "check_every = 0"),
    (dict(mu=[0.1, 0.2]), "mu: expected a scalar or 3 friction"),
    (dict(r0=np.zeros(5)), "r0: expected 6 entries"),
])
def test_bad_arguments(kwargs, match):
    W, q = random_problem(n=3)
    args = dict(mu=0.3)
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        face_solve(W, q, **args)
    with pytest.raises(InputError, match="q: expected 6 entries"):
        face_solve(W, q[:-1], 0.3)
    # the kernel's own checks (reached without SolverOptions)
    with pytest.raises(InputError, match="omega = 0.0: expected 0 < omega <= 2"):
        nlgs.solve_block_csr(to_block_csr(W, 2), q, 0.3, omega=0.0)



def test_bad_arguments_3d_and_block_csr():
    W, q = random_problem(n=3)  # 6 x 6: two 3D contacts or three 2D contacts
    with pytest.raises(InputError, match=r"W: expected a square matrix of size dim \* n_contacts"):
        face_solve(W[:5, :5], q[:5], 0.3, dim=3)
    with pytest.raises(InputError, match="q: expected finite values"):
        face_solve(W, np.full(6, np.nan), 0.3, dim=3)
    with pytest.raises(InputError, match="r0: expected finite values"):
        face_solve(W, q, 0.3, dim=3, r0=np.full(6, np.inf))
    B2 = to_block_csr(W, 2)
    with pytest.raises(InputError, match="dim = 3: W is a BlockCSR of 2x2 blocks"):
        face_solve(B2, q, 0.3, dim=3)


# ----------------------------------------------------------------------------- 3D local solver
J = np.empty((3, 3))


def local3(W, q, mu, guess=(0.0, 0.0, 0.0)):
    W = np.asarray(W, dtype=float)[None].copy()
    r0, r1, r2, case = loc.local_3d(W, 0, q[0], q[1], q[2], mu, guess[0], guess[1], guess[2], J)
    return np.array([r0, r1, r2]), case


def test_local_3d_open_and_stick():
    W = np.array([[2.0, 0.1, -0.2], [0.1, 1.0, 0.05], [-0.2, 0.05, 1.5]])
    r, case = local3(W, (0.5, 3.0, -2.0), 0.3)
    assert case == 0 and np.array_equal(r, np.zeros(3))
    r_stick = np.array([1.0, 0.1, -0.2])  # inside the cone for mu = 0.5
    q = -W @ r_stick
    r, case = local3(W, q, 0.5)
    assert case == 1
    np.testing.assert_allclose(r, r_stick, rtol=1e-14)
    np.testing.assert_allclose(W @ r + q, 0.0, atol=1e-15)


@pytest.mark.parametrize("phi", [0.0, 0.7, np.pi / 2, 2.0, np.pi, 4.0])
@pytest.mark.parametrize("guess", [(0.0, 0.0, 0.0), (5.0, 1.0, -1.0)])
def test_local_3d_slide_closed_form(phi, guess):
    """W = diag(a, b, b): r_N = -q_N/a, r_T = -mu r_N q_T/‖q_T‖, v_T = q_T (1 - b mu r_N/‖q_T‖); forward
    (phi) and backward (phi + pi) sliding directions, any warm start."""
    a, b, mu, qn, qt = 2.0, 0.5, 0.4, -1.0, 3.0
    e = np.array([np.cos(phi), np.sin(phi)])
    q = np.array([qn, *(qt * e)])
    r, case = local3(np.diag([a, b, b]), q, mu, guess)
    rn = -qn / a
    assert case == 2
    np.testing.assert_allclose(r, [rn, *(-mu * rn * e)], rtol=1e-13, atol=1e-15)
    v = np.diag([a, b, b]) @ r + q
    np.testing.assert_allclose(v, [0.0, *(qt * (1 - b * mu * rn / qt) * e)], atol=1e-14)


@pytest.mark.parametrize("q", [(-1.0, 0.2), (-1.0, 4.0), (-1.0, -4.0), (-2.0, 1.3), (0.3, 1.0)])
@pytest.mark.parametrize("w01, w10", [(0.0, 0.0), (0.4, 0.4), (0.4, -0.3)])
def test_local_3d_reduces_to_exact_2d(q, w01, w10):
    """A 3D contact with no coupling to the second tangent and q_T2 = 0 is the 2D problem: same reaction as
    the exact 2D case analysis (also for a non-symmetric block)."""
    W2 = np.array([[2.0, w01], [w10, 1.5]])
    mu = 0.5
    rn, rt, case2 = nlgs.local_2d(W2[0, 0], W2[0, 1], W2[1, 0], W2[1, 1], q[0], q[1], mu)
    W3 = np.zeros((3, 3))
    W3[:2, :2] = W2
    W3[2, 2] = 1.5
    r, case = local3(W3, (q[0], q[1], 0.0), mu)
    np.testing.assert_allclose(r, [rn, rt, 0.0], rtol=1e-12, atol=1e-14)


def random_block(rng, asym):
    A = rng.standard_normal((3, 3))
    w = A @ A.T + 0.05 * np.eye(3)
    w += asym * rng.standard_normal((3, 3)) * np.abs(np.diag(w)).mean()
    lam = np.linalg.eigvalsh(0.5 * (w + w.T)).min()
    if lam <= 0:
        w += (0.1 - lam) * np.eye(3)
    return w


def test_local_3d_random_blocks_all_solved():
    """2000 random blocks (symmetric and strongly non-symmetric, mu up to 3, random warm starts): the local
    natural-map residual is at round-off level, and every fallback (search, projection) is exercised
    without failure."""
    rng = np.random.default_rng(0)
    cases = np.zeros(6, dtype=int)
    for k in range(2000):
        w = random_block(rng, rng.choice([0.0, 0.3, 1.0]))
        q = rng.standard_normal(3)
        mu = rng.choice([0.0, 0.1, 0.5, 1.0, 3.0])
        guess = rng.standard_normal(3) * rng.choice([0, 1])
        r, case = local3(w, q, mu, guess)
        cases[case + 1] += 1
        res = loc.local_residual3(w[None], 0, q[0], q[1], q[2], mu, *r)
        scale = np.linalg.norm(r) + np.linalg.norm(q) / w[0, 0]
        assert res <= 1e-11 * scale, (k, case, res / scale)
        assert r[0] >= 0 and np.hypot(r[1], r[2]) <= mu * r[0] * (1 + 1e-12) + 1e-300
    assert cases[0] == 0 and cases[1] > 0 and cases[2] > 0 and cases[3] > 0 and cases[4] > 0


def test_local_3d_search_and_projection_agree_with_newton():
    """Symmetric blocks, small mu (unique solution): the exact direction search and the projection fixed point
    give the Newton sliding solution."""
    rng = np.random.default_rng(1)
    n_slide = 0
    for k in range(300):
        w = random_block(rng, 0.0)
        q = rng.standard_normal(3)
        q[0] = -abs(q[0])
        mu = 0.3
        r, case = local3(w, q, mu)
        if case != 2:
            continue
        n_slide += 1
        s0, s1, s2, found = loc._slide_search(w[None], 0, q[0], q[1], q[2], mu)
        assert found
        np.testing.assert_allclose([s0, s1, s2], r, rtol=1e-9, atol=1e-12 * np.linalg.norm(r))
        p = loc._projection(w[None], 0, q[0], q[1], q[2], mu, 0.0, 0.0, 0.0, 20000)
        np.testing.assert_allclose(p, r, rtol=1e-6, atol=1e-8 * np.linalg.norm(r))
    assert n_slide > 50


# ----------------------------------------------------------------------------- 3D assembled problems
def skew(x):
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def test_3d_body_on_three_supports_balances_the_load():
    """A rigid body (mass m, inertia diag(I)) on three contacts of the plane z = 0 (frame n = z, t1 = x,
    t2 = y), hit by an impulse (P, moment C) that keeps it in sticking contact: it stops (u = 0) and the
    reactions balance the applied wrench exactly, G^T r = -(P, C); normal reactions sum to -P_z."""
    m, I = 3.0, np.array([0.4, 0.5, 0.3])
    pts = np.array([[0.5, 0.0, -0.2], [-0.3, 0.4, -0.2], [-0.2, -0.45, -0.2]])  # from the centre of mass
    R = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # rows n, t1, t2
    G = np.vstack([R @ np.hstack([np.eye(3), -skew(p)]) for p in pts])  # u_loc = R (v + ω × p)
    Minv = np.diag(np.r_[np.full(3, 1 / m), 1 / I])
    wrench = np.array([0.2, -0.1, -5.0, 0.1, 0.2, -0.05])
    W = G @ Minv @ G.T
    q = G @ (Minv @ wrench)
    for dense in (True, False):
        res = face_solve(W if dense else sp.csr_matrix(W), q, mu=0.6, dim=3, tol=1e-14, criterion="residual",
                         max_sweeps=100000)
        assert res.converged and res.residual <= 1e-14
        np.testing.assert_allclose(G.T @ res.r, -wrench, rtol=0, atol=1e-12 * np.linalg.norm(wrench))
        assert res.r[0::3].sum() == pytest.approx(5.0, rel=1e-12)
        np.testing.assert_allclose(res.u, 0.0, atol=1e-12)


@pytest.mark.parametrize("phi", [0.0, 1.1, -2.5])
def test_3d_incline_one_step(phi):
    """Particle on a plane inclined by alpha whose down-slope direction is (cos phi, sin phi) in the tangent
    frame; one step h: with mu < tan(alpha) it slides down-slope with v_T = h g (sin a - mu cos a),
    with mu > tan(alpha) it sticks; r_N = m h g cos a in both cases."""
    g, h, m, alpha = 9.81, 1e-2, 3.0, np.deg2rad(30)
    e = np.array([np.cos(phi), np.sin(phi)])
    q = np.array([-h * g * np.cos(alpha), *(h * g * np.sin(alpha) * e)])
    W = np.eye(3) / m
    for mu in (0.3, 0.7):
        res = face_solve(W, q, mu=mu, dim=3, tol=1e-14, criterion="residual")
        vt = h * g * (np.sin(alpha) - mu * np.cos(alpha)) if mu < np.tan(alpha) else 0.0
        np.testing.assert_allclose(res.u, [0.0, *(vt * e)], atol=1e-15)
        assert res.r[0] == pytest.approx(m * h * g * np.cos(alpha), rel=1e-14)


def random_problem_3d(n=40, seed=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((3 * n, 4 * n)) * (rng.random((3 * n, 4 * n)) < 0.04)
    W = A @ A.T + np.diag(1 + rng.random(3 * n))
    q = rng.standard_normal(3 * n)
    return W, q


def test_3d_orders_deterministic_warm_start_relaxation():
    W, q = random_problem_3d()
    base = None
    for order in ("given", "reversed", "shuffled"):
        r1 = face_solve(W, q, 0.3, dim=3, tol=1e-12, order=order, seed=7, criterion="residual")
        r2 = face_solve(W, q, 0.3, dim=3, tol=1e-12, order=order, seed=7, criterion="residual")
        assert r1.converged and r1.residual <= 1e-12
        assert np.array_equal(r1.r, r2.r)
        R = fclib.residual(W, q, 0.3, r1.r, dim=3)  # independent numpy natural map
        assert R.rel_q <= 1e-12 and r1.residual == pytest.approx(R.rel_q, rel=1e-6, abs=1e-15)
        base = r1.r if base is None else base
        np.testing.assert_allclose(r1.r, base, atol=1e-9)
    s1 = face_solve(W, q, 0.3, dim=3, tol=1e-12, order="shuffled", seed=1)
    s2 = face_solve(W, q, 0.3, dim=3, tol=1e-12, order="shuffled", seed=2)
    assert not np.array_equal(s1.r, s2.r)
    cold = face_solve(W, q, 0.3, dim=3, tol=1e-10)
    warm = face_solve(W, q, 0.3, dim=3, tol=1e-10, r0=cold.r)
    assert cold.converged and warm.converged and warm.sweeps <= 2 < cold.sweeps
    relaxed = face_solve(W, q, 0.3, dim=3, tol=1e-10, omega=0.8, criterion="residual")
    assert relaxed.converged and relaxed.residual <= 1e-10
    bad = face_solve(W, q, 0.3, dim=3, tol=1e-15, max_sweeps=2, criterion="residual")
    assert not bad.converged and "not converged after 2 sweeps" in bad.message


def test_sweep_and_block_csr_path_match_solve():
    """The raw kernel path (to_block_csr + sweep / solve_block_csr) gives the same reactions as solver.solve."""
    W, q = random_problem_3d(n=10, seed=4)
    B = to_block_csr(sp.csr_matrix(W), 3)
    assert B.blocks.shape == (B.indices.size, 3, 3) and B.blocks.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(B.indices[B.diag_pos], np.arange(10))
    np.testing.assert_allclose(B.to_scipy().toarray(), W, rtol=0, atol=0)
    r = np.zeros(30)
    for k in range(5):
        nlgs.sweep(B.indptr, B.indices, B.blocks, B.diag_pos, q, np.full(10, 0.3), r, np.arange(10))
    ref = face_solve(W, q, 0.3, dim=3, tol=1e-300, max_sweeps=5)
    np.testing.assert_array_equal(r, ref.r)
    res = nlgs.solve_block_csr(B, q, 0.3, r0=np.zeros(30), tol=1e-300, max_sweeps=5)
    np.testing.assert_array_equal(res.r, ref.r)


def test_local_2d_degenerate_block_least_residual():
    """Rank-1 block a aᵀ, a = (0.0707, -0.9975), q = (-0.274, -1.881), mu = 0.5: v_T = q_T - a_T q_N/a_N < 0 is
    fixed once v_N = 0, and backward sliding needs r_N < 0, so no solution exists (open impossible: q_N < 0).
    The solver returns case -1 with a local residual no larger than any candidate's (open, frictionless,
    forward slide)."""
    a = np.array([0.0707, -0.9975])
    w = np.outer(a, a)
    q0, q1, mu = -0.274, -1.881, 0.5
    rn, rt, case = nlgs.local_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], q0, q1, mu)
    assert case == -1
    e = nlgs.local_residual_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], q0, q1, mu, rn, rt)
    den = w[0, 0] - mu * w[0, 1]
    for cn, ct in ((0.0, 0.0), (-q0 / w[0, 0], 0.0), (-q0 / den, mu * q0 / den)):
        assert e <= nlgs.local_residual_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], q0, q1, mu, cn, ct)
    assert rn >= 0 and abs(rt) <= mu * rn * (1 + 1e-14)


def test_local_2d_random_nonsymmetric_blocks_exact():
    """20 000 random blocks with positive definite symmetric part (up to strongly non-symmetric), mu up to 3:
    a consistent case is always found and the local natural-map residual is at round-off level."""
    rng = np.random.default_rng(2)
    for k in range(20000):
        A = rng.standard_normal((2, 2))
        w = A @ A.T + 0.01 * np.eye(2)
        w += rng.choice([0.0, 0.3, 1.0, 3.0]) * rng.standard_normal((2, 2)) * np.abs(np.diag(w)).mean()
        lam = np.linalg.eigvalsh(0.5 * (w + w.T)).min()
        if lam <= 0:
            w += (0.05 - lam) * np.eye(2)
        q = rng.standard_normal(2)
        mu = rng.choice([0.0, 0.1, 0.5, 1.0, 3.0])
        rn, rt, case = nlgs.local_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], q[0], q[1], mu)
        e = nlgs.local_residual_2d(w[0, 0], w[0, 1], w[1, 0], w[1, 1], q[0], q[1], mu, rn, rt)
        assert case >= 0 and e <= 1e-12 * (np.hypot(rn, rt) + np.linalg.norm(q) / w[0, 0]), (k, case, e)

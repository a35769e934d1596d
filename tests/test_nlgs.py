"""2D NLGS: exact local cases, small closed-form problems, determinism, and the FCLIB 2D problems."""
import glob
import json
import os

import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.io import fclib
from fem_blocks.solver import nlgs

FCLIB = "/work/shared/data/fclib"
if not os.path.isdir(FCLIB):
    FCLIB = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "fclib")


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
    res = nlgs.solve(W, q, mu=0.0, tol=1e-14, max_sweeps=10000)
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
        res = nlgs.solve(W / m * m, q, mu=mu, tol=1e-14)
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
        r1 = nlgs.solve(W, q, 0.4, tol=1e-12, order=order, seed=7, criterion="residual")
        r2 = nlgs.solve(W, q, 0.4, tol=1e-12, order=order, seed=7, criterion="residual")
        assert r1.converged and r1.residual <= 1e-12
        assert np.array_equal(r1.r, r2.r)  # bitwise reproducible
        f, frel = nlgs.fclib_residual(W, q, 0.4, r1.r)
        assert frel == r1.residual  # never better than recomputed
        base = r1.r if base is None else base
        assert np.allclose(r1.r, base, atol=1e-9)  # unique solution here (W SPD, small mu)
    s1 = nlgs.solve(W, q, 0.4, tol=1e-12, order="shuffled", seed=1)
    s2 = nlgs.solve(W, q, 0.4, tol=1e-12, order="shuffled", seed=2)
    assert s1.sweeps != s2.sweeps or not np.array_equal(s1.r, s2.r)


def test_warm_start_and_relaxation():
    W, q = random_problem(seed=5)
    cold = nlgs.solve(W, q, 0.3, tol=1e-10)
    warm = nlgs.solve(W, q, 0.3, tol=1e-10, r0=cold.r)
    assert warm.sweeps <= 2 < cold.sweeps
    relaxed = nlgs.solve(W, q, 0.3, tol=1e-10, omega=0.8, criterion="residual")
    assert relaxed.converged and relaxed.residual <= 1e-10


def test_nonconvergence_reported_not_raised():
    W, q = random_problem(seed=6)
    res = nlgs.solve(W, q, 0.3, tol=1e-15, max_sweeps=3)
    assert not res.converged and res.sweeps == 3 and "not converged after 3 sweeps" in res.message


@pytest.mark.parametrize("kwargs, match", [
    (dict(mu=-0.1), "mu: expected friction coefficients >= 0"),
    (dict(tol=0.0), "tol = 0.0: expected tol > 0"),
    (dict(omega=2.5), "omega = 2.5"),
    (dict(order="random"), "order = 'random'"),
    (dict(max_sweeps=0), "max_sweeps = 0"),
    (dict(dim=3), "dim = 3"),
])
def test_bad_arguments(kwargs, match):
    W, q = random_problem(n=3)
    args = dict(mu=0.3)
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        nlgs.solve(W, q, **args)
    with pytest.raises(InputError, match="q: expected 6 entries"):
        nlgs.solve(W, q[:-1], 0.3)


# ----------------------------------------------------------------------------- FCLIB 2D problems
def fclib_2d():
    out = []
    for f in sorted(glob.glob(os.path.join(FCLIB, "**", "*.hdf5"), recursive=True)):
        cat = os.path.basename(f)
        if "fc2d" in cat or "FC2D" in cat:
            out.append(f)
    return out


REFERENCE = {}
if os.path.exists(os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")):
    REFERENCE = {d["problem"]: d for d in json.load(open(os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")))}

# Siconos' NSGS stalls on these two granular problems (README): we report the residual reached after
# 20 000 sweeps and require it to be no worse than 2x Siconos' figure after its (longer) runs.
STALLING = {"fc2d_granularflowonwall_02020_00213": 1.0e-6, "fc2d_granularflowonwall_07002_00801": 3.0e-8}


@pytest.mark.skipif(not fclib_2d(), reason="FCLIB data not available")
@pytest.mark.parametrize("path", fclib_2d(), ids=lambda p: os.path.basename(p)[:-5])
def test_fclib_2d(path):
    p = fclib.read(path)
    assert p.dim == 2
    res = nlgs.solve(p.W, p.q, p.mu, tol=1e-8, max_sweeps=20000, criterion="residual", check_every=10)
    f, frel = nlgs.fclib_residual(p.W, p.q, p.mu, res.r)
    assert frel == pytest.approx(res.residual, rel=1e-12)  # reported residual is the recomputed one
    if p.name in STALLING:
        assert res.residual <= STALLING[p.name]
    else:
        assert res.converged and res.residual <= 1e-8, res.message
    assert np.all(res.r[0::2] >= 0) and np.all(np.abs(res.r[1::2]) <= p.mu * res.r[0::2] * (1 + 1e-12) + 1e-300)


def test_fclib_bad_file(tmp_path):
    with pytest.raises(InputError, match="FCLIB file not found"):
        fclib.read(str(tmp_path / "none.hdf5"))
    (tmp_path / "x.hdf5").write_text("not hdf5")
    with pytest.raises(InputError, match="not an HDF5 file"):
        fclib.read(str(tmp_path / "x.hdf5"))

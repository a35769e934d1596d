"""The global semismooth Newton does the work itself: from r = 0, without the Gauss–Seidel start, it converges
in a few iterations with no Gauss–Seidel fallback (a wrong Newton direction makes every line search fail, and
the fallback sweeps would then solve the problem while the other Newton tests still pass). The solution is
checked against the Signorini–Coulomb conditions written out here, not against the solver's residual."""
import re

import numpy as np
import pytest

from fem_blocks.solver import newton
from fem_blocks.linalg import to_block_csr

from test_nlgs import random_problem  # noqa: E402


def counts(message):
    """(Newton iterations, Gauss–Seidel sweeps, fallbacks) from the result message of solve_newton."""
    m = re.search(r"(\d+) Newton iterations, (\d+) Gauss-Seidel sweeps \((\d+) fallbacks\)", message)
    assert m, message
    return tuple(int(x) for x in m.groups())


def assert_signorini_coulomb(W, q, mu, r, tol):
    """u = W r + q; per contact (normal first): r_N >= 0, u_N >= 0, r_N u_N = 0, |r_T| <= μ r_N, u_T = 0 when
    |r_T| < μ r_N, else r_T = -μ r_N sign(u_T). Tolerances relative to the scales of r and u."""
    u = W @ r + q
    rN, rT, uN, uT = r[0::2], r[1::2], u[0::2], u[1::2]
    rs, us = np.abs(r).max(), np.abs(q).max()
    assert rN.min() >= -tol * rs and uN.min() >= -tol * us
    assert np.abs(rN * uN).max() <= tol * rs * us
    assert np.all(np.abs(rT) <= mu * rN + tol * rs)
    stick = np.abs(rT) < mu * rN - 1e-6 * rs
    assert np.abs(uT[stick]).max(initial=0.0) <= tol * us
    slip = np.abs(uT) > 1e-6 * us
    np.testing.assert_allclose(rT[slip], -mu * rN[slip] * np.sign(uT[slip]), rtol=0, atol=tol * rs)
    assert stick.sum() >= 3 and slip.sum() >= 3 and (rN < 1e-12 * rs).sum() >= 3  # open, stick and slip present


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("mu", [0.3, 0.8])
def test_pure_newton_converges_without_fallback(seed, mu):
    """60 contacts, W SPD (test_nlgs.random_problem), r0 = 0, gs_sweeps = 0: converged to 1e-13 in at most 8
    Newton iterations (measured: 4), no fallback, no Gauss–Seidel sweep."""
    W, q = random_problem(n=60, seed=seed)
    res = newton.solve_newton(to_block_csr(W, 2), q, mu, tol=1e-13, gs_sweeps=0)
    assert res.converged, res.message
    it, sweeps, fallbacks = counts(res.message)
    assert fallbacks == 0 and sweeps == 0, res.message
    assert 1 <= it <= 8, res.message
    assert_signorini_coulomb(W, q, mu, res.r, 1e-10)


def test_newton_after_gauss_seidel_start_finishes_in_few_iterations():
    """With the default start (20 sweeps), Newton finishes: at most 3 iterations, no fallback."""
    W, q = random_problem(n=60, seed=2)
    res = newton.solve_newton(to_block_csr(W, 2), q, 0.8, tol=1e-15)
    assert res.converged, res.message
    it, sweeps, fallbacks = counts(res.message)
    assert fallbacks == 0 and sweeps == 20 and 1 <= it <= 3, res.message
    assert_signorini_coulomb(W, q, 0.8, res.r, 1e-10)

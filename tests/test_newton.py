"""Global semismooth Newton (solver/newton.py): FCLIB problems, random problems against NLGS, a hyperstatic
(singular W) support against statics, and every interface-law closed-form test of test_laws.py re-run with
`solver = "newton"`."""
import glob
import os

import numpy as np
import pytest

from fem_blocks.contact.step import ContactStep
from fem_blocks.io import fclib
from fem_blocks.solver import newton, nlgs
from fem_blocks.linalg import to_block_csr

import test_laws as tl  # noqa: E402
from test_nlgs import random_problem  # noqa: E402

from _paths import FCLIB  # noqa: E402
# small 2D problems that NLGS solves: Newton must reach 1e-12 (the two large granular flows are degenerate:
# many more contacts than dofs, a rank-deficient W on which neither NLGS nor Newton reaches 1e-8, see
# docs/benchmarks.md)
SMALL_2D = ["FC2D_SliderCrankLagrangian00000", "FC2D_SliderCrankLagrangian00001",
            "fc2d_granularflowonwall_00667_00000", "gfc2d_granularflowonwall_00069_00350",
            "gfc2d_granularflowonwall_00230_00206"]


def _fclib_problems():
    out = {}
    for f in glob.glob(os.path.join(FCLIB, "**", "*.hdf5"), recursive=True):
        name = os.path.splitext(os.path.basename(f))[0]
        if name in SMALL_2D:
            out[name] = f
    return out


@pytest.mark.parametrize("name", SMALL_2D)
def test_fclib_2d_problems(name):
    files = _fclib_problems()
    if name not in files:
        pytest.skip(f"{name} not in {FCLIB}")
    p = fclib.read(files[name])
    res = newton.solve_newton(to_block_csr(p.W, 2), p.q, p.mu, tol=1e-12)
    assert res.converged, res.message
    assert fclib.residual(p.W, p.q, p.mu, res.r, 2).rel_q <= 1e-12  # recomputed independently


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("mu", [0.0, 0.3, 0.8])
def test_random_problems_agree_with_nlgs(seed, mu):
    W, q = random_problem(n=60, seed=seed)
    B = to_block_csr(W, 2)
    res = newton.solve_newton(B, q, mu, tol=1e-13, gs_sweeps=0)  # pure Newton from r = 0
    assert res.converged, res.message
    ref = nlgs.solve_block_csr(B, q, mu, tol=1e-13, max_sweeps=200000, criterion="residual")
    assert ref.converged
    assert np.allclose(res.r, ref.r, rtol=0, atol=1e-9 * np.abs(ref.r).max())


def test_hyperstatic_block_on_a_floor_balances_the_load():
    """A rigid block on a fixed floor with 4 contact points (8 unknowns, 3 dofs: W has rank 3) under its weight
    and a horizontal force below μ W: the reactions are not unique, but their resultant is the load (statics),
    the block does not move. The plain Newton system is singular here (regularised Jacobian, Gauss–Seidel
    fallback)."""
    m, I, h, g, F, mu = 10.0, 0.4, 1e-3, 9.81, 20.0, 0.5
    xs = np.array([-0.3, -0.1, 0.1, 0.3])
    G = np.zeros((8, 3))  # (v_N, v_T) of each point from (vx, vy, omega) at the centre (0, 0.1 above the floor)
    for k, x in enumerate(xs):
        G[2 * k] = [0.0, 1.0, x]
        G[2 * k + 1] = [1.0, 0.0, 0.1]   # v_T = vx - omega * (-0.1)
    Minv = np.diag([1 / m, 1 / m, 1 / I])
    W = G @ Minv @ G.T
    assert np.linalg.matrix_rank(W) == 3
    q = G @ (h * Minv @ np.array([F, -m * g, 0.0]))
    res = newton.solve_newton(to_block_csr(W, 2), q, mu, tol=1e-12, gs_sweeps=0)
    assert res.converged, res.message
    P = res.r.reshape(-1, 2)
    assert P[:, 0].sum() == pytest.approx(h * m * g, rel=1e-10)
    assert P[:, 1].sum() == pytest.approx(-h * F, rel=1e-10)
    assert np.abs(res.u).max() <= 1e-10 * h * g
    assert np.all(np.abs(P[:, 1]) <= mu * P[:, 0] + 1e-12)


@pytest.fixture
def newton_contacts(monkeypatch):
    orig = ContactStep.__init__

    def init(self, *a, **k):
        orig(self, *a, **k)
        self.opts.solver = "newton"
    monkeypatch.setattr(ContactStep, "__init__", init)


@pytest.mark.parametrize("test", [
    tl.test_fremond_normal_opening_curve_and_energy, tl.test_fremond_pure_shear_zero_pressure,
    tl.test_fremond_shear_under_pressure_peak_and_residual, tl.test_fremond_unloading_secant_and_no_healing,
    tl.test_dugdale_breaks_at_rc_and_dissipates_rc_lc, tl.test_elastic_brittle_dissipates_rc2_over_2cN,
    tl.test_cohesive_residual_criterion,
], ids=lambda f: f.__name__[5:])
def test_interface_laws_with_newton(newton_contacts, test):
    test()


def test_mixed_mode_with_newton(newton_contacts):
    """The mixed-mode law's peaks and energies with the global Newton, in shear under pressure (mode II+p: the normal
    and the tangential branches of the law's Jacobian at once; its opening in tension with Newton:
    test_hanging_weight_with_newton[mixed]. Pure modes I and II and the mixed path run with the Gauss–Seidel solver
    in tests/test_laws.py; with Newton as well they cost about 40 s of the suite's 10-minute budget.)"""
    tl.test_mixed_mode_peaks_and_energies("II+p", "linear")


@pytest.mark.parametrize("law, params", [("elastic", dict(c_N=1e10, c_T=1e10, mu=0.5)),
                                         ("mixed", dict(tl.MIXED, k_n=1e10))])
def test_compliant_compression_with_newton(newton_contacts, law, params):
    tl.test_compliant_joint_in_compression(law, params)


@pytest.mark.parametrize("law, params, strength", [
    ("fremond", dict(c_N=tl.CN, c_T=tl.CT, w=0.09, mu=0.5), np.sqrt(0.09 * tl.CN)),
    ("mixed", dict(tl.MIXED, f_t=3e4, G_I=1.0), 3e4),
])
def test_hanging_weight_with_newton(newton_contacts, law, params, strength):
    tl.test_hanging_weight_held_below_strength_released_above(law, params, strength)


def test_bad_arguments():
    W, q = random_problem(n=5)
    # 3D is supported by solve_newton (tests/test_newton3d.py), not by the interface-law solver
    with pytest.raises(Exception, match="2D"):
        newton.solve_cohesive_newton(to_block_csr(np.eye(6), 3), np.zeros(6), 0.3, np.zeros(2, dtype=int),
                                     np.zeros((2, 16)), np.zeros((2, 6)), np.zeros((2, 2)), np.ones(2), 1e-3, 0.5)
    with pytest.raises(Exception, match="r0"):
        newton.solve_newton(to_block_csr(W, 2), q, 0.3, r0=np.zeros(3))

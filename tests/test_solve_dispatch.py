"""solver.solve(ContactProblem, SolverOptions): each dispatch branch on a 2-contact problem with a closed-form
answer, and the label of the solver that produced it (a wrong branch gives another answer or another label)."""
import dataclasses

import numpy as np
import pytest

from fem_blocks.contact.step import ContactOptions
from fem_blocks.errors import InputError
from fem_blocks.laws import initial_state, law_parameters
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import ContactProblem, InterfaceLaws, SolverOptions, solve

# two 2D contacts coupled through their normals: W_NN = [[2, 1], [1, 2]], tangents decoupled (W_TT = 2)
W = np.array([[2.0, 0.0, 1.0, 0.0],
              [0.0, 2.0, 0.0, 0.0],
              [1.0, 0.0, 2.0, 0.0],
              [0.0, 0.0, 0.0, 2.0]])


def coulomb_problem():
    """Both pushed into contact (q_N = -1) with no tangential load: r_N solves [[2, 1], [1, 2]] r_N = 1, so
    r_N = 1/3 each, r_T = 0, u = 0."""
    return ContactProblem(to_block_csr(W, 2), np.array([-1.0, 0.0, -1.0, 0.0]), 0.5), np.array([1, 0, 1, 0]) / 3


@pytest.mark.parametrize("options, label", [
    (dict(solver="nlgs", criterion="residual"), "NLGS"),
    (dict(solver="newton"), "Newton"),
    # one Gauss-Seidel sweep cannot solve the coupled pair (r_N = (1/2, 1/4) after it): the budget is spent, Newton
    # finishes
    (dict(solver="nlgs", criterion="residual", fallback="newton", max_sweeps=1), "NLGS + Newton fallback"),
])
def test_coulomb_branches(options, label):
    problem, r_exact = coulomb_problem()
    res = solve(problem, SolverOptions(tol=1e-13, check_every=1, **options))
    assert res.solver == label, res.message
    assert res.converged and res.trial is None
    np.testing.assert_allclose(res.r, r_exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.u, 0.0, atol=1e-12)


def test_nlgs_alone_does_not_reach_the_answer_in_one_sweep():
    """The fallback case above needs Newton: NLGS with the same budget stops at r_N = (1/2, 1/4)."""
    problem, _ = coulomb_problem()
    res = solve(problem, SolverOptions(tol=1e-13, check_every=1, criterion="residual", max_sweeps=1))
    assert res.solver == "NLGS" and not res.converged
    np.testing.assert_allclose(res.r, [0.5, 0.0, 0.25, 0.0], rtol=0, atol=1e-15)


def elastic_problem():
    """Elastic joints (laws.py: r_adh = (c_N u_N, c_T u_T), u = u_eff + hθ v) pulled apart (q_N > 0) from u_eff = 0:
    in tension the transformed impulse P̃ = P + h A r_adh(u) is 0 (the joint is open for Signorini–Coulomb on P̃), so
    P = -h A C hθ (W P + q): (I + h²θ A C W) P = -h²θ A C q, C = diag(c_N, c_T) per contact, a linear system."""
    h, theta, area = 0.1, 0.5, np.array([2.0, 1.5])
    code, par = law_parameters("elastic", dict(c_N=50.0, c_T=30.0, mu=0.5), "interfaces.j")
    law = np.full(2, code)
    pars = np.vstack([par, par])
    q = np.array([0.4, -0.3, 0.7, 0.2])
    laws = InterfaceLaws(law, pars, initial_state(law, 2), np.zeros((2, 2)), area, h, theta)
    S = h * h * theta * np.diag(np.repeat(area, 2) * np.tile([50.0, 30.0], 2))
    P = np.linalg.solve(np.eye(4) + S @ W, -S @ q)
    v = W @ P + q
    assert v[0] > 0 and v[2] > 0  # both in tension: the assumed branch holds
    return ContactProblem(W, q, pars[:, 0], 2, laws=laws), P, v


@pytest.mark.parametrize("solver, label", [("nlgs", "NLGS"), ("newton", "Newton")])
def test_interface_law_branches(solver, label):
    problem, P, v = elastic_problem()
    res = solve(problem, SolverOptions(solver=solver, tol=1e-13, criterion="residual", check_every=1,
                                       max_sweeps=10000))
    assert res.solver == label, res.message
    assert res.converged, res.message
    assert res.trial is not None and res.trial.shape == (2,)
    np.testing.assert_allclose(res.r, P, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(res.u, v, rtol=1e-10, atol=1e-14)


def test_dispatch_errors():
    problem, _ = coulomb_problem()
    with pytest.raises(InputError, match="coarse"):
        solve(problem, SolverOptions(coarse="interfaces"))  # the coarse space is built by the caller
    law = np.zeros(2, dtype=np.int64)
    par = np.vstack([law_parameters("coulomb", {"mu": 0.5}, "j")[1]] * 2)
    laws3 = InterfaceLaws(law, par, initial_state(law, 3), np.zeros((2, 3)), np.ones(2), 0.1, 1.0)
    with pytest.raises(InputError, match="dim = 3"):  # no 3D Newton for interface laws
        solve(ContactProblem(np.eye(6), np.zeros(6), 0.5, 3, laws=laws3), SolverOptions(solver="newton"))
    with pytest.raises(InputError, match="dim = 3: W is a BlockCSR of 2x2 blocks"):
        ContactProblem(to_block_csr(W, 2), np.zeros(4), 0.5, 3)


def test_options_fields_defined_once():
    """ContactOptions adds the time stepper's fields to SolverOptions and redefines none of the solver's;
    every field states its meaning."""
    solver_fields = [f.name for f in dataclasses.fields(SolverOptions)]
    contact_fields = [f.name for f in dataclasses.fields(ContactOptions)]
    assert contact_fields[:len(solver_fields)] == solver_fields
    assert contact_fields[len(solver_fields):] == ["geometry", "redetect_every", "rebalance",
                                                   "on_nonconvergence", "max_refinements", "attempt_budget",
                                                   "grow_after", "predictor"]
    for cls in (SolverOptions, ContactOptions):
        assert {f.name: f.default for f in dataclasses.fields(cls)}["tol"] == 1e-6
        assert all(f.metadata.get("doc") for f in dataclasses.fields(cls))
    assert issubclass(ContactOptions, SolverOptions)
    with pytest.raises(InputError, match=r"contact\.omega = 2\.0: expected 0 < omega < 2"):
        SolverOptions(omega=2.0)


def test_imports_go_one_way():
    """nlgs.py does not import newton.py (the NLGS -> Newton hand-over lives in driver.py), and the options (the
    schema, specs.py) load without the compiled kernels."""
    import subprocess
    import sys
    code = ("import sys; from fem_blocks.solver import SolverOptions; "
            "a = sorted(m for m in sys.modules if m.startswith('fem_blocks.'));"
            " import fem_blocks.solver.nlgs; print(a, 'fem_blocks.solver.newton' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "['fem_blocks.errors', 'fem_blocks.solver', 'fem_blocks.specs'] False"

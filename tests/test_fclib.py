"""NLGS on the real FCLIB problems of shared/data/fclib (every 2D and 3D Coulomb problem, local and global),
the FCLIB reader (local, global + condensation, residual) and its input errors.

Target: FCLIB residual ‖F‖/‖q‖ <= 1e-8 (README), 20 000 sweeps at most unless stated per problem (OPTIONS). The
exceptions (STALLING) are stated per problem with the reason; they are problems on which Siconos' own Gauss-Seidel
(NSGS) stalls too (data README) and only a global Newton method reaches 1e-8 in reasonable time. For those we
assert the level the kernel reaches (about 2x the measured value), so that a regression still fails the test.
"""
import glob
import json
import os

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.errors import InputError
from fem_blocks.io import fclib
from fem_blocks.solver import nlgs

from _paths import FCLIB  # noqa: E402  (../shared/data/fclib beside the project: CI lays shared/ there)
from test_nlgs import face_solve  # noqa: E402  (solver.solve with the former nlgs.solve defaults)

SUMMARY = {}
if os.path.exists(os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")):
    with open(os.path.join(FCLIB, "reference_solutions", "SUMMARY.json")) as fh:
        SUMMARY = {d["problem"]: d for d in json.load(fh)}

MAX_SWEEPS = 20000
# problem -> (tolerance asserted after MAX_SWEEPS sweeps, reason). Measured on this kernel, order "given".
STALLING = {
    "spheres-in-a-box-98-i10000-256-10": (1.1e-5, "slow Gauss-Seidel convergence (README: NSGS stalls); ours "
                                                  "5.5e-6 after 2e4 sweeps, 8e-8 after 1e6 (50 s, see the bench); "
                                                  "Siconos reached 1.7e-14 with the global Newton NSN_AC"),
    "fc2d_granularflowonwall_02020_00213": (1e-6, "Siconos NSGS stalls near 4.7e-7 after 5e5 sweeps (README); "
                                                  "ours 5.5e-7 after 2e4"),
    "fc2d_granularflowonwall_07002_00801": (3e-8, "Siconos NSGS stalls near 1.2e-8 after 1.2e5 sweeps (README); "
                                                  "ours 1.7e-8 after 2e4"),
}
# problem -> solve options.
# * OneObject: in the given order Gauss-Seidel falls into a period-2 cycle at 1.7e-3 (the reactions alternate
#   exactly between two states); a shuffled order breaks it and reaches 1e-8 in ~500 sweeps.
# * stacked boxes (README: Siconos NSGS stalls at 1e-5..1e-3 after 2e4 sweeps): the convergence is slow, not a
#   stall: 1e-8 after 2.6e5 (BoxesStack1) and 1.7e5 (fclib_local_problem_test) sweeps, about 1.5 s each.
OPTIONS = {"OneObject-i100000-316": dict(order="shuffled", seed=0),
           "BoxesStack1-i100000-32": dict(max_sweeps=300000),
           "fclib_local_problem_test": dict(max_sweeps=300000)}
# files that are not Signorini-Coulomb problems: read must refuse them with a clear InputError
NOT_COULOMB = {"Chute-ndof-768-nc-4-3": "rolling-friction problem (/fclib_global_rolling, 5 rows per contact)"}


def files():
    return sorted(glob.glob(os.path.join(FCLIB, "**", "*.hdf5"), recursive=True))


def name_of(path):
    return os.path.splitext(os.path.basename(path))[0]


COULOMB = [f for f in files() if name_of(f) not in NOT_COULOMB]


def test_fclib_data_present_in_ci():
    """In CI (CI=true) the FCLIB problems must be there: their absence fails instead of skipping every solver
    test on real data. Outside CI a missing ../shared only skips the FCLIB tests."""
    if not os.environ.get("CI"):
        pytest.skip("not in CI")
    assert COULOMB and SUMMARY, f"FCLIB data not found at {FCLIB} (expected ../shared/data/fclib beside the project)"
_cache = {}


def problem(path):
    if path not in _cache:
        _cache[path] = fclib.read(path)
    return _cache[path]


@pytest.mark.skipif(not COULOMB, reason="FCLIB data not available")
@pytest.mark.parametrize("path", COULOMB, ids=[name_of(p) for p in COULOMB])  # a list: with no data, no call
def test_nlgs_on_fclib(path):
    p = problem(path)
    opts = dict(max_sweeps=MAX_SWEEPS)
    opts.update(OPTIONS.get(p.name, {}))
    res = face_solve(p.W, p.q, p.mu, dim=p.dim, tol=1e-8, criterion="residual", check_every=10, **opts)
    # the reported residual is the README one, recomputed independently (numpy) from the returned r
    R = fclib.residual(p.W, p.q, p.mu, res.r, p.dim)
    # (u = W r + q is summed in another order: differences of round-off size relative to |W||r| + |q| + |r|)
    scale = abs(p.W) @ np.abs(res.r) + np.abs(p.q)
    assert abs(R.rel_q - res.residual) <= 1e-14 * (np.linalg.norm(scale) + np.linalg.norm(res.r)) / np.linalg.norm(p.q)
    assert np.all(np.abs(res.u - (p.W @ res.r + p.q)) <= 1e-14 * scale + 1e-300)
    if p.name in STALLING:
        tol, why = STALLING[p.name]
        assert not res.converged and "not converged" in res.message
        assert res.residual <= tol, why
    else:
        assert res.converged and res.residual <= 1e-8, res.message
    rr = res.r.reshape(-1, p.dim)
    assert np.all(rr[:, 0] >= 0)
    assert np.all(np.linalg.norm(rr[:, 1:], axis=1) <= p.mu * rr[:, 0] * (1 + 1e-12) + 1e-300)
    if p.dim == 3:
        assert res.local_cases[0] == 0  # no local solve without a positive diagonal block


@pytest.mark.skipif(not SUMMARY, reason="FCLIB reference solutions not available")
@pytest.mark.parametrize("name", sorted(SUMMARY))
def test_residual_matches_siconos_on_reference_solutions(name):
    """Our residual of Siconos' best solution equals the figure Siconos reported (same definition): to 1e-6
    relative, or both at round-off level (<= 1e-12; ‖q‖ = 4e-18 for the 667-grain problem)."""
    ref = SUMMARY[name]
    path = [f for f in COULOMB if name_of(f) == name][0]
    p = problem(path)
    z = np.load(os.path.join(FCLIB, "reference_solutions", ref["file"]))
    R = fclib.residual(p.W, p.q, p.mu, z["r"], p.dim)
    # u = W r + q summed in another order: equal up to round-off relative to |W||r| + |q| + |r|
    err = 1e-14 * (np.linalg.norm(abs(p.W) @ np.abs(z["r"]) + np.abs(p.q)) + np.linalg.norm(z["r"])) / \
        np.linalg.norm(p.q)
    if ref["err_rel_q"] > 1e-12:
        assert abs(R.rel_q - ref["err_rel_q"]) <= max(1e-6 * ref["err_rel_q"], err)
        assert R.rel_max == pytest.approx(ref["err_rel_max"], rel=max(1e-6, err / ref["err_rel_q"]))
    else:
        assert R.rel_q <= 1e-12
    f, frel = nlgs.fclib_residual(p.W, p.q, p.mu, z["r"], dim=p.dim)  # compiled version agrees
    assert abs(frel - R.rel_q) <= max(1e-6 * R.rel_q, err, 1e-14)


def test_warm_start_from_guess_cuts_sweeps(fclib_dir):
    """README: warm-starting Capsules-i97-269 from /guesses/1 cuts Siconos' NSGS from 2423 to 98 sweeps."""
    p = problem(os.path.join(FCLIB, "Capsules-i97-269.hdf5"))
    assert p.guess_r is not None and p.guess_r.size == p.q.size
    cold = face_solve(p.W, p.q, p.mu, dim=3, tol=1e-8, max_sweeps=MAX_SWEEPS, criterion="residual")
    warm = face_solve(p.W, p.q, p.mu, dim=3, tol=1e-8, max_sweeps=MAX_SWEEPS, criterion="residual",
                      r0=p.guess_r)
    assert cold.converged and warm.converged
    assert warm.sweeps < cold.sweeps / 2


def test_condense_dense_and_sparse_paths_agree(fclib_dir):
    g = fclib.read_global(os.path.join(FCLIB, "converted_from_siconos_dat",
                                       "gfc2d_granularflowonwall_00069_00350.hdf5"))
    assert g.dim == 2 and g.n_contacts == 69 and g.H.shape == (900, 138)
    dense = fclib.condense(g, dense_limit=10 ** 6)
    sparse = fclib.condense(g, dense_limit=0)
    Wd = dense.W.toarray()
    np.testing.assert_allclose(sparse.W.toarray(), Wd, rtol=0, atol=1e-12 * np.abs(Wd).max())
    np.testing.assert_allclose(sparse.q, dense.q, rtol=0, atol=1e-12 * np.abs(dense.q).max())
    # W = H^T M^-1 H with M SPD: symmetric positive semi-definite
    np.testing.assert_allclose(Wd, Wd.T, atol=1e-12 * np.abs(Wd).max())
    assert np.linalg.eigvalsh(0.5 * (Wd + Wd.T)).min() >= -1e-12 * np.abs(Wd).max()
    # q = H^T M^-1 f + w, checked on one column combination by a direct solve
    v = np.linalg.solve(g.M.toarray(), g.f)
    np.testing.assert_allclose(dense.q, g.H.T @ v + g.w, rtol=1e-12, atol=1e-14)


def test_read_local_fields(fclib_dir):
    p = fclib.read_local(os.path.join(FCLIB, "converted_from_siconos_dat", "Rover4396.hdf5"))
    assert (p.dim, p.n_contacts, p.W.shape, p.q.shape) == (3, 2, (6, 6), (6,))
    assert isinstance(p.W, sp.csr_matrix) and np.all(p.mu == 0.7)


def _write(path, **groups):
    with h5py.File(path, "w") as h:
        for gname, items in groups.items():
            g = h.create_group(gname)
            for k, v in items.items():
                g[k] = v


def _csr_group(h, name, A):
    A = sp.csr_matrix(A)
    g = h.create_group(name)
    g["m"] = [A.shape[0]]
    g["n"] = [A.shape[1]]
    g["nz"] = [-2]
    g["nzmax"] = [A.nnz]
    g["p"] = A.indptr
    g["i"] = A.indices
    g["x"] = A.data


def test_reader_errors(tmp_path, fclib_dir):
    with pytest.raises(InputError, match="FCLIB file not found"):
        fclib.read(str(tmp_path / "none.hdf5"))
    (tmp_path / "x.hdf5").write_text("not hdf5")
    with pytest.raises(InputError, match="not an HDF5 file"):
        fclib.read(str(tmp_path / "x.hdf5"))
    chute = os.path.join(FCLIB, "Chute-ndof-768-nc-4-3.hdf5")
    if os.path.exists(chute):
        with pytest.raises(InputError, match=r"expected a /fclib_local or /fclib_global group.*fclib_global_rolling"):
            fclib.read(chute)
    with pytest.raises(InputError, match="expected a /fclib_global group"):
        fclib.read_global(os.path.join(FCLIB, "converted_from_siconos_dat", "Rover4396.hdf5"))
    with pytest.raises(InputError, match="expected a /fclib_local group"):
        fclib.read_local(os.path.join(FCLIB, "CubeH8.hdf5"))
    # hand-written local files: wrong spacedim, inconsistent sizes, bad matrix storage, negative mu
    for name, dim, q, mu, nz, match in [
        ("d4", 4, np.zeros(4), np.ones(1), -2, "spacedim = 4: expected 2 or 3"),
        ("sizes", 2, np.zeros(3), np.ones(1), -2, "inconsistent sizes"),
        ("mu", 2, np.zeros(4), -np.ones(2), -2, "mu: expected friction coefficients >= 0"),
        ("nz", 2, np.zeros(4), np.ones(2), -7, "nz = -7"),
    ]:
        path = str(tmp_path / f"{name}.hdf5")
        with h5py.File(path, "w") as h:
            g = h.create_group("fclib_local")
            g["spacedim"] = [dim]
            _csr_group(g, "W", np.eye(4))
            g["W/nz"][0] = nz
            g.create_group("vectors")
            g["vectors/q"] = q
            g["vectors/mu"] = mu
        with pytest.raises(InputError, match=match):
            fclib.read(path)
    path = str(tmp_path / "noq.hdf5")
    with h5py.File(path, "w") as h:
        g = h.create_group("fclib_local")
        g["spacedim"] = [2]
        _csr_group(g, "W", np.eye(2))
        g.create_group("vectors")["mu"] = [0.3]
    with pytest.raises(InputError, match="missing dataset /fclib_local/vectors/q"):
        fclib.read_local(path)
    with pytest.raises(InputError, match="dim = 4: expected 2 or 3"):
        fclib.residual(np.eye(2), np.zeros(2), 0.3, np.zeros(2), 4)

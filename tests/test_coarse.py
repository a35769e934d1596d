"""Two-level NLGS (solver/coarse.py, `[contact] coarse = "interfaces"`): the Galerkin coarse operator, the same
converged answer as plain NLGS, fewer sweeps where plain Gauss–Seidel has to carry a load down a long path, and
the option's validation."""
import numpy as np
import pytest
import scipy.sparse as sp

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.meshing import mesh_rectangle
from fem_blocks.solver import coarse as co
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import nlgs

L, H, RHO, T = 0.25, 0.06, 1800.0, 0.12


def column(n, kind, coarse, tol=1e-8, placement="positions"):
    """n blocks L x H stacked on a fixed rigid floor, θ = 1 with velocity reset (quasi-static), residual criterion."""
    if kind == "rigid":
        bodies = [RigidBody([(0, k * H), (L, k * H), (L, (k + 1) * H), (0, (k + 1) * H)], rho=RHO, thickness=T)
                  for k in range(n)]
    else:
        bt = BlockType(mesh_rectangle(L, H, 0.0625, cell="quad"), Material(E=5e9, nu=0.2, rho=RHO, thickness=T))
        bodies = [DeformableBody(bt, (0.0, k * H)) for k in range(n)]
    floor = RigidBody([(-0.1, -0.2), (L + 0.1, -0.2), (L + 0.1, 0), (-0.1, 0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    cs = ContactStep([InterfaceSpec("j", ("b", "b"), mu=0.7, placement=placement),
                      InterfaceSpec("f", ("b", "g"), mu=0.7, placement=placement)], ["b"] * n + ["g"],
                     ContactOptions(tol=tol, max_sweeps=300000, criterion="residual", check_every=10, coarse=coarse))
    sim = Simulation(bodies + [floor], h=1e-3, theta=1.0, contact=cs, velocity_reset=True)
    return sim, cs, floor, RHO * L * H * T * 9.81 * n


def test_galerkin_operator_is_PtWP():
    """_galerkin's block-CSR W_c equals Pᵀ W P formed with scipy, on a random symmetric W and a random sticking
    set; rows of non-sticking contacts do not contribute."""
    rng = np.random.default_rng(1)
    nc, ng = 40, 9
    A = sp.random(2 * nc, 2 * nc, density=0.15, random_state=2) + sp.eye(2 * nc)
    W = to_block_csr((A @ A.T).tocsr(), 2)
    group = rng.integers(0, ng, nc)
    group[:ng] = np.arange(ng)
    point = rng.random((nc, 2))
    t = np.tile([1.0, 0.0], (nc, 1))
    C = co.InterfaceCoarse(group, point, t)
    active = rng.random(nc) < 0.7
    P = C._basis_for(active)
    order = np.argsort(group, kind="stable").astype(np.int64)
    gstart = np.r_[0, np.cumsum(np.bincount(group, minlength=ng))].astype(np.int64)
    ip, ix, bl = co._galerkin(W.indptr, W.indices, W.blocks, group, P, active, order, gstart, ng)
    Wc = sp.bsr_matrix((bl, ix, ip), shape=(3 * ng, 3 * ng)).toarray()
    Pd = np.zeros((2 * nc, 3 * ng))
    for a in range(nc):
        Pd[2 * a:2 * a + 2, 3 * group[a]:3 * group[a] + 3] = P[a]
    ref = Pd.T @ W.to_scipy().toarray() @ Pd
    assert np.abs(Wc - ref).max() <= 1e-12 * np.abs(ref).max()
    assert not P[~active].any()
    # centred, normalised moment column on every interface with two distinct sticking points
    s = P[active, 0, 1]
    g = group[active]
    assert np.allclose(np.bincount(g, s, minlength=ng), 0.0, atol=1e-12)


def test_rigid_column_closed_form_and_sweeps():
    """20 rigid blocks stacked on a fixed floor, one quasi-static step from rest: every bed joint carries the
    weight above it, N_k = h m g (n - k), with no moment and no shear resultant (statically determinate). Plain NLGS carries the load down one joint per sweep and
    needs > 10⁵ sweeps for ‖F‖/‖q‖ <= 1e-8; with the interface coarse space the first correction solves it (measured
    116 280 against 20 sweeps): assert a ratio of at least 100."""
    n, h = 20, 1e-3
    out = {}
    for coarse in ("none", "interfaces"):
        sim, cs, floor, weight = column(n, "rigid", coarse)
        info = sim.step()
        assert info.contact["converged"] and info.contact["residual"] <= 1e-8
        P = cs.P
        bottom_block = np.where((cs.cs.cand_body == n) | (cs.cs.ant_body == n), -1,
                                np.minimum(cs.cs.cand_body, cs.cs.ant_body))
        N = np.bincount(bottom_block + 1, P[:, 0], minlength=n + 1)  # index 0: floor joint, k + 1: joint above k
        m_g = RHO * L * H * T * 9.81
        expect = h * m_g * (n - np.arange(n))  # joint below block k carries blocks k..n-1
        assert np.allclose(N[:n], expect, rtol=1e-7), (N[:n] / expect)
        # no moment: the joint's two points share its normal impulse; no shear resultant (the tangential split
        # between the two points is a null direction of W, within the cones)
        assert np.allclose(P[:, 0], 0.5 * N[bottom_block + 1], rtol=1e-4)  # measured 5e-6 at ‖F‖/‖q‖ = 1e-8
        T_res = np.bincount(bottom_block + 1, P[:, 1], minlength=n + 1)
        assert np.abs(T_res).max() <= 1e-6 * expect[0]  # measured 1.8e-7
        assert floor.reaction[1] == pytest.approx(weight, rel=1e-7)
        out[coarse] = info.contact["sweeps"]
    assert out["none"] >= 100 * out["interfaces"], out


def test_deformable_column_same_solution():
    """8 deformable bricks (Q1), candidate points at the nodes (regular W: unique reactions), 3 quasi-static steps:
    plain and two-level NLGS converge to the same impulses (relative 1e-5, tolerance 1e-8 on ‖F‖/‖q‖) and the same
    floor reaction (relative 1e-7)."""
    res = {}
    for coarse in ("none", "interfaces"):
        sim, cs, floor, weight = column(8, "deformable", coarse, placement="nodes")
        for _ in range(3):
            info = sim.step()
            assert info.contact["converged"] and info.contact["residual"] <= 1e-8
        res[coarse] = (cs.P.copy(), floor.reaction.copy(), weight, cs)
    (P0, R0, w, _), (P1, R1, _, cs1) = res["none"], res["interfaces"]
    assert np.abs(P1 - P0).max() <= 1e-5 * np.abs(P0).max()
    assert R1[1] == pytest.approx(R0[1], rel=1e-7)
    assert R0[1] == pytest.approx(w, rel=1e-3)  # settling: within 0.1 % of the weight after 3 steps
    assert cs1._coarse.n_correct > 0  # the corrections ran


def test_options_validation():
    with pytest.raises(InputError, match="contact.coarse"):
        ContactOptions(coarse="multigrid")
    with pytest.raises(InputError, match="contact.coarse_every"):
        ContactOptions(coarse="interfaces", coarse_every=0)
    with pytest.raises(InputError, match="contact.coarse"):
        ContactOptions(coarse="interfaces", solver="newton")
    with pytest.raises(InputError, match="contact.coarse"):
        ContactOptions(coarse="interfaces", criterion="residual", fallback="newton")
    assert ContactOptions().coarse == "none"
    with pytest.raises(InputError, match="coarse.every"):
        co.InterfaceCoarse(np.zeros(2, dtype=int), np.zeros((2, 2)), np.ones((2, 2)), every=0)
    W = to_block_csr(np.eye(4), 2)
    C = co.InterfaceCoarse(np.zeros(3, dtype=int), np.zeros((3, 2)), np.ones((3, 2)))
    with pytest.raises(InputError, match="coarse: built for 3 contacts"):
        nlgs.solve_block_csr(W, np.zeros(4), 0.5, coarse=C)


def test_cohesive_law_rejected():
    bt = BlockType(mesh_rectangle(L, H, 0.0625, cell="quad"), Material(E=5e9, nu=0.2, rho=RHO, thickness=T))
    floor = RigidBody([(-0.1, -0.2), (L + 0.1, -0.2), (L + 0.1, 0), (-0.1, 0)],
                      drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    cs = ContactStep([InterfaceSpec("j", ("b", "g"), law="fremond", params=dict(c_N=1e10, c_T=1e10, w=10.0, mu=0.7))],
                     ["b", "g"], ContactOptions(coarse="interfaces"))
    sim = Simulation([DeformableBody(bt, (0.0, 0.0)), floor], h=1e-3, theta=1.0, contact=cs, velocity_reset=True)
    with pytest.raises(InputError, match="interfaces.j.law.*contact.coarse"):
        sim.step()


def test_case_file_key(tmp_path):
    """[contact] coarse / coarse_every reach ContactOptions through the case file."""
    from fem_blocks.case import load_case
    src = open(__file__.replace("test_coarse.py", "bad_cases/122_contact_coarse_newton.toml")).read()
    f = tmp_path / "c.toml"
    f.write_text(src.replace('solver = "newton"', "coarse_every = 7"))
    case = load_case(str(f))
    opts = case.contact
    assert isinstance(opts, ContactOptions)
    assert (opts.coarse, opts.coarse_every) == ("interfaces", 7)

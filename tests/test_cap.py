"""Compressive cap (f_c, any law): r̃_N <= f_c A, plastic closure kept in the state (no spring-back on unloading),
dissipation f_c A |u_p|, friction bounded by μ f_c A at the cap — against closed forms, with both solvers."""
import numpy as np
import pytest

from fem_blocks.bodies import Driver, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.laws import P_FC, P_GFC, S_DISS, S_UN, S_UP, law_parameters

L, T, H_BLK, RHO = 0.2, 0.1, 0.1, 2000.0
A = L * T          # one contact point at mid-edge carries the whole edge: tributary area L x T
M = RHO * L * H_BLK * T
FC = 1e6           # 1 MPa: cap force f_c A = 20 kN
FIX = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}


def pressed(law, params, solver, fx=0.0, h=1e-2):
    forces = {"y": {"times": [0.0, 1.0], "values": [-3 * FC * A, -3 * FC * A]}}
    drivers = {"rz": Driver("velocity", 0.0)}
    if fx:
        forces["x"] = fx
    else:
        drivers["x"] = Driver("velocity", 0.0)
    blk = RigidBody([(0, 0), (L, 0), (L, H_BLK), (0, H_BLK)], rho=RHO, thickness=T, drivers=drivers, forces=forces)
    base = RigidBody([(-0.1, -0.1), (0.3, -0.1), (0.3, 0), (-0.1, 0)], drivers=dict(FIX), thickness=T)
    cs = ContactStep([InterfaceSpec("j", ("b", "g"), law=law, params=dict(params, f_c=FC), placement="positions",
                                   positions=(0.5,))],
                     ["b", "g"], ContactOptions(tol=1e-13, max_sweeps=1000, criterion="residual", solver=solver))
    sim = Simulation([blk, base], h=h, theta=1.0, contact=cs, gravity=(0.0, 0.0), velocity_reset=True)
    return blk, cs, sim


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_crushing_at_the_cap_then_no_spring_back(solver):
    blk, cs, sim = pressed("coulomb", dict(mu=0.5), solver)
    h, n = sim.h, 5
    F = 3 * FC * A
    for _ in range(n):
        sim.step()
    # each step (velocity reset, θ = 1): v = -h (F - f_c A)/m, Δq = h v
    q = -n * h * h * (F - FC * A) / M
    assert sim.last_contact.r[0, 0] == pytest.approx(FC * A, rel=1e-10)
    assert blk.q[1] == pytest.approx(q, rel=1e-9)
    assert cs.state[0, S_UP] == pytest.approx(q, rel=1e-9)            # the surface moved with the block
    assert cs.state[0, S_DISS] == pytest.approx(FC * A * abs(q), rel=1e-9)
    # unload to half the cap: the block stays where crushing left it, the joint carries the load
    blk.set_force("y", -0.5 * FC * A)
    for _ in range(4):
        sim.step()
    assert blk.q[1] == pytest.approx(q, rel=1e-9, abs=1e-15)
    assert sim.last_contact.r[0, 0] == pytest.approx(0.5 * FC * A, rel=1e-10)
    assert cs.state[0, S_UP] == pytest.approx(q, rel=1e-9)


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_friction_at_the_cap_is_bounded_by_mu_fc_A(solver):
    mu = 0.4
    blk, cs, sim = pressed("coulomb", dict(mu=mu), solver, fx=0.5 * FC * A)  # 0.5 f_c A > μ f_c A: slides
    for _ in range(3):
        sim.step()
    assert sim.last_contact.r[0, 0] == pytest.approx(FC * A, rel=1e-10)
    assert abs(sim.last_contact.r[0, 1]) == pytest.approx(mu * FC * A, rel=1e-10)
    assert blk.u[0] > 0


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_cap_on_a_compliant_joint(solver):
    """Elastic joint (c_N) with a cap: the reaction saturates at f_c A; beyond it the closure is plastic and the
    elastic jump stays at -f_c / c_N."""
    cN = 1e12
    blk, cs, sim = pressed("elastic", dict(c_N=cN, c_T=cN, mu=0.5), solver)
    for _ in range(6):
        sim.step()
    assert sim.last_contact.r[0, 0] == pytest.approx(FC * A, rel=1e-9)
    assert cs.state[0, S_UN] == pytest.approx(-FC / cN, rel=1e-6)
    assert cs.state[0, S_UP] < 0 and blk.q[1] == pytest.approx(cs.state[0, S_UP] - FC / cN, rel=1e-6)


def test_cap_parameter_validated():
    with pytest.raises(InputError, match="f_c"):
        law_parameters("coulomb", dict(mu=0.5, f_c=-1.0), "interfaces.j")
    code, p = law_parameters("mixed", dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6,
                                           f_c=1e7), "interfaces.j")
    assert p[P_FC] == 1e7


# ----------------------------------------------------------------------------- softening cap (G_fc)
@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_softening_cap_follows_the_exponential_law(solver):
    """Cap with a compressive fracture energy G_fc: the cap of each step is f_c exp(-f_c |u_p| / G_fc) at the
    committed closure (explicit), so under a constant force F > f_c A the rigid block follows the recurrence
    q_{k+1} = q_k - h² (F - f_k A)/m, f_k = f_c exp(-f_c |q_k| / G_fc), and the dissipation is Σ f_k A |Δq_k|."""
    G = 2.0 * FC  # J/m^2: one e-fold of the cap per 2 m of closure (the rigid block closes ~1 m per step here)
    blk, cs, sim = pressed("coulomb", dict(mu=0.5, G_fc=G), solver)
    h, F = sim.h, 3 * FC * A
    q, diss = 0.0, 0.0
    for _ in range(8):
        f = FC * np.exp(-FC * abs(q) / G)
        dq = -h * h * (F - f * A) / M
        sim.step()
        assert sim.last_contact.r[0, 0] == pytest.approx(f * A, rel=1e-10)
        q += dq
        diss += f * A * abs(dq)
        assert blk.q[1] == pytest.approx(q, rel=1e-9)
        assert cs.state[0, S_UP] == pytest.approx(q, rel=1e-9)
        assert cs.state[0, S_DISS] == pytest.approx(diss, rel=1e-9)
    assert sim.last_contact.r[0, 0] < 0.2 * FC * A  # softened well below the initial cap


def test_softening_cap_dissipates_G_fc():
    """Closing the joint in steps of δ G_fc/f_c dissipates A Σ f_c e^{-kδ} δ G_fc/f_c = A G_fc δ(1 - e^{-nδ})/(1 - e^{-δ})
    (the explicit cap is a left Riemann sum of ∫ f_c e^{-f_c u/G_fc} du = G_fc): → A G_fc as δ → 0, n δ → ∞. Here
    the kernel commit_step is driven directly with the closure increments (rigid joint: Δu_p = the closure)."""
    from fem_blocks.laws import commit_step, initial_state, COULOMB
    G, area, h, theta = 5000.0, 0.01, 1.0, 1.0
    code, p = law_parameters("coulomb", dict(mu=0.6, f_c=FC, G_fc=G), "j")
    law, par = np.array([code]), p[None, :].copy()
    st = initial_state(law)
    delta, n = 0.01, 1000                              # n δ = 10: e^{-10} stays above CAP_FLOOR
    du = delta * G / FC
    for _ in range(n):
        fc = FC * np.exp(-FC * abs(st[0, S_UP]) / G)
        P = np.array([h * fc * area, 0.0])             # at the cap
        v = np.array([-du / (h * theta), 0.0])         # closes by du in the step
        commit_step(law, par, st, np.zeros(1), np.zeros((1, 2)), P, v, np.array([area]), h, theta)
    exact = area * G * delta * (1 - np.exp(-n * delta)) / (1 - np.exp(-delta))
    assert st[0, S_DISS] == pytest.approx(exact, rel=1e-12)
    assert st[0, S_DISS] == pytest.approx(area * G, rel=6e-3)   # δ/2 = 0.5 % above G_fc A (explicit cap)
    assert st[0, S_UP] == pytest.approx(-n * du, rel=1e-12)


def test_cap_fracture_energy_validated():
    for bad, msg in ((dict(G_fc=0.0), "G_fc"), (dict(G_fc=-5.0), "G_fc"), (dict(G_fc=float("inf")), "G_fc")):
        with pytest.raises(InputError, match=msg):
            law_parameters("coulomb", dict(mu=0.5, f_c=1e7, **bad), "interfaces.j")
    with pytest.raises(InputError, match="needs the compressive strength f_c"):
        law_parameters("mixed", dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6,
                                     G_fc=5000.0), "interfaces.j")
    code, p = law_parameters("fremond", dict(mu=0.7, c_N=5e9, c_T=3e9, w=18.0, f_c=1e7, G_fc=5000.0), "j")
    assert p[P_FC] == 1e7 and p[P_GFC] == 5000.0

"""Compressive cap (f_c, any law): r̃_N <= f_c A, plastic closure kept in the state (no spring-back on unloading),
dissipation f_c A |u_p|, friction bounded by μ f_c A at the cap — against closed forms, with both solvers."""
import math

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


# ----------------------------------------------------------------------------- hardening cap (kappa_p, f_ci)
def cap_closed_form(kappa, fc, fci, kp, G):
    """Lourenço's cap with κ the plastic closure: f_ci + (f_c - f_ci) sqrt(2κ/κ_p - κ²/κ_p²) up to the peak f_c at
    κ_p, then f_c exp(-f_c (κ - κ_p)/G) (written here from the definition, not from fem_blocks)."""
    if kappa < kp:
        x = kappa / kp
        return fci + (fc - fci) * np.sqrt(2 * x - x * x)
    return fc * np.exp(-fc * (kappa - kp) / G)


def cap_energy(kappa, fc, fci, kp, G):
    """∫_0^κ of `cap_closed_form`: with t = 1 - s, ∫_0^x sqrt(2s - s²) ds = ∫_{1-x}^1 sqrt(1 - t²) dt
    = π/4 - ½((1-x) sqrt(1-(1-x)²) + asin(1-x)); the hardening branch to κ_p gives κ_p (f_ci + (π/4)(f_c - f_ci)),
    the softening branch G (1 - exp(-f_c (κ - κ_p)/G))."""
    x = min(kappa / kp, 1.0)
    area = np.pi / 4 - 0.5 * ((1 - x) * np.sqrt(1 - (1 - x) ** 2) + np.arcsin(1 - x))
    e = fci * kp * x + (fc - fci) * kp * area
    if kappa > kp:
        e += G * (1 - np.exp(-fc * (kappa - kp) / G))
    return e


def test_cap_closed_form_helpers_agree():
    """The test's own closed forms: the energy is the integral of the cap (numerical quadrature, 1e-7), and the
    hardening branch of Lourenço's cap is a quarter ellipse from f_ci at κ = 0 to the peak f_c at κ_p."""
    from scipy.integrate import quad
    fc, fci, kp, G = 1e6, 1e6 / 3, 1e-4, 200.0
    for k in (3e-5, 1e-4, 2.5e-4, 8e-4):
        ref = quad(lambda s: cap_closed_form(s, fc, fci, kp, G), 0, k, points=[kp], limit=200)[0]
        assert cap_energy(k, fc, fci, kp, G) == pytest.approx(ref, rel=1e-7)
    assert cap_closed_form(0.0, fc, fci, kp, G) == fci and cap_closed_form(kp, fc, fci, kp, G) == fc
    assert cap_energy(1.0, fc, fci, kp, G) == pytest.approx(kp * (fci + np.pi / 4 * (fc - fci)) + G, rel=1e-12)


@pytest.mark.parametrize("f_ci", [None, 0.5e6])
def test_cap_stress_hardening_then_softening(f_ci):
    """laws.cap_stress at given committed closures κ = -u_p against the closed form (1e-13); f_ci defaults to
    f_c/3; κ_p = 0 is the cap without hardening to the last bit."""
    from fem_blocks.laws import cap_stress, initial_state, COULOMB
    kp, G = 1e-4, 200.0
    extra = {} if f_ci is None else dict(f_ci=f_ci)
    code, par = law_parameters("coulomb", dict(mu=0.5, f_c=FC, G_fc=G, kappa_p=kp, **extra), "j")
    fci = FC / 3 if f_ci is None else f_ci
    st = initial_state(np.array([COULOMB]))[0]
    for k in (0.0, 1e-7, 3e-5, 0.5e-4, 0.999e-4, 1e-4, 1.5e-4, 4e-4, 2e-3):
        st[S_UP] = -k
        assert cap_stress(par, st) == pytest.approx(cap_closed_form(k, FC, fci, kp, G), rel=1e-13), k
    # without kappa_p: the softening cap f_c exp(-f_c κ/G) of before, bitwise; the expectation's exp is the C
    # library's (math.exp), the one the compiled law calls: NumPy's vectorised exp can differ from it by one ulp
    # (on a CPU with AVX-512: exp(-2) here)
    code, par0 = law_parameters("coulomb", dict(mu=0.5, f_c=FC, G_fc=G), "j")
    for k in (0.0, 3e-5, 4e-4):
        st[S_UP] = -k
        assert cap_stress(par0, st) == FC * max(math.exp(-FC * abs(-k) / G), 1e-6)
    # hardening to a perfectly plastic cap (no G_fc)
    code, par1 = law_parameters("coulomb", dict(mu=0.5, f_c=FC, kappa_p=kp), "j")
    st[S_UP] = -0.5 * kp
    assert cap_stress(par1, st) == pytest.approx(FC / 3 + (FC - FC / 3) * np.sqrt(0.75), rel=1e-13)
    st[S_UP] = -3 * kp
    assert cap_stress(par1, st) == FC


def driven_joint(params, hist, solver, h=1.0):
    """Rigid block driven vertically (displacement history `hist` of its y dof, x and rotation fixed) on a fixed
    base through one elastic joint point carrying the whole edge (area A) with a cap."""
    drivers = dict(FIX)
    drivers["y"] = Driver("displacement", hist)
    blk = RigidBody([(0, 0), (L, 0), (L, H_BLK), (0, H_BLK)], thickness=T, drivers=drivers)
    base = RigidBody([(-0.1, -0.1), (0.3, -0.1), (0.3, 0), (-0.1, 0)], drivers=dict(FIX), thickness=T)
    cs = ContactStep([InterfaceSpec("j", ("b", "g"), law="elastic", params=params, placement="positions",
                                   positions=(0.5,))],
                     ["b", "g"], ContactOptions(tol=1e-13, max_sweeps=1000, criterion="residual", solver=solver))
    sim = Simulation([blk, base], h=h, theta=1.0, contact=cs, gravity=(0.0, 0.0))
    return blk, cs, sim


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_hardening_softening_cap_under_imposed_closure(solver):
    """A block pressed into a compliant joint (c_N = k) by an imposed closure d(t) (loading past the cap's peak into
    its softening branch, unloading into tension, reloading, crushing further). The explicit cap of each step is
    σ_c(κ_n) at the committed plastic closure κ_n, so each step is the return map
    σ = k (d - κ_n) if k (d - κ_n) <= σ_c(κ_n), else σ = σ_c(κ_n) and κ_{n+1} = d - σ_c(κ_n)/k
    (Lourenço's hardening from f_c/3 to the peak f_c at κ_p, then exponential softening with G_fc from κ_p;
    σ_c written in the test, `cap_closed_form`). Checked at every row from the previous committed closure: the
    normal force (1e-10 of f_c A), the new closure (1e-10 of κ_p), the dissipation increment σ_c(κ_n) A Δκ (1e-9);
    and along the whole path against the recurrence run in the test alone (1e-7: the slope of σ_c is unbounded at
    κ = 0, so round-off differences of κ grow along the path). On unloading the block keeps the crushed closure (the
    joint is stress-free at d = κ, not at d = 0: no spring-back) and reloads elastically up to the committed cap;
    the total dissipation equals A ∫_0^κ σ_c (closed form `cap_energy`) within the left-Riemann bound
    Δκ_max × (total variation of σ_c along the path)."""
    k, kp, G = 1e10, 1e-4, 200.0          # N/m^3, m, J/m^2: the elastic limit f_c/(3k) = 3.3e-5 m
    d_pts = [0.0, 4e-4, 3.0e-4, 4.2e-4, 6e-4]  # m, closure (block moves down by d)
    t_pts = [0.0, 400.0, 450.0, 510.0, 690.0]    # 1 step per unit time: <= 1e-6 m of closure per step
    blk, cs, sim = driven_joint(dict(c_N=k, c_T=k, mu=0.5, f_c=FC, G_fc=G, kappa_p=kp),
                                {"times": t_pts, "values": [-d for d in d_pts]}, solver)
    kap, diss, dkmax = 0.0, 0.0, 0.0       # the recurrence run by the test alone
    crushed = unload_checked = reload_elastic = 0
    stress_unload = []
    for n in range(690):
        kap0, diss0 = (0.0, 0.0) if n == 0 else (-cs.state[0, S_UP], cs.state[0, S_DISS])  # committed state
        sim.step()
        d = float(np.interp(sim.time, t_pts, d_pts))
        # one step of the return map from the committed state
        cap0 = cap_closed_form(kap0, FC, FC / 3, kp, G)
        s1, k1 = k * (d - kap0), kap0
        if s1 > cap0:
            s1, k1 = cap0, d - cap0 / k
        assert sim.last_contact.r[0, 0] == pytest.approx(s1 * A, abs=1e-10 * FC * A), (n, d)
        assert -cs.state[0, S_UP] == pytest.approx(k1, abs=1e-10 * kp), (n, d)
        assert cs.state[0, S_DISS] - diss0 == pytest.approx(cap0 * A * (k1 - kap0), rel=1e-9, abs=1e-9 * FC * A * kp)
        # the whole path
        cap = cap_closed_form(kap, FC, FC / 3, kp, G)
        s = k * (d - kap)
        if s > cap:
            s, dk = cap, d - cap / k - kap
            diss += cap * A * dk
            kap += dk
            dkmax = max(dkmax, dk)
            crushed += 1
        elif 450 < sim.time <= 510:
            reload_elastic += 1
        assert sim.last_contact.r[0, 0] == pytest.approx(s * A, abs=1e-7 * FC * A), (n, d)
        assert -cs.state[0, S_UP] == pytest.approx(kap, abs=1e-7 * kp), (n, d)
        assert cs.state[0, S_DISS] == pytest.approx(diss, rel=1e-7), (n, d)
        if 400 < sim.time <= 450:              # unloading: κ frozen, stress k (d - κ)
            unload_checked += 1
            assert -cs.state[0, S_UP] == kap0
            stress_unload.append(s)
    assert crushed > 300 and unload_checked == 50 and reload_elastic > 40
    # the path is informative: past the peak into softening, into tension on unloading (d < κ)
    assert kap > 4 * kp and min(stress_unload) < 0
    # against the integral of the closed-form cap
    tv = (FC - FC / 3) + (FC - cap_closed_form(kap, FC, FC / 3, kp, G))
    exact = A * cap_energy(kap, FC, FC / 3, kp, G)
    assert abs(cs.state[0, S_DISS] - exact) <= A * dkmax * tv
    assert A * dkmax * tv < 0.015 * exact   # the bound is tight: 1.3 % of the energy here (Δκ up to 2.3e-6 m:
    #                                          on the softening branch Δκ = Δd / (1 + σ_c'/k), σ_c' < 0)


@pytest.mark.parametrize("dim", [2, 3])
def test_hardening_cap_dissipates_its_closed_form(dim):
    """Closure increments δ driven through commit_step (rigid joint: Δu_p = the closure): the dissipation is the left
    Riemann sum of σ_c, and to completion (n δ ≫ κ_p + G_fc/f_c) it tends to
    κ_p (f_ci + (π/4)(f_c - f_ci)) + G_fc per unit area (G_fc counts the softening branch only); here within the
    left-sum bound δ × (total variation 2 f_c - f_ci). The same in 3D (state rows of NSTATE3 columns)."""
    from fem_blocks.laws import commit_step, initial_state, cap_stress
    kp, G, fci, area, h, theta = 1e-3, 5000.0, 0.4 * FC, 0.01, 1.0, 1.0
    code, p = law_parameters("coulomb", dict(mu=0.6, f_c=FC, G_fc=G, kappa_p=kp, f_ci=fci), "j")
    law, par = np.array([code]), p[None, :].copy()
    st = initial_state(law, dim=dim)
    du, n = 5e-6, 12000                                # κ up to 0.06 m = κ_p + 11.8 G/f_c
    ref = 0.0
    for _ in range(n):
        kap = -st[0, S_UP]
        fc = cap_stress(par[0], st[0])
        assert fc == pytest.approx(cap_closed_form(kap, FC, fci, kp, G), rel=1e-12)
        ref += fc * area * du
        P = np.zeros(dim)
        P[0] = h * fc * area                           # at the cap
        v = np.zeros(dim)
        v[0] = -du / (h * theta)                       # closes by du in the step
        commit_step(law, par, st, np.zeros(1), np.zeros((1, dim)), P, v, np.array([area]), h, theta)
    assert st[0, S_DISS] == pytest.approx(ref, rel=1e-12)
    total = area * (kp * (fci + np.pi / 4 * (FC - fci)) + G)
    tail = area * G * np.exp(-FC * (n * du - kp) / G)  # energy left beyond the last closure
    assert abs(st[0, S_DISS] - (total - tail)) <= area * du * (2 * FC - fci)
    assert area * du * (2 * FC - fci) < 2e-3 * total


def test_hardening_cap_parameters_validated():
    base = dict(mu=0.5, f_c=1e7)
    code, p = law_parameters("coulomb", dict(base, kappa_p=1e-4), "j")
    from fem_blocks.laws import P_FCI, P_KP
    assert p[P_KP] == 1e-4 and p[P_FCI] == pytest.approx(1e7 / 3, rel=1e-15)   # f_ci defaults to f_c/3
    code, p = law_parameters("coulomb", dict(base), "j")
    assert p[P_KP] == 0.0 and p[P_FCI] == 0.0                                  # no hardening by default
    for bad, msg in ((dict(kappa_p=0.0), "kappa_p"), (dict(kappa_p=-1e-4), "kappa_p"),
                     (dict(kappa_p=float("inf")), "kappa_p"), (dict(kappa_p=1e-4, f_ci=2e7), "f_ci <= f_c"),
                     (dict(kappa_p=1e-4, f_ci=0.0), "f_ci"), (dict(f_ci=3e6), "needs kappa_p")):
        with pytest.raises(InputError, match=msg):
            law_parameters("coulomb", dict(base, **bad), "interfaces.j")
    with pytest.raises(InputError, match="kappa_p: needs the compressive strength f_c"):
        law_parameters("elastic", dict(c_N=1e10, c_T=1e10, kappa_p=1e-4), "interfaces.j")

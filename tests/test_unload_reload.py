"""Load–unload–reload of a couplet (a rigid block on a fixed rigid base through one joint point carrying the whole
edge, area A = L T) under driven displacement histories with reversals, against the closed forms of the laws at
every row, with both solvers:

* mixed-mode law in mode I: loading past the peak f_t into softening, secant unloading to the origin with the damage
  frozen, closing into compression (full stiffness k_n: the crack closes), reloading along the secant up to the
  envelope, continuing on the envelope to complete failure (linear and exponential softening);
* mixed-mode law in mode II under a constant compression p: cohesion (secant, damage frozen on unloading) plus
  friction tan φ p in the direction of the slip rate, which changes sign at every reversal; the damage grows again
  only when |u_T| exceeds its largest value (the law is symmetric in u_T);
* the compressive cap with hardening (κ_p) on the mixed law: crushing, unloading with no spring-back, the crack
  opening from the crushed position (the law sees the elastic jump u - u_p), closing, and crushing again from the
  committed cap.

The closed forms are written here from the laws' definitions (docs/laws.md), never from fem_blocks:
linear softening envelope σ(u) = k u (u <= δ), f (u_f - u)/(u_f - δ) (δ < u < u_f), 0 beyond, with δ = f/k and
u_f = 2G/f (triangle of area G); exponential softening σ(u) = f exp(-(u - δ)/(u_e)), u_e = G/f - δ/2 (area G);
secant unloading σ = σ_env(u_max) u / u_max.
"""
import numpy as np
import pytest

from fem_blocks.bodies import Driver, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.laws import S_DISS, S_UP

L, T = 0.2, 0.1
A = L * T
FIX = {k: Driver("velocity", 0.0) for k in ("x", "y", "rz")}
PRM = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6)   # δ_I = 2 µm, δ_II = 6 µm


H = 1e-3   # s, time step (θ = 1: the jump of a step is the driven displacement); histories are given in steps


def couplet(params, drivers, solver, forces=None, rho=None, tol=1e-11):
    """Rigid block on a fixed base, one mixed-mode joint point at mid-edge (tributary area A), step H. (With h = 1 s
    the velocities of µm steps are ~1e-6 and the residual relative to them cannot go below ~1e-7 in Newton: the
    round-off of P̃ = P + h A r_adh, of the size of the impulse, divided by ‖q‖.)"""
    blk = RigidBody([(0, 0), (L, 0), (L, 0.1), (0, 0.1)], drivers=drivers, forces=forces, rho=rho, thickness=T)
    base = RigidBody([(-0.1, -0.1), (0.3, -0.1), (0.3, 0), (-0.1, 0)], drivers=dict(FIX), thickness=T)
    cs = ContactStep([InterfaceSpec("j", ("b", "g"), law="mixed", params=params, placement="positions",
                                    positions=(0.5,))],
                     ["b", "g"], ContactOptions(tol=tol, max_sweeps=1000, criterion="residual", solver=solver))
    sim = Simulation([blk, base], h=H, theta=1.0, contact=cs, gravity=(0.0, 0.0), velocity_reset=rho is not None)
    return blk, cs, sim


def envelope(u, k, f, G, softening):
    """Traction of monotone loading to the jump u >= 0 (pure mode), from the triangle / exponential of area G."""
    d = f / k
    if u <= d:
        return k * u
    if softening == "linear":
        uf = 2 * G / f
        return f * (uf - u) / (uf - d) if u < uf else 0.0
    ue = G / f - d / 2        # ∫_d^∞ f e^{-(u-d)/ue} du = f ue; + f d / 2 = G
    return f * np.exp(-(u - d) / ue)


def test_envelopes_have_the_fracture_energies():
    """The test's envelopes: area G_I / G_II (quadrature, 1e-6), peak f at δ = f/k."""
    from scipy.integrate import quad
    for soft in ("linear", "exponential"):
        for k, f, G in ((PRM["k_n"], PRM["f_t"], PRM["G_I"]), (PRM["k_s"], PRM["c"], PRM["G_II"])):
            d = f / k
            e = quad(lambda u: envelope(u, k, f, G, soft), 0, d)[0] + \
                quad(lambda u: envelope(u, k, f, G, soft), d, 200 * G / f, limit=400)[0]
            assert e == pytest.approx(G, rel=1e-6)
            assert envelope(d, k, f, G, soft) == pytest.approx(f, rel=1e-14)


def history(points):
    """Piecewise-linear displacement history through (step, value) points -> driver table (times = step × H)."""
    return {"times": [t * H for t, _ in points], "values": [float(v) for _, v in points]}


def advance(sim):
    """One step, converged; returns the step number (1, 2, ...)."""
    sim.step()
    assert sim.last_contact.stats["converged"], sim.last_contact.stats["message"]
    return sim.step_count


@pytest.mark.parametrize("softening", ["linear", "exponential"])
@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_mode_I_secant_unloading_closing_and_reloading(solver, softening):
    """Opening u (block lifted, base fixed): load to 15 δ_I (softening), unload to the origin and close to -δ_I,
    reopen and reload to 15 δ_I along the secant, continue on the envelope to 60 δ_I (past u_f = 50 δ_I: broken). At every row
    the normal traction is σ_env(u_max) u/u_max in tension and k_n u in compression (the damage does not act on the
    closed crack), to 1e-9 f_t; the damage never decreases; the dissipated energy at the end is the work of the
    envelope less the elastic energy left, G_I (linear: broken at u_f = 50 δ_I) or
    G_I - f_t u_e e^{-(u-δ_I)/u_e} - ½ σ_env(u) u (exponential), to 1e-3 (trapezoidal ∫ Y dD, δ_I/10 per step)."""
    k, f, G = PRM["k_n"], PRM["f_t"], PRM["G_I"]
    d = f / k
    # (no row lands on u = 0 while closed: with every body driven the free velocity of the step is then ~0 and the
    # residual relative to it meaningless; docs/laws.md "Tests of unloading and reloading")
    pts = [(0, 0.0), (150, 15 * d), (300, 0.0), (320, -d), (340, 0.05 * d), (490, 15 * d), (940, 60 * d)]
    drivers = dict(FIX)
    drivers["y"] = Driver("displacement", history(pts))
    blk, cs, sim = couplet(dict(PRM, softening=softening), drivers, solver)
    tt, uu = [p[0] for p in pts], [p[1] for p in pts]
    umax, rows, dmg = 0.0, {}, []
    for n in range(940):
        t = advance(sim)
        u = float(np.interp(t, tt, uu))
        umax = max(umax, u)
        if u >= 0:
            ref = envelope(umax, k, f, G, softening) * u / umax if umax > 0 else 0.0
        else:
            ref = k * u
        sig = -sim.last_contact.r[0, 0] / A      # tension positive
        assert sig == pytest.approx(ref, abs=1e-9 * f), (n, u)
        dmg.append(cs.state[0, 0])
        phase = ("load" if t <= 150 else "unload" if t <= 300 else "compress" if t <= 340 else "reload" if t <= 490
                 else "envelope")
        rows[phase] = rows.get(phase, 0) + 1
        if 150 < t <= 490:                       # unloading, closing, reloading: damage frozen (to round-off
            assert cs.state[0, 0] == pytest.approx(dmg[149], rel=1e-13)   # where u returns to u_max)
    assert rows == {"load": 150, "unload": 150, "compress": 40, "reload": 150, "envelope": 450}
    assert np.all(np.diff(dmg) >= 0)
    assert 0.5 < dmg[149] < 1.0                  # the unloading starts well inside the softening branch
    # dissipated = work of the envelope to u - elastic energy left: ∫_0^u σ_env - ½ σ_env(u) u (G once broken)
    u = 60 * d
    if softening == "linear":
        ref = G
    else:
        ue = G / f - d / 2
        ref = G - f * ue * np.exp(-(u - d) / ue) - 0.5 * envelope(u, k, f, G, softening) * u
    assert cs.state[0, S_DISS] / A == pytest.approx(ref, rel=1e-3)


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_mode_II_under_compression_with_reversals(solver):
    """Constant compression p (force on the free vertical dof; the block settles at -p/k_n, so ⟨u_N⟩₊ = 0: pure mode
    II), slip u_T driven: 0 → 15 δ_II (softening) → -8 δ_II (unloading and reversal, |u_T| below its largest value:
    damage frozen) → -25 δ_II (past the largest |u_T|: the damage grows again, symmetric law) → 0.
    At every row with a slip rate (linear softening): τ = σ_env(s_max) u_T/s_max + tan φ p sgn(Δu_T), with
    s_max = max |u_T| so far, to 1e-9 c; the friction part changes sign at each reversal."""
    k, f, G = PRM["k_s"], PRM["c"], PRM["G_II"]
    p = 1e5
    d = f / k
    pts = [(0, 0.0), (10, 0.0), (160, 15 * d), (390, -8 * d), (560, -25 * d), (810, 0.0)]
    drivers = {"x": Driver("displacement", history(pts)), "rz": Driver("velocity", 0.0)}
    blk, cs, sim = couplet(dict(PRM), drivers, solver, forces={"y": -p * A}, rho=2000.0)
    tt, uu = [q[0] for q in pts], [q[1] for q in pts]
    smax, prev, signs, dmg = 0.0, 0.0, [], []
    for n in range(810):
        t = advance(sim)
        u = float(np.interp(t, tt, uu))
        du, prev = u - prev, u
        smax = max(smax, abs(u))
        if t <= 10:                       # settling under p with the slip held: friction undetermined
            continue
        assert sim.last_contact.r[0, 0] / A == pytest.approx(p, rel=1e-12)
        coh = envelope(smax, k, f, G, "linear") * u / smax if smax > 0 else 0.0
        ref = coh + PRM["tan_phi"] * p * np.sign(du)
        assert sim.last_contact.r[0, 1] / A == pytest.approx(ref, abs=1e-9 * f), (n, u)
        signs.append(np.sign(du))
        dmg.append(cs.state[0, 0])
        if 160 < t <= 390:                       # damage frozen while |u_T| < 15 δ_II
            assert cs.state[0, 0] == pytest.approx(dmg[149], rel=1e-13)
    assert signs.count(1.0) == 150 + 250 and signs.count(-1.0) == 400    # two reversals, both checked
    assert dmg[-1] > dmg[149] > 0.5 and np.all(np.diff(dmg) >= 0)


@pytest.mark.parametrize("solver", ["nlgs", "newton"])
def test_cap_crushing_unloading_opening_and_reloading(solver):
    """Mixed joint with a hardening cap (f_c, κ_p, G_fc): closure driven to crushing (the cap hardens from f_c/3),
    unloaded with no spring-back (stress-free at u = u_p, not at u = 0), opened from the crushed position past f_t
    (the crack's jump is the elastic jump e = u - u_p), closed again and crushed further from the committed cap.
    Each row against the return map from the committed state (u_p, D) with the test's closed forms:
    e = u - u_p; tension e > 0: σ = σ_env(e_max) e/e_max (secant, e_max the largest tensile elastic jump);
    compression: σ = k_n e unless -k_n e > σ_c(κ), κ = -u_p, then σ = -σ_c(κ) and u_p moves to u + σ_c(κ)/k_n,
    σ_c(κ) = f_ci + (f_c - f_ci) sqrt(2κ/κ_p - κ²/κ_p²) (κ < κ_p), f_c exp(-f_c (κ - κ_p)/G_fc) beyond.
    Traction to 1e-9 f_c, u_p to 1e-9 κ_p."""
    k, ft, GI = PRM["k_n"], PRM["f_t"], PRM["G_I"]
    fc, kp, Gfc = 4e6, 1e-4, 400.0           # the cap's elastic limit f_c/(3 k_n) = 13 µm
    fci = fc / 3
    dI = ft / k
    pts = [(0, 0.0), (200, -2e-4), (260, -1.4e-4), (360, -1.4e-4 + 25 * dI), (460, -2.2e-4), (560, -3e-4)]
    drivers = dict(FIX)
    drivers["y"] = Driver("displacement", history(pts))
    blk, cs, sim = couplet(dict(PRM, f_c=fc, kappa_p=kp, G_fc=Gfc), drivers, solver)
    tt, uu = [q[0] for q in pts], [q[1] for q in pts]

    def cap(kap):
        if kap < kp:
            x = kap / kp
            return fci + (fc - fci) * np.sqrt(2 * x - x * x)
        return fc * np.exp(-fc * (kap - kp) / Gfc)

    emax, crushed, opened, unload = 0.0, 0, 0, []
    for n in range(560):
        up0 = 0.0 if n == 0 else cs.state[0, S_UP]
        t = advance(sim)
        u = float(np.interp(t, tt, uu))
        e = u - up0
        up = up0
        if e > 0:
            emax = max(emax, e)
            sig = envelope(emax, k, ft, GI, "linear") * e / emax
            opened += 1
        else:
            sig = k * e
            if -sig > cap(-up0):
                sig, up = -cap(-up0), u + cap(-up0) / k
                crushed += 1
        assert -sim.last_contact.r[0, 0] / A == pytest.approx(sig, abs=1e-9 * fc), (n, u)
        assert cs.state[0, S_UP] == pytest.approx(up, abs=1e-9 * kp), (n, u)
        if 200 < t <= 260:
            unload.append((u, sig, up0))
    assert crushed > 150 and opened > 50
    assert -cs.state[0, S_UP] > 2 * kp                  # crushed into the softening branch of the cap
    # no spring-back: on unloading the closure stays and the stress changes sign where u passes it (within a step),
    # far from u = 0
    up200 = unload[0][2]
    assert all(r[2] == up200 for r in unload) and up200 < -1.5e-4
    first = next(r for r in unload if r[1] > 0)
    assert 0 < first[0] - up200 <= 1e-6 + 1e-18

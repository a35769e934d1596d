"""Interface-law terms that the peak/energy tests of test_laws.py cannot see, each against a closed form or an
independent solution (never against fem_blocks' own formula):

* Frémond–Cangémi viscous rate law with p ≠ 1 (p = ½ and 2): β from the kernel against the implicit equation
  b (β − β_prev)/h = −[(β Y − w)⁺]^{1/p} solved by scipy's brentq;
* friction μ(β) = (1 − β) μ_r along a sliding test under pressure p: the whole force-slip curve against
  μ(β) p + β² c_T |u_T| with β = min(1, w/(c_T u_T²)), and the residual μ_r p;
* mixed-mode softening: the energy dissipated along a proportional opening + sliding path in closed form, with
  fracture energies G_I and G_II far apart so that any other blend of the two modes fails.
"""

import numpy as np
import pytest
from scipy.optimize import brentq

from fem_blocks.bodies import Driver
from fem_blocks.laws import FREMOND, S_BETA, S_DISS, initial_state, internal_update, law_parameters

from test_laws import A, CN, CT, W, driven, joint, ramp  # noqa: E402


@pytest.mark.parametrize("p", [0.5, 2.0])
def test_fremond_viscous_exponent_against_implicit_equation(p):
    """b (β − β0)/h = −[(β Y − w)⁺]^{1/p} (thesis eq. 5.3.42, backward Euler), Y = c_N⟨u_N⟩₊² + c_T u_T²:
    β from `internal_update` equals the root of that scalar equation on [0, β0] found by brentq (1e-12)."""
    b = 2.0
    code, par = law_parameters("fremond", dict(c_N=CN, c_T=CT, w=W, b=b, p=p), "j")
    assert code == FREMOND
    uc = np.sqrt(W / CN)
    checked = 0
    for beta0 in (1.0, 0.6):
        st = initial_state(np.array([FREMOND]))[0]
        st[S_BETA] = beta0
        for uN, uT in ((1.5 * uc, 0.0), (3 * uc, 0.0), (2 * uc, np.sqrt(W / CT)), (10 * uc, 0.0)):
            Y = CN * max(uN, 0.0) ** 2 + CT * uT ** 2
            if beta0 * Y <= W:
                continue
            for h in (1e-6, 1e-4, 1e-2):
                f = lambda beta: b * (beta - beta0) / h + max(beta * Y - W, 0.0) ** (1.0 / p)  # noqa: E731
                ref = brentq(f, 0.0, beta0, xtol=1e-15, rtol=1e-15)
                got = internal_update(FREMOND, par, st, uN, uT, h)
                assert got == pytest.approx(ref, rel=1e-12, abs=1e-14), (beta0, uN, uT, h)
                checked += 1
    assert checked >= 18
    # the cases are informative: β moves away from β0 and stays above the rate-independent limit w/Y
    st = initial_state(np.array([FREMOND]))[0]
    beta = internal_update(FREMOND, par, st, 3 * uc, 0.0, 1e-4)
    assert W / (9 * W) < beta < 1.0


def test_fremond_damage_friction_sliding_curve_and_residual():
    """Rigid block under pressure p = 2e5 Pa (force on its free vertical dof), slid horizontally by a driver to
    20 u_c (u_c = sqrt(w/c_T)); friction = "damage", μ_r = 0.6. Sliding all along (driven), the tangential
    reaction per unit area is μ(β) p + β² c_T |u_T| with β = min(1, w/(c_T u_T²)) (rate-independent, monotone)
    and μ(β) = (1 − β) μ_r (thesis §5.3.5.b): the whole curve to 1e-6 (the first step adds the inertia m v/h of
    the 4 kg block set in motion), the residual → μ_r p."""
    mu_r, p = 0.6, 2e5
    uc = np.sqrt(W / CT)
    drivers = {"x": Driver("displacement", ramp([0, 20 * uc], [0, 2])), "rz": Driver("velocity", 0.0)}
    blk, base, cs, sim = joint("fremond", dict(c_N=CN, c_T=CT, w=W, friction="damage", mu_r=mu_r), drivers=drivers,
                               forces={"y": -p * A}, rho=2000.0, h=1e-2)
    s, ref = [], []
    for _ in range(200):
        sim.step()
        ut = abs(blk.q[0])
        beta = min(1.0, W / (CT * ut * ut))
        s.append(abs(blk.reaction[0]) / A)
        ref.append((1 - beta) * mu_r * p + beta ** 2 * CT * ut)
    s, ref = np.array(s), np.array(ref)
    assert s[0] - ref[0] == pytest.approx(4.0 * 10 * uc / 1e-2 / A, rel=1e-6)  # + m v/h: the driver starts it
    np.testing.assert_allclose(s[1:], ref[1:], rtol=1e-6)
    assert s[-1] == pytest.approx(mu_r * p, rel=0.01)   # β = 1/400 at the end
    assert cs.state[:, S_BETA].max() < 0.003


def mixed_dissipation(prm, m):
    """Energy per unit area dissipated by the mixed-mode law (linear softening) along a proportional path of
    mode ratio m = (u_T/δ_II)²/λ² to complete failure, in closed form.

    With a = u_N/δ_I, b = u_T/δ_II (δ_I = f_t/k_n, δ_II = c/k_s), λ² = a² + b² and e_I = f_t²/(2k_n),
    e_II = c²/(2k_s): Y = ½(k_n u_N² + k_s u_T²) = λ² ē, ē = (1 − m) e_I + m e_II (constant on the path);
    D = λ_f (λ − 1)/(λ(λ_f − 1)) with λ_f = (1 − m) G_I/e_I + m G_II/e_II, so dD/dλ = λ_f/((λ_f − 1) λ²) and
    ∫_1^{λ_f} Y dD = ē λ_f. Pure modes: m = 0 gives G_I, m = 1 gives G_II."""
    eI = prm["f_t"] ** 2 / (2 * prm["k_n"])
    eII = prm["c"] ** 2 / (2 * prm["k_s"])
    ebar = (1 - m) * eI + m * eII
    lf = (1 - m) * prm["G_I"] / eI + m * prm["G_II"] / eII
    return ebar * lf, lf


@pytest.mark.parametrize("m", [0.25, 0.75])
def test_mixed_mode_proportional_path_dissipation_closed_form(m):
    """Opening and sliding driven together, u_N = √(1−m) δ_I λ, u_T = √m δ_II λ (mode ratio m constant), to
    λ = 1.1 λ_f: the dissipated energy is the closed form of `mixed_dissipation` to 0.1 % (trapezoidal ∫ Y dD
    over 1000 steps, finer around the peak λ = 1). G_II/G_I = 40: the blends m and √m (or a linear interpolation of
    the energies) differ by a factor 1.5 to 3."""
    prm = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=5.0, G_II=200.0, tan_phi=0.6)
    e_ref, lf = mixed_dissipation(prm, m)
    dI, dII = prm["f_t"] / prm["k_n"], prm["c"] / prm["k_s"]
    lam = np.array([0.0, 0.95, 5.0, 1.1 * lf])
    times = [0.0, 0.05, 0.55, 1.0]
    n = 1000
    hist = {"y": ramp(list(np.sqrt(1 - m) * dI * lam), times), "x": ramp(list(-np.sqrt(m) * dII * lam), times)}
    blk, base, cs, sim = joint("mixed", prm, h=1.0 / n, drivers=driven(hist))
    for _ in range(n):
        sim.step()
    assert np.all(cs.state[:, S_BETA] == 1.0)  # fully damaged
    e = cs.state[:, S_DISS].sum() / A
    assert e == pytest.approx(e_ref, rel=1e-3)  # measured 1e-5 (m = ¼) and 1e-4 (m = ¾)
    other = [mixed_dissipation(prm, x)[0] for x in (np.sqrt(m), m * m)]
    assert all(abs(o - e_ref) > 0.2 * e_ref for o in other)  # the test tells the blends apart

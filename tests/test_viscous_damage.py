"""Viscous regularisation of the mixed-mode damage (laws.viscous_damage, interface key `damage_viscosity` η):
backward Euler of Ḋ = (D_s(u) - D)/η. Checked against the closed form of the discrete scheme under a held jump,
the rate-independent limit η -> 0, the consistent tangent against finite differences, the dissipated energy of a
slow mode-I opening (-> G_I), the damage returned by the global Newton, and the input validation."""
import numpy as np
import pytest

from fem_blocks import laws
from fem_blocks.errors import InputError
from fem_blocks.laws import MIXED, NSTATE, P_ETA, S_BETA, S_DISS

PAR = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6)
DI = PAR["f_t"] / PAR["k_n"]  # opening at the peak, δ_I
DII = PAR["c"] / PAR["k_s"]


def _par(eta=0.0, softening="linear"):
    prm = dict(PAR, softening=softening)
    if eta is not None:
        prm["damage_viscosity"] = eta
    return laws.law_parameters("mixed", prm, "interfaces.j")[1]


def test_input_validation():
    assert _par(None)[P_ETA] == 0.0  # default: rate-independent
    assert _par(0.02)[P_ETA] == 0.02
    for bad in (-1e-3, float("inf"), float("nan"), "fast"):
        with pytest.raises(InputError, match=r"interfaces\.j\.damage_viscosity"):
            _par(bad)
    with pytest.raises(InputError, match="damage_viscosity"):  # mixed law only
        laws.law_parameters("elastic", dict(mu=0.5, c_N=1e9, c_T=1e9, damage_viscosity=0.1), "interfaces.j")


@pytest.mark.parametrize("softening", ["linear", "exponential"])
def test_held_jump_relaxes_as_the_discrete_closed_form(softening):
    """Jump held beyond the peak (λ = 3, mixed mode) from D = 0: D_n = D_s (1 - (1 + h/η)^(-n)) to 1e-14,
    D_n increasing and below D_s; one commit per step as in ContactStep."""
    h, eta = 1e-3, 7e-3
    p = _par(eta, softening)
    uN, uT = 3 * DI * np.cos(0.6), 3 * DII * np.sin(0.6)
    Ds = laws.internal_update(MIXED, _par(0.0, softening), np.zeros(NSTATE), uN, uT, h)
    assert 0.3 < Ds < 1.0
    st = np.zeros(NSTATE)
    prev = 0.0
    for n in range(1, 61):
        D = laws.internal_update(MIXED, p, st, uN, uT, h)
        laws.commit(MIXED, p, st, D, uN, uT, 1.0)
        assert abs(D - Ds * (1 - (1 + h / eta) ** -n)) <= 1e-14
        assert prev < D < Ds
        prev = D


def test_vanishing_viscosity_is_the_rate_independent_law():
    """η = 0: the same value as the law without the key, to the last bit; η = 1e-13 h: equal to round-off
    (|D - D_s| <= η/h + 1e-16) along random jumps and committed damage."""
    rng = np.random.default_rng(3)
    h = 1e-3
    p0, pz, pe = _par(None), _par(0.0), _par(1e-13 * h)
    st = np.zeros(NSTATE)
    for _ in range(300):
        lam, ang = rng.uniform(0.5, 60.0), rng.uniform(-np.pi / 2, np.pi)
        uN, uT = lam * np.cos(ang) * DI, lam * np.sin(ang) * DII
        st[S_BETA] = rng.choice([0.0, 0.4])
        Ds = laws.internal_update(MIXED, p0, st, uN, uT, h)
        assert laws.internal_update(MIXED, pz, st, uN, uT, h) == Ds
        assert abs(laws.internal_update(MIXED, pe, st, uN, uT, h) - Ds) <= 1e-13 + 1e-16


def test_viscous_tangent_matches_finite_differences():
    """∂D/∂u = h/(η + h) ∂D_s/∂u (the Newton tangent) against central differences of internal_update."""
    h, eta = 1e-3, 4e-3
    p = _par(eta)
    st = np.zeros(NSTATE)
    st[S_BETA] = 0.2
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(200):
        lam, ang = rng.uniform(2.0, 10.0), rng.uniform(0.05, 1.5)
        uN, uT = lam * np.cos(ang) * DI, lam * np.sin(ang) * DII
        Ds, gN, gT = laws.mixed_damage_gradient(p, st[S_BETA], uN, uT)
        D, vN, vT = laws.viscous_damage(p, st[S_BETA], Ds, gN, gT, h)
        assert D == laws.internal_update(MIXED, p, st, uN, uT, h)
        if Ds <= st[S_BETA] + 1e-3 or Ds >= 1.0 - 1e-3:
            continue
        eN, eT = 1e-7 * DI, 1e-7 * DII
        fN = (laws.internal_update(MIXED, p, st, uN + eN, uT, h) - laws.internal_update(MIXED, p, st, uN - eN, uT, h)) \
            / (2 * eN)
        fT = (laws.internal_update(MIXED, p, st, uN, uT + eT, h) - laws.internal_update(MIXED, p, st, uN, uT - eT, h)) \
            / (2 * eT)
        scale = abs(fN) * DI + abs(fT) * DII
        assert abs(vN - fN) * DI <= 1e-6 * scale and abs(vT - fT) * DII <= 1e-6 * scale
        assert abs(vN - h / (eta + h) * gN) <= 1e-15 * abs(gN)
        checked += 1
    assert checked > 100


def _mode_I_dissipation(eta, rate, h):
    """Opening at constant rate u̇ (pure mode I) to 1.2 δ_f, then held until D >= 1 - 1e-12; dissipation per unit
    area [J/m²] as committed by the law (trapezoidal ∫ Y dD)."""
    p = _par(eta)
    lf = 2 * PAR["G_I"] * PAR["k_n"] / PAR["f_t"] ** 2
    st = np.zeros(NSTATE)
    u = 0.0
    for _ in range(200000):
        u = min(u + rate * h, 1.2 * lf * DI)
        D = laws.internal_update(MIXED, p, st, u, 0.0, h)
        laws.commit(MIXED, p, st, D, u, 0.0, 1.0)
        if D >= 1.0 - 1e-12:
            break
    return st[S_DISS]


def test_dissipated_energy_tends_to_G_I():
    """Slow opening: the dissipated energy tends to G_I. Rate-independent (η = 0): G_I to 1e-5 (trapezoidal ∫ Y dD,
    2000 steps over δ_f). Viscous: a positive excess, first order in η u̇/δ_I (measured 1.6e-2 G_I at
    η u̇ = 0.1 δ_I, ten times less at 0.01 δ_I)."""
    lf = 2 * PAR["G_I"] * PAR["k_n"] / PAR["f_t"] ** 2
    h = lf * DI / 2000  # time unit: u̇ = 1
    e0 = _mode_I_dissipation(0.0, 1.0, h)
    assert abs(e0 - PAR["G_I"]) <= 1e-5 * PAR["G_I"]
    ex = [_mode_I_dissipation(eta, 1.0, h) - e0 for eta in (0.1 * DI, 0.01 * DI)]
    assert ex[0] > ex[1] > 0.0
    assert ex[0] <= 0.02 * PAR["G_I"]
    assert 8.0 <= ex[0] / ex[1] <= 12.0  # first order in η u̇


def test_newton_returns_the_viscous_damage():
    """Global Newton with damage inside (one joint pulled open past the peak by q): converged, the returned damage
    is the viscous law at the returned jump, below the rate-independent damage of the same problem."""
    from fem_blocks.solver import newton
    from fem_blocks.linalg import to_block_csr
    h, th = 1e-3, 1.0
    W = to_block_csr(np.array([[2.0, 0.3], [0.3, 1.5]]) * 1e-2, 2)
    law = np.array([MIXED])
    area = np.array([1e-3])
    q = np.array([40 * DI / (h * th), 5 * DII / (h * th)])
    out = {}
    for eta in (0.0, 5e-3):
        par = _par(eta)[None, :].copy()
        par[:, laws.P_FC] = 0.0
        st = laws.initial_state(law)
        res, x = newton.solve_cohesive_newton(W, q, np.array([PAR["tan_phi"]]), law, par, st, np.zeros((1, 2)), area,
                                              h, th, tol=1e-10)
        assert res.converged
        uN, uT = h * th * res.u[0], h * th * res.u[1]
        assert abs(x[0] - laws.internal_update(MIXED, par[0], st[0], uN, uT, h)) <= 1e-12
        out[eta] = x[0]
    assert 0.0 < out[5e-3] < out[0.0]

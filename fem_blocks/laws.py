"""Interface laws per contact point (thesis §5.2–5.3, docs/method.md §4): Signorini–Coulomb plus cohesive parts.

Every law is written with the change of variables of thesis §6.3.4: r̃ = r + r_adh, where
(v_N shifted, r̃_N) ∈ Signorini and (v_T, r̃_T) ∈ Coulomb(μ r̃_N). Per unit area (then times the
contact's tributary area A), with u = (u_N, u_T) the displacement jump since the reference state
(θ-integrated: u_{i+1} = u_i + h[(1-θ) v_i + θ v_{i+1}]):

* coulomb (0):        r_adh = 0.
* elastic (1):        r_adh = (c_N u_N, c_T u_T) (§5.3.2).
* brittle (2), variant "elastic": r_adh = (c_N u_N, c_T u_T) until c_N u_N > r_c (or |c_T u_T| > s_c
  when a shear strength s_c is given), then broken for good (Signorini–Coulomb). Dissipated energy at
  the break = the elastic energy released, r_c²/(2 c_N) per unit area in pure tension.
* brittle (3), variant "dugdale": r_adh = (r_c, 0) while u_N < l_c (a constant cohesive stress: the
  joint holds any tension up to r_c, then opens at constant stress), then broken. Dissipation r_c·l_c.
  Through Coulomb on r̃_N = r_N + r_c the joint also has a cohesion μ r_c in shear.
* fremond (4) (Frémond–Cangémi, §5.3.4, eq. 5.3.40–5.3.44): r_adh = β² (c_N u_N, c_T u_T) with the
  adhesion intensity β ∈ [0, 1] non-increasing, Y = c_N⟨u_N⟩₊² + c_T u_T²:
  rate-independent (b = 0): β = min(β_prev, w / Y);
  viscous (b > 0): b (β - β_prev)/h = -[(β Y - w)⁺]^{1/p} solved implicitly for β ≤ β_prev.
  Friction μ constant or μ(β) = (1 - β) μ_r. Dissipated (decohesion) energy w (β_prev - β) per unit area.
* mixed (5) (mixed-mode softening): r_adh = (1 - D)(k_n⟨u_N⟩₊, k_s u_T) with Coulomb tan φ on r̃ (the
  compressive part), so the shear strength is c + tan φ p and the residual tan φ p. Damage from the
  normalised jump λ = sqrt((⟨u_N⟩₊/δ_I)² + (u_T/δ_II)²), δ_I = f_t/k_n, δ_II = c/k_s (quadratic
  initiation criterion (σ/f_t)² + (τ/c)² = 1); linear softening D = λ_f(λ-1)/(λ(λ_f-1)) or exponential
  D = 1 - exp(-(λ-1)/λ_e)/λ, with λ_f (λ_e) interpolated between modes I and II by the mode ratio
  m = (u_T/δ_II)²/λ² so that pure modes dissipate G_I and G_II. Dissipation Y ΔD with Y = ½(k_n⟨u_N⟩₊² + k_s u_T²).
  Optional viscous regularisation (`damage_viscosity` η > 0): Ḋ = (D_s(u) - D)/η with D_s the rate-independent value,
  backward Euler D = (D_n + (h/η) D_s)/(1 + h/η) (`viscous_damage`); η = 0 is the rate-independent law.
  IMPL-EX (`damage_integration = "implex"`, mixed and fremond; Oliver, Huespe & Cante 2008): the step runs at the
  internal variable extrapolated from the two last committed values, x̃ = x_n + h_{n+1}(x_n - x_{n-1})/h_n (rate in
  S_HIST, `implex_extrapolate`), held fixed; commit_step commits the implicit value of the converged jump.

Compressive cap (any law, optional `f_c` [Pa]): r̃_N <= f_c A (elastic–perfectly plastic crushing). At the cap
the joint closes further; the closure u_p <= 0 (state S_UP) shifts the contact surface (Signorini on g - g0 - u_p,
so unloading does not spring back), the laws see the elastic jump u - u_p, and f_c A |Δu_p| is dissipated.
With a compressive fracture energy `G_fc` [J/m²] the cap softens exponentially with the committed closure:
f_c(u_p) = f_c exp(-f_c |u_p| / G_fc) (∫ f_c(u_p) d|u_p| = G_fc), floored at CAP_FLOOR f_c (`cap_stress`).
With a plastic closure at the peak `kappa_p` κ_p [m] the cap first hardens from `f_ci` (default f_c/3) to f_c,
f_c(κ) = f_ci + (f_c - f_ci) sqrt(2κ/κ_p - κ²/κ_p²) for κ = |u_p| < κ_p, then softens from the peak:
f_c exp(-f_c (κ - κ_p)/G_fc) (G_fc counts the softening branch only: the whole crushing dissipates
κ_p (f_ci + (π/4)(f_c - f_ci)) + G_fc per unit area).

Elliptic cap (mixed law, optional `C_ss` >= 0, default 0: the cap above): the admissible impulses are
{P̃_N² + C_ss |P̃_T|² <= (h f_c(κ) A)², |P̃_T| <= μ P̃_N, P̃_N >= 0} (Lourenço–Rots' cap C_nn σ² + C_ss τ² = σ̄_c²,
C_nn = 1, C_n = 0, on the frictional part r̃), with associated flow on the ellipse, v' = -λ (P̃_N, C_ss P̃_T); the
plastic closure is its normal part (solver/nlgs.py _cap_ell, _cap3_ell; solver/newton.py rows; commit_step).

Compression: Signorini is always kept on r̃. For coulomb, brittle and fremond it is rigid (g - g0 >= 0); the
elastic and mixed laws have a compliant joint in compression (stiffness c_N, k_n): g̃ + r̃_N/(k A) >= 0 ⊥
r̃_N >= 0, so the normal spring acts in tension through r_adh and in compression through r̃ (on which
friction acts).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from . import specs as _specs
from .errors import InputError

COULOMB, ELASTIC, BRITTLE, DUGDALE, FREMOND, MIXED = 0, 1, 2, 3, 4, 5
LAW_NAMES = {"coulomb": COULOMB, "elastic": ELASTIC, "brittle": BRITTLE, "dugdale": DUGDALE,
             "fremond": FREMOND, "mixed": MIXED}
# parameter columns (per unit area)
P_MU, P_CN, P_CT, P_RC, P_SC, P_LC, P_W, P_B, P_P, P_MUR, P_MUKIND, P_FT, P_C, P_GI, P_GII, P_SOFT, P_FC, P_ETA, \
    P_GFC, P_KP, P_FCI, P_CSS, P_IMPLEX = range(23)
NPAR = 23
# state columns; 3D (u = (u_N, u_T, u_S)) appends the second tangential jump S_US, the 2D columns stay in place.
# S_HIST: Dugdale's largest opening; mixed and fremond: the rate of the internal variable over the last committed
# step, (x_n - x_{n-1})/h_n, for the IMPL-EX extrapolation (written by commit_step only with damage_integration =
# "implex")
S_BETA, S_UN, S_UT, S_DISS, S_HIST, S_BROKEN, S_UP = range(7)
NSTATE = 7
S_US = 7
NSTATE3 = 8

LAW_KEYS = _specs.LAW_KEYS  # the parameters each law takes (specs.LAW_PARAMS, the one table)

# parameter name -> column of the parameter vector (mixed: k_n, k_s, tan_phi share the columns of c_N, c_T, mu)
_COLUMNS = dict(mu=P_MU, c_N=P_CN, c_T=P_CT, r_c=P_RC, s_c=P_SC, l_c=P_LC, w=P_W, b=P_B, p=P_P, mu_r=P_MUR,
                k_n=P_CN, k_s=P_CT, f_t=P_FT, c=P_C, G_I=P_GI, G_II=P_GII, tan_phi=P_MU, damage_viscosity=P_ETA,
                f_c=P_FC, G_fc=P_GFC, kappa_p=P_KP, f_ci=P_FCI, C_ss=P_CSS)


def pack(law: str, values: dict) -> tuple[int, np.ndarray]:
    """Validated parameter values (specs.validate_law_params) -> (law code, parameter row of NPAR columns)."""
    p = np.zeros(NPAR)
    for k, v in values.items():
        if k in _COLUMNS:
            p[_COLUMNS[k]] = v
    if law == "coulomb":
        return COULOMB, p
    if law == "elastic":
        return ELASTIC, p
    if law == "brittle":
        return (DUGDALE if values["variant"] == "dugdale" else BRITTLE), p
    if law == "fremond":
        p[P_MUKIND] = 1.0 if values["friction"] == "damage" else 0.0
        p[P_IMPLEX] = 1.0 if values["damage_integration"] == "implex" else 0.0
        return FREMOND, p
    p[P_SOFT] = 0.0 if values["softening"] == "linear" else 1.0
    p[P_IMPLEX] = 1.0 if values["damage_integration"] == "implex" else 0.0
    return MIXED, p


def law_parameters(law: str, params: dict, name: str) -> tuple[int, np.ndarray]:
    """Validate a law's parameters (SI, per unit area; specs.validate_law_params) -> (law code, parameter row)."""
    return pack(law, _specs.validate_law_params(law, params, name))


def initial_state(law: np.ndarray, dim: int = 2) -> np.ndarray:
    """Committed state of intact joints: (n, NSTATE) in 2D, (n, NSTATE3) in 3D (extra column S_US)."""
    if dim not in (2, 3):
        raise InputError(f"dim = {dim!r}: expected 2 or 3")
    st = np.zeros((law.size, NSTATE if dim == 2 else NSTATE3))
    st[:, S_BETA] = np.where(law == MIXED, 0.0, 1.0)  # beta = 1 (intact); for MIXED the column holds D = 0
    return st


# ----------------------------------------------------------------------------- compiled law evaluation
CAP_FLOOR = 1e-6  # a softened cap never drops below CAP_FLOOR f_c (a zero cap would read as "no cap")


@njit(cache=True)
def cap_stress(par, st):
    """Current compressive strength of the cap [Pa] (0: no cap) at the committed plastic closure κ = |u_p|,
    u_p = st[S_UP] <= 0 (explicit in the step: the cap of a step is that of the committed state):

    * hardening (κ_p = `kappa_p` > 0, κ < κ_p): f_ci + (f_c - f_ci) sqrt(2κ/κ_p - κ²/κ_p²), from f_ci at κ = 0
      to the peak f_c at κ = κ_p (Lourenço's cap hardening, with κ the plastic closure);
    * then, with a compressive fracture energy G_fc > 0, the exponential softening measured from the peak,
      f_c max(exp(-f_c (κ - κ_p) / G_fc), CAP_FLOOR) (κ_p = 0: from κ = 0); without G_fc, f_c (perfectly plastic).

    κ_p = 0 evaluates the expression of the cap without hardening (same arithmetic, bitwise)."""
    fc = par[P_FC]
    if fc <= 0.0:
        return fc
    k = abs(st[S_UP])
    kp = par[P_KP]
    if kp > 0.0:
        if k < kp:
            x = k / kp
            return par[P_FCI] + (fc - par[P_FCI]) * np.sqrt(x * (2.0 - x))
        k = k - kp
    if par[P_GFC] <= 0.0:
        return fc
    return fc * max(np.exp(-fc * k / par[P_GFC]), CAP_FLOOR)


@njit(cache=True)
def _fremond_beta(par, beta0, Y, h):
    w = par[P_W]
    b = par[P_B]
    if Y <= 0.0:
        return beta0
    if b == 0.0:
        return min(beta0, w / Y)
    p = par[P_P]
    # b (beta - beta0)/h = -((beta Y - w)+)^(1/p), beta in [0, beta0]: monotone -> bisection
    if beta0 * Y <= w:
        return beta0
    lo, hi = 0.0, beta0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        f = b * (mid - beta0) / h + max(mid * Y - w, 0.0) ** (1.0 / p)
        if f > 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


@njit(cache=True)
def _mixed_damage(par, D0, uN, uT):
    kn, ks = par[P_CN], par[P_CT]
    dI = par[P_FT] / kn
    dII = par[P_C] / ks
    un = max(uN, 0.0)
    lam2 = (un / dI) ** 2 + (uT / dII) ** 2
    if lam2 <= 1.0:
        return D0
    lam = np.sqrt(lam2)
    m = (uT / dII) ** 2 / lam2  # mode ratio: 0 pure I, 1 pure II
    if par[P_SOFT] == 0.0:
        lfI = 2.0 * par[P_GI] * kn / par[P_FT] ** 2
        lfII = 2.0 * par[P_GII] * ks / par[P_C] ** 2
        lf = (1.0 - m) * lfI + m * lfII
        D = 1.0 if lam >= lf else lf * (lam - 1.0) / (lam * (lf - 1.0))
    else:
        # G = f^2/(2k) + f * delta_e  ->  lambda_e = delta_e/delta_0 = (2 G k / f^2 - 1)/2
        leI = (2.0 * par[P_GI] * kn / par[P_FT] ** 2 - 1.0) / 2.0
        leII = (2.0 * par[P_GII] * ks / par[P_C] ** 2 - 1.0) / 2.0
        le = (1.0 - m) * leI + m * leII
        D = 1.0 - np.exp(-(lam - 1.0) / le) / lam
    return max(D0, min(D, 1.0))


@njit(cache=True)
def viscous_damage(par, D0, Ds, gN, gT, h):
    """Viscous regularisation of the mixed-mode damage (Duvaut–Lions / overstress type, `damage_viscosity` η > 0):
    Ḋ = (D_s(u) - D)/η with D_s = max(D_committed, D(λ(u))) the rate-independent damage of the current jump,
    backward Euler over the step h from the committed D0: D = (D0 + a D_s)/(1 + a), a = h/η, i.e.
    D = D0 + w (D_s - D0) with w = a/(1 + a) in [0, 1) (monotone: D >= D0 since D_s >= D0), and the consistent
    tangent ∂D/∂u = w ∂D_s/∂u. η = 0 returns (D_s, gN, gT) unchanged (rate-independent law, bitwise).
    Under a held jump (D_s fixed) D_n = D_s - (D_s - D0)(1 + a)^(-n)."""
    eta = par[P_ETA]
    if eta == 0.0:
        return Ds, gN, gT
    w = h / (eta + h)  # a/(1 + a), a = h/eta
    return D0 + w * (Ds - D0), w * gN, w * gT


@njit(cache=True)
def mixed_damage_gradient(par, D0, uN, uT):
    """Damage of the mixed-mode law implied by the jump (uN, uT), D = max(D0, D(λ, m)) as in `internal_update`,
    and its derivative (∂D/∂u_N, ∂D/∂u_T) on the active piece (0 where D = D0, λ <= 1 or D = 1), for the
    consistent tangent of the global Newton (solver/newton.py). With a = ⟨u_N⟩₊/δ_I, b = u_T/δ_II, λ² = a² + b²,
    m = b²/λ²: ∂λ/∂a = a/λ, ∂λ/∂b = b/λ, ∂m/∂a = -2ab²/λ⁴, ∂m/∂b = 2ba²/λ⁴; linear softening
    D = λ_f(1 - 1/λ)/(λ_f - 1): ∂D/∂λ = λ_f/((λ_f - 1)λ²), ∂D/∂λ_f = -(1 - 1/λ)/(λ_f - 1)²; exponential
    D = 1 - e^{-(λ-1)/λ_e}/λ: ∂D/∂λ = e^{-(λ-1)/λ_e}(1/(λ_e λ) + 1/λ²), ∂D/∂λ_e = -e^{-(λ-1)/λ_e}(λ-1)/(λ λ_e²);
    λ_f (λ_e) = mode I value + m (mode II - mode I). Returns (D, dD/du_N, dD/du_T)."""
    kn, ks = par[P_CN], par[P_CT]
    dI = par[P_FT] / kn
    dII = par[P_C] / ks
    un = max(uN, 0.0)
    a = un / dI
    b = uT / dII
    lam2 = (un / dI) ** 2 + (uT / dII) ** 2  # the arithmetic of _mixed_damage (same D to the last bit)
    if lam2 <= 1.0:
        return D0, 0.0, 0.0
    lam = np.sqrt(lam2)
    m = (uT / dII) ** 2 / lam2
    dm_da = -2.0 * a * b * b / (lam2 * lam2)
    dm_db = 2.0 * b * a * a / (lam2 * lam2)
    if par[P_SOFT] == 0.0:
        lfI = 2.0 * par[P_GI] * kn / par[P_FT] ** 2
        lfII = 2.0 * par[P_GII] * ks / par[P_C] ** 2
        lf = (1.0 - m) * lfI + m * lfII
        if lam >= lf:
            D, gl, gm = 1.0, 0.0, 0.0
        else:
            D = lf * (lam - 1.0) / (lam * (lf - 1.0))
            gl = lf / ((lf - 1.0) * lam2)
            gm = -(1.0 - 1.0 / lam) / (lf - 1.0) ** 2 * (lfII - lfI)
    else:
        leI = (2.0 * par[P_GI] * kn / par[P_FT] ** 2 - 1.0) / 2.0
        leII = (2.0 * par[P_GII] * ks / par[P_C] ** 2 - 1.0) / 2.0
        le = (1.0 - m) * leI + m * leII
        e = np.exp(-(lam - 1.0) / le)
        D = 1.0 - e / lam
        gl = e * (1.0 / (le * lam) + 1.0 / lam2)
        gm = -e * (lam - 1.0) / (lam * le * le) * (leII - leI)
    if D >= 1.0:
        return 1.0, 0.0, 0.0
    if D <= D0:
        return D0, 0.0, 0.0
    dD_da = gl * a / lam + gm * dm_da
    dD_db = gl * b / lam + gm * dm_db
    return D, (dD_da / dI if uN > 0.0 else 0.0), dD_db / dII


@njit(cache=True)
def implicit_update(law, par, st, uN, uT, h):
    """Internal variable implied by the jump (uN, uT), irreversible with respect to the committed state:
    β (Frémond), intact flag 1/0 (brittle, Dugdale), damage D (mixed), 1 otherwise (the implicit, backward-Euler
    value of the law). The tangential jump enters only through |uT| (isotropic laws): 3D passes uT = ‖u_T‖."""
    if law == COULOMB or law == ELASTIC:
        return 1.0
    if st[S_BROKEN] > 0.0:
        return st[S_BETA]
    if law == BRITTLE:
        if par[P_CN] * uN > par[P_RC] or (par[P_SC] > 0.0 and abs(par[P_CT] * uT) > par[P_SC]):
            return 0.0
        return 1.0
    if law == DUGDALE:
        return 0.0 if uN >= par[P_LC] else 1.0
    if law == FREMOND:
        un = max(uN, 0.0)
        return _fremond_beta(par, st[S_BETA], par[P_CN] * un * un + par[P_CT] * uT * uT, h)
    D0 = st[S_BETA]
    return viscous_damage(par, D0, _mixed_damage(par, D0, uN, uT), 0.0, 0.0, h)[0]


@njit(cache=True)
def is_implex(law, par):
    """True where the internal variable is integrated by IMPL-EX (`damage_integration = "implex"`: mixed, fremond)."""
    return (law == MIXED or law == FREMOND) and par[P_IMPLEX] == 1.0


@njit(cache=True)
def implex_extrapolate(law, par, st, h):
    """IMPL-EX (Oliver, Huespe & Cante 2008): the internal variable of the step, extrapolated from the two last
    committed values, x̃_{n+1} = x_n + (h_{n+1}/h_n)(x_n - x_{n-1}) = x_n + h_{n+1} ẋ_n with ẋ_n = st[S_HIST] (the
    rate of the last committed step), kept admissible: D̃ in [D_n, 1] (mixed), β̃ in [0, β_n] (Frémond). Held fixed
    in the step (secant law, positive stiffness); commit_step then stores the implicit value."""
    x = st[S_BETA]
    if st[S_BROKEN] > 0.0:
        return x
    xt = x + h * st[S_HIST]
    if law == MIXED:
        return min(max(xt, x), 1.0)
    return max(min(xt, x), 0.0)


@njit(cache=True)
def internal_update(law, par, st, uN, uT, h):
    """Internal variable of the step for the jump (uN, uT): the implicit value (`implicit_update`), or with
    IMPL-EX (`is_implex`) the extrapolated one, independent of the jump (`implex_extrapolate`)."""
    if is_implex(law, par):
        return implex_extrapolate(law, par, st, h)
    return implicit_update(law, par, st, uN, uT, h)


@njit(cache=True)
def step_start(law, par, st, h):
    """Internal variables the solvers start a step from: the committed x_n, or the IMPL-EX extrapolation."""
    n = law.shape[0]
    x = np.empty(n)
    for a in range(n):
        x[a] = implex_extrapolate(law[a], par[a], st[a], h) if is_implex(law[a], par[a]) else st[a, S_BETA]
    return x


@njit(cache=True)
def linear_part(law, par, st, x, tension):
    """Adhesive force per unit area for a given internal variable x: r_adh = (kN uN + fN, kT uT + fT);
    `tension` selects the branch of laws acting in tension only. Returns (kN, kT, fN, fT, mu). fT = 0 for every
    law (isotropic tangential part), so in 3D r_adh = (kN uN + fN, kT u_T, kT u_S)."""
    mu = par[P_MU]
    if law == COULOMB or st[S_BROKEN] > 0.0:
        if law == FREMOND and par[P_MUKIND] == 1.0:
            mu = par[P_MUR]
        return 0.0, 0.0, 0.0, 0.0, mu
    if law == ELASTIC:
        return (par[P_CN] if tension else 0.0), par[P_CT], 0.0, 0.0, mu
    if law == BRITTLE:
        if x == 0.0:
            return 0.0, 0.0, 0.0, 0.0, mu
        return par[P_CN], par[P_CT], 0.0, 0.0, mu
    if law == DUGDALE:
        if x == 0.0:
            return 0.0, 0.0, 0.0, 0.0, mu
        return 0.0, 0.0, par[P_RC], 0.0, mu
    if law == FREMOND:
        if par[P_MUKIND] == 1.0:
            mu = (1.0 - x) * par[P_MUR]
        b2 = x * x
        return b2 * par[P_CN], b2 * par[P_CT], 0.0, 0.0, mu
    kN = (1.0 - x) * par[P_CN] if tension else 0.0
    return kN, (1.0 - x) * par[P_CT], 0.0, 0.0, mu


@njit(cache=True)
def compression_stiffness(law, par):
    """Normal stiffness in compression per unit area (0: rigid, Signorini). The elastic and mixed-mode laws
    model a compliant mortar joint: Signorini with compliance, g̃ + r̃_N/(k A) >= 0 ⊥ r̃_N >= 0."""
    if law == ELASTIC:
        return par[P_CN]
    if law == MIXED:
        return par[P_CN]
    return 0.0


@njit(cache=True)
def _commit_core(law, par, st, x, uN, uT, uT0, area):
    """Internal variable x and dissipated energy [J] at the end of a step; uT, uT0: tangential jump now and at the
    last commit (2D: signed; 3D: the norm ‖u_T‖, the laws being isotropic)."""
    if law != COULOMB and st[S_BROKEN] == 0.0:
        if law == BRITTLE and x == 0.0:
            st[S_DISS] += area * 0.5 * (par[P_CN] * st[S_UN] ** 2 * (st[S_UN] > 0) + par[P_CT] * uT0 ** 2)
            st[S_BROKEN] = 1.0
            st[S_BETA] = 0.0
        elif law == DUGDALE:
            if uN > st[S_HIST]:
                st[S_DISS] += area * par[P_RC] * (min(uN, par[P_LC]) - max(st[S_HIST], 0.0))
                st[S_HIST] = min(uN, par[P_LC])
            if x == 0.0:
                st[S_BROKEN] = 1.0
                st[S_BETA] = 0.0
        elif law == FREMOND:
            st[S_DISS] += area * par[P_W] * (st[S_BETA] - x)
            st[S_BETA] = x
            if x == 0.0:
                st[S_BROKEN] = 1.0
        elif law == MIXED:
            un = max(uN, 0.0)
            Y = 0.5 * (par[P_CN] * un * un + par[P_CT] * uT * uT)
            un0 = max(st[S_UN], 0.0)
            Y0 = 0.5 * (par[P_CN] * un0 * un0 + par[P_CT] * uT0 * uT0)
            st[S_DISS] += area * 0.5 * (Y + Y0) * (x - st[S_BETA])  # trapezoidal ∫ Y dD
            st[S_BETA] = x
            if x >= 1.0:
                st[S_BROKEN] = 1.0


@njit(cache=True)
def commit(law, par, st, x, uN, uT, area):
    """End of step (2D): store the jump, the internal variable x (β / intact flag / D, final trial value of the
    converged iteration) and the dissipated energy [J]."""
    _commit_core(law, par, st, x, uN, uT, st[S_UT], area)
    st[S_UN] = uN
    st[S_UT] = uT


@njit(cache=True)
def commit3(law, par, st, x, uN, uT, uS, area):
    """End of step (3D, state row of NSTATE3 columns): as `commit` with the tangential jump (u_T, u_S) entering
    through its norm."""
    _commit_core(law, par, st, x, uN, np.sqrt(uT * uT + uS * uS), np.sqrt(st[S_UT] * st[S_UT] + st[S_US] * st[S_US]),
                 area)
    st[S_UN] = uN
    st[S_UT] = uT
    st[S_US] = uS


@njit(cache=True)
def commit_step(law, par, st, trial, ueff, P, v, area, h, theta):
    """End of a converged cohesive step, any dimension d = ueff.shape[1] (2: state rows NSTATE, 3: NSTATE3).
    P (impulses) and v (shifted velocities, u = u_eff + hθ v) are flat, d entries per contact. At the cap
    (P̃_N = P_N + hA(k_N u_N + f_N) >= h f_c A, f_c = cap_stress at the committed state) the closure is plastic: Δu_p = min(0, hθ(v_N + cmp P̃_N)) (cmp the
    compliance 1/(h²θ k A) of compliant joints in compression); the laws see the elastic jump u_N - Δu_p, then
    u_p += Δu_p and f_c A |Δu_p| is dissipated. Elliptic cap (C_ss > 0): at the cap when P̃_N² + C_ss |P̃_T|² >=
    (h f_c A)² (P̃_T = P_T + hA k_T u_T), the same Δu_p (the normal part of the associated flow), and the cap's whole
    plastic work f_c A |Δu_p| h f_c A/P̃_N is dissipated (its tangential slip λ C_ss P̃_T included).
    Called by ContactStep (step.py) at the end of every cohesive step."""
    d = ueff.shape[1]
    for a in range(law.shape[0]):
        uN = ueff[a, 0] + h * theta * v[d * a]
        uT = ueff[a, 1] + h * theta * v[d * a + 1]
        dup = 0.0
        fc = cap_stress(par[a], st[a])
        capv = h * fc * area[a]
        wfac = 1.0  # cap work per f_c A |Δu_p| (the elliptic cap's tangential plastic slip adds to it)
        if capv > 0.0:
            tension = uN > 1e-15
            kN, kT, fN, fT, m = linear_part(law[a], par[a], st[a], trial[a], tension)
            Pt = P[d * a] + h * area[a] * kN * h * theta * v[d * a] + h * area[a] * (kN * ueff[a, 0] + fN)
            cmp = 0.0
            if law[a] != COULOMB and not tension:
                kc = compression_stiffness(law[a], par[a]) * area[a]
                if kc > 0.0:
                    cmp = 1.0 / (h * h * theta * kc)
            css = par[a, P_CSS]
            if css > 0.0:  # elliptic cap: on the ellipse P̃_N² + C_ss |P̃_T|² = (h f_c A)²
                Pt1 = P[d * a + 1] + h * area[a] * (kT * uT + fT)
                PtT2 = Pt1 * Pt1
                if d == 3:
                    Pt2 = P[d * a + 2] + h * area[a] * kT * (ueff[a, 2] + h * theta * v[d * a + 2])
                    PtT2 += Pt2 * Pt2
                # (a tolerance of 1e-6 on P_c²: a converged Newton iterate lies on the curved ellipse only to the
                # residual tolerance; off the cap v'_N = 0 to that tolerance, so min(0, hθ v'_N) adds noise at most)
                if Pt > 0.0 and Pt * Pt + css * PtT2 >= capv * capv * (1 - 1e-6):
                    dup = min(0.0, h * theta * (v[d * a] + cmp * Pt))
                    wfac = capv / Pt  # associated flow: work (P̃_N² + C_ss |P̃_T|²)|Δu_p|/(h P̃_N)
            elif Pt >= capv * (1 - 1e-9):
                dup = min(0.0, h * theta * (v[d * a] + cmp * Pt))
        x = trial[a]
        implex = is_implex(law[a], par[a]) and st[a, S_BROKEN] == 0.0
        if implex:  # IMPL-EX: the step ran at the extrapolated x̃; commit the implicit value from the converged jump
            x0 = st[a, S_BETA]
            uS = ueff[a, 2] + h * theta * v[d * a + 2] if d == 3 else 0.0
            x = implicit_update(law[a], par[a], st[a], uN - dup, np.sqrt(uT * uT + uS * uS), h)
        if d == 2:
            commit(law[a], par[a], st[a], x, uN - dup, uT, area[a])
        else:
            commit3(law[a], par[a], st[a], x, uN - dup, uT, ueff[a, 2] + h * theta * v[d * a + 2], area[a])
        if implex:
            st[a, S_HIST] = (x - x0) / h  # ẋ_{n+1}: the next step's extrapolation
        if dup != 0.0:
            st[a, S_UP] += dup
            if wfac == 1.0:
                st[a, S_DISS] += fc * area[a] * abs(dup)
            else:
                st[a, S_DISS] += fc * area[a] * abs(dup) * wfac

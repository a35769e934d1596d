"""IMPL-EX integration of the softening internal variables (interface key `damage_integration = "implex"`,
laws.implex_extrapolate / commit_step; Oliver, Huespe & Cante 2008): the step runs at the damage extrapolated
from the two last committed values, D̃_{n+1} = D_n + (h_{n+1}/h_n)(D_n - D_{n-1}), held fixed; the commit stores the
implicit value of the converged jump. Checked through the real path of a contact step (solver/newton.py on the
transformed problem, then laws.commit_step) on single joints and a coupled row of joints, against the closed forms
of the rate-independent mixed-mode law (linear softening, pure mode I: t(u) = k u up to δ_I, then
f_t (λ_f - λ)/(λ_f - 1), λ = u/δ_I, λ_f = 2 G_I k/f_t²)."""
import os

import numpy as np
import pytest

from fem_blocks import laws
from fem_blocks.errors import InputError
from fem_blocks.laws import FREMOND, MIXED, P_IMPLEX, S_BETA, S_BROKEN, S_DISS, S_HIST, S_UN, S_UT
from fem_blocks.linalg import to_block_csr
from fem_blocks.solver import newton

PAR = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6)
DI = PAR["f_t"] / PAR["k_n"]  # δ_I = 2 µm
DII = PAR["c"] / PAR["k_s"]
LF = 2 * PAR["G_I"] * PAR["k_n"] / PAR["f_t"] ** 2  # λ_f = 50
A = 1e-3  # m², tributary area
H = 1e-3  # s, step


def _par(integration=None, law="mixed"):
    if law == "mixed":
        prm = dict(PAR)
    else:
        prm = dict(mu=0.5, c_N=1e11, c_T=5e10, w=1.0)
    if integration is not None:
        prm["damage_integration"] = integration
    return laws.law_parameters(law, prm, "interfaces.j")[1]


def _envelope(u):
    """Rate-independent mode-I traction of the linear-softening law at the opening u (closed form)."""
    lam = u / DI
    if lam <= 1.0:
        return PAR["k_n"] * u
    return max(PAR["f_t"] * (LF - lam) / (LF - 1.0), 0.0)


class Joints:
    """n joints (mixed law) between an elastic body of compliance C [m/N] (2n x 2n, normal/tangential per joint)
    and imposed displacements (U_N, U_T) at its far end: one contact step per load increment, θ = 1 (quasi-static),
    as ContactStep does it — the shifted normal velocity (hθ v_N = the opening at the end of the step,
    u_eff,N = 0), u_eff,T the committed slip, W = C/h², solve, laws.commit_step."""

    def __init__(self, C, integration):
        self.n = C.shape[0] // 2
        self.W = to_block_csr(C / H ** 2, 2)
        self.law = np.full(self.n, MIXED)
        self.par = np.repeat(_par(integration)[None, :], self.n, 0)
        self.st = laws.initial_state(self.law)
        self.area = np.full(self.n, A)
        self.r = np.zeros(2 * self.n)

    def step(self, UN, UT, gs_sweeps=0):
        ueff = self.st[:, [S_UN, S_UT]].copy()
        ueff[:, 0] = 0.0
        q = np.column_stack([UN / H, (UT - ueff[:, 1]) / H]).ravel()
        res, x = newton.solve_cohesive_newton(self.W, q, np.full(self.n, PAR["tan_phi"]), self.law, self.par,
                                              self.st, ueff, self.area, H, 1.0, r0=self.r, tol=1e-10,
                                              gs_sweeps=gs_sweeps)
        assert res.converged, res.message
        self.r = res.r
        laws.commit_step(self.law, self.par, self.st, x, ueff, res.r, res.u, self.area, H, 1.0)
        t = -res.r.reshape(-1, 2)[:, 0] / (H * A)  # normal traction (tension > 0)
        return t, x, res


def _single(cs, integration="implex"):
    return Joints(np.diag([cs, cs]) + 1e-30, integration)


# ----------------------------------------------------------------------------- input and the extrapolation
def test_input_validation():
    assert _par()[P_IMPLEX] == 0.0 and _par(law="fremond")[P_IMPLEX] == 0.0  # default: implicit (as before)
    assert _par("implicit")[P_IMPLEX] == 0.0
    assert _par("implex")[P_IMPLEX] == 1.0 and _par("implex", "fremond")[P_IMPLEX] == 1.0
    for bad in ("explicit", "IMPLEX", 1.0):
        with pytest.raises(InputError, match=r"interfaces\.j\.damage_integration = .*: expected 'implicit' or "
                                             r"'implex'"):
            _par(bad)
    with pytest.raises(InputError, match=r"interfaces\.j\.damage_integration: unknown parameter"):
        laws.law_parameters("elastic", dict(mu=0.5, c_N=1e9, c_T=1e9, damage_integration="implex"), "interfaces.j")


def _commit_imposed(law, par, st, uN, uT, h):
    """One committed step at the imposed jump (uN, uT) (no contact impulse, no cap)."""
    x = laws.step_start(np.array([law]), par[None, :], st[None, :], h)
    ueff = np.array([[uN, uT]])
    row = st[None, :].copy()
    laws.commit_step(np.array([law]), par[None, :], row, x, ueff, np.zeros(2), np.zeros(2), np.array([1.0]), h, 1.0)
    st[:] = row[0]


def test_extrapolation_is_the_two_step_formula():
    """After commits at h_n then the query with h_{n+1}: D̃ = D_n + (h_{n+1}/h_n)(D_n - D_{n-1}) (to round-off),
    clipped to [D_n, 1]; the committed D is the implicit value of the jump (laws.implicit_update) whatever the
    extrapolation; the step does not change the committed state (D̃ is never committed). Frémond: β̃ = β_n +
    (h_{n+1}/h_n)(β_n - β_{n-1}) clipped to [0, β_n]."""
    p, p0 = _par("implex"), _par()
    st = laws.initial_state(np.array([MIXED]))[0]
    h1, h2 = 2e-3, 5e-4
    _commit_imposed(MIXED, p, st, 3 * DI, 0.0, h1)
    D1 = st[S_BETA]
    assert D1 == laws.implicit_update(MIXED, p0, laws.initial_state(np.array([MIXED]))[0], 3 * DI, 0.0, h1) > 0
    assert st[S_HIST] == pytest.approx(D1 / h1, rel=1e-15)
    _commit_imposed(MIXED, p, st, 4 * DI, 0.0, h1)
    D2 = st[S_BETA]
    for hn in (h2, h1, 3 * h1):
        expect = min(D2 + (hn / h1) * (D2 - D1), 1.0)
        assert abs(laws.implex_extrapolate(MIXED, p, st, hn) - expect) <= 1e-15
        assert laws.internal_update(MIXED, p, st, 40 * DI, 0.0, hn) == laws.implex_extrapolate(MIXED, p, st, hn)
    assert laws.implex_extrapolate(MIXED, p, st, 1e3) == 1.0  # clipped at full damage
    # implicit integration unchanged: the jump decides
    assert laws.internal_update(MIXED, p0, st, 40 * DI, 0.0, h1) == laws.implicit_update(MIXED, p0, st, 40 * DI,
                                                                                          0.0, h1) > D2
    # unloading: the implicit damage stays, the rate of the next extrapolation is 0
    _commit_imposed(MIXED, p, st, 2 * DI, 0.0, h1)
    assert st[S_BETA] == D2 and st[S_HIST] == 0.0
    assert laws.implex_extrapolate(MIXED, p, st, h1) == D2
    # Frémond β (rate-independent: β = min(β_prev, w/Y))
    pf = _par("implex", "fremond")
    sf = laws.initial_state(np.array([FREMOND]))[0]
    u1, u2 = 6e-3, 9e-3  # Y = c_N u² > w
    _commit_imposed(FREMOND, pf, sf, u1, 0.0, h1)
    b1 = sf[S_BETA]
    _commit_imposed(FREMOND, pf, sf, u2, 0.0, h1)
    b2 = sf[S_BETA]
    assert b1 == pytest.approx(1.0 / (1e11 * u1 ** 2), rel=1e-12) and b2 == pytest.approx(1.0 / (1e11 * u2 ** 2),
                                                                                            rel=1e-12)
    assert abs(laws.implex_extrapolate(FREMOND, pf, sf, h2) - (b2 + (h2 / h1) * (b2 - b1))) <= 1e-15
    assert laws.implex_extrapolate(FREMOND, pf, sf, 1e3) == 0.0


# ----------------------------------------------------------------------------- mode I: lag, dissipation, unloading
@pytest.mark.parametrize("m", [1, 2, 4, 8])
def test_mode_I_traction_lags_the_envelope_by_first_order(m):
    """Opening imposed on the joint (stiff body) in steps Δu = δ_I/m, up to 1.1 δ_f. Elastic branch: t = k u
    exactly. First step past the peak (u = (1 + 1/m) δ_I): D̃ = 0 (no damage rate yet), so t = k u and the error
    against the envelope is exactly (f_t/m) λ_f/(λ_f - 1) — the largest of the run (first order: halves with the
    step); elsewhere the lag is smaller (the extrapolation of a smooth D(u)); t = 0 once D = 1; the committed
    damage is the rate-independent D(u) at every step."""
    j = _single(1e-30)
    du = DI / m
    err = []
    for k in range(1, int(round(1.1 * LF * m)) + 1):
        u = k * du
        t, x, res = j.step(np.array([u]), np.array([0.0]))
        err.append(abs(t[0] - _envelope(u)))
        if k <= m:
            assert abs(t[0] - PAR["k_n"] * u) <= 1e-9 * PAR["f_t"]
        lam = u / DI
        Dri = 0.0 if lam <= 1 else min(LF * (lam - 1) / (lam * (LF - 1)), 1.0)
        assert abs(j.st[0, S_BETA] - Dri) <= 1e-12
        if lam > LF + 1.0 / m + 1e-9:
            assert abs(t[0]) <= 1e-9 * PAR["f_t"]
    first = PAR["f_t"] / m * LF / (LF - 1)
    assert abs(err[m] - first) <= 1e-9 * PAR["f_t"]
    assert max(err) == pytest.approx(first, rel=1e-9)


def _separate(n, integration="implex"):
    """Joint in series with a spring 5x stiffer than it (cs = 0.2/(k_n A), no snap-back: 1/cs > k_n A/(λ_f - 1)),
    far end moved monotonically to 1.1 δ_f in n steps. Returns (dissipated energy per unit area, joint)."""
    j = _single(0.2 / (PAR["k_n"] * A), integration)
    for k in range(1, n + 1):
        j.step(np.array([1.1 * LF * DI * k / n]), np.array([0.0]))
    assert j.st[0, S_BROKEN] == 1.0
    return j.st[0, S_DISS] / A, j


def test_dissipated_energy_converges_to_G_I():
    """Complete separation through a spring: the dissipated energy (committed from the implicit D, trapezoidal
    ∫ Y dD) tends to G_I; its error at least halves with the step (measured: ratio 0.21–0.27, 1.1 % of G_I at 50
    steps, 0.014 % at 400) and is within 25 % of the implicit scheme's error (measured 5–15 % above it)."""
    errs = []
    for n in (50, 100, 200, 400):
        e, _ = _separate(n)
        ei, _ = _separate(n, "implicit")
        errs.append(abs(e - PAR["G_I"]))
        assert abs(e - PAR["G_I"]) <= 1.25 * abs(ei - PAR["G_I"]) + 1e-6 * PAR["G_I"]
    assert errs[-1] <= 2e-4 * PAR["G_I"]
    for a, b in zip(errs, errs[1:]):
        assert b <= 0.5 * a


def test_unloading_and_reloading_are_secant():
    """Load to λ = 10 (softening), unload to u = 0, reload to λ = 20. In the first unloading step the law runs at
    the damage extrapolated from the last loading step (D̃ > D_c); from the second unloading step until the
    largest past opening is regained t = (1 - D_c) k u exactly, with D_c the committed damage (secant to the
    origin, no damage growth); beyond it the damage grows again."""
    j = _single(1e-30)
    du = DI / 4
    for k in range(1, 41):
        t, x, _ = j.step(np.array([k * du]), np.array([0.0]))
    Dc = j.st[0, S_BETA]
    assert 0.5 < Dc < 1.0 and j.st[0, S_HIST] > 0.0
    path = [40 - k for k in range(1, 41)] + list(range(1, 81))
    for i, k in enumerate(path):
        u = k * du
        t, x, _ = j.step(np.array([u]), np.array([0.0]))
        if i == 0:
            assert x[0] > Dc and abs(t[0] - (1 - x[0]) * PAR["k_n"] * u) <= 1e-9 * PAR["f_t"]
        elif k <= 40 or i < 40:  # unloading, and reloading up to the largest past opening (k = 40)
            assert j.st[0, S_BETA] == Dc
            assert abs(t[0] - (1 - Dc) * PAR["k_n"] * u) <= 1e-9 * PAR["f_t"]
    assert j.st[0, S_BETA] > Dc


# ----------------------------------------------------------------------------- the step problem at fixed D̃
def _row(n=12, c0=3.0):
    """n joints under one elastic body: compliance c0/(k_n A) (I + ½ e^{-|x_i - x_j|}) coupling the normal
    components (half of it the tangential ones); stiffer than the joints' softening, so the quasi-static path
    has no snap-back."""
    xs = np.linspace(-1.0, 1.0, n)
    K = 0.5 * np.exp(-np.abs(xs[:, None] - xs[None, :])) + np.eye(n)
    C = np.zeros((2 * n, 2 * n))
    C[0::2, 0::2] = c0 / (PAR["k_n"] * A) * K
    C[1::2, 1::2] = 0.5 * c0 / (PAR["k_n"] * A) * K
    return C, xs


def test_fixed_damage_step_converges_in_three_newton_iterations():
    """12 coupled joints opened in mixed mode with a rotation profile (opening 0.2–1.8 × 1.5 δ_f, slip 10 δ_II)
    in 25 steps, without Gauss–Seidel start. With IMPL-EX every step converges to 1e-10 in at most 3 Newton
    iterations: at fixed D̃ every joint here stays open in tension, where the Alart–Curnier function of the
    transformed problem is affine in the impulses (F = P̃ = P + S v + c), so the Newton step is exact up to the
    proximal regularisation J = D + E(W + εI) (ε = 1e-6 W_αα, divided by 10 after each full step), whose error
    the next one or two iterations remove (measured: 3 in the 6 first, undamaged steps, 2 after). The implicit
    scheme (damage inside, consistent tangent) needs more on the same steps (measured up to 9), as the softening
    makes its step problem non-monotone."""
    C, xs = _row()
    its = {}
    for integration in ("implex", "implicit"):
        j = Joints(C, integration)
        it = []
        for k in range(1, 26):
            s = k / 25
            _, _, res = j.step(1.5 * LF * DI * s * (1.0 + 0.8 * xs), np.full(len(xs), 10 * DII * s))
            it.append(res.sweeps)
        its[integration] = np.array(it)
        assert np.all(j.st[:, S_BETA] > 0.9)  # every joint has softened
    assert its["implex"].max() <= 3
    assert its["implicit"].max() > 2


def test_every_newton_pass_runs_at_the_extrapolated_damage():
    """A row of joints, half IMPL-EX and half implicit (damage inside), softening; then one step solved with a budget
    of one Newton iteration per pass, so that the coupled pass fails and the Alart–Curnier retry and the staggered
    passes run too. In every iteration of every pass the IMPL-EX contacts hold x̃ = laws.step_start (bitwise): a
    retry or fallback that restarted them from the committed D_n (x[:] = st[:, S_BETA]) would be caught here."""
    C, xs = _row()
    j = Joints(C, "implex")
    j.par[1::2] = _par("implicit")  # every other joint implicit: the coupled pass has damage inside
    for k in range(1, 9):
        j.step(1.5 * LF * DI * k / 25 * (1.0 + 0.8 * xs), np.full(len(xs), 10 * DII * k / 25))
    s = 9 / 25
    ueff = j.st[:, [S_UN, S_UT]].copy()
    ueff[:, 0] = 0.0
    q = np.column_stack([1.5 * LF * DI * s * (1.0 + 0.8 * xs) / H, (10 * DII * s - ueff[:, 1]) / H]).ravel()
    xt = laws.step_start(j.law, j.par, j.st, H)
    imp = np.arange(j.n) % 2 == 0
    assert np.any(xt[imp] > j.st[imp, S_BETA])  # the extrapolation moves some IMPL-EX contacts
    seen = []
    newton.solve_cohesive_newton(j.W, q, np.full(j.n, PAR["tan_phi"]), j.law, j.par, j.st, ueff, j.area, H, 1.0,
                                 r0=j.r, tol=1e-14, max_iter=1, max_total_iter=6, gs_sweeps=0,
                                 probe=lambda ev: seen.append(ev["x"][imp].copy()))
    assert len(seen) >= 3  # coupled, retry and staggered passes
    for x in seen:
        assert np.array_equal(x, xt[imp])


# ----------------------------------------------------------------------------- checkpoint / resume
@pytest.mark.dolfinx
def test_resume_from_a_checkpoint_is_bitwise_with_implex(tmp_path, cli):
    """The damage rate of the extrapolation lives in the law state (column S_HIST), so a checkpoint carries it:
    the small wall of tests/test_resume.py with IMPL-EX Frémond joints (weaker), run through; then its output directory
    with the previous checkpoint (checkpoint_every = 7) put back as the newest, resumed: the same history, bitwise.
    The final checkpoint holds non-zero rates (the column is part of the checkpointed state); the rates of the
    previous checkpoint happen to be 0 in this run, so a rate kept outside the state would not be caught here.
    The reference runs in its own process, the resume in this one (conftest.cli): nothing of the reference is in
    the resumed run's process."""
    import shutil
    import subprocess
    import sys

    from _paths import ROOT
    from test_resume import CASE
    from fem_blocks.output.checkpoint import read_checkpoint

    case = tmp_path / "case.toml"
    assert 'law = "fremond"' in CASE
    assert "w = 18.0" in CASE
    # weaker adhesion (w = 0.001 J/m²) so that the joints decohere during the push and β still changes at the end
    case.write_text(CASE.replace('law = "fremond"', 'law = "fremond"\ndamage_integration = "implex"')
                    .replace("w = 18.0", "w = 0.001"))

    ref = tmp_path / "ref"
    p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", "run", str(case), "--out", str(ref), "--quiet"],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert p.returncode in (0, 3), p.stderr
    st = read_checkpoint(ref / "checkpoint.npz")["contact.state"]
    assert np.any(st[:, S_HIST] < 0.0)  # IMPL-EX rates of β in the checkpoint (Frémond: β decreasing)
    again = tmp_path / "again"
    shutil.copytree(ref, again)
    os.replace(again / "checkpoint.prev.npz", again / "checkpoint.npz")
    p2 = cli("run", case, "--out", again, "--quiet", "--resume")
    assert p2.returncode == p.returncode, p2.stderr
    assert (again / "history.csv").read_text() == (ref / "history.csv").read_text()
    a, b = read_checkpoint(again / "checkpoint.npz"), read_checkpoint(ref / "checkpoint.npz")
    assert np.array_equal(a["contact.state"], b["contact.state"])

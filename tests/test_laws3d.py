"""Interface laws in 3D (u = (u_N, u_T, u_S), tangential quantities as 2-vectors) with the 3D cohesive NLGS,
against closed forms on single joints, direction independence in the tangent plane, and the 2D kernel on
2D-embedded problems.

The one-contact problems are those of tests/test_laws.py written out: a rigid block glued on a fixed rigid base,
each dof driven (prescribed displacement: no inverse mass, W = 0 in that direction) or free (mass m, constant
force), Moreau–Jean θ-step with frozen geometry and impulses P = h r: W = G M⁻¹ Gᵀ (3x3 blocks), q = G v_free +
gap shift, `nlgs.solve_cohesive`, `laws.commit_step`. The contact frame (n, t, s) is rotated in the tangent plane
(n = e_z, t at 0.3 rad from e_x) so that t and s are not the global axes.
"""
import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.laws import (NSTATE3, S_BETA, S_BROKEN, S_DISS, S_UN, S_UP, S_US, S_UT, commit_step, initial_state,
                             law_parameters, linear_part)
from fem_blocks.solver import nlgs
from fem_blocks.linalg import to_block_csr

L, T = 0.2, 0.1
A = L * T  # joint area (one contact point carrying the whole joint)
CN, CT, W = 1e10, 5e9, 50.0
ANG = 0.3
N3 = np.array([0.0, 0.0, 1.0])
T3 = np.array([np.cos(ANG), np.sin(ANG), 0.0])
S3 = np.array([-np.sin(ANG), np.cos(ANG), 0.0])
DIRS = {"t": T3, "s": S3, "ts": (T3 + S3) / np.sqrt(2.0)}
MIXED = dict(k_n=1e11, k_s=5e10, f_t=2e5, c=3e5, G_I=10.0, G_II=50.0, tan_phi=0.6)


def ramp(values, times):
    return lambda t: float(np.interp(t, times, values))


class Joint:
    """Rigid block (ndof generalised dofs, diagonal mass) on a fixed base through nc contact points with local
    rows G (nc, d, ndof) (frozen geometry, reference gap 0). drive: {dof: displacement(t)}, the other dofs are free
    with force {dof: value or function of t}."""

    def __init__(self, law, params, G, area, mass, drive=(), force=(), h=1e-2, theta=1.0, reset=True,
                 tol=1e-12, criterion="change"):
        self.G = np.asarray(G, dtype=float)
        self.nc, self.d, self.ndof = self.G.shape
        code, par = law_parameters(law, params, "interfaces.j")
        self.law = np.full(self.nc, code, dtype=np.int64)
        self.par = np.tile(par, (self.nc, 1))
        self.mu = self.par[:, 0].copy()
        self.st = initial_state(self.law, self.d)
        self.area = np.broadcast_to(np.asarray(area, dtype=float), (self.nc,)).copy()
        self.mass = np.asarray(mass, dtype=float)
        self.drive, self.force = dict(drive), dict(force)
        self.free = np.array([k not in self.drive for k in range(self.ndof)])
        self.minv = np.where(self.free, 1.0 / self.mass, 0.0)
        self.h, self.theta, self.reset, self.tol, self.criterion = h, theta, reset, tol, criterion
        self.q = np.zeros(self.ndof)
        self.v = np.zeros(self.ndof)
        self.t = 0.0
        self.P = np.zeros((self.nc, self.d))
        Wd = np.einsum("aik,k,bjk->aibj", self.G, self.minv, self.G).reshape(self.nc * self.d, self.nc * self.d)
        self.W = to_block_csr(Wd, self.d)
        self.results = []

    def _f(self, k, t):
        f = self.force.get(k, 0.0)
        return f(t) if callable(f) else f

    def step(self):
        h, th = self.h, self.theta
        t0, t1 = self.t, self.t + h
        vi = np.zeros(self.ndof) if self.reset else self.v.copy()
        vfree = vi.copy()
        for k in range(self.ndof):
            if self.free[k]:
                vfree[k] += h * ((1 - th) * self._f(k, t0) + th * self._f(k, t1)) * self.minv[k]
            else:
                vfree[k] = ((self.drive[k](t1) - self.drive[k](t0)) / h - (1 - th) * vi[k]) / th
        vloc = self.G @ vfree
        vil = self.G @ vi
        gbar = self.G[:, 0, :] @ self.q - self.st[:, S_UP] + h * (1 - th) * vil[:, 0]
        q = vloc.copy()
        q[:, 0] += gbar / (h * th)
        cols = [S_UN, S_UT] if self.d == 2 else [S_UN, S_UT, S_US]
        ueff = self.st[:, cols] + h * (1 - th) * vil
        ueff[:, 0] -= gbar
        res, trial = nlgs.solve_cohesive(self.W, q.ravel(), self.mu, self.law, self.par, self.st, ueff, self.area,
                                         h, th, r0=self.P.ravel(), tol=self.tol, max_sweeps=10000,
                                         criterion=self.criterion, check_every=1)
        assert res.converged, res.message
        self.last = (q.ravel().copy(), ueff.copy(), trial.copy(), self.st.copy())
        commit_step(self.law, self.par, self.st, trial, ueff, res.r, res.u, self.area, h, th)
        self.P = res.r.reshape(self.nc, self.d).copy()
        v1 = vfree + self.minv * np.einsum("aik,ai->k", self.G, self.P)
        self.q += h * ((1 - th) * vi + th * v1)
        self.v = v1
        self.t = t1
        self.results.append(res)
        return res

    def traction(self, a=0):
        """Force per unit area applied by the joint on the base (tension positive): -P/(h A), local frame."""
        return -self.P[a] / (self.h * self.area[a])

    def jump(self, a=0):
        return self.G[a] @ self.q


def one_point(law, params, drive=None, force=None, m=4.0, **kw):
    """One contact point, block translations (x, y, z), frame (n, t, s) = (e_z, T3, S3)."""
    G = np.array([[N3, T3, S3]])
    drive = {k: (lambda t: 0.0) for k in range(3)} if drive is None else drive
    return Joint(law, params, G, A, [m, m, m], drive=drive, force=force or {}, **kw)


def tangential_drive(direction, hist):
    """x, y displacement along `direction` (in the tangent plane) with magnitude hist(t); z held at 0."""
    return {0: lambda t: direction[0] * hist(t), 1: lambda t: direction[1] * hist(t), 2: lambda t: 0.0}


def fc_curve(u, c):
    uc = np.sqrt(W / c)
    return np.where(u <= uc, c * u, W ** 2 / (c * np.maximum(u, 1e-300) ** 3))


def assert_parallel(tr, direction, tol=1e-10):
    """Tangential traction tr (2 local components) along +direction (global, in the tangent plane)."""
    e = np.array([direction @ T3, direction @ S3])
    assert abs(tr[0] * e[1] - tr[1] * e[0]) <= tol * (np.linalg.norm(tr) + 1e-300)
    assert tr @ e >= -tol * np.linalg.norm(tr)


# ----------------------------------------------------------------------------- Frémond–Cangémi
def test_fremond_mode_I_curve_peak_energy():
    uc = np.sqrt(W / CN)
    j = one_point("fremond", dict(c_N=CN, c_T=CT, w=W, mu=0.5),
                  drive={0: lambda t: 0.0, 1: lambda t: 0.0, 2: ramp([0, 3 * uc, 300 * uc], [0, 1, 2])})
    u, s = [], []
    for _ in range(200):
        j.step()
        u.append(j.jump()[0])
        s.append(j.traction()[0])
        assert np.all(j.P[0, 1:] == 0.0)
    u, s = np.array(u), np.array(s)
    ref = fc_curve(u, CN)
    pts = u <= 3 * uc
    assert pts.sum() >= 20
    assert np.all(np.abs(s[pts] - ref[pts]) <= 0.01 * ref[pts])
    assert np.all(np.abs(s[u <= uc] - CN * u[u <= uc]) <= 1e-8 * CN * u[u <= uc])  # elastic part exact
    post = (u > uc) & pts
    assert np.all(np.abs(s[post] - W ** 2 / (CN * u[post] ** 3)) <= 1e-8 * s[post])  # w²/(c_N u³) exact
    assert s.max() == pytest.approx(np.sqrt(W * CN), rel=0.01)
    assert j.st[0, S_DISS] / A == pytest.approx(W, rel=0.01)


def shear_curve(direction, mu=0.0, p=None, n=100, umax=3.0, law="fremond", params=None):
    """Drive the block along `direction` in the tangent plane up to umax u_c (u_c = √(w/c_T)); under a pressure p
    the normal dof is free (force -p A). Returns (‖u_T‖, ‖τ‖, joint)."""
    uc = np.sqrt(W / CT)
    hist = ramp([0, umax * uc], [0, 1])
    drive = tangential_drive(direction, hist)
    force = {}
    if p is not None:
        del drive[2]
        force = {2: -p * A}
    j = one_point(law, params or dict(c_N=CN, c_T=CT, w=W, mu=mu), drive=drive, force=force, h=1.0 / n)
    u, s = [], []
    for _ in range(n):
        j.step()
        u.append(np.linalg.norm(j.jump()[1:]))
        tr = j.traction()
        s.append(np.linalg.norm(tr[1:]))
        if s[-1] > 0:
            assert_parallel(tr[1:], direction)
    return np.array(u), np.array(s), j


def test_fremond_mode_II_independent_of_the_direction():
    curves = {k: shear_curve(d) for k, d in DIRS.items()}
    u, s, j = curves["t"]
    for k in ("s", "ts"):
        assert np.allclose(curves[k][0], u, rtol=1e-10, atol=0)
        assert np.allclose(curves[k][1], s, rtol=1e-10, atol=0)
    ref = fc_curve(u, CT)
    assert np.all(np.abs(s - ref) <= 1e-8 * ref)  # c_T u then w²/(c_T u³), exact at the sampled jumps
    assert s.max() == pytest.approx(np.sqrt(W * CT), rel=0.01)
    assert curves["ts"][2].st[0, S_DISS] / A == pytest.approx(W * (1 - W / (CT * u[-1] ** 2)), rel=1e-8)


def test_fremond_shear_under_pressure_peak_and_residual():
    """Constant pressure p, constant μ, oblique shear: peak μp + √(w c_T), residual μp (independent of the
    direction)."""
    mu, p = 0.6, 2e5
    u, s, j = shear_curve(DIRS["ts"], mu=mu, p=p, n=200, umax=20.0)
    assert s.max() == pytest.approx(mu * p + np.sqrt(W * CT), rel=0.01)
    assert s[-1] == pytest.approx(mu * p, rel=0.01)
    assert j.traction()[0] == pytest.approx(-p, rel=1e-10)  # the joint carries the pressure
    u2, s2, _ = shear_curve(DIRS["s"], mu=mu, p=p, n=200, umax=20.0)
    assert np.allclose(s2, s, rtol=1e-10, atol=0) and np.allclose(u2, u, rtol=1e-10, atol=0)


def test_fremond_unloading_keeps_beta():
    uc = np.sqrt(W / CT)
    d = DIRS["ts"]
    j = one_point("fremond", dict(c_N=CN, c_T=CT, w=W, mu=0.5),
                  drive=tangential_drive(d, ramp([0, 2 * uc, 0.5 * uc], [0, 1, 2])))
    for _ in range(100):
        j.step()
    beta = j.st[0, S_BETA]
    assert beta == pytest.approx(0.25, rel=1e-12)  # w / (c_T (2 u_c)²)
    for _ in range(100):
        j.step()
        assert j.st[0, S_BETA] == beta
        assert np.linalg.norm(j.traction()[1:]) == pytest.approx(beta ** 2 * CT * np.linalg.norm(j.jump()[1:]),
                                                                 rel=1e-10)


# ----------------------------------------------------------------------------- mixed-mode softening
@pytest.mark.parametrize("softening", ["linear", "exponential"])
@pytest.mark.parametrize("mode", ["I", "II", "II+p"])
def test_mixed_mode_peaks_and_energies(mode, softening):
    prm = dict(MIXED, softening=softening)
    p = 1e5
    umax = 40 * prm["G_II"] / prm["c"] if mode != "I" else 40 * prm["G_I"] / prm["f_t"]
    n = 4000
    hist = ramp([0, umax], [0, 1])
    if mode == "I":
        j = one_point("mixed", prm, drive={0: lambda t: 0.0, 1: lambda t: 0.0, 2: hist}, h=1.0 / n)
    else:
        drive = tangential_drive(DIRS["ts"], hist)
        force = {}
        if mode == "II+p":
            del drive[2]
            force = {2: -p * A}
        j = one_point("mixed", prm, drive=drive, force=force, h=1.0 / n)
    s = []
    for _ in range(n):
        j.step()
        tr = j.traction()
        s.append(tr[0] if mode == "I" else np.linalg.norm(tr[1:]))
    s = np.array(s)
    if mode == "I":
        assert s.max() == pytest.approx(prm["f_t"], rel=0.01)
        assert j.st[0, S_DISS] / A == pytest.approx(prm["G_I"], rel=0.01)
    else:
        peak = prm["c"] + (prm["tan_phi"] * p if mode == "II+p" else 0.0)
        assert s.max() == pytest.approx(peak, rel=0.01)
        assert j.st[0, S_DISS] / A == pytest.approx(prm["G_II"], rel=0.01)
        if mode == "II+p":
            assert s[-1] == pytest.approx(prm["tan_phi"] * p, rel=0.01)
    assert j.st[0, S_BETA] == 1.0


def test_mixed_path_between_modes_and_direction_independent():
    prm = dict(MIXED)
    umax = 40 * prm["G_II"] / prm["c"]
    n = 2000
    e = {}
    for k in ("t", "ts"):
        d = DIRS[k]
        hT, hN = ramp([0, umax], [0, 1]), ramp([0, umax / 4], [0, 1])
        j = one_point("mixed", prm, h=1.0 / n, drive={0: lambda t, d=d: d[0] * hT(t), 1: lambda t, d=d: d[1] * hT(t),
                                                     2: hN})
        for _ in range(n):
            j.step()
        e[k] = j.st[0, S_DISS] / A
        assert j.st[0, S_BETA] == 1.0
    assert prm["G_I"] < e["t"] < prm["G_II"]
    assert e["ts"] == pytest.approx(e["t"], rel=1e-10)


# ----------------------------------------------------------------------------- brittle, Dugdale, elastic
def test_elastic_brittle_mode_I_break():
    rc = 3e5
    ub = rc / CN
    j = one_point("brittle", dict(variant="elastic", c_N=CN, c_T=CT, r_c=rc, mu=0.5), h=1e-3,
                  drive={0: lambda t: 0.0, 1: lambda t: 0.0, 2: ramp([0, 2 * ub], [0, 1])})
    s = []
    for _ in range(1000):
        j.step()
        s.append(j.traction()[0])
    assert max(s) == pytest.approx(rc, rel=0.01) and max(s) <= rc
    assert abs(s[-1]) < 1e-6 * rc and j.st[0, S_BROKEN] == 1.0
    assert j.st[0, S_DISS] / A == pytest.approx(rc ** 2 / (2 * CN), rel=0.01)


@pytest.mark.parametrize("direction", ["t", "ts"])
def test_elastic_brittle_shear_break_on_the_norm(direction):
    """Shear criterion on ‖c_T u_T‖ > s_c: along an oblique direction the joint breaks at the same ‖u_T‖ (a
    criterion on the components would break later), dissipating s_c²/(2 c_T)."""
    sc = 2e5
    ub = sc / CT
    u, s, j = shear_curve(DIRS[direction], n=1000, umax=2.0005 * ub / np.sqrt(W / CT), law="brittle",
                          params=dict(variant="elastic", c_N=CN, c_T=CT, r_c=3e5, s_c=sc, mu=0.0))
    intact = s > 0
    assert np.all(np.abs(s[intact] - CT * u[intact]) <= 1e-8 * s[intact])
    assert s.max() == pytest.approx(sc, rel=0.01) and s.max() <= sc
    assert u[intact].max() <= ub < u[~intact].min()
    assert j.st[0, S_BROKEN] == 1.0 and s[-1] == 0.0
    assert j.st[0, S_DISS] / A == pytest.approx(sc ** 2 / (2 * CT), rel=0.01)


def test_dugdale_breaks_at_rc_and_dissipates_rc_lc():
    rc, lc = 3e5, 2e-4
    j = one_point("brittle", dict(variant="dugdale", r_c=rc, l_c=lc, mu=0.5),
                  drive={0: lambda t: 0.0, 1: lambda t: 0.0, 2: ramp([0, 2 * lc], [0, 1])}, h=1.0 / 400)
    s = []
    for _ in range(400):
        j.step()
        s.append(j.traction()[0])
    s = np.array(s)
    assert s.max() == pytest.approx(rc, rel=1e-9)
    assert abs(s[-1]) < 1e-6 * rc
    assert j.st[0, S_DISS] / A == pytest.approx(rc * lc, rel=0.01)


def test_elastic_shear_vector_and_compliant_compression():
    """Elastic law: r_T = -c_T u_T as a 2-vector (oblique drive); a pressed joint shortens by F/(c_N A)."""
    d = DIRS["ts"]
    j = one_point("elastic", dict(c_N=CN, c_T=CT, mu=0.5), drive=tangential_drive(d, ramp([0, 1e-5], [0, 1])))
    for _ in range(10):
        j.step()
        uT = j.jump()[1:]
        assert np.allclose(j.traction()[1:], CT * uT, rtol=1e-10, atol=0)
    F = 1e4
    j = one_point("elastic", dict(c_N=CN, c_T=CT, mu=0.5), drive={0: lambda t: 0.0, 1: lambda t: 0.0},
                  force={2: -F}, tol=1e-14)
    for _ in range(3):
        j.step()
    assert j.q[2] == pytest.approx(-F / (CN * A), rel=1e-10)
    assert j.P[0, 0] / j.h == pytest.approx(F, rel=1e-10)


@pytest.mark.parametrize("law, params, strength", [
    ("brittle", dict(variant="elastic", c_N=CN, c_T=CT, r_c=3e5, s_c=1e5, mu=0.5), 1e5),
    ("elastic", dict(c_N=CN, c_T=CT, mu=0.5), np.inf),
])
def test_oblique_shear_force_under_pressure(law, params, strength):
    """Free block (W = I/m) pressed by p and pushed by F along an oblique tangent: friction takes μ p A, the spring
    the rest: static jump (F - μ p A)/(c_T A) along F (exact); an elastic-brittle joint holds while
    F < (μ p + s_c) A and slides away above."""
    p, mu = 1e5, 0.5
    d = DIRS["ts"]
    for factor in (0.8, 1.25):
        F = factor * (mu * p + (strength if np.isfinite(strength) else 1e5)) * A
        j = one_point(law, params, drive={}, force={0: F * d[0], 1: F * d[1], 2: -p * A}, h=1e-3, tol=1e-14)
        for _ in range(60):
            j.step()
        uT = j.jump()[1:]
        if factor < 1 or not np.isfinite(strength):
            ref = (F - mu * p * A) / (CT * A)
            assert np.linalg.norm(uT) == pytest.approx(ref, rel=1e-8)
            assert_parallel(uT, d)
            assert np.linalg.norm(j.v) < 1e-12
        else:
            assert j.st[0, S_BROKEN] == 1.0 and np.linalg.norm(j.v) > 1e-3  # sliding, (F - μ p A)/m accelerates


# ----------------------------------------------------------------------------- compressive cap
FC = 1e6


def pressed(law, params, fx=0.0):
    M = 4.0
    force = {2: -3 * FC * A}
    drive = {0: lambda t: 0.0, 1: lambda t: 0.0}
    if fx:
        d = DIRS["ts"]
        force.update({0: fx * d[0], 1: fx * d[1]})
        drive = {}
    return one_point(law, dict(params, f_c=FC), drive=drive, force=force, m=M, tol=1e-14, criterion="residual"), M


def test_cap_crushing_then_no_spring_back():
    j, M = pressed("coulomb", dict(mu=0.5))
    F = 3 * FC * A
    n = 5
    for _ in range(n):
        j.step()
    q = -n * j.h ** 2 * (F - FC * A) / M
    assert j.P[0, 0] / j.h == pytest.approx(FC * A, rel=1e-10)
    assert j.q[2] == pytest.approx(q, rel=1e-9)
    assert j.st[0, S_UP] == pytest.approx(q, rel=1e-9)
    assert j.st[0, S_DISS] == pytest.approx(FC * A * abs(q), rel=1e-9)
    j.force[2] = -0.5 * FC * A
    for _ in range(4):
        j.step()
    assert j.q[2] == pytest.approx(q, rel=1e-9, abs=1e-15)
    assert j.P[0, 0] / j.h == pytest.approx(0.5 * FC * A, rel=1e-10)
    assert j.st[0, S_UP] == pytest.approx(q, rel=1e-9)


def test_friction_at_the_cap_bounded_and_along_the_force():
    mu = 0.4
    j, M = pressed("coulomb", dict(mu=mu), fx=0.5 * FC * A)  # 0.5 f_c A > μ f_c A: slides along the force
    for _ in range(3):
        j.step()
    assert j.P[0, 0] / j.h == pytest.approx(FC * A, rel=1e-10)
    assert np.linalg.norm(j.P[0, 1:]) / j.h == pytest.approx(mu * FC * A, rel=1e-10)
    assert_parallel(-j.P[0, 1:], DIRS["ts"])
    assert_parallel(j.jump()[1:], DIRS["ts"])
    # velocity reset, θ = 1: each step v_T = h (0.5 - μ) f_c A / M along the force
    vT = j.h * (0.5 - mu) * FC * A / M
    assert np.linalg.norm(j.v[:2]) == pytest.approx(vT, rel=1e-10)
    assert np.linalg.norm(j.jump()[1:]) == pytest.approx(3 * j.h * vT, rel=1e-10)


def test_softening_cap_follows_the_exponential_law():
    """G_fc: the cap of each step is f_c exp(-f_c |u_p| / G_fc) at the committed closure (as in 2D, test_cap.py)."""
    G = 2.0 * FC
    j, M = pressed("coulomb", dict(mu=0.5, G_fc=G))
    F = 3 * FC * A
    q, diss = 0.0, 0.0
    for _ in range(6):
        f = FC * np.exp(-FC * abs(q) / G)
        dq = -j.h ** 2 * (F - f * A) / M
        j.step()
        q += dq
        diss += f * A * abs(dq)
        assert j.P[0, 0] / j.h == pytest.approx(f * A, rel=1e-10)
        assert j.q[2] == pytest.approx(q, rel=1e-9)
        assert j.st[0, S_UP] == pytest.approx(q, rel=1e-9)
        assert j.st[0, S_DISS] == pytest.approx(diss, rel=1e-9)


def test_cap_on_a_compliant_joint():
    cN = 1e12
    j, M = pressed("elastic", dict(c_N=cN, c_T=cN, mu=0.5))
    for _ in range(6):
        j.step()
    assert j.P[0, 0] / j.h == pytest.approx(FC * A, rel=1e-9)
    assert j.st[0, S_UN] == pytest.approx(-FC / cN, rel=1e-6)
    assert j.st[0, S_UP] < 0 and j.q[2] == pytest.approx(j.st[0, S_UP] - FC / cN, rel=1e-6)


# ----------------------------------------------------------------------------- 3D kernel = 2D kernel on 2D problems
def block_rows(dim, points, center, frame):
    """Local rows G (nc, dim, ndof) of a rigid block, dofs 2D (x, y, rz) or 3D (x, y, z, rx, ry, rz); frame rows
    (n, t[, s]) in global coordinates."""
    G = []
    for p in points:
        r = np.asarray(p, float) - center
        if dim == 2:
            J = np.array([[1.0, 0.0, -r[1]], [0.0, 1.0, r[0]]])  # point velocity from (vx, vy, ωz)
            G.append(np.array(frame)[:, :2] @ J)
        else:
            J = np.hstack([np.eye(3), -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])])
            G.append(np.array(frame) @ J)
    return np.array(G)


EMBED = [
    ("coulomb", dict(mu=0.5, f_c=2.9e5)),
    ("elastic", dict(c_N=1e8, c_T=5e7, mu=0.5)),
    ("brittle", dict(variant="elastic", c_N=1e8, c_T=5e7, r_c=2e4, s_c=1.5e4, mu=0.5)),
    ("brittle", dict(variant="dugdale", r_c=2e4, l_c=2e-4, mu=0.5)),
    ("fremond", dict(c_N=1e8, c_T=5e7, w=2.0, mu=0.5)),
    ("fremond", dict(c_N=1e8, c_T=5e7, w=2.0, b=0.05, friction="damage", mu_r=0.6, f_c=2.9e5)),
    ("coulomb", dict(mu=0.5, f_c=2.9e5, G_fc=5.0)),
    ("mixed", dict(k_n=1e8, k_s=5e7, f_t=2e4, c=3e4, G_I=10.0, G_II=20.0, tan_phi=0.6)),
]


@pytest.mark.parametrize("law, params", EMBED, ids=[f"{k}-{i}" for i, (k, _) in enumerate(EMBED)])
def test_3d_run_of_a_2d_problem_equals_2d(law, params):
    """A free rigid block on two contact points (coupled through its rotation), pressed, then sheared and pulled
    off-centre, dynamic (no velocity reset; θ = 1 so that the rocking does not amplify round-off). The 3D problem
    adds z (free, unloaded: tangent s unused), rx and ry (held); its trajectory, impulses and law states equal the
    2D ones to 1e-12 of each quantity's largest value over the run."""
    pts3 = [(0.03, 0.0, 0.0), (0.17, 0.0, 0.0)]
    c3 = np.array([0.1, 0.05, 0.0])
    frame3 = [(0, 1, 0), (1, 0, 0), (0, 0, 1)]
    G2 = block_rows(2, [p[:2] for p in pts3], c3[:2], [f[:2] for f in frame3[:2]])
    G3 = block_rows(3, pts3, c3, frame3)
    m, I = 4.0, 0.02
    fy = ramp([-6e3, -6e3, 1.2e4], [0, 0.05, 0.3])
    fx = ramp([0, 0, 300.0], [0, 0.05, 0.3])
    mz = ramp([0, 0, 20.0], [0, 0.1, 0.3])
    area = 0.5 * A
    j2 = Joint(law, params, G2, area, [m, m, I], force={0: fx, 1: fy, 2: mz}, h=1e-3, theta=1.0, reset=False,
               tol=1e-15)
    j3 = Joint(law, params, G3, area, [m, m, m, I, I, I], drive={3: lambda t: 0.0, 4: lambda t: 0.0},
               force={0: fx, 1: fy, 5: mz}, h=1e-3, theta=1.0, reset=False, tol=1e-15)
    assert j3.st.shape[1] == NSTATE3
    H2, H3 = [], []
    for _ in range(300):
        j2.step()
        j3.step()
        H2.append(np.concatenate([j2.P.ravel(), j2.q, j2.v, j2.st.ravel()]))
        H3.append(np.concatenate([j3.P[:, :2].ravel(), j3.q[[0, 1, 5]], j3.v[[0, 1, 5]], j3.st[:, :7].ravel()]))
        assert np.all(j3.P[:, 2] == 0.0) and np.all(j3.st[:, S_US] == 0.0) and j3.q[2] == 0.0  # s unused
    H2, H3 = np.array(H2), np.array(H3)
    scale = np.abs(H2).max(axis=0) + 1e-300  # per quantity over the history
    err = (np.abs(H3 - H2) / scale).max(axis=0)
    assert err.max() <= 1e-12, err
    nP = 4
    assert np.any(H2[:, :nP:2] < 0) or law == "coulomb"  # tension carried
    assert np.any(H2[:, :nP:2] > 0)  # compression
    if law not in ("coulomb", "elastic"):
        assert np.any(j2.st[:, S_DISS] > 0)  # the joint was damaged / broken on the way
    if law == "coulomb" or "f_c" in params:
        assert np.any(j2.st[:, S_UP] < 0)  # crushed at the cap


# ----------------------------------------------------------------------------- residual, API, validation
def test_residual_criterion_and_natural_map():
    """With the residual criterion every step converges to ‖F‖/‖q‖ <= 1e-9 (natural map of the transformed
    problem, recomputed); a perturbed impulse has a residual of the size of the perturbation."""
    mu, p = 0.6, 2e5
    uc = np.sqrt(W / CT)
    d = DIRS["ts"]
    drive = tangential_drive(d, ramp([0, 6 * uc], [0, 1]))
    del drive[2]
    j = one_point("fremond", dict(c_N=CN, c_T=CT, w=W, mu=mu), drive=drive, force={2: -p * A}, h=1e-2,
                  tol=1e-9, criterion="residual")
    for _ in range(100):
        res = j.step()
        assert res.converged and res.residual <= 1e-9
        assert res.local_cases is not None and res.local_cases[0] == 0
    q, ueff, trial, st = j.last
    args = (j.W.indptr, j.W.indices, j.W.blocks, q, j.mu)
    f = nlgs.natural_map_cohesive(*args, res.r, j.law, j.par, st, trial, ueff, j.area, j.h, j.theta)
    assert f == pytest.approx(res.residual_abs, rel=1e-12, abs=1e-300) and f <= 1e-9 * np.linalg.norm(q)
    r = res.r.copy()
    r[1:] *= 1.1  # radial perturbation of the tangential impulse: outside the (transformed) cone
    dr = 0.1 * np.linalg.norm(res.r[1:])
    assert nlgs.natural_map_cohesive(*args, r, j.law, j.par, st, trial, ueff, j.area, j.h, j.theta) > 0.1 * dr


def test_linear_part_has_no_tangential_constant():
    """The 3D kernel takes r_adh,T = k_T u_T (isotropic): every law's constant tangential term is 0."""
    for law, params in [("elastic", dict(c_N=CN, c_T=CT)), ("brittle", dict(c_N=CN, c_T=CT, r_c=1e5)),
                        ("brittle", dict(variant="dugdale", r_c=1e5, l_c=1e-4)),
                        ("fremond", dict(c_N=CN, c_T=CT, w=W)), ("mixed", MIXED), ("coulomb", dict(mu=0.3))]:
        code, par = law_parameters(law, params, "j")
        st = initial_state(np.array([code]), 3)[0]
        for x in (0.0, 0.5, 1.0):
            for tension in (True, False):
                assert linear_part(code, par, st, x, tension)[3] == 0.0


def test_3d_inputs_validated():
    j = one_point("fremond", dict(c_N=CN, c_T=CT, w=W, mu=0.5))
    q = np.array([-1.0, 0.0, 0.0])
    with pytest.raises(InputError, match=r"st: expected the 3D state layout"):
        nlgs.solve_cohesive(j.W, q, j.mu, j.law, j.par, initial_state(j.law, 2), np.zeros((1, 3)), j.area, 1e-2, 1.0)
    with pytest.raises(InputError, match=r"ueff: expected shape \(1, 3\)"):
        nlgs.solve_cohesive(j.W, q, j.mu, j.law, j.par, j.st, np.zeros((1, 2)), j.area, 1e-2, 1.0)
    with pytest.raises(InputError, match=r"dim = 4"):
        initial_state(j.law, 4)


@pytest.mark.parametrize("law, params", [("fremond", dict(c_N=CN, c_T=CT, w=W, mu=0.5)),
                                         ("brittle", dict(c_N=CN, c_T=CT, r_c=3e5, s_c=5e5, mu=0.5))])
def test_3d_block_on_four_points_equilibrium_and_isotropy(law, params):
    """A free 3D rigid block (6 dofs) on four joint points (W_αβ full 3x3 blocks coupled through the rotations),
    pressed and pushed by an oblique horizontal force at its centre (overturning moment carried by the joint),
    quasi-static: at rest the contact forces balance the load (force and moment, to 1e-9), and turning the force
    by 90° about the normal permutes the contact forces (isotropy, to 1e-9). (Laws rigid in compression: with
    compliant joints as stiff as these, h²kW >> 1, the Gauss–Seidel iteration converges too slowly here.)"""
    a, H = 0.05, 0.1
    pts = [(-a, -a, 0.0), (a, -a, 0.0), (a, a, 0.0), (-a, a, 0.0)]
    center = np.array([0.0, 0.0, H / 2])
    G = block_rows(3, pts, center, [N3, T3, S3])
    m, I = 8.0, 0.02
    Fz, Ft = 4e3, 5e3
    out = []
    for phi in (0.2, 0.2 + np.pi / 2):
        F = np.array([Ft * np.cos(phi), Ft * np.sin(phi), -Fz, 0.0, 0.0, 0.0])
        j = Joint(law, params, G, A / 4, [m, m, m, I, I, I], force=dict(enumerate(F)), h=1e-3, tol=1e-11)
        for _ in range(40):
            j.step()
        assert np.linalg.norm(j.v) < 1e-9 * Ft * j.h / m  # at rest
        Fc = np.einsum("aik,ai->k", G, j.P) / j.h
        assert np.abs(Fc + F).max() <= 1e-9 * Fz
        assert np.any(j.P[:, 0] < 0) and np.any(j.P[:, 0] > 0)  # tension and compression under the moment
        assert np.all(j.st[:, S_BROKEN] == 0.0)
        out.append(np.sort(np.concatenate([j.P[:, 0], np.linalg.norm(j.P[:, 1:], axis=1)])))
    assert np.allclose(out[0], out[1], rtol=0, atol=1e-9 * np.abs(out[0]).max())


def test_cap3_kkt_on_random_anisotropic_blocks():
    """_cap3 (tangential problem at the cap) on random SPD 3x3 blocks (anisotropic W_TT): p_T in the disk of radius
    R = μ capP, v_T = W_TN capP + W_TT p_T + q_T, and stick (v_T = 0) or slide (‖p_T‖ = R, v_T = -λ p_T/R, λ >= 0)."""
    rng = np.random.default_rng(3)
    nslide = 0
    for _ in range(300):
        M = rng.normal(size=(3, 3))
        w = (M @ M.T + 0.05 * np.eye(3))[None]
        q = rng.normal(size=3)
        mu, cap = rng.uniform(0.0, 1.0), rng.uniform(0.1, 2.0)
        pn, p1, p2 = nlgs._cap3(w, 0, 2 * cap, 0.0, 0.0, q[1], q[2], mu, cap)
        assert pn == cap
        p = np.array([p1, p2])
        v = w[0, 1:, 0] * cap + w[0, 1:, 1:] @ p + q[1:]
        R = mu * cap
        assert np.linalg.norm(p) <= R * (1 + 1e-12) + 1e-300
        if np.linalg.norm(v) > 1e-10 * (np.linalg.norm(q) + cap):
            nslide += 1
            assert np.linalg.norm(p) == pytest.approx(R, rel=1e-10)
            assert abs(v[0] * p[1] - v[1] * p[0]) <= 1e-9 * np.linalg.norm(v) * R  # v_T ∥ p_T
            assert v @ p <= 0.0
    assert 50 < nslide < 300  # both cases met


@pytest.mark.parametrize("law, params", EMBED + [("mixed", dict(MIXED, k_n=1e8, k_s=5e7, f_t=2e4, c=3e4, G_I=10.0,
                                                                    G_II=20.0, softening="exponential"))])
def test_random_coupled_problems_converge_to_zero_natural_map(law, params):
    """Six contacts with a random SPD Delassus matrix (full 3x3 blocks coupled), random free velocities and jumps:
    the staggered 3D cohesive NLGS converges and the recomputed natural map of the transformed problem is <= tol;
    the internal variables returned are those implied by the returned jumps (fixed point of the staggered update)."""
    rng = np.random.default_rng(7)
    n = 6
    code, par = law_parameters(law, params, "j")
    for trial_no in range(5):
        M = rng.normal(size=(3 * n, 3 * n))
        Wd = M @ M.T / (3 * n) + 0.1 * np.eye(3 * n)
        W3 = to_block_csr(Wd, 3)
        q = rng.normal(size=3 * n) * 0.1
        lawv = np.full(n, code, dtype=np.int64)
        parv = np.tile(par, (n, 1))
        muv = parv[:, 0].copy()  # contiguous, as the contact step passes it (a strided view compiles new kernels)
        st = initial_state(lawv, 3)
        ueff = rng.normal(size=(n, 3)) * 1e-4
        area = np.full(n, 0.01)
        res, x = nlgs.solve_cohesive(W3, q, muv, lawv, parv, st, ueff, area, 1e-2, 1.0, tol=1e-11,
                                     criterion="residual", check_every=1, max_sweeps=20000)
        assert res.converged, res.message
        f = nlgs.natural_map_cohesive(W3.indptr, W3.indices, W3.blocks, q, muv, res.r, lawv, parv, st, x,
                                      ueff, area, 1e-2, 1.0)
        assert f <= 1e-11 * np.linalg.norm(q)
        x2 = x.copy()
        assert nlgs._update_internal(lawv, parv, st, ueff, res.u, 1e-2, 1.0, x2) <= 1e-12

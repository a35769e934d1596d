"""Inertia in quasi-static stages (issue #18 item 9): the inertial part of the driver reactions (history columns
BODY.Id, summary `inertia_share`, warning above 1 %).

Closed form: a driven rigid platen pushes a rigid block (mass m, only y free, no gravity) onto a fixed base through
an elastic joint (c_N, area A). With velocity reset and theta = 1 the block starts every step at rest and must move
by du = v h with the platen: its inertia force is m du / h^2 exactly, and the platen's reaction is
R = -(c_N A delta + m du / h^2) with delta = k du after k steps (step 1 also carries the platen's own acceleration
from rest to v: m_p v / h).
"""
import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.output.history import read_history
from fem_blocks.runner import inertia_shares, run_case

M_BLOCK, M_PLATEN, C_N, AREA = 100.0, 10.0, 1e9, 1.0  # kg, kg, N/m^3, m^2 (1 m face x 1 m thickness)

CASE = """
name = "platen"
gravity = [0.0, 0.0]
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]]
mass = 1000.0
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "block"
group = "block"
vertices = [[0.0, 0.5], [1.0, 0.5], [1.0, 1.0], [0.0, 1.0]]
mass = {m}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "platen"
group = "platen"
vertices = [[0.0, 1.0], [1.0, 1.0], [1.0, 1.2], [0.0, 1.2]]
mass = {mp}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = {vy}}}
rz = {{kind = "velocity", history = 0.0}}
[[interfaces]]
between = ["block", "base"]
law = "elastic"
c_N = {cn}
c_T = 1.0
mu = 0.0
[[interfaces]]
between = ["platen", "block"]
placement = "positions"
positions = [0.5]
mu = 0.0
[contact]
tol = 1e-12
solver = "newton"
[[stages]]
name = "push"
duration = {dur}
h = {h}
theta = 1.0
velocity_reset = true
"""

DU, STEPS = 1e-5, 5  # displacement per step [m], steps


def _run(tmp_path, h, capsys):
    path = tmp_path / f"h{h:g}.toml"
    path.write_text(CASE.format(m=M_BLOCK, mp=M_PLATEN, vy=-DU / h, cn=C_N, dur=STEPS * h, h=h))
    out = tmp_path / f"out{h:g}"
    s = run_case(load_case(str(path)), str(out), progress=False)
    return read_history(out / "history.csv"), s, capsys.readouterr().err


def test_inertial_part_of_the_platen_reaction_is_m_du_over_h2(tmp_path, capsys):
    res = {h: _run(tmp_path, h, capsys) for h in (0.01, 0.002)}
    for h, (hist, s, err) in res.items():
        assert np.all(hist["converged"] == 1)
        inert = M_BLOCK * DU / h ** 2  # by hand
        k = np.arange(1, STEPS + 1)
        expected_I = np.full(STEPS, inert)
        expected_I[0] += M_PLATEN * DU / h ** 2  # step 1: the platen itself goes from rest to v
        # history rows 1..STEPS; the platen moves down: R and I are negative (force of the driver on the platen)
        np.testing.assert_allclose(-hist["platen.Iy"][1:], expected_I, rtol=1e-9)
        np.testing.assert_allclose(-hist["platen.Ry"][1:], C_N * AREA * k * DU + expected_I, rtol=1e-9)
        # fixed dofs and free dofs carry no inertial part (they do no work)
        for col in ("base.Iy", "base.Ix", "block.Ix", "block.Iy", "platen.Ix", "platen.Irz"):
            assert np.all(hist[col] == 0.0), col
        # summary: max share over the steps with |R| >= 10 % of its stage maximum (here all 5), and at the peak
        sh = s["stages"][0]["inertia_share"]["platen.Ry"]
        assert sh["max_share"] == pytest.approx(expected_I[0] / (C_N * AREA * DU + expected_I[0]), rel=1e-9)
        assert sh["share_at_peak"] == pytest.approx(inert / (C_N * AREA * STEPS * DU + inert), rel=1e-9)
        assert s["stages"][0]["inertia_share"]["base.Ry"]["max_share"] == 0.0
    # h = 10 ms: 11 N of 10 011 N (0.11 %) at most: no warning; h = 2 ms: 275 N of 10 275 N (2.7 %): warning
    assert "inertial part" not in res[0.01][2]
    err = res[0.002][2]
    assert "stage 'push'" in err and "inertial part of reaction platen.Ry reaches 2.7%" in err
    assert "block.R" not in err and "base.R" not in err
    # the static part R - I does not depend on h
    np.testing.assert_allclose(res[0.01][0]["platen.Ry"] - res[0.01][0]["platen.Iy"],
                               res[0.002][0]["platen.Ry"] - res[0.002][0]["platen.Iy"], rtol=1e-9, atol=1e-9)


def test_inertia_shares_ignore_small_reactions_and_other_stages():
    hist = {"step": np.array([0, 1, 2, 3, 4]), "stage": np.array([0, 0, 0, 1, 1]),
            "b.Rx": np.array([0.0, 1.0, 100.0, 5.0, 5.0]), "b.Ix": np.array([0.0, 0.9, 2.0, 1.0, 0.0]),
            "b.Ry": np.zeros(5), "b.Iy": np.zeros(5)}
    s0 = inertia_shares(hist, 0)
    assert set(s0) == {"b.Rx"}  # b.Ry: zero reaction (free dof) throughout
    # |R| = 1 is below 10 % of the stage's peak 100: its 90 % share is not counted
    assert s0["b.Rx"] == dict(max_share=0.02, share_at_peak=0.02, max_abs_R=100.0)
    assert inertia_shares(hist, 1)["b.Rx"]["max_share"] == 0.2


# ----------------------------------------------------------------------------- static step (stage key static = true)
E, LX, LY, T = 1e9, 0.2, 0.4, 0.1  # Pa, m, m, m: column clamped at its base, nu = 0 (uniaxial, exact in P1/Q1)

STATIC = """
name = "static"
gravity = [0.0, 0.0]
[materials.m]
E = {E}
nu = 0.0
rho = 2000.0
thickness = {T}
[block_types.col]
geometry = "rectangle"
material = "m"
lx = {LX}
ly = {LY}
mesh_size = 0.1
[[blocks]]
type = "col"
name = "col"
group = "col"
[[blocks.clamps]]
tag = "bottom"
components = "{clamp}"
[[rigid_bodies]]
name = "platen"
group = "platen"
vertices = [[-0.05, {LY}], [0.25, {LY}], [0.25, 0.5], [-0.05, 0.5]]
mass = 10.0
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
{ydrv}
rz = {{kind = "velocity", history = 0.0}}
[[interfaces]]
between = ["col", "platen"]
mu = 0.0
placement = "nodes"
[contact]
tol = 1e-12
solver = "newton"
[[stages]]
name = "push"
duration = {dur}
h = {h}
{stage}
"""


def _static_case(tmp_path, h, stage="static = true", clamp="xy", ydrv=None, name="s"):
    if ydrv is None:
        ydrv = f'y = {{kind = "velocity", history = {-DU / h!r}}}'
    path = tmp_path / f"{name}{h:g}.toml"
    path.write_text(STATIC.format(E=E, T=T, LX=LX, LY=LY, clamp=clamp, ydrv=ydrv, dur=STEPS * h, h=h, stage=stage))
    return load_case(str(path))


def test_static_step_platen_reaction_is_E_A_delta_over_L_for_any_h(tmp_path, capsys):
    Ry = {}
    for h in (0.01, 0.002, 1e-5):  # 1e-5: pseudo-velocities of 1 m/s (no kinetic energy, no guard on it)
        out = tmp_path / f"out{h:g}"
        run_case(_static_case(tmp_path, h), str(out), progress=False)
        hist = read_history(out / "history.csv")
        assert np.all(hist["converged"] == 1)
        Ry[h] = hist["platen.Ry"][1:]
        k = np.arange(1, STEPS + 1)
        # static equilibrium after k steps: |R| = E A delta / L, A = LX T, delta = k du (closed form, no h)
        np.testing.assert_allclose(-Ry[h], E * LX * T * k * DU / LY, rtol=1e-10)
        assert np.all(hist["platen.Iy"] == 0.0)
        assert np.all(hist["kinetic"] == 0.0)  # no inertia in the model (u = dq/h is a pseudo-velocity)
    np.testing.assert_allclose(Ry[0.002], Ry[0.01], rtol=1e-10)
    np.testing.assert_allclose(Ry[1e-5], Ry[0.01], rtol=1e-10)
    assert "inertial part" not in capsys.readouterr().err
    # the same stage with velocity reset instead: the column's inertia is in the reaction and depends on h
    out = tmp_path / "reset"
    run_case(_static_case(tmp_path, 0.002, stage="theta = 1.0\nvelocity_reset = true", name="r"), str(out),
             progress=False)
    Rr = read_history(out / "history.csv")["platen.Ry"][1:]
    assert np.all(np.abs(Rr - Ry[0.002]) > 1e-3 * np.abs(Ry[0.002]))


def test_static_step_rejects_bodies_without_static_equilibrium(tmp_path):
    from fem_blocks.errors import InputError
    with pytest.raises(InputError, match=r"stages\[0\]\.static = true: body 'platen': its dofs y are not driven"):
        run_case(_static_case(tmp_path, 0.01, ydrv="", name="a"), str(tmp_path / "a"), progress=False)
    with pytest.raises(InputError, match=r"stages\[0\]\.static = true: body 'col': its clamps leave a rigid motion"):
        run_case(_static_case(tmp_path, 0.01, clamp="y", name="b"), str(tmp_path / "b"), progress=False)
    with pytest.raises(InputError, match=r"stages\[0\]\.theta: = 0\.5: expected 1 .*static = true"):
        _static_case(tmp_path, 0.01, stage="static = true\ntheta = 0.5", name="c")


def test_clamps_fix_rigid_modes():
    from fem_blocks.bodies import BlockType, Material
    from fem_blocks.meshing import mesh_rectangle
    bt = BlockType(mesh_rectangle(0.2, 0.4, 0.1), Material(E=1e9, nu=0.0, rho=2000.0))
    y = bt.mesh.points[:, 1]
    base = np.flatnonzero(np.abs(y) < 1e-12)
    clamped = np.zeros(bt.ndof, dtype=bool)
    clamped[2 * base + 1] = True          # base, y only: x translation free
    assert not bt.clamps_fix_rigid_modes(clamped)
    clamped[2 * base[0]] = True           # + x of one base node: fixed (the y of two nodes stop the rotation)
    assert bt.clamps_fix_rigid_modes(clamped)
    one = np.zeros(bt.ndof, dtype=bool)
    one[[2 * base[0], 2 * base[0] + 1]] = True  # one node, x and y: rotation about it free
    assert not bt.clamps_fix_rigid_modes(one)


def test_inertial_part_from_a_deformable_column_matches_the_1d_bar_by_hand(tmp_path):
    """Velocity reset on the clamped column (nu = 0, consistent mass, 2 x 4 Q1 elements): the column's response is
    u_y(y) only, so the step is the 4-element bar, solved here by hand: (K + M/h^2) dq = 0 on the interior nodes
    with dq = du at the top and 0 at the base (starting from q_i), R_top = (M dq / h^2 + K q_{i+1})_top,
    I = dq . M dq / h^2 / du (the work of the inertia forces over the platen's displacement)."""
    h, rho, n = 0.002, 2000.0, 4
    path = tmp_path / "col.toml"
    text = _static_case(tmp_path, h, stage="theta = 1.0\nvelocity_reset = true", name="x").source
    src = open(text).read().replace('mesh_size = 0.1', 'mesh_size = 0.1\nmass = "consistent"')
    path.write_text(src)
    out = tmp_path / "out"
    run_case(load_case(str(path)), str(out), progress=False)
    hist = read_history(out / "history.csv")
    assert np.all(hist["converged"] == 1)
    # the bar by hand
    le, A, m_e = LY / n, LX * T, rho * LX * T * LY / n
    K = np.zeros((n + 1, n + 1))
    M = np.zeros((n + 1, n + 1))
    for e in range(n):
        K[e:e + 2, e:e + 2] += E * A / le * np.array([[1.0, -1.0], [-1.0, 1.0]])
        M[e:e + 2, e:e + 2] += m_e / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    S = K + M / h ** 2
    f = np.arange(1, n)  # interior nodes; 0 clamped, n under the platen
    q = np.zeros(n + 1)
    R_hand, I_hand = [], []
    for k in range(STEPS):
        dq = np.zeros(n + 1)
        dq[n] = -DU
        dq[f] = np.linalg.solve(S[np.ix_(f, f)], -K[f] @ q - S[f, n] * dq[n])
        q = q + dq
        top = (M @ dq / h ** 2 + K @ q)[n]  # force of the platen on the column (negative: compression)
        R_hand.append(top)
        I_hand.append(dq @ M @ dq / h ** 2 / dq[n])
    own = np.zeros(STEPS)
    own[0] = -10.0 * DU / h ** 2  # step 1: the platen (10 kg) from rest to -du/h
    np.testing.assert_allclose(hist["platen.Ry"][1:], np.array(R_hand) + own, rtol=1e-9)
    np.testing.assert_allclose(hist["platen.Iy"][1:], np.array(I_hand) + own, rtol=1e-9)
    # close to the quasi-static mode's m/3 du/h^2 (linear dq): 1.0 % below it at step 1, where dq lags the
    # linear mode, then 6e-4, 5e-7, 4e-9, 3e-11 (the increments become the linear mode)
    m = rho * LX * LY * T
    np.testing.assert_allclose(-np.array(I_hand), m / 3 * DU / h ** 2, rtol=0.01)


def test_a_driver_standing_still_gets_no_inertia_from_motion_it_does_not_drive():
    """A free block falls (velocity reset: dq = g h^2 per step) beside a driven block whose increment is rounding
    noise (1e-18 m per step): the falling block's inertia work is not divided by that increment (before: I ~ 1e10 N);
    a driver that moves (here 1 mm per step, the only driver) still gets W_I / dq."""
    from fem_blocks.bodies import Driver, RigidBody
    from fem_blocks.dynamics import Simulation
    sq = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    for vy, expect_zero in ((-1e-18 / 0.01, True), (-1e-3 / 0.01, False)):
        falling = RigidBody(sq, mass=100.0, inertia=10.0)
        drv = {k: Driver("velocity", 0.0) for k in ("x", "rz")}
        drv["y"] = Driver("velocity", vy)
        fixed = RigidBody([(x + 5.0, y) for x, y in sq], mass=1.0, inertia=1.0, drivers=drv)
        sim = Simulation([falling, fixed], h=0.01, theta=1.0, velocity_reset=True)
        sim.step()
        sim.step()
        w_i = 100.0 * 9.81 ** 2 * 0.01 ** 2  # dq . m (u - 0) / h = (g h^2)(m g h)/h
        assert sim.inertia_work == pytest.approx(w_i, rel=1e-12)
        if expect_zero:
            assert np.all(fixed.reaction_inertia == 0.0)
        else:
            assert fixed.reaction_inertia[1] == pytest.approx(w_i / (vy * 0.01), rel=1e-12)

"""The bond tests of the virtual laboratory (issue #23): couplet direct tension and the EN 1052-5 bond wrench
(fem_blocks/lab/bond.py, bond_tension.py, bond_wrench.py; docs/lab-tests.md).

Closed forms (issue #23 "Checks against closed forms"):
* couplet tension, rigid bricks: every point of the joint opens by the same δ, so the peak force is f_t A
  (A = L t) within 1 %, and a full separation dissipates G_I A (the mixed law's pure mode I, docs/laws.md);
* bond wrench, rigid bricks, brittle mixed joint (G_I = 1.01 f_t²/(2 k_n), the least the law accepts is any
  G_I > f_t²/(2 k_n)): the standard's f_w = M/Z − N/A_j equals f_t within 2 % with 21 points through the joint's
  depth, i.e. the failure moment equals f_t b d²/6 + N d/6 (the issue's f_t b d²/6 under the knife's compression);
  and the failure load equals that of an independent sequential-linear analysis of the discrete joint (n + 1 linear
  springs with trapezoidal areas that break at f_t one after the other, `cascade_peak` below).
The read-out formulas on hand-made arrays, the dead load F2 e2 by hand, one CLI run of each demo with --quick.
"""
import json
import os

import numpy as np
import pytest

pytestmark = pytest.mark.dolfinx
from _paths import DEMOS  # noqa: E402

from fem_blocks.lab import load_lab, run_lab  # noqa: E402
from fem_blocks.lab.bond_tension import peak_problems, tension_readout  # noqa: E402
from fem_blocks.lab.bond_wrench import (KNIFE_WIDTH, LEVER_DEPTH, STEEL, dead_load, failure_problems,  # noqa: E402
                                         wrench_readout)

# the demos' joint (Lourenço & Rots 1997 low-pressure joints, approximate), mm-N-MPa
K_N, F_T = 82.0, 0.25


def _file(tmp_path, test, lab_lines, G_I=0.018, thickness=210.0, gravity=None, name="case"):
    text = f"""units = "mm-N-MPa"
{'' if gravity is None else f'gravity = [0.0, {gravity}]'}
[materials.brick]
E = 16700.0
nu = 0.15
rho = 2.0e-9
thickness = {thickness}

[laws.joint]
law = "mixed"
k_n = {K_N}
k_s = 36.0
f_t = {F_T}
c = 0.35
G_I = {G_I!r}
G_II = 0.125
tan_phi = 0.75

[lab]
test = "{test}"
""" + "\n".join(lab_lines) + "\n"
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    return str(p)


# ------------------------------------------------------------------------------------------ read-outs by hand
def test_tension_readout_on_a_triangle():
    """F rises linearly to 5000 N at δ = 0.003 mm and falls to 0 at 0.15 mm, then stays 0: f_t,b = 5000 / A,
    G_f = ½ · 5000 N · 0.15e-3 m / A (the trapezoidal rule is exact on the vertices); a curve that ends loaded
    has no G_f (it would count stored elastic energy). Catches: the area, the peak row, the separation test."""
    u = np.array([0.0, 1e-6, 3e-6, 50e-6, 150e-6, 200e-6])
    F = np.array([0.0, 5000 / 3, 5000.0, 5000 * (150 - 50) / 147, 0.0, 0.0])
    A = 0.21 * 0.1
    r = tension_readout(u, F, A)
    assert r["f_tb_Pa"] == pytest.approx(5000 / A, rel=1e-14)
    assert r["peak_row"] == 2 and r["opening_at_peak_m"] == 3e-6 and r["separated"]
    assert r["G_f_J_m2"] == pytest.approx(0.5 * 5000 * 150e-6 / A, rel=1e-12)
    r2 = tension_readout(u[:4], F[:4], A)
    assert not r2["separated"] and np.isnan(r2["G_f_J_m2"])


def test_wrench_readout_formula():
    """f_w = (F1 e1 + F2 e2)/Z − (F1 + F2)/A_j at the largest F1 (EN 1052-5 as recalled), by hand: b = 0.21 m,
    d = 0.1 m, Z = b d²/6 = 3.5e-4 m³, A_j = 0.021 m²; F1 = 400 N at e1 = 0.25 m, F2 = 50 N at e2 = 0.1 m:
    M = 105 N m, N = 450 N, f_w = 105/3.5e-4 − 450/0.021 = 300000 − 21428.571... Pa. Catches: a sign of the
    compression term, e2 or F2 dropped, the wrong row."""
    b, d = 0.21, 0.1
    A, Z = b * d, b * d * d / 6
    r = wrench_readout([0.0, 100.0, 400.0, 300.0], 0.25, 50.0, 0.1, A, Z)
    assert Z == pytest.approx(3.5e-4, rel=1e-14)
    assert r["failure_row"] == 2 and r["M_fail_Nm"] == pytest.approx(105.0) and r["N_fail_N"] == pytest.approx(450.0)
    assert r["f_w_Pa"] == pytest.approx(300000.0 - 450.0 / 0.021, rel=1e-12)
    assert r["fwZ_Nm"] == pytest.approx(105.0 - 450.0 * d / 6, rel=1e-12)


def test_no_failure_is_no_result():
    """A curve whose largest force is at its last row (still rising) or never positive has no peak: the read-outs
    say why (and the reports then write NaN for the strengths). Catches a report that reads a truncated test or a
    specimen broken before the load as a strength."""
    assert failure_problems([0.0, 10.0, 5.0]) == [] and peak_problems([0.0, 10.0, 5.0]) == []
    assert "still rising" in failure_problems([0.0, 5.0, 10.0])[0]
    assert "still rising" in peak_problems([0.0, 5.0, 10.0])[0]
    assert "never loaded" in failure_problems([0.0, -0.0, 0.0])[0] and "never carried" in peak_problems([0.0, -1.0])[0]


def test_dead_load_by_hand(tmp_path):
    """F2 = g (m_lever + m_upper) and e2 = their centre of gravity from the joint's centre line, by hand from the
    specimen's dimensions (d = 100 mm, H = 62 mm, e1 = 250 mm, knife w = d/100, lever [0, d/2 + e1 + w] x H/2 of
    steel, t = 210 mm, brick 2000 kg/m³); without gravity both are 0."""
    lab = load_lab(_file(tmp_path, "bond_wrench", ["bricks = \"rigid\"", "divisions = 4"], gravity=-9810.0))
    case = lab.specimens[0][1]
    d, H, t, e1 = 0.1, 0.062, 0.21, 0.25
    w = KNIFE_WIDTH * d
    Ll = d / 2 + e1 + w
    m_l, m_b = STEEL * Ll * LEVER_DEPTH * H * t, 2000.0 * d * H * t
    F2, e2 = dead_load(lab.spec, case)
    assert F2 == pytest.approx(9.81 * (m_l + m_b), rel=1e-12)
    assert e2 == pytest.approx((m_l * Ll / 2 + m_b * d / 2) / (m_l + m_b) - d / 2, rel=1e-12)
    lab0 = load_lab(_file(tmp_path, "bond_wrench", ["bricks = \"rigid\"", "divisions = 4"], name="g0"))
    assert dead_load(lab0.spec, lab0.specimens[0][1])[0] == 0.0


def test_rigid_wrench_joint_has_n_plus_1_points(tmp_path):
    """Rigid bricks: the bed faces are cut into `divisions` edges, so the joint interface meets n + 1 vertices on
    each face (placement "overlap": n + 1 points); deformable bricks get mesh size d / n."""
    lab = load_lab(_file(tmp_path, "bond_wrench", ["bricks = \"rigid\"", "divisions = 7"]))
    rb = {b.name: b for b in lab.specimens[0][1].rigid_bodies}
    v = np.asarray(rb["upper"].vertices)
    assert np.sum(np.isclose(v[:, 1], 0.062)) == 8 and np.sum(np.isclose(v[:, 1], 0.124)) == 8
    lab2 = load_lab(_file(tmp_path, "bond_wrench", ["divisions = 8"], name="def"))
    assert lab2.spec.mesh_size == pytest.approx(0.1 / 8)


# ------------------------------------------------------------------------------------------ closed forms
def test_couplet_tension_rigid_peak_is_ft_A_and_work_is_G_I(tmp_path):
    """Rigid bricks pulled apart through the glued plates: F_max = f_t A within 1 % (A = 210 mm x 100 mm: 5250 N;
    the sampled peak lies within one step of the true one: 0.2 mm / 200 steps = 1 µm against the softening
    branch's 141 µm), and the work of separation ∫F dδ / A = G_I within 1 %. Catches: a glue that opens or caps the
    force, a wrong area, the inertial part left in the reaction, the opening taken from the plate."""
    path = _file(tmp_path, "couplet_tension", ["bricks = \"rigid\"", "brick_length = 210.0", "pull = 0.2",
                                               "steps = 200"], thickness=100.0)
    out = tmp_path / "out"
    assert run_lab(load_lab(path), str(out), quiet=True) == 0
    q = json.loads((out / "summary.json").read_text())["quantities"]
    A = 210.0 * 100.0
    assert q["F_max"]["value"] == pytest.approx(F_T * A, rel=0.01)
    assert q["f_tb"]["value"] == pytest.approx(F_T * 1e6, rel=0.01) and q["f_tb"]["measures"] == "laws.joint.f_t"
    assert q["G_f"]["value"] == pytest.approx(0.018e3, rel=0.01)
    assert (out / "couplet_tension.png").exists() and (out / "couplet" / "history.csv").exists()


def cascade_peak(n, d, b, e1, ft):
    """The failure load of a joint of n + 1 brittle linear springs at x_i = −d/2 + i d/n with trapezoidal areas
    (b d/n, halved at the ends) under the knife's F at e1 (N = F, M = F e1; no dead load): the springs break one
    after the other from the tension edge; with k springs broken the stress σ = s0 + g x (tension > 0) solves
    Σ w σ = −F, Σ w σ x = −F e1 on the rest, and the next one breaks at F_k = f_t / σ_k(F = 1). Returns max_k F_k
    (the brittle joint's failure load, independent of the code under test)."""
    x = np.linspace(-d / 2, d / 2, n + 1)
    w = np.full(n + 1, b * d / n)
    w[[0, -1]] /= 2
    F = []
    for k in range(n // 2):
        xa, wa = x[k:], w[k:]
        M = np.array([[wa.sum(), wa @ xa], [wa @ xa, wa @ (xa * xa)]])
        s0, g = np.linalg.solve(M, [-1.0, -e1])
        F.append(ft / (s0 + g * xa[0]))
    return max(F)


def test_cascade_peak_tends_to_the_continuum():
    """The discrete brittle joint's f_w tends to f_t as the points multiply (measured: 1.0274 f_t with 11
    points, 1.0102 with 21, 1.0012 with 129): the 2 % of the issue needs n >= 14 (1.0167 at 14, 1.0208 at 12)."""
    d, b, e1, ft = 0.1, 0.21, 0.25, 0.25e6
    A, Z = b * d, b * d * d / 6

    def fw(n):
        F = cascade_peak(n, d, b, e1, ft)
        return (F * e1 / Z - F / A) / ft
    vals = [fw(n) for n in (8, 16, 32, 64, 128)]
    assert all(a > b_ for a, b_ in zip(vals, vals[1:])) and vals[-1] == pytest.approx(1.0, abs=2e-3)
    assert fw(16) < 1.02 < fw(10)


def test_bond_wrench_brittle_joint_fw_is_ft(tmp_path):
    """Rigid bricks, 21 points through d = 100 mm, a brittle mixed joint (λ_f = 2 G_I k_n / f_t² = 1.01 < 2/n:
    the edge point has lost its strength before its neighbour reaches it), knife at e1 = 250 mm, no gravity:
    f_w = f_t within 2 % (the issue's closed form: the failure moment f_w Z = f_t b d²/6); F1 equals the
    sequential-linear failure load of the discrete joint within one load step below and 0.2 % above; the joint
    resultant's moment M_j = F1 e1 within 0.5 % (the knife bears within w/2 = 0.5 mm of e1). Catches: a wrong Z or
    A_j, the compression term's sign, a lever not carrying the moment, too few contact points."""
    G_I = 1.01 * F_T ** 2 / (2 * K_N)
    path = _file(tmp_path, "bond_wrench", ["bricks = \"rigid\"", "brick_length = 100.0", "lever_arm = 250.0",
                                           "deflection = 0.02", "divisions = 20", "steps = 150"], G_I=G_I)
    out = tmp_path / "out"
    assert run_lab(load_lab(path), str(out), quiet=True) == 0
    s = json.loads((out / "summary.json").read_text())
    q, rep = s["quantities"], s["report"]
    b, d, e1 = 0.21, 0.1, 0.25
    Z = b * d * d / 6
    assert q["f_w"]["value"] == pytest.approx(F_T * 1e6, rel=0.02)
    assert q["fwZ"]["value"] == pytest.approx(F_T * 1e6 * Z, rel=0.02) and q["fwZ"]["input"] == pytest.approx(
        F_T * 1e6 * Z)
    Fc = cascade_peak(20, d, b, e1, F_T * 1e6)
    from fem_blocks.output.history import read_history
    h = read_history(str(out / "couplet" / "history.csv"))
    F1 = -(h["knife.Ry"] - h["knife.Iy"])
    step = np.max(np.diff(F1[: rep["failure_row"] + 1]))   # the largest rise per step before the failure
    assert Fc - 1.05 * step <= q["F1"]["value"] <= 1.002 * Fc
    assert rep["Mj_fail_Nm"] == pytest.approx(q["M_fail"]["value"], rel=0.005)


# ------------------------------------------------------------------------------------------ the demos
@pytest.mark.parametrize("demo", ["couplet_tension", "bond_wrench"])
def test_demo_cli_quick(tmp_path, cli, demo):
    """`fem-blocks run demos/DEMO.toml --quick` end to end (deformable bricks, the wall's joint): exit 0, the report
    and figure; couplet tension reads f_t back within 1 % and G_I within 2 %; the bond wrench's ductile joint gives
    f_w above f_t (the standard's elastic formula on a joint that redistributes)."""
    out = tmp_path / demo
    p = cli("run", os.path.join(DEMOS, f"{demo}.toml"), "--quick", "--quiet", "--out", out)  # this process: conftest.cli
    assert p.returncode == 0, p.stdout + p.stderr
    s = json.loads((out / "summary.json").read_text())
    q = s["quantities"]
    assert (out / f"{demo}.png").exists() and s["variant"] == "quick x2"
    if demo == "couplet_tension":
        assert q["f_tb"]["value"] == pytest.approx(0.25e6, rel=0.01)
        assert q["G_f"]["value"] == pytest.approx(18.0, rel=0.02)
    else:
        assert q["f_w"]["value"] > 1.5 * 0.25e6 and q["f_w"]["measures"] == "laws.joint.f_t"

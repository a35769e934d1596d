"""Issue #18 items 2 and 11: a run with unconverged steps must not look like a success, and the
force–displacement data are signed, in the unit of each dof.

* a completed run with steps whose contact solve ended above the tolerance exits with status 3 (unless
  `[checks] accept_unconverged = true`: status 0, still reported); the count and the worst residual with its
  step are in the last line printed, in summary.json ("convergence") and on the PNG; the warning names the solver;
* the curve data are signed (no abs), translations in mm / kN, rotations in rad / moments in kN·m, and
  summary.json keeps moments out of `other_reactions_at_peak_kN`.

The expected counts and residuals come from history.csv (the solver's per-row `converged` / `residual`
columns), not from the summary code under test."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

from fem_blocks.cli import main
from fem_blocks.errors import InputError
from fem_blocks.output.history import HistoryWriter, read_history

pytestmark = pytest.mark.dolfinx

# two bricks under a rigid beam pressed down slowly; max_sweeps = 1 with a residual tolerance of 1e-10 leaves
# the steps with closed contacts unconverged (the forced failure)
CASE = """
name = "tiny_prism"
[materials.brick]
E = 5e9
nu = 0.2
rho = 2000.0
thickness = 0.1
[wall]
type = "prism"
material = "brick"
brick_length = 0.2
brick_height = 0.05
bricks = 2
mesh_size = 0.05
[wall.foundation]
depth = 0.05
[wall.beam]
depth = 0.05
[wall.beam.drivers]
x = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
y = {kind = "displacement", history = {times = [0.0, 0.004], values = [0.0, -1e-6]}}
[contact]
solver = "SOLVER"
criterion = "residual"
check_every = 1
tol = TOL
max_sweeps = 1
[[interfaces]]
name = "bed"
between = ["bricks", "bricks"]
mu = 0.6
placement = "nodes"
[[interfaces]]
name = "base"
between = ["bricks", "foundation"]
mu = 0.6
placement = "nodes"
[[interfaces]]
name = "top"
between = ["bricks", "beam"]
mu = 0.6
placement = "nodes"
[output]
paraview = false
crack_pattern = false
[output.curve]
body = "beam"
force = "y"
displacement = "y"
[[stages]]
name = "press"
duration = 0.004
h = 0.001
theta = 1.0
velocity_reset = true
"""


def _run(tmp_path, capsys, extra="", solver="nlgs", tol="1e-10"):
    case = tmp_path / "tiny.toml"
    case.write_text(CASE.replace("SOLVER", solver).replace("TOL", tol) + extra)
    out = tmp_path / "out"
    rc = main(["run", str(case), "--out", str(out), "--quiet"])
    cap = capsys.readouterr()
    s = json.loads((out / "summary.json").read_text())
    h = read_history(out / "history.csv")
    return rc, cap, s, h, out


def _expected(h):
    """Count, worst residual and its step from history.csv (row 0 is the initial state)."""
    bad = np.flatnonzero(h["converged"][1:] == 0) + 1
    k = bad[np.argmax(h["residual"][bad])]
    return len(bad), float(h["residual"][k]), int(h["step"][k]), float(h["time"][k])


def test_unconverged_run_exits_3_and_reports_everywhere(tmp_path, capsys):
    rc, cap, s, h, out = _run(tmp_path, capsys)
    n, worst, step, t = _expected(h)
    assert n >= 1 and worst > 1e-10  # the failure was forced
    assert rc == 3
    c = s["convergence"]
    assert c["unconverged_steps"] == n and c["solved_steps"] == len(h["step"]) - 1 == 4
    assert c["worst_residual"] == worst and c["worst_step"] == step and c["worst_time"] == t
    assert c["accepted"] is False and c["exit_status"] == 3 and s["exit_status"] == 3
    assert c["worst_solver"] == "NLGS" and c["solvers"] == ["NLGS"] and c["tolerance"] == 1e-10
    assert c["criterion"] == "residual" and "not converged after 1 sweeps" in c["worst_message"]
    assert s["status"] == "completed with unconverged steps"
    assert s["stages"][0]["unconverged_steps"] == n
    last = cap.out.strip().splitlines()[-1]
    assert last.startswith("fem-blocks: UNCONVERGED:") and f"{n} of 4 steps" in last
    assert f"worst residual {worst:.3g} at step {step}" in last and "exit status 3" in last
    assert "accept_unconverged" in last
    # one convergence warning (other warnings, e.g. the inertial share of this forced run, may be printed too)
    warn = [ln for ln in cap.err.splitlines() if "warning" in ln and "tolerance" in ln]
    assert len(warn) == 1 and "NLGS solver" in warn[0] and f"{n} of 4 steps" in warn[0]
    assert "sweep limit" not in warn[0]
    assert (out / "force_displacement.png").stat().st_size > 0
    # item 11: moments are not reactions in kN
    k = int(np.argmax(np.abs(h["beam.Ry"])))
    assert set(s["other_reactions_at_peak_kN"]) == {"beam.Rx"}
    assert s["other_moments_at_peak_kNm"] == {"beam.Rrz": pytest.approx(h["beam.Rrz"][k] / 1e3, rel=1e-15)}
    assert s["peak_force_kN"] == pytest.approx(abs(h["beam.Ry"][k]) / 1e3, rel=1e-15)


def test_accepted_unconverged_run_exits_0_and_still_reports(tmp_path, capsys):
    rc, cap, s, h, _ = _run(tmp_path, capsys, extra="[checks]\naccept_unconverged = true\n")
    n, worst, step, _t = _expected(h)
    assert n >= 1
    assert rc == 0
    c = s["convergence"]
    assert c["unconverged_steps"] == n and c["worst_residual"] == worst and c["worst_step"] == step
    assert c["accepted"] is True and c["exit_status"] == 0 and s["exit_status"] == 0
    assert s["status"] == "completed with unconverged steps"
    last = cap.out.strip().splitlines()[-1]
    assert "unconverged (accepted)" in last and f"{n} of 4 steps" in last and "exit status 0" in last


def test_refined_sub_steps_are_counted_as_rows(tmp_path, capsys):
    """on_nonconvergence = "refine" at its limit: every kept sub-step is a history row and counts."""
    case = CASE.replace("SOLVER", "nlgs").replace("TOL", "1e-10").replace(
        "max_sweeps = 1", "max_sweeps = 1\non_nonconvergence = \"refine\"\nmax_refinements = 1")
    (tmp_path / "r.toml").write_text(case)
    rc = main(["run", str(tmp_path / "r.toml"), "--out", str(tmp_path / "r"), "--quiet"])
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    h = read_history(tmp_path / "r" / "history.csv")
    n, worst, step, _t = _expected(h)
    assert len(h["step"]) - 1 == 8 and np.all(h["h"][1:] == 5e-4)  # 4 steps, each redone as 2 sub-steps
    assert rc == 3 and s["convergence"]["unconverged_steps"] == n and s["convergence"]["solved_steps"] == 8
    assert s["convergence"]["worst_residual"] == worst and s["convergence"]["worst_step"] == step


def test_converged_run_exits_0_with_a_converged_last_line(tmp_path, capsys):
    case = CASE.replace("max_sweeps = 1", "max_sweeps = 100000")
    (tmp_path / "c.toml").write_text(case.replace("SOLVER", "nlgs").replace("TOL", "1e-8"))
    rc = main(["run", str(tmp_path / "c.toml"), "--out", str(tmp_path / "out"), "--quiet"])
    last = capsys.readouterr().out.strip().splitlines()[-1]
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    h = read_history(tmp_path / "out" / "history.csv")
    assert np.all(h["converged"][1:] == 1)
    assert rc == 0 and s["status"] == "completed" and s["convergence"]["unconverged_steps"] == 0
    assert s["convergence"]["worst_residual"] is None and s["exit_status"] == 0
    assert last == (f"fem-blocks: contact solver: all 4 steps converged (largest residual "
                    f"{h['residual'][1:].max():.3g})")


def test_solver_label_names_the_solver_and_its_fallback():
    """The step info's `solver` (used by the warning, the summary and the last line) is the solver result's own
    `solver`, set where each solver runs: Newton alone, Newton whose line search handed over to Gauss-Seidel,
    Gauss-Seidel alone (also when fallback = "newton" was not needed), Gauss-Seidel then Newton."""
    from fem_blocks.linalg import to_block_csr
    from fem_blocks.solver import ContactProblem, SolverOptions, newton, nlgs, solve
    from test_nlgs import random_problem
    W, q = random_problem()
    B = to_block_csr(W, 2)
    res = newton.solve_newton(B, q, 0.3, tol=1e-12)
    assert res.converged and res.solver == "Newton"
    assert newton._result(res.r, res.u, 5, 20, 0, 0.0, 1.0, 1e-8, q).solver == "Newton"
    assert newton._result(res.r, res.u, 5, 20, 3, 0.0, 1.0, 1e-8, q).solver == "Newton + NLGS fallback"
    assert nlgs.solve_block_csr(B, q, 0.3, tol=1e-10, criterion="residual").solver == "NLGS"
    # fallback = "newton": windows of 200 sweeps that converge alone, or a budget of 1 sweep that hands over to Newton
    fb = dict(criterion="residual", check_every=10, fallback="newton")
    alone = solve(ContactProblem(B, q, 0.3), SolverOptions(tol=1e-10, max_sweeps=100000, **fb))
    assert alone.converged and alone.solver == "NLGS" and "Gauss-Seidel alone" in alone.message
    handed = solve(ContactProblem(B, q, 0.3), SolverOptions(tol=1e-12, max_sweeps=1, **fb))
    assert handed.converged and handed.solver == "NLGS + Newton fallback" and "then Newton" in handed.message


def test_fail_policy_message_names_the_solver(tmp_path, capsys):
    case = CASE.replace("SOLVER", "nlgs").replace("TOL", "1e-10").replace(
        "max_sweeps = 1", "max_sweeps = 1\non_nonconvergence = \"fail\"")
    (tmp_path / "f.toml").write_text(case)
    rc = main(["run", str(tmp_path / "f.toml"), "--out", str(tmp_path / "f"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1 and "contact solver (NLGS) did not converge: not converged after 1 sweeps" in err
    s = json.loads((tmp_path / "f" / "summary.json").read_text())
    assert s["status"].startswith("stopped:") and s["exit_status"] == 1
    assert s["convergence"]["unconverged_steps"] == 1 and s["convergence"]["worst_step"] == 1


# ----------------------------------------------------------------------------- item 11: signed data, units
def _history():
    return {"step": np.array([0.0, 1, 2, 3]), "converged": np.array([1.0, 0, 1, 1]),
            "beam.ux": np.array([0.0, 1e-3, -2e-3, 0.5e-3]), "beam.Rx": np.array([0.0, 5e3, -7e3, 1e3]),
            "beam.urz": np.array([0.0, 0.2, -0.1, 0.05]), "beam.Rrz": np.array([0.0, 1500.0, -300.0, 20.0]),
            "beam.Ry": np.array([0.0, -2e3, -3e3, -1e3])}


def test_curve_data_signed_with_units_per_dof():
    from fem_blocks.output.figures import curve_data
    c = curve_data(_history(), "beam", "Rx", "ux")
    np.testing.assert_allclose(c["x"], [0.0, 1.0, -2.0, 0.5], rtol=1e-15)  # mm, signed
    np.testing.assert_allclose(c["y"], [0.0, 5.0, -7.0, 1.0], rtol=1e-15)  # kN, signed
    assert c["xlabel"] == "beam displacement ux [mm]" and c["ylabel"] == "beam reaction Rx [kN]"
    assert c["unconverged"].tolist() == [False, True, False, False]
    r = curve_data(_history(), "beam", "Rrz", "urz")
    np.testing.assert_allclose(r["x"], [0.0, 0.2, -0.1, 0.05], rtol=1e-15)  # rad, not x 1000
    np.testing.assert_allclose(r["y"], [0.0, 1.5, -0.3, 0.02], rtol=1e-15)  # kN·m
    assert r["xlabel"] == "beam rotation urz [rad]" and r["ylabel"] == "beam moment Rrz [kN·m]"
    h = _history()
    del h["converged"]  # a run without contact has no converged column
    assert not curve_data(h, "beam", "Rx", "ux")["unconverged"].any()
    with pytest.raises(InputError, match="rigid-body dof column"):
        curve_data(dict(h, **{"beam.kinetic": h["beam.ux"]}), "beam", "kinetic", "ux")


def test_plot_curve_marks(tmp_path):
    from fem_blocks.output.plots import plot_curve
    p = plot_curve(tmp_path / "m.png", [0, 1, -2], [0, 5, -7], "u [mm]", "F [kN]", "t", marks=[False, True, False],
                   marks_label="unconverged step (1)", note="1 unconverged step")
    assert p == tmp_path / "m.png" and (tmp_path / "m.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(InputError, match="one flag per point"):
        plot_curve(tmp_path / "bad.png", [0, 1], [0, 1], "u", "F", marks=[True])


def test_summary_keys_of_a_rotation_curve(tmp_path):
    """[output.curve] force = displacement = "rz": the peak is a moment in kN·m at a rotation in rad; the
    translations' reactions stay in kN."""
    from fem_blocks.runner import _figures
    h = _history()
    cols = list(h)
    with HistoryWriter(tmp_path / "history.csv", cols, keep=True) as w:
        for i in range(4):
            w.write({c: h[c][i] for c in cols})
    case = SimpleNamespace(dimension=2, name="rot", output={"crack_pattern": False,
                                                             "curve": dict(body="beam", force="rz", displacement="rz")})
    model = SimpleNamespace(bodies=[])
    conv = dict(unconverged_steps=1, accepted=False, worst_residual=2.5, worst_step=1, worst_time=0.1)
    out = _figures(case, None, model, str(tmp_path), w.columns_dict(), conv)
    assert out["peak_moment_kNm"] == pytest.approx(1.5, rel=1e-15)  # |Rrz| max at row 1
    assert out["rotation_at_peak_rad"] == pytest.approx(0.2, rel=1e-15)
    assert "peak_force_kN" not in out and "displacement_at_peak_mm" not in out
    assert out["other_reactions_at_peak_kN"] == {"beam.Rx": pytest.approx(5.0, rel=1e-15),
                                                 "beam.Ry": pytest.approx(-2.0, rel=1e-15)}
    assert "other_moments_at_peak_kNm" not in out
    assert "initial_stiffness_kNm_per_rad" in out
    assert (tmp_path / "force_displacement.png").exists()

"""Step strategy ([contact] on_nonconvergence = "adaptive", attempt_budget, grow_after, predictor; runner._step,
contact/step.py ContactStep.warm_start).

* the predictor's formulas against forces linear in time (exact for "extrapolated");
* the adaptive schedule: with failures injected at h > h/4 inside a time window, the sub-steps are exactly the
  hand-computed sequence (halvings, doubling after `grow_after` converged sub-steps on the coarser grid, level
  carried over, nominal grid kept), every kept sub-step is a row with its h;
* a thrown-away attempt leaves no trace: a rigid block glued by a softening (Frémond) joint pulled off at a constant
  rate gives, at every row of an adaptive run with thrown-away attempts, the closed-form force of the opening curve
  (test_stop_after_peak.py) — an attempt whose damage stayed committed would give a lower force;
* the budget kill: attempts that can still be halved stop after `attempt_budget` sweeps and are counted
  (summary.json convergence.failed_attempts); the deepest level gets the full max_sweeps and converges.
"""
import json

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.contact.step import ContactStep
from fem_blocks.dynamics import Simulation
from fem_blocks.output.history import read_history
from fem_blocks.runner import run_case
from fem_blocks.specs import ContactOptions

CN, W, L, T = 1e10, 50.0, 0.2, 0.1
UC = np.sqrt(W / CN)
A = L * T
H = 0.01
RATE = 4.5 * UC  # opening per second

COUPLET = f"""
name = "couplet"
gravity = [0.0, 0.0]
[contact]
tol = 1e-12
max_sweeps = 10000
on_nonconvergence = "adaptive"
max_refinements = 2
grow_after = 2
[[rigid_bodies]]
name = "block"
group = "block"
vertices = [[0.0, 0.0], [{L}, 0.0], [{L}, 0.1], [0.0, 0.1]]
thickness = {T}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "displacement", history = {{times = [0.0, 1.0], values = [0.0, {RATE!r}]}}}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[-0.1, -0.1], [0.3, -0.1], [0.3, 0.0], [-0.1, 0.0]]
thickness = {T}
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[interfaces]]
name = "joint"
between = ["block", "base"]
law = "fremond"
mu = 0.5
c_N = {CN!r}
c_T = 5e9
w = {W!r}
placement = "positions"
positions = [0.25, 0.75]
[[stages]]
name = "pull"
duration = 0.1
h = {H}
theta = 1.0
output_every = 100
"""


def _closed_form_force(u):
    """Frémond joint pulled open monotonically (thesis eq. 5.3.47): r_N = A c_N u (u <= u_c), A w² / (c_N u³)."""
    u = np.asarray(u, float)
    return np.where(u <= UC, A * CN * u, A * W ** 2 / (CN * np.maximum(u, 1e-300) ** 3))


def _fail_in_window(monkeypatch, t_a, t_b, h_ok):
    """Steps ending in (t_a, t_b] with h > h_ok report "not converged" (their state is kept by the step; the runner
    decides): the injected difficulty of a hard stretch."""
    orig = Simulation.step

    def step(self):
        info = orig(self)
        if t_a < self.time <= t_b + 1e-12 and self.h > h_ok * (1 + 1e-9):
            info.contact = dict(info.contact, converged=False)
        return info
    monkeypatch.setattr(Simulation, "step", step)


def _run(tmp_path, text):
    p = tmp_path / "c.toml"
    p.write_text(text)
    s = run_case(load_case(str(p)), str(tmp_path / "out"), progress=False)
    return s, read_history(tmp_path / "out" / "history.csv")


def test_warm_start_predictors_are_exact_for_linear_forces():
    """r(t) = a + b t per contact: "extrapolated" gives h3 r(t2 + h3) from P_prev = h1 r(t1), P = h2 r(t2);
    "scaled" gives h3 r(t2); "previous" the last impulses themselves (today's warm start, unchanged)."""
    a, b = np.array([[3.0, -1.0], [0.5, 2.0]]), np.array([[10.0, 4.0], [-2.0, 1.0]])
    t1, h2, h3 = 0.2, 0.01, 0.0025
    t2 = t1 + h2
    cs = ContactStep([], [])
    cs.P_prev, cs.h_prev = 0.02 * (a + b * t1), 0.02
    cs.P, cs.h_last = h2 * (a + b * t2), h2
    cs.opts = ContactOptions(predictor="extrapolated")
    assert np.allclose(cs.warm_start(h3), h3 * (a + b * (t2 + h3)), rtol=1e-13, atol=0)
    cs.opts = ContactOptions(predictor="scaled")
    assert np.allclose(cs.warm_start(h3), h3 * (a + b * t2), rtol=1e-13, atol=0)
    cs.opts = ContactOptions(predictor="previous")
    assert cs.warm_start(h3) is cs.P
    cs.opts, cs.P_prev = ContactOptions(predictor="extrapolated"), None  # e.g. after a re-detection: "scaled"
    assert np.allclose(cs.warm_start(h3), h3 * (a + b * t2), rtol=1e-13, atol=0)


def test_adaptive_schedule_halves_grows_back_and_keeps_the_nominal_grid(tmp_path, monkeypatch):
    """Failures for h > H/4 on (sub-)steps ending in (0.032, 0.05]. By hand (max_refinements = 2, grow_after = 2),
    in units of H/4: steps 1-3 at H; step 4 (0.03-0.04): H fails, H/2 fails, 1, 1, then (2 converged, at a point
    of the H/2 grid) H/2 is tried and fails, 1, 1, and the level drops to 1 at its end; step 5 (0.04-0.05), level
    carried over: H/2 fails, 1, 1, H/2 (ending at 0.05, in the window) fails, 1, 1, level 1 again; step 6: 2, 2
    (2 converged at level 1 on the H grid: level 0); steps 7-10 at H."""
    _fail_in_window(monkeypatch, 0.032, 0.05, H / 4)
    s, h = _run(tmp_path, COUPLET)
    hs = list(np.round(np.asarray(h["h"][1:]) / H * 4).astype(int))  # sub-step sizes in units of H/4
    expected = [4, 4, 4] + [1, 1, 1, 1] + [1, 1, 1, 1] + [2, 2] + [4] * 4
    assert hs == expected
    t = np.asarray(h["time"])
    assert t[-1] == pytest.approx(0.1, abs=1e-15)
    assert np.allclose(np.cumsum(np.asarray(h["h"][1:])), t[1:], rtol=0, atol=1e-14)
    conv = s["convergence"]
    assert conv["nominal_steps"] == 10 and conv["substepped_steps"] == 3 and conv["substepped_share"] == 0.3
    assert conv["unconverged_steps"] == 0 and conv["solved_steps"] == len(expected)
    # thrown away: step 4 at H and twice at H/2; step 5 twice at H/2
    assert conv["failed_attempts"] == 5 == s["contact"]["failed_attempts"]


def test_thrown_away_attempts_leave_the_closed_form_opening_curve(tmp_path, monkeypatch):
    """Every row of the adaptive run (attempts thrown away around the peak, u_c at t = 0.222 s) carries the
    closed-form force of the Frémond joint at its opening; a committed thrown-away attempt (damage β of a larger
    opening) would lower the force after the peak below the curve by up to (u_big/u)^2."""
    _fail_in_window(monkeypatch, 0.2, 0.26, H / 4)
    text = COUPLET.replace("duration = 0.1", "duration = 0.3")
    s, h = _run(tmp_path, text)
    t, F = np.asarray(h["time"][1:]), np.abs(np.asarray(h["block.Ry"][1:]))
    assert s["convergence"]["failed_attempts"] >= 2 and s["convergence"]["unconverged_steps"] == 0
    assert np.any(np.asarray(h["h"][1:]) < H)
    assert np.allclose(F, _closed_form_force(RATE * t), rtol=1e-6, atol=0)
    # the same end state as the uniform fine run (every step at H/4)
    fine = COUPLET.replace("duration = 0.1", "duration = 0.3").replace(f"h = {H}", f"h = {H / 4}")
    monkeypatch.undo()
    _, hf = _run(tmp_path / "fine" if (tmp_path / "fine").mkdir() is None else tmp_path, fine)
    assert F[-1] == pytest.approx(abs(hf["block.Ry"][-1]), rel=1e-9)


PRISM = """
name = "prism"
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
bricks = 3
mesh_size = 0.05
[wall.foundation]
depth = 0.05
[contact]
tol = 1e-10
max_sweeps = 100000
on_nonconvergence = "adaptive"
max_refinements = 2
attempt_budget = 2
[[interfaces]]
name = "bed"
between = ["bricks", "bricks"]
mu = 0.6
[[interfaces]]
name = "base"
between = ["bricks", "foundation"]
mu = 0.6
[[stages]]
name = "gravity"
duration = 0.002
h = 1e-3
theta = 1.0
velocity_reset = true
"""


@pytest.mark.dolfinx
def test_attempt_budget_kills_attempts_and_the_last_level_converges(tmp_path):
    """Gauss–Seidel needs far more than 2 sweeps to 1e-10 on the settling prism: with attempt_budget = 2 the
    attempts at h and h/2 stop after 2 sweeps and are thrown away (counted, their sweeps too), the sub-steps at
    h/4 have the full max_sweeps and converge; rows are the kept sub-steps only."""
    s, h = _run(tmp_path, PRISM)
    conv = s["convergence"]
    hs = np.asarray(h["h"][1:])
    assert conv["unconverged_steps"] == 0 and np.all(np.asarray(h["converged"][1:]) == 1)
    assert conv["failed_attempts"] >= 2 and s["contact"]["failed_sweeps"] <= 2 * conv["failed_attempts"]
    assert hs[0] == pytest.approx(2.5e-4, rel=1e-12) and np.all(np.asarray(h["sweeps"][1:]) > 2)
    assert h["time"][-1] == pytest.approx(0.002, abs=1e-15) and conv["nominal_steps"] == 2
    # without the budget the first attempt converges at h: no attempt thrown away
    s2, h2 = _run(tmp_path / "nb" if (tmp_path / "nb").mkdir() is None else tmp_path,
                  PRISM.replace("attempt_budget = 2", "attempt_budget = 0"))
    assert s2["convergence"]["failed_attempts"] == 0 and np.all(np.asarray(h2["h"][1:]) == 1e-3)


def test_interrupted_adaptive_run_resumes_bitwise(tmp_path, monkeypatch):
    """SIGINT in the middle of a hard stretch (level 1 carried over into nominal step 5), then --resume: the history
    is bitwise that of the uninterrupted run — the adaptive level and count are part of the checkpoint (without
    them the resumed step 5 would start at H). (The predictor's history is checkpointed too, but on this two-contact
    couplet the solver reaches the same bits from any start, so this test does not see it.)"""
    import os
    import signal
    from fem_blocks.runner import RunStopped
    text = COUPLET.replace('grow_after = 2', 'grow_after = 2\npredictor = "extrapolated"')
    _fail_in_window(monkeypatch, 0.032, 0.05, H / 4)
    _, ref = _run(tmp_path, text)
    p = tmp_path / "c.toml"
    out = tmp_path / "out2"
    orig = Simulation.step

    def step(self):  # the interruption arrives during the 2nd sub-step of nominal step 5 (level 1 carried over)
        info = orig(self)
        if abs(self.time - 0.0425) < 1e-9:
            os.kill(os.getpid(), signal.SIGINT)
        return info
    monkeypatch.setattr(Simulation, "step", step)
    with pytest.raises(RunStopped):
        run_case(load_case(str(p)), str(out), progress=False)
    monkeypatch.setattr(Simulation, "step", orig)
    _fail_in_window(monkeypatch, 0.032, 0.05, H / 4)
    run_case(load_case(str(p)), str(out), progress=False, resume=True)
    new = read_history(out / "history.csv")
    assert set(new) == set(ref)
    for col in ref:
        assert np.array_equal(np.asarray(new[col]), np.asarray(ref[col]), equal_nan=True), col

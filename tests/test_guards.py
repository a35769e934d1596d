"""Numerical safety: NaN/Inf, penetration and energy-creation guards stop the run with a message naming the step,
the body or contact and the quantity, after writing the outputs and a checkpoint of the last good step; solver
policies on_nonconvergence = "fail" | "refine"."""
import json

import numpy as np
import pytest

from fem_blocks.case import load_case
from fem_blocks.dynamics import Simulation
from fem_blocks.output.checkpoint import read_checkpoint
from fem_blocks.output.history import read_history
from fem_blocks.runner import RunStopped, run_case

pytestmark = pytest.mark.dolfinx
from test_run_contact import CASE  # noqa: E402  (3-brick prism on a foundation, gravity to equilibrium)


def _case(tmp_path, text):
    p = tmp_path / "c.toml"
    p.write_text(text)
    return load_case(str(p))


def _inject(monkeypatch, at_step, action):
    orig = Simulation.step

    def step(self):
        info = orig(self)
        if self.step_count == at_step:
            action(self)
            info = self.info(info.contact)
        return info
    monkeypatch.setattr(Simulation, "step", step)


def _check_stopped_outputs(out, failed_step):
    h = read_history(out / "history.csv")
    assert int(h["step"][-1]) == failed_step  # the failing step's row is kept (to see what went wrong)
    ck = read_checkpoint(out / "checkpoint.npz")
    assert int(ck["sim.step"]) == failed_step - 1  # the checkpoint is the last good state
    s = json.loads((out / "summary.json").read_text())
    assert s["status"].startswith("stopped:")


def _poison_impulse(sim):
    sim.last_contact.P[2, 0] = np.nan  # the step's record, which the checks read


@pytest.mark.parametrize("step, action, what", [
    (5, lambda sim: sim.bodies[1].u.__setitem__(0, np.nan), "velocity of body 'brick1'"),
    (4, lambda sim: sim.bodies[2].q.__setitem__(3, np.inf), "displacement of body 'brick2'"),
    (3, _poison_impulse, "contact impulse at contact 2"),
], ids=["velocity", "displacement", "contact_impulse"])
def test_nan_stops_with_the_quantity_and_step(tmp_path, monkeypatch, step, action, what):
    """NaN/Inf in a velocity, a displacement or a contact impulse stops the run naming the step and where."""
    case = _case(tmp_path, CASE)
    _inject(monkeypatch, step, action)
    with pytest.raises(RunStopped) as e:
        run_case(case, str(tmp_path / "out"), progress=False)
    msg = str(e.value)
    assert f"step {step}" in msg and what in msg and "NaN/Inf" in msg and "--resume" in msg
    _check_stopped_outputs(tmp_path / "out", step)


def test_energy_created_from_nothing_stops_the_run(tmp_path, monkeypatch):
    case = _case(tmp_path, CASE)

    def kick(sim):  # 1 m/s on every node of one brick: kinetic energy far above the gravity work put in
        sim.bodies[0].u[:] = 1.0
    _inject(monkeypatch, 3, kick)
    with pytest.raises(RunStopped) as e:
        run_case(case, str(tmp_path / "out"), progress=False)
    assert "step 3" in str(e.value) and "energy grew" in str(e.value)
    _check_stopped_outputs(tmp_path / "out", 3)


def test_energy_balance_holds_on_a_converged_run(tmp_path):
    """The same case without injection: E - E_0 - W <= 0 (no energy created), so the guard stays silent."""
    s = run_case(_case(tmp_path, CASE), str(tmp_path / "out"), progress=False)
    assert s["status"] == "completed" and s["energy_created_ratio_max"] <= 1e-6


def test_penetration_beyond_the_limit_names_the_contact(tmp_path):
    text = CASE.replace("tol = 1e-10\nmax_sweeps = 100000", "tol = 1e-12\nmax_sweeps = 1") \
        .replace("[[stages]]", "[checks]\nmax_penetration = 1e-9\n\n[[stages]]")
    with pytest.raises(RunStopped) as e:
        run_case(_case(tmp_path, text), str(tmp_path / "out"), progress=False)
    msg = str(e.value)
    assert "penetration" in msg and "exceeds 1e-09 m" in msg and "bodies" in msg


def test_nonconvergence_policy_fail(tmp_path):
    text = CASE.replace("tol = 1e-10\nmax_sweeps = 100000", 'tol = 1e-12\nmax_sweeps = 2\non_nonconvergence = "fail"')
    with pytest.raises(RunStopped) as e:
        run_case(_case(tmp_path, text), str(tmp_path / "out"), progress=False)
    assert "step 1 " in str(e.value) and "(NLGS) did not converge: not converged after 2 sweeps" in str(e.value)
    _check_stopped_outputs(tmp_path / "out", 1)


def test_nonconvergence_policy_refine_halves_the_step(tmp_path):
    """A step that does not converge is redone with 2, then 4 sub-steps; rows carry their h; the nominal time grid
    is kept; the stage's steps stay the nominal ones."""
    text = CASE.replace("tol = 1e-10\nmax_sweeps = 100000",
                        'tol = 1e-12\nmax_sweeps = 3\non_nonconvergence = "refine"\nmax_refinements = 2') \
        .replace("duration = 1.0", "duration = 0.004")
    s = run_case(_case(tmp_path, text), str(tmp_path / "out"), progress=False)
    h = read_history(tmp_path / "out" / "history.csv")
    hs = h["h"][1:]
    assert np.all(hs == 2.5e-4)  # never converges in 3 sweeps: every step refined to the limit, 4 sub-steps
    assert len(hs) == 16 and s["contact"]["refined_steps"] == 4
    assert h["time"][-1] == pytest.approx(0.004, abs=1e-15)
    assert np.allclose(h["time"][4::4], [0.001, 0.002, 0.003, 0.004], rtol=0, atol=1e-15)
    # each sub-step row carries the state at the end of its sub-step, not the end of the nominal step
    ry = h["foundation.Ry"][1:].reshape(4, 4)
    assert np.all(np.abs(np.diff(ry, axis=1)).max(axis=1) > 1e-3)


def test_a_nan_velocity_is_the_largest_velocity(tmp_path):
    """Simulation.max_velocity (the history's largest velocity) is NaN when a node of a body has a NaN velocity,
    whatever the other bodies: a NaN must show in the history, not be dropped by a maximum (Python's max(v, nan) is
    v). Expectation: NaN in the column of one brick of a 2-course wall, the other bricks finite. Catches the maximum
    taken with Python's max (the NaN lost)."""
    import math
    import dist_cases
    from _case_steps import stepping
    path = tmp_path / "w.toml"
    path.write_text(dist_cases.wall("w", courses=2, per=3))
    _, _, sim, _ = stepping(str(path), None)
    sim.step()
    assert math.isfinite(sim.max_velocity()) and sim.max_velocity() > 0
    gr = next(g for g in sim.groups if g.U.shape[1] > 1)
    gr.U[:, -1] = np.nan  # the last member of a group: finite bodies before it
    assert math.isnan(sim.max_velocity())


def _watch_record(gap, cand, ant, ids):
    """A stand-in step record of a rank on N ranks: its contact set (one interface, g0 = 0), every row its own,
    their contact ids (the record's gather's)."""
    from types import SimpleNamespace
    n = len(gap)
    cs = SimpleNamespace(gap=np.array(gap, dtype=float), g0=np.zeros(n), interface=np.zeros(n, dtype=np.int64),
                         cand_body=np.array(cand, dtype=np.int64), ant_body=np.array(ant, dtype=np.int64))
    return SimpleNamespace(cs=cs, law=np.zeros(n, dtype=np.int64), rows=np.arange(n),
                           gather=SimpleNamespace(ids=np.array(ids, dtype=np.int64)))


@pytest.mark.parametrize("mine, theirs, first", [
    (([], [], [], []), ([-8e-4], [2], [3], [7]), ("c", "d", 8e-4)),            # nothing here: the other rank's
    (([0.0, -5e-4], [0, 0], [1, 2], [3, 4]), ([-8e-4], [2], [3], [7]), ("c", "d", 8e-4)),  # the deeper
    (([0.0, -8e-4], [0, 1], [1, 2], [3, 4]), ([-8e-4], [2], [3], [7]), ("b", "c", 8e-4)),  # a tie: the smaller id
    (([0.0, -8e-4], [0, 1], [1, 2], [3, 9]), ([-8e-4], [2], [3], [7]), ("c", "d", 8e-4)),
])
def test_the_missed_contact_watch_agrees_across_ranks(mine, theirs, first):
    """runner._MissedContactWatch on N > 1 ranks reads the contacts of its record's rows (a rank's own) and agrees
    with the other ranks on the deepest missed contact (p0 / alert largest, the smallest contact id among equals, as
    one process's argmax over the whole set), every rank recording the same. A fake communicator of 2 ranks gives the
    other rank's finding, computed by the same watch on its record. Catches each rank keeping its own finding (the
    rank without one silent: what rank 0 writes in summary.json depends on the partition), the first rank's finding
    taken, ties broken by rank rather than id."""
    from types import SimpleNamespace
    from fem_blocks.runner import _MissedContactWatch
    names = ["a", "b", "c", "d", "e"]
    step = SimpleNamespace(opts=SimpleNamespace(geometry="updated"),
                           interfaces=[SimpleNamespace(name="hit", alert=1e-3)],
                           law_codes=lambda cs: np.zeros(len(cs.gap), dtype=np.int64))
    model = SimpleNamespace(contact=step)
    other = _MissedContactWatch(model, names)._deepest(_watch_record(*theirs))

    class Comm:
        def allgather(self, x):
            return [other, x]  # (the other rank is rank 0: its finding comes first)
    watch = _MissedContactWatch(model, names, comm=Comm())
    sim = SimpleNamespace(last_contact=_watch_record(*mine), step_count=5, time=0.004)
    assert watch.check(sim) is not None
    f = watch.state["first"]
    assert (f["bodies"][0], f["bodies"][1], f["depth"]) == first and f["interface"] == "hit" and f["step"] == 5

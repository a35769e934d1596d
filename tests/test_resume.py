"""Checkpoint and resume: a run killed (SIGKILL, SIGINT) and resumed gives bitwise the same history, final state and
ParaView frames as an uninterrupted run; a truncated newest checkpoint falls back to the previous one; a changed case
file is refused unless --force; two runs of the same case are bitwise identical (determinism)."""
import json
import os
import random
import signal
import subprocess
import sys
import time

import meshio
import numpy as np
import pytest

from fem_blocks.output.checkpoint import read_checkpoint

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402

# two courses of a running-bond wall between a foundation and a beam, Frémond–Cangémi joints, shuffled NLGS order:
# pre-compression (h = 2e-3), then a horizontal push with another time step (h = 1e-3): every piece of state
# (law internal variables, warm start, RNG seed, stage drivers, step operators for two h) must survive a restart.
CASE = """
name = "resume"
[materials.brick]
E = 16.7e9
nu = 0.15
rho = 2500.0
thickness = 0.1
[wall]
type = "courses"
material = "brick"
brick_length = 0.21
brick_height = 0.052
joint = 0.01
expanded = true
rows = [[1, 1, 0.5], [0.5, 1, 1]]
mesh_size = 0.06
cell = "quad"
group = "bricks"
[wall.foundation]
depth = 0.1
[wall.beam]
depth = 0.1
rho = 7800.0
[wall.beam.drivers]
x = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[wall.beam.forces]
y = {times = [0.0, 0.05], values = [0.0, -10000.0]}
[contact]
tol = 1e-6
max_sweeps = 400
order = "shuffled"
seed = 3
[[interfaces]]
name = "joints"
between = ["bricks", "bricks"]
law = "fremond"
c_N = 0.5e10
c_T = 0.3e10
w = 18.0
mu = 0.75
[[interfaces]]
name = "foundation"
between = ["bricks", "foundation"]
mu = 0.75
[[interfaces]]
name = "beam"
between = ["bricks", "beam"]
mu = 0.75
[checks]
max_energy_growth = 1e6
[output]
checkpoint_every = 7
stress = false
[[stages]]
name = "precompression"
duration = 0.06
h = 2e-3
theta = 1.0
velocity_reset = true
output_every = 10
[[stages]]
name = "push"
duration = 0.2
h = 1e-3
theta = 1.0
velocity_reset = true
output_every = 25
[stages.drivers.beam]
y = {kind = "velocity", history = 0.0}
x = {kind = "displacement", history = {times = [0.06, 0.26], values = [0.0, 0.0006]}}
"""


# the case stops NLGS at max_sweeps = 400 (a short run): it completes with unconverged steps, exit status 3
UNCONVERGED = 3


def _run(case, out, *extra, wait=True):
    cmd = [sys.executable, "-m", "fem_blocks.cli", "run", str(case), "--out", str(out), "--quiet", *extra]
    if wait:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


def _resume(cli, case, out, *extra):
    """`fem-blocks run CASE --out OUT --quiet --resume ...` in this process (conftest.cli: cli.main), after a run
    killed in another process: nothing of that run is in this process, so the resumed run has only the checkpoint
    and the files. The uninterrupted runs (the reference, the determinism run) and the killed runs stay separate
    processes."""
    return cli("run", case, "--out", out, "--quiet", "--resume", *extra)


def _wait_for_checkpoint_step(proc, out, step, timeout=300):
    """Poll until the newest checkpoint holds at least `step` steps (or the run ended); returns its step."""
    t0 = time.monotonic()
    path = out / "checkpoint.npz"
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            return None
        if path.exists():
            try:
                s = int(read_checkpoint(path)["sim.step"])
            except Exception:  # noqa: BLE001 - replaced while reading
                s = -1
            if s >= step:
                return s
        time.sleep(0.005)
    return None


def _kill_between_checkpoint_writes(proc, ck, prev):
    """SIGKILL the run at an instant where checkpoint.npz and checkpoint.prev.npz are two different files. Inside
    a checkpoint write both names are, for two system calls, hard links to one file (the newest becomes .prev, then
    the new one is renamed over checkpoint.npz: output/checkpoint.py); a kill there leaves two names of one
    complete checkpoint, which is not the state this test needs (an in-place truncation of one would cut both). The
    run is frozen (SIGSTOP), the two names are compared, and it runs on for a moment until they differ."""
    for _ in range(2000):
        proc.send_signal(signal.SIGSTOP)
        if ck.exists() and prev.exists() and not os.path.samefile(ck, prev):
            break
        proc.send_signal(signal.SIGCONT)
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not os.path.samefile(ck, prev)


def _final(out):
    with open(out / "history.csv") as f:
        hist = f.read()
    ck = read_checkpoint(out / "checkpoint.npz")
    state = {k: v for k, v in ck.items() if k.startswith(("sim.", "contact."))}
    frames = sorted(f for f in os.listdir(out / "paraview") if f.startswith("blocks_"))
    last = meshio.read(out / "paraview" / frames[-1])
    cframes = sorted(f for f in os.listdir(out / "paraview") if f.startswith("contacts_"))
    lastc = meshio.read(out / "paraview" / cframes[-1])
    with open(out / "summary.json") as f:
        conv = json.load(f)["convergence"]  # counted over the whole run, across the resume (checkpointed)
    return hist, state, last, lastc, conv


def _assert_identical(a, b):
    ha, sa, la, ca, va = a
    hb, sb, lb, cb, vb = b
    assert ha == hb  # every history row, %.17g: bitwise
    assert va == vb and va["unconverged_steps"] > 0
    assert sorted(sa) == sorted(sb)
    for k in sa:
        assert np.array_equal(sa[k], sb[k]), k
    assert np.array_equal(la.point_data["displacement"], lb.point_data["displacement"])
    for f in ("damage", "r_N", "r_T", "opening"):
        assert np.array_equal(ca.point_data[f], cb.point_data[f]), f


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    d = tmp_path_factory.mktemp("resume")
    case = d / "case.toml"
    case.write_text(CASE)
    out = d / "ref"
    p = _run(case, out)
    assert p.returncode == UNCONVERGED, p.stderr
    return case, out, _final(out)


def test_two_runs_are_bitwise_identical(reference, tmp_path):
    case, _, ref = reference
    out = tmp_path / "again"
    p = _run(case, out)
    assert p.returncode == UNCONVERGED, p.stderr
    _assert_identical(_final(out), ref)


def test_sigkill_at_a_random_step_then_resume_is_bitwise_identical(reference, tmp_path, cli):
    case, _, ref = reference
    n_steps = 30 + 200
    target = random.Random(12345).randrange(10, n_steps - 20)
    out = tmp_path / "killed"
    proc = _run(case, out, wait=False)
    s = _wait_for_checkpoint_step(proc, out, target)
    assert s is not None, "the run ended before the kill"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    # the kill left a history with rows past the checkpoint (or a torn last line): resume must cut them
    p = _resume(cli, case, out)
    assert p.returncode == UNCONVERGED, p.stderr
    _assert_identical(_final(out), ref)


def test_truncated_checkpoint_falls_back_to_the_previous_one(reference, tmp_path, cli):
    case, _, ref = reference
    out = tmp_path / "trunc"
    proc = _run(case, out, wait=False)
    s = _wait_for_checkpoint_step(proc, out, 60)
    assert s is not None
    ck, prev = out / "checkpoint.npz", out / "checkpoint.prev.npz"
    _kill_between_checkpoint_writes(proc, ck, prev)
    newest = int(read_checkpoint(ck)["sim.step"])  # the run may have written another one before the kill
    data = ck.read_bytes()
    ck.write_bytes(data[: len(data) // 2])  # as if cut mid-write by a full disk
    prev_step = int(read_checkpoint(out / "checkpoint.prev.npz")["sim.step"])
    assert prev_step < newest
    p = _resume(cli, case, out)
    assert p.returncode == UNCONVERGED, p.stderr
    assert "checkpoint.npz" in p.stderr and "previous checkpoint" in p.stderr  # the fallback is reported
    _assert_identical(_final(out), ref)


def test_sigint_writes_a_checkpoint_and_says_how_to_resume(reference, tmp_path, cli):
    case, _, ref = reference
    out = tmp_path / "int"
    proc = _run(case, out, wait=False)
    s = _wait_for_checkpoint_step(proc, out, 40)
    assert s is not None
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert "--resume" in err and "Traceback" not in err
    ck = read_checkpoint(out / "checkpoint.npz")
    assert int(ck["sim.step"]) > s  # the step in progress was finished and checkpointed
    p = _resume(cli, case, out)
    assert p.returncode == UNCONVERGED, p.stderr
    _assert_identical(_final(out), ref)  # (the interruption added one frame at the checkpoint time; the last agree)


def test_resume_refuses_a_changed_case_unless_forced(reference, tmp_path, cli):
    case, ref_out, _ = reference
    out = tmp_path / "changed"
    proc = _run(case, out, wait=False)
    assert _wait_for_checkpoint_step(proc, out, 20) is not None
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    changed = tmp_path / "case.toml"
    changed.write_text(CASE.replace("tol = 1e-6", "tol = 1e-7"))
    p = _resume(cli, changed, out)
    assert p.returncode == 2 and "changed since this checkpoint" in p.stderr and "--force" in p.stderr
    p = _resume(cli, changed, out, "--force")
    assert p.returncode == UNCONVERGED, p.stderr
    p = _resume(cli, case, tmp_path / "empty")
    assert p.returncode == 2 and "cannot resume" in p.stderr


def test_checkpoint_npz_never_missing_while_a_new_one_is_written(tmp_path, monkeypatch):
    """While a checkpoint is written, `checkpoint.npz` always names a complete checkpoint: at the final rename the
    old newest is already `.prev` (hard link) and still `checkpoint.npz`; afterwards newest = new, prev = old.
    (A kill between the old rename-first steps left only `.prev`: test_truncated_checkpoint_... read a missing file.)"""
    import numpy as np
    from fem_blocks.output import atomic
    from fem_blocks.output.checkpoint import NAME, PREV, write_checkpoint
    write_checkpoint(str(tmp_path), {"sim.step": np.int64(1)})
    seen = []
    real_replace = atomic.os.replace

    def replace(src, dst):
        if os.path.basename(dst) == NAME:  # the new checkpoint is about to replace the newest
            seen.append((int(read_checkpoint(tmp_path / NAME)["sim.step"]),
                         int(read_checkpoint(tmp_path / PREV)["sim.step"])))
        return real_replace(src, dst)
    monkeypatch.setattr(atomic.os, "replace", replace)
    write_checkpoint(str(tmp_path), {"sim.step": np.int64(2)})
    assert seen == [(1, 1)]
    assert int(read_checkpoint(tmp_path / NAME)["sim.step"]) == 2
    assert int(read_checkpoint(tmp_path / PREV)["sim.step"]) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([NAME, PREV])  # no temporary or link file left

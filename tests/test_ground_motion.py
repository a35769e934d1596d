"""Ground motion and driven rotations of rigid bodies (docs/case-files.md "Ground acceleration", "Rotation about a
pivot", "Histories from CSV files"), against closed forms computed here by hand:

* a constant acceleration a integrated by the θ-rule: v = a t exactly at the step ends; θ = 1/2: q = a t²/2; θ = 1:
  q_n = Σ h v_k = a h² n (n + 1)/2 = a t²/2 + a h t/2;
* the linear baseline correction: its (c0, c1) from the closed-form 2x2 system of uniform sampling; a one-sine pulse
  corrected ends at rest at zero displacement (h = Δt, θ = 1/2) and, with h = Δt/2, at the trapezoid rule's
  closed-form residual (h² - Δt²)/12 (a_c(T) - a_c(0));
* a table turned by 30° about a hinge: the hinge's material point stays where it was (1e-12 m), the angle follows
  its history at every step end (2D and 3D);
* a block resting on an accelerated base without slipping: the base's driver reaction is m a;
* a history from a CSV file equals the inline one, units converted; the file's content is in the case hash.
"""
import copy
import math

import numpy as np
import pytest

from fem_blocks.bodies import Driver, History, RigidBody, RigidBody3D
from fem_blocks.records import baseline_linear, record_velocity
from fem_blocks.case import fingerprint, load_case, parse_case
from fem_blocks.dynamics import Simulation
from fem_blocks.errors import InputError
from fem_blocks.geometry import rotation3d
from fem_blocks.model import build_model


def _base(drivers, **kw):
    return RigidBody([[0, -0.1], [1, -0.1], [1, 0], [0, 0]], drivers=drivers, name="base", **kw)


def _run(sim, n):
    out = []
    for _ in range(n):
        sim.step()
        b = sim.bodies[0]
        out.append((sim.time, b.u.copy(), b.q.copy()))
    return out


@pytest.mark.parametrize("theta", [0.5, 1.0])
def test_constant_acceleration_record(theta):
    a, h, n = 2.5, 0.01, 100
    for hist in (a, {"times": [0.0, 2.0], "values": [a, a]}):
        base = _base({"x": ("acceleration", hist), "y": ("velocity", 0.0), "rz": ("velocity", 0.0)})
        sim = Simulation([base], h=h, theta=theta, gravity=(0.0, 0.0))
        for k, (t, u, q) in enumerate(_run(sim, n), 1):
            assert u[0] == pytest.approx(a * k * h, rel=1e-13, abs=0)
            q_exact = 0.5 * a * (k * h) ** 2 if theta == 0.5 else a * h * h * k * (k + 1) / 2
            assert q[0] == pytest.approx(q_exact, rel=1e-12, abs=0)
        if theta == 1.0:  # the θ = 1 error a h t / 2 by hand
            assert q[0] - 0.5 * a * (n * h) ** 2 == pytest.approx(0.5 * a * h * n * h, rel=1e-10)


def test_record_velocity_is_the_exact_integral_and_zero_outside():
    rec = History([1.0, 2.0, 4.0], [0.0, 2.0, -1.0])
    # by hand: ∫_1^1.5 2(s-1) ds = 0.25; up to 2: 1; up to 3: 1 + ∫_2^3 (2 - 1.5(s-2)) ds = 1 + 2 - 0.75 = 2.25
    assert record_velocity(rec.times, rec.values, 0.5) == 0.0
    assert record_velocity(rec.times, rec.values, 1.5) == pytest.approx(0.25, abs=1e-15)
    assert record_velocity(rec.times, rec.values, 3.0) == pytest.approx(2.25, abs=1e-15)
    assert record_velocity(rec.times, rec.values, 9.0) == pytest.approx(2.0, abs=1e-15)  # 1 + (2 - 1)/2 x 2
    assert Driver("acceleration", rec).step_velocity(2.5, 3.0) == pytest.approx(2.25, abs=1e-15)


def _sine(A=1.5, T=0.8, N=200):
    t = np.linspace(0.0, T, N + 1)
    return t, A * np.sin(2 * np.pi * t / T)


def test_linear_baseline_closed_form_coefficients():
    t, a = _sine()
    T, dt = t[-1], t[1] - t[0]
    # the raw record's final velocity and displacement, trapezoid twice by a loop (not records.record_velocity_knots)
    v = d = 0.0
    for k in range(len(t) - 1):
        v1 = v + dt * (a[k] + a[k + 1]) / 2
        d += dt * (v + v1) / 2
        v = v1
    Mx = np.array([[T, T ** 2 / 2], [T ** 2 / 2, T ** 3 / 6 + dt ** 2 * T / 12]])
    c0, c1 = np.linalg.solve(Mx, [v, d])
    ac, g0, g1 = baseline_linear(t, a)
    assert g0 == pytest.approx(c0, rel=1e-9) and g1 == pytest.approx(c1, rel=1e-9)
    assert np.allclose(ac, a - (c0 + c1 * t), rtol=0, atol=1e-12)


def _case_base_pulse(hist_extra, h, duration):
    t, a = _sine()
    return {
        "gravity": [0.0, 0.0],
        "rigid_bodies": [{"name": "base", "vertices": [[0, -0.1], [1, -0.1], [1, 0], [0, 0]],
                          "drivers": {"x": dict({"kind": "acceleration",
                                                 "history": {"times": t.tolist(), "values": a.tolist()}},
                                                **hist_extra),
                                      "y": {"kind": "velocity", "history": 0.0},
                                      "rz": {"kind": "velocity", "history": 0.0}}}],
        "stages": [{"name": "pulse", "duration": duration, "h": h, "theta": 0.5}],
    }


def _run_case(data):
    case = parse_case(data, "pulse.toml")
    model = build_model(case)
    st = case.stages[0]
    sim = Simulation(model.bodies, h=st.h, theta=st.theta, gravity=model.gravity)
    n = int(round(st.duration / st.h))
    for _ in range(n):
        sim.step()
    return case, model.bodies[0]


def test_sine_pulse_with_linear_baseline_ends_at_rest_at_zero_displacement():
    t, a = _sine()
    dt, T = t[1] - t[0], t[-1]
    _, b = _run_case(_case_base_pulse({"baseline": "linear"}, dt, T))
    assert abs(b.u[0]) < 1e-12 and abs(b.q[0]) < 1e-12
    # uncorrected: it drifts (final displacement ≈ A T² / (2π) for the sampled sine)
    _, raw = _run_case(_case_base_pulse({}, dt, T))
    assert raw.q[0] == pytest.approx(1.5 * T ** 2 / (2 * np.pi), rel=1e-3)
    # half the sampling interval: the trapezoid rule's residual (h² - Δt²)/12 (a_c(T) - a_c(0)) in closed form
    case, half = _run_case(_case_base_pulse({"baseline": "linear"}, dt / 2, T))
    ac = case.rigid_bodies[0].drivers["x"][1]["values"]
    assert abs(half.u[0]) < 1e-12
    assert half.q[0] == pytest.approx(((dt / 2) ** 2 - dt ** 2) / 12 * (ac[-1] - ac[0]), rel=1e-8, abs=1e-15)


@pytest.mark.parametrize("kind", ["displacement", "velocity"])
def test_table_turns_about_its_hinge_2d(kind):
    p = np.array([1.0, 0.0])  # right top corner of the table
    alpha, dur, h = math.radians(30.0), 1.0, 0.01
    hist = {"times": [0.0, dur], "values": [0.0, alpha]} if kind == "displacement" else alpha / dur
    base = _base({"rz": Driver(kind, hist, name="rz", pivot=p)})
    assert base.driven.all() and base.mass[0] == 0.0  # massless: the pivot drives x and y
    c0, rp = base.center0.copy(), p - base.center0
    sim = Simulation([base], h=h, theta=0.5, gravity=(0.0, 0.0))
    for k, (t, u, q) in enumerate(_run(sim, int(round(dur / h))), 1):
        # displacement: the angle history at the step end; velocity: ω(t_k) at the step end and the θ-rule angle
        # h Σ (ω_{j-1} + ω_j)/2 from rest (ω_0 = 0): ω h (k - 1/2)
        phi = alpha * k * h / dur if kind == "displacement" else alpha / dur * h * (k - 0.5)
        assert q[2] == pytest.approx(phi, rel=1e-13, abs=1e-15)
        if kind == "velocity":
            assert u[2] == alpha / dur
        c = c0 + q[:2]
        R = np.array([[np.cos(q[2]), -np.sin(q[2])], [np.sin(q[2]), np.cos(q[2])]])
        assert np.abs(c + R @ rp - p).max() < 1e-12
        # the translation velocity is ω × (c - p) at the step end
        w = u[2]
        assert np.allclose(u[:2], w * np.array([-(c - p)[1], (c - p)[0]]), rtol=0, atol=1e-12)
    assert q[2] == pytest.approx(alpha if kind == "displacement" else alpha - alpha / dur * h / 2, rel=1e-13)


def test_table_turns_about_its_hinge_3d():
    p = np.array([1.0, 0.0, 0.2])  # a point of the table's edge y = 0.. top z = 0.2
    alpha, dur, h = math.radians(30.0), 1.0, 0.01
    drv = {"ry": Driver("displacement", {"times": [0.0, dur], "values": [0.0, -alpha]}, name="ry", pivot=p),
           "rx": Driver("velocity", 0.0, name="rx"), "rz": Driver("velocity", 0.0, name="rz")}
    base = RigidBody3D.box(1.0, 1.0, 0.2, drivers=drv, name="table")
    c0, rp = base.center0.copy(), p - base.center0
    sim = Simulation([base], h=h, theta=0.5, gravity=(0.0, 0.0, 0.0))
    for k in range(1, int(round(dur / h)) + 1):
        sim.step()
        assert base.q[4] == pytest.approx(-alpha * k * h / dur, rel=1e-13, abs=1e-15)
        assert np.abs(base.center + base.orientation @ rp - p).max() < 1e-12
    assert np.allclose(base.orientation, rotation3d([0.0, -alpha, 0.0]), rtol=0, atol=1e-12)


def test_pivot_rules():
    p = [0.0, 0.0]
    with pytest.raises(InputError, match="pivot.*own driver"):
        _base({"rz": Driver("velocity", 1.0, pivot=p), "x": Driver("velocity", 0.0)})
    with pytest.raises(InputError, match="rotation dof"):
        _base({"x": Driver("velocity", 1.0, pivot=p), "y": ("velocity", 0.0), "rz": ("velocity", 0.0)})
    with pytest.raises(InputError, match="every rotation dof"):
        RigidBody3D.box(1, 1, 1, rho=1000.0, drivers={"rz": Driver("velocity", 1.0, pivot=[0, 0, 0])})
    b = _base({"x": ("velocity", 0.0), "y": ("velocity", 0.0), "rz": ("velocity", 0.0)}, rho=1000.0)
    b.set_driver("rz", Driver("velocity", 1.0, pivot=p))  # a stage: the pivot takes x and y over
    assert b.driven.all() and set(b.drivers) == {2}
    b.set_driver("rz", None)
    assert not b.driven.any()


def test_block_on_accelerated_base_reaction_is_m_a():
    a, m = 1.2, 50.0
    data = {
        "gravity": [0.0, -9.81],
        "rigid_bodies": [
            {"name": "base", "vertices": [[-1, -0.2], [1, -0.2], [1, 0], [-1, 0]], "group": "base",
             "drivers": {"x": {"kind": "acceleration", "history": a}, "y": {"kind": "velocity", "history": 0.0},
                         "rz": {"kind": "velocity", "history": 0.0}}},
            {"name": "block", "vertices": [[-0.2, 0], [0.2, 0], [0.2, 0.3], [-0.2, 0.3]], "mass": m,
             "group": "block"}],
        "interfaces": [{"name": "bed", "between": ["base", "block"], "mu": 100.0}],
        "contact": {"tol": 1e-14, "max_sweeps": 10000},
        "stages": [{"name": "s", "duration": 0.05, "h": 1e-3, "theta": 0.5}],
    }
    case = parse_case(data, "accel.toml")
    model = build_model(case)
    sim = Simulation(model.bodies, h=1e-3, theta=0.5, gravity=model.gravity, contact=model.contact)
    base, block = model.bodies
    for k in range(1, 51):
        sim.step()
        assert block.u[0] == pytest.approx(base.u[0], rel=1e-9)  # no slip
        # the force of the driver on the base = the force of the base on the block = m a (x), m g (y)
        assert base.reaction[0] == pytest.approx(m * a, rel=1e-9)


CSV = """# a record: time [ms], acceleration [g]
t_ms, acc_g
0, 0
100, 0.5
200, -0.25
300, 0
"""


def test_history_from_csv_file(tmp_path):
    (tmp_path / "rec.csv").write_text(CSV)
    path = tmp_path / "rec.toml"
    path.write_text("""
gravity = [0.0, 0.0]
[[rigid_bodies]]
name = "base"
vertices = [[0, -0.1], [1, -0.1], [1, 0], [0, 0]]
[rigid_bodies.drivers]
x = {kind = "acceleration", history = {file = "rec.csv", time = "t_ms", value = 1, time_unit = "ms", value_unit = "g", scale = 2.0}}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[stages]]
duration = 0.3
h = 0.01
""")
    case = load_case(str(path))
    h = case.rigid_bodies[0].drivers["x"][1]
    assert h["times"] == pytest.approx([0.0, 0.1, 0.2, 0.3], rel=1e-15)
    assert h["values"] == pytest.approx([0.0, 2 * 0.5 * 9.80665, -2 * 0.25 * 9.80665, 0.0], rel=1e-15)
    fp = fingerprint(case)
    (tmp_path / "rec.csv").write_text(CSV.replace("-0.25", "-0.26"))
    assert fingerprint(load_case(str(path))) != fp  # the CSV content is part of the case hash


def test_rocking_demo_reads_its_pulse():
    """demos/rocking_block.toml: listed, its base driven by the Ricker record of demos/data (baseline-corrected: the
    base ends at rest where it started), whose peak exceeds the uplift threshold g b/h of the 0.25 x 1.0 m block."""
    import os
    from fem_blocks.records import record_velocity_knots
    from fem_blocks.cli import list_demos
    path = list_demos()["rocking_block"]
    case = load_case(path)
    kind, rec = case.stages[1].drivers["base"]["x"]
    assert kind == "acceleration" and os.path.basename(rec["file"]) == "ricker_pulse.csv"
    T, a = np.asarray(rec["times"]), np.asarray(rec["values"])
    v = record_velocity_knots(T, a)
    d = np.sum(np.diff(T) * 0.5 * (v[:-1] + v[1:]))
    assert abs(v[-1]) < 1e-12 and abs(d) < 1e-12
    bt = case.block_types["slender"]
    assert a.max() > 9.81 * bt.lx / bt.ly * 1.5
    assert case.contact.geometry == "updated"


def test_stage_sets_a_pivot_on_a_fixed_table(tmp_path):
    """Through the runner: a massless table fixed by its [[rigid_bodies]] drivers; the second stage turns it by 30°
    about its right top corner (the pivot takes x and y over). history.csv: the corner stays put (1e-12 m)."""
    from fem_blocks.cli import main
    from fem_blocks.output.history import read_history
    path = tmp_path / "tilt.toml"
    path.write_text("""
gravity = [0.0, -9.81]
[[rigid_bodies]]
name = "table"
vertices = [[0, -0.1], [1, -0.1], [1, 0], [0, 0]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[[stages]]
name = "rest"
duration = 0.1
h = 0.01
[[stages]]
name = "tilt"
duration = 1.0
h = 0.01
[stages.drivers.table]
rz = {kind = "displacement", history = {times = [0.1, 1.1], values = [0.0, 0.5235987755982988]}, pivot = [1.0, 0.0]}
""")
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    h = read_history(str(tmp_path / "out" / "history.csv"))
    phi, ux, uy = (np.asarray(h[k], dtype=float) for k in ("table.urz", "table.ux", "table.uy"))
    c0, p = np.array([0.5, -0.05]), np.array([1.0, 0.0])
    for f, x, y in zip(phi, ux, uy):
        R = np.array([[np.cos(f), -np.sin(f)], [np.sin(f), np.cos(f)]])
        assert np.abs(c0 + [x, y] + R @ (p - c0) - p).max() < 1e-12
    assert phi[-1] == pytest.approx(math.radians(30.0), rel=1e-13)


def test_pivot_in_a_3d_case_and_check_report():
    base = {
        "dimension": 3, "gravity": [0.0, 0.0, -9.81],
        "rigid_bodies": [{"name": "table", "size": [1.0, 1.0, 0.1],
                          "drivers": {"rx": {"kind": "velocity", "history": 0.0},
                                      "ry": {"kind": "displacement", "history": {"times": [0, 1], "values": [0, 0.3]},
                                             "pivot": [1.0, 0.0, 0.1]},
                                      "rz": {"kind": "velocity", "history": 0.0}}}],
        "stages": [{"name": "s", "duration": 0.01, "h": 0.005}],
    }
    case = parse_case(copy.deepcopy(base), "t3.toml")
    assert case.rigid_bodies[0].drivers["ry"].pivot == (1.0, 0.0, 0.1)
    body = build_model(case).bodies[0]
    assert body.driven.all() and body.mass == 0.0
    bad = copy.deepcopy(base)
    del bad["rigid_bodies"][0]["drivers"]["rz"]
    with pytest.raises(InputError, match=r"rigid_bodies\[0\]\.drivers\.ry\.pivot: expected every rotation dof driven"):
        parse_case(bad, "t3.toml")


def test_check_reports_the_record_and_its_end(capsys):
    from fem_blocks.check import check_case
    from fem_blocks.cli import list_demos
    lines, _ = check_case(list_demos()["rocking_block"])
    rec = [ln for ln in lines if "drivers.base.x: acceleration" in ln]
    assert len(rec) == 1 and "ricker_pulse.csv" in rec[0] and "at its end the driven velocity is" in rec[0]

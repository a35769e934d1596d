"""Cyclic displacement protocol (docs/case-files.md "Cyclic displacement protocol") and the `cycles` block of
summary.json (output/summary.cycles_block).

* The expansion {protocol = "cyclic", amplitudes, cycles, rate, start} -> {times, values} against hand-written
  knot lists (SI and mm-N-MPa files), and the load-time warnings that keep a protocol from being cut silently.
* ∮ F du with the step rule Σ F_{k+1} Δu_k on a synthetic elastic–perfectly-plastic loop (stiffness k, yield
  force F_y, amplitude a, increments Δu): a steady cycle encloses 4 F_y (a - F_y/k) (the parallelogram); the step
  rule adds k Δu²/2 per step of its two elastic branches (2 F_y/k long each), 2 F_y Δu in all. The first cycle,
  from the virgin state at u = 0 to u = 0 where the spring is at F_y: 4 F_y a - 5 F_y²/k dissipated + F_y²/(2k)
  stored, plus 2.5 F_y Δu from its three elastic branches (F_y/k + 2 F_y/k + 2 F_y/k).
* A real run: a rigid block pressed by N on a rigid base through a Coulomb interface (μ, no cohesion) and driven
  along x by the protocol: the block slides at the force μN as soon as it moves (rigid: no elastic branch), so
  every cycle of amplitude a dissipates 4 μ N a (closed form). Tolerance 1e-6 relative: the solver tolerance is
  1e-10 and the inertia the quasi-static step adds to the reaction is m v / h = 1 kg x 1e-4 m/s / 1 s = 1e-4 N
  against μN = 5000 N (2e-8). The same block on an elastic–brittle joint checks the energy balance of the
  `cycles` block: energy_J = stored_change_J + dissipated_J (the joint's break energy) + friction work + the step
  rule's excess on the spring's branch, each in closed form.
"""
import json

import numpy as np
import pytest

from fem_blocks.case import cyclic_history, load_case, parse_case
from fem_blocks.output.summary import cycles_block

# --------------------------------------------------------------------------------------------- the expansion


def test_expansion_knots_and_times_by_hand():
    h = cyclic_history([0.5e-3, 1e-3], 2, 1e-3, start=0.4)
    assert h["values"] == pytest.approx([0.0, 0.5e-3, -0.5e-3, 0.5e-3, -0.5e-3, 1e-3, -1e-3, 1e-3, -1e-3, 0.0],
                                        abs=0)
    assert h["times"] == pytest.approx([0.4, 0.9, 1.9, 2.9, 3.9, 5.4, 7.4, 9.4, 11.4, 12.4], rel=1e-14)
    one = cyclic_history([2.0], 1, 4.0)
    assert one == {"times": [0.0, 0.5, 1.5, 2.0], "values": [0.0, 2.0, -2.0, 0.0]}


BASE = """
gravity = [0.0, 0.0]
{units}
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[-1000.0, -100.0], [1000.0, -100.0], [1000.0, 0.0], [-1000.0, 0.0]]
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "block"
group = "block"
vertices = [[-100.0, 0.0], [100.0, 0.0], [100.0, 100.0], [-100.0, 100.0]]
mass = 1.0
[rigid_bodies.drivers]
rz = {{kind = "velocity", history = 0.0}}
[rigid_bodies.forces]
y = -10000.0
[[interfaces]]
between = ["block", "base"]
mu = 0.5
[[stages]]
name = "cyclic"
duration = {duration}
h = {h}
{stop}
[stages.drivers.block]
x = {{kind = "displacement", history = {{protocol = "cyclic", amplitudes = [0.5, 1.0], cycles = 2, rate = 0.5{start}}}}}
"""


def _case(units="mm-N-MPa", duration=24.0, h=1.0, stop="", start="", history_times=None):
    text = BASE.format(units=f'units = "{units}"' if units else "", duration=duration, h=h, stop=stop, start=start)
    if history_times:
        text = f'history_times = "{history_times}"\n' + text
    return parse_case(__import__("tomllib").loads(text), "cyc.toml")


def test_protocol_in_a_case_file_is_the_expansion_in_si():
    """mm-N-MPa: amplitudes [mm] and rate [mm/s] converted once; the stage sees an ordinary history."""
    c = _case()
    kind, hist = c.stages[0].drivers["block"]["x"]
    assert kind == "displacement"
    assert hist == cyclic_history([0.5e-3, 1e-3], 2, 0.5e-3)
    assert hist["times"][-1] == pytest.approx(4 * 2 * 1.5 / 0.5)  # sum 4 n a / v = 24 s
    assert c.warnings == []


def test_protocol_cut_by_the_stage_warns():
    """A stage shorter than the protocol: the stage-time warning names the history and what is applied."""
    c = _case(duration=20.0)
    assert len(c.warnings) == 1
    assert "stages[0].drivers.block.x: the history runs to t = 24 s but stops applying" in c.warnings[0]


def test_reversal_between_steps_warns_with_the_value_reached():
    """h = 0.4 s: the first reversal (t = 1 s) is 2.5 steps in; the driven value turns at u(0.8 s) = 0.4 mm."""
    c = _case(h=0.4)
    rev = [w for w in c.warnings if "falls between two steps" in w]
    assert len(rev) == 1 and "reversal at t = 1 s (value 0.0005 m)" in rev[0] and "turns at 0.0004" in rev[0]


def test_quick_rechecks_the_reversals_on_its_doubled_step():
    """h = 1 s puts every knot (1, 3, 5, 7, 10, ... s) on a step; --quick (h = 2 s) moves the first off it."""
    from fem_blocks.case import quick
    c = _case()
    assert c.warnings == []
    q = quick(c)
    assert len(q.warnings) == 1 and "reversal at t = 1 s" in q.warnings[0] and "h = 2 s" in q.warnings[0]


def test_stage_times_shift_the_protocol_and_start_counts():
    c = _case(start=", start = 2.0", duration=26.0, history_times="stage")
    assert c.stages[0].drivers["block"]["x"][1]["times"][0] == 2.0
    assert c.warnings == []


def test_stop_after_peak_on_a_reversing_driver_warns():
    c = _case(stop='[stages.stop_after_peak]\nbody = "block"\ndof = "x"')
    assert any("stop_after_peak: the driver of block.x reverses" in w for w in c.warnings)


# ---------------------------------------------------------------------------------- ∮ F du, synthetic loops
def _epp(u, k, fy):
    """Elastic–perfectly-plastic spring (return mapping) along the path u (from the virgin state)."""
    F, up = np.zeros_like(u), 0.0
    for i in range(1, len(u)):
        f = k * (u[i] - up)
        if abs(f) > fy:
            up = u[i] - np.sign(f) * fy / k
            f = np.sign(f) * fy
        F[i] = f
    return F


def test_elastic_perfectly_plastic_loop_energy_closed_form():
    k, fy, du = 10.0, 5.0, 1e-3  # F_y/k = 0.5: the elastic branches are whole numbers of steps
    amps = [1.0, 2.0]
    h = cyclic_history(amps, 2, 1.0)
    t = np.arange(0.0, h["times"][-1] + 0.5 * du, du)  # rate 1: one row per du, every knot on a row
    u = np.interp(t, h["times"], h["values"])
    F = _epp(u, k, fy)
    c = cycles_block(t, u, F, u_scale=1.0, u_unit="m", f_scale=1.0, f_unit="N")
    assert c["count"] == 4 and [r["complete"] for r in c["cycles"]] == [True] * 4
    e = [r["energy_J"] for r in c["cycles"]]
    first = 4 * fy * 1.0 - 5 * fy ** 2 / k + fy ** 2 / (2 * k) + 2.5 * fy * du
    assert e[0] == pytest.approx(first, rel=1e-9)
    for ei, a in zip(e[1:], [1.0, 2.0, 2.0]):  # steady cycles (the jump to a = 2 starts yielded at u = 0, as a
        assert ei == pytest.approx(4 * fy * (a - fy / k) + 2 * fy * du, rel=1e-9)  # steady one does)
    r = c["cycles"][2]
    assert (r["displacement_pos_m"], r["displacement_neg_m"]) == pytest.approx((2.0, -2.0), abs=1e-12)
    assert (r["peak_force_pos_N"], r["peak_force_neg_N"]) == pytest.approx((fy, -fy), abs=1e-12)
    assert c["energy_total_J"] == pytest.approx(sum(e), rel=1e-12)


def test_crossings_between_rows_are_interpolated():
    """Rigid–plastic friction F = μN sign(du) on rows whose zero crossings fall mid-step: each cycle is still
    4 μN a (the step of a crossing is cut there, its force is the step's)."""
    mun, a = 3.0, 1.0
    h = cyclic_history([a], 3, 1.0, start=0.05)
    t = np.arange(0.0, h["times"][-1] + 0.15, 0.1)  # rows at 0.1 s: zero crossings at 2.05 s, 6.05 s
    t = np.union1d(t, h["times"])  # knots kept (the turning points), crossings between rows
    u = np.interp(t, h["times"], h["values"])
    F = np.r_[0.0, mun * np.sign(np.diff(u))]
    c = cycles_block(t, u, F, u_scale=1.0, u_unit="m", f_scale=1.0, f_unit="N")
    assert c["count"] == 3
    assert [r["energy_J"] for r in c["cycles"]] == pytest.approx([4 * mun * a] * 3, rel=1e-12)
    assert c["cycles"][1]["t_start"] == pytest.approx(4.05, abs=1e-12)


def test_monotone_record_has_no_cycles_and_a_cut_cycle_is_flagged():
    t = np.linspace(0, 1, 11)
    assert cycles_block(t, t * 1e-3, t * 5.0) is None
    h = cyclic_history([1e-3], 2, 1e-3)
    t = np.arange(0.0, 6.0 + 1e-9, 0.1)  # cut after 6 s of 8: the second cycle stops at -1 mm
    u = np.interp(t, h["times"], h["values"])
    c = cycles_block(t, u, np.r_[0.0, np.sign(np.diff(u))])
    assert c["count"] == 1 and [r["complete"] for r in c["cycles"]] == [True, False]
    assert c["energy_total_J"] == pytest.approx(4e-3, rel=1e-12)


def test_initial_stiffness_rows_stop_at_the_first_reversal():
    """summary.json initial_stiffness is fitted on the virgin loading branch only (runner._virgin): an unloading
    branch of a cyclic test (stiffer or softer) must not enter the fit; a monotone record keeps every row."""
    from fem_blocks.runner import _virgin
    assert _virgin([0, 0, 1, 2, 3, 2, 1, 0, -1]).tolist() == [True] * 5 + [False] * 4
    assert _virgin([0.0, -1.0, -2.0, -1.0]).tolist() == [True, True, True, False]
    assert _virgin([0.0, 1.0, 2.0]).all() and _virgin([0.0, 0.0]).all()


# ------------------------------------------------------------------------------------------ a real small run
SLIDE = """
name = "slide"
gravity = [0.0, 0.0]
[[rigid_bodies]]
name = "base"
group = "base"
vertices = [[-1.0, -0.1], [1.0, -0.1], [1.0, 0.0], [-1.0, 0.0]]
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[[rigid_bodies]]
name = "block"
group = "block"
vertices = [[-0.1, 0.0], [0.1, 0.0], [0.1, 0.1], [-0.1, 0.1]]
mass = 1.0
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}
[rigid_bodies.forces]
y = -{N}
[[interfaces]]
name = "slide"
between = ["block", "base"]
mu = {MU}
[contact]
tol = 1e-10
max_sweeps = 10000
[output]
paraview = false
[output.curve]
body = "block"
force = "x"
displacement = "x"
[[stages]]
name = "load"
duration = 2.0
h = 1.0
theta = 1.0
velocity_reset = true
[[stages]]
name = "cyclic"
duration = 120.0
h = 1.0
theta = 1.0
velocity_reset = true
[stages.drivers.block]
x = {{kind = "displacement", history = {{protocol = "cyclic", amplitudes = [1e-3, 2e-3], cycles = 1, rate = 1e-4, start = 2.0}}}}
"""


@pytest.mark.dolfinx
def test_block_sliding_on_coulomb_dissipates_4_mu_n_a_per_cycle(tmp_path):
    from fem_blocks.runner import run_case
    N, MU = 10000.0, 0.5
    f = tmp_path / "slide.toml"
    f.write_text(SLIDE.format(N=N, MU=MU))
    s = run_case(load_case(str(f)), str(tmp_path / "out"), progress=False)
    assert s["convergence"]["unconverged_steps"] == 0
    cyc = json.loads((tmp_path / "out" / "summary.json").read_text())["cycles"]
    assert cyc["count"] == 2 and s["hysteresis"] == "hysteresis.png"
    assert (tmp_path / "out" / "hysteresis.png").stat().st_size > 1000
    for r, a in zip(cyc["cycles"], (1e-3, 2e-3)):
        assert r["complete"]
        assert r["energy_J"] == pytest.approx(4 * MU * N * a, rel=1e-6)
        assert (r["displacement_pos_mm"], r["displacement_neg_mm"]) == pytest.approx((1e3 * a, -1e3 * a), rel=1e-12)
        assert (r["peak_force_pos_kN"], r["peak_force_neg_kN"]) == pytest.approx((MU * N / 1e3, -MU * N / 1e3),
                                                                                  rel=1e-6)
        assert r["dissipated_J"] == 0.0  # Coulomb friction is not in the laws' dissipated energy
        assert r["friction_J"] == pytest.approx(4 * MU * N * a, rel=1e-6)  # it is in friction_dissipated
        assert abs(r["stored_change_J"]) < 1e-6 * r["energy_J"]
    # the energy balance: the only moving driver is block.x, so ∮F du is the drivers' work in the stage
    assert cyc["energy_total_J"] == pytest.approx(s["final_energy"]["driver_work"], rel=1e-6)
    assert s["friction_dissipated_J"] == pytest.approx(4 * MU * N * 3e-3, rel=1e-6)  # the two cycles: all friction
    hist = (tmp_path / "out" / "history.csv").read_text().splitlines()
    cols = hist[0].split(",")
    assert cols[cols.index("dissipated") + 1] == "friction_dissipated"
    assert float(hist[-1].split(",")[cols.index("friction_dissipated")]) == s["friction_dissipated_J"]


@pytest.mark.dolfinx
def test_energy_balance_with_a_brittle_joint(tmp_path):
    """The same block glued by an elastic–brittle joint (c_T, shear strength s_c, then Coulomb μ; docs/laws.md):
    the shear spring c_T A u works in parallel with the friction μN while it lasts (u <= s_c / c_T = 0.55 mm, i.e.
    m = 5 steps of Δu = 0.1 mm) and breaks in the step after, releasing its elastic energy ½ c_T A (m Δu)² into the
    contacts' `dissipated`. Cycle 1: dissipated_J = ½ c_T A (m Δu)², and energy_J - dissipated_J - stored_change_J =
    4 μ N a (friction) + ½ c_T A m Δu² (the step rule's excess Σ_k c_T A Δu² k - ½ c_T A (m Δu)² on the spring's
    branch). Cycle 2: friction only, dissipated_J = 0."""
    from fem_blocks.runner import run_case
    N, MU, CT, SC, A, du, m = 10000.0, 0.5, 2e9, 1.1e6, 0.2, 1e-4, 5
    f = tmp_path / "brittle.toml"
    f.write_text(SLIDE.format(N=N, MU=MU).replace(f"mu = {MU}", f'law = "brittle"\nmu = {MU}\nc_N = {CT}\n'
                                                                 f'c_T = {CT}\nr_c = 1e6\ns_c = {SC}'))
    s = run_case(load_case(str(f)), str(tmp_path / "out"), progress=False)
    assert s["convergence"]["unconverged_steps"] == 0
    c1, c2 = s["cycles"]["cycles"]
    k = CT * A
    assert c1["dissipated_J"] == pytest.approx(0.5 * k * (m * du) ** 2, rel=1e-9)
    assert c1["peak_force_pos_kN"] == pytest.approx((k * m * du + MU * N) / 1e3, rel=1e-9)
    assert c1["energy_J"] - c1["dissipated_J"] - c1["stored_change_J"] == pytest.approx(
        4 * MU * N * 1e-3 + 0.5 * k * m * du ** 2, rel=1e-6)
    assert c2["dissipated_J"] == 0.0 and c2["energy_J"] == pytest.approx(4 * MU * N * 2e-3, rel=1e-6)
    # friction acts on r̃ (in parallel with the spring, then alone): 4 μ N a per cycle, the spring's work not in it
    assert c1["friction_J"] == pytest.approx(4 * MU * N * 1e-3, rel=1e-6)
    assert c2["friction_J"] == pytest.approx(4 * MU * N * 2e-3, rel=1e-6)

"""EN 1052-3 triplet shear test (fem_blocks/lab/triplet.py, docs/lab-tests.md).

Expectations come from closed forms written here, never from fem_blocks:
* least squares through points on a known line, and through three hand-solved points;
* the mixed-mode joint law's strength under a compression p is c + tan_phi p and its residual tan_phi p
  (docs/laws.md, from the law's definition): a triplet of uniform joints between bricks stiff against the joints (E_b = 16.7 GPa, k_s L = 8 GPa) must give f_vo = c
  and tan α = tan_phi within 2 % (the issue's tolerance; measured -0.5 % and -0.8 %: the bricks' strain makes the joint's shear
  non-uniform, so the joint does not reach c + tan_phi σ everywhere at once),
  and the residual line the friction tan_phi;
* the middle brick's equilibrium: the ram's force F = T_upper + T_lower at every step (to 1e-9 relative), and the
  pre-compression: the joints' normal force = σ_p A.
"""
import json
import os

import numpy as np
import pytest

from fem_blocks.errors import InputError
from fem_blocks.lab.readout import check_levels, fit_line, peak_and_residual

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Joint parameters different from the demo's: δ_II = c/k_s = 10 µm, u_f = 2 G_II / c = 0.625 mm (linear softening);
# 200 steps over 1 mm: 5 µm per step
C, TAN_PHI = 4e5, 0.6
LEVELS = (0.1e6, 0.5e6, 0.9e6)
STIFF = f"""
name = "triplet_stiff"
[materials.brick]
E = 1.67e10
nu = 0.2
rho = 2000.0
thickness = 0.1
[laws.joint]
law = "mixed"
k_n = 1e11
k_s = 4e10
f_t = 3e5
c = {C}
G_I = 20.0
G_II = 125.0
tan_phi = {TAN_PHI}
[lab]
test = "triplet_shear"
mesh_size = 0.07
precompressions = [{LEVELS[0]}, {LEVELS[1]}, {LEVELS[2]}]
brick_length = 0.2
brick_height = 0.06
joint_thickness = 0.01
slip = 1.0e-3
steps = 200
[output]
paraview = false
"""


def test_fit_line_recovers_an_exact_line_and_hand_solved_points():
    """Bug caught: slope without centring (Σστ/Σσ²), intercept τ̄ - slope instead of τ̄ - slope σ̄, R² inverted."""
    s = np.array([0.2, 0.6, 1.0, 1.4])
    f = fit_line(s, 0.3 + 0.8 * s)
    assert f["intercept"] == pytest.approx(0.3, abs=1e-14) and f["slope"] == pytest.approx(0.8, rel=1e-14)
    assert f["r2"] == pytest.approx(1.0, abs=1e-14) and f["n"] == 4
    # (0, 1), (1, 2), (2, 2): σ̄ = 1, τ̄ = 5/3, Sστ = 1, Sσσ = 2 -> slope 1/2, intercept 7/6; SSres = 1/6, SStot = 2/3
    f = fit_line([0, 1, 2], [1, 2, 2])
    assert f["slope"] == pytest.approx(0.5, rel=1e-14) and f["intercept"] == pytest.approx(7 / 6, rel=1e-14)
    assert f["r2"] == pytest.approx(1 - (1 / 6) / (2 / 3), rel=1e-12)


def test_peak_and_residual():
    """Peak = the largest value (not the last, not the first); residual = mean of the last 10 % of the rows; NaN
    when the peak lies in that tail (a curve still rising: no post-peak branch)."""
    t = np.concatenate([np.linspace(0, 5, 11), np.linspace(5, 2, 80)[1:], np.full(10, 2.0)])
    pk, k, res = peak_and_residual(t)
    assert (pk, k) == (5.0, 10) and res == 2.0
    pk, k, res = peak_and_residual(np.linspace(0, 1, 50))
    assert pk == 1.0 and np.isnan(res)


@pytest.mark.parametrize("levels, text", [([0.2, 0.6], "2 level(s)"), ([-0.1, 0.6, 1.0], "negative"),
                                          ([0.2, 0.2, 1.0], "not strictly increasing"),
                                          ([0.2, 1.0, 0.6], "not strictly increasing"),
                                          ("0.2 0.6 1.0", "expected a list"), ([0.2, True, 1.0], "expected a list")])
def test_bad_precompressions(levels, text):
    with pytest.raises(InputError, match="lab.precompressions") as e:
        check_levels(levels)
    assert text in str(e.value)
    assert list(check_levels([0, 0.2, 0.6])) == [0, 0.2, 0.6]


@pytest.fixture(scope="module")
def stiff_run(tmp_path_factory):
    from fem_blocks.lab import load_lab, run_lab
    from fem_blocks.output.history import read_history
    d = tmp_path_factory.mktemp("triplet")
    (d / "t.toml").write_text(STIFF)
    lab = load_lab(str(d / "t.toml"))
    rc = run_lab(lab, str(d / "out"), quiet=True)
    runs = [dict(history=read_history(d / "out" / label / "history.csv"), case=case, info=info)
            for label, case, info in lab.specimens]
    return lab, rc, json.loads((d / "out" / "summary.json").read_text()), runs, d / "out"


@pytest.mark.dolfinx
def test_triplet_recovers_c_tan_phi_and_the_residual_friction(stiff_run):
    """Uniform joints, stiff bricks: f_vo = c, tan α = tan_phi within 2 % (the issue); the residual line passes
    through 0 (within 0.5 % of c) with slope tan_phi (2 %); each peak c + tan_phi σ_p within 1 %. Every step
    converged. Both joints carry the same stress (symmetry) to 1e-5 of c; the ram's force equals the sum of the
    joints' shear forces (the middle brick's equilibrium) and the joints' normal force is σ_p A, both to 1e-4 (the
    inertial part of the quasi-static steps, measured 1.3e-5 and 7e-5).
    Bugs caught: the ram's force divided by A instead of 2A, the pre-compression lost, applied twice or on the
    wrong area (tan α off), the residual taken at the peak, the joints' points fitted per level mean."""
    from fem_blocks.lab.triplet import curves
    lab, rc, s, runs, _ = stiff_run
    assert rc == 0 and s["exit_status"] == 0
    A = 0.2 * 0.1
    for r in runs:
        c = curves(lab.spec, r)
        np.testing.assert_allclose(c["upper"], c["lower"], rtol=1e-6, atol=1e-5 * C)
        np.testing.assert_allclose(2 * c["total"], c["upper"] + c["lower"], rtol=1e-4)  # the brick's inertia
        np.testing.assert_allclose(c["normal"], r["info"]["precompression_Pa"], rtol=1e-4)  # inertia of the steps
        assert c["slip"][-1] == pytest.approx(1.0e-3, rel=1e-12)
        assert s["report"]["joint_area_m2"] == pytest.approx(A, rel=1e-15)
    q = s["quantities"]
    assert q["f_vo"]["value"] == pytest.approx(C, rel=0.02)
    assert q["tan_alpha"]["value"] == pytest.approx(TAN_PHI, rel=0.02)
    assert q["residual_slope"]["value"] == pytest.approx(TAN_PHI, rel=0.02)
    assert abs(q["residual_intercept"]["value"]) < 0.005 * C
    for row, sp in zip(s["report"]["levels"], LEVELS):
        for j in ("upper", "lower"):
            assert row[f"peak_{j}_Pa"] == pytest.approx(C + TAN_PHI * sp, rel=0.01)
            assert row[f"residual_{j}_Pa"] == pytest.approx(TAN_PHI * sp, rel=0.01)


@pytest.mark.dolfinx
def test_specimens_are_ordinary_runs(stiff_run, tmp_path):
    """Each specimen is an ordinary case run: its own history.csv, summary.json and force_displacement.png (the
    ram's curve); summary.json lists the specimens with their exit status and convergence line."""
    lab, rc, s, runs, _ = stiff_run
    assert [sp["label"] for sp in s["specimens"]] == ["p0", "p1", "p2"]
    assert all(sp["exit_status"] == 0 and "converged" in sp["convergence"] for sp in s["specimens"])
    assert [sp["precompression_Pa"] for sp in s["specimens"]] == pytest.approx(list(LEVELS), rel=1e-15)
    assert all(len(r["history"]["step"]) == 1 + 200 + 10 for r in runs)


@pytest.mark.dolfinx
def test_demo_case_runs_and_writes_the_report(tmp_path):
    """`fem-blocks run demos/triplet_shear.toml --quick` (deformable bricks, mm-N-MPa): exit 0, summary.json with the
    standard's quantities in SI with units and the law parameter each measures (its value in SI), the PNG; f_vo
    and tan α recover c and tan_phi within 2 % with deformable bricks too."""
    from fem_blocks.cli import list_demos, main
    assert list_demos()["triplet_shear"].endswith("demos/triplet_shear.toml")
    out = tmp_path / "out"
    rc = main(["run", os.path.join(ROOT, "demos", "triplet_shear.toml"), "--out", str(out), "--quick", "--quiet"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    q = s["quantities"]
    assert s["standard"].startswith("EN 1052-3") and s["exit_status"] == 0 and s["variant"] == "quick x2"
    assert q["f_vo"]["unit"] == "Pa" and q["f_vo"]["measures"] == "laws.joint.c" and q["f_vo"]["input"] == 0.35e6
    assert q["tan_alpha"]["measures"] == "laws.joint.tan_phi" and q["tan_alpha"]["input"] == 0.75
    assert s["inputs"]["lab"]["precompressions"] == pytest.approx([0.2e6, 0.6e6, 1.0e6], rel=1e-15)
    assert s["inputs"]["joint"]["c"] == 0.35 and s["inputs"]["units_of_material_and_joint"] == "mm-N-MPa"
    assert q["f_vo"]["value"] == pytest.approx(0.35e6, rel=0.02)
    assert q["tan_alpha"]["value"] == pytest.approx(0.75, rel=0.02)
    assert (out / "triplet_shear.png").stat().st_size > 10000
    for sp in ("p0", "p1", "p2"):
        assert (out / sp / "history.csv").exists() and (out / sp / "paraview" / "blocks.pvd").exists()


@pytest.mark.dolfinx
def test_unconverged_or_stopped_specimens_set_the_exit_status(tmp_path, capsys):
    """Specimens whose contact solves stay above the tolerance (NLGS limited to 30 sweeps): each specimen says so
    (3: unconverged steps; 1: stopped by the penetration guard), the test's exit status is the most severe of them
    (1 over 3 over 0), summary.json records each, and the last line printed warns. Bugs caught: a specimen's status
    dropped or ranked by number (max(3, 1) = 3), exit 0 on an untrustworthy report."""
    from fem_blocks.cli import main
    case = tmp_path / "t.toml"
    case.write_text(STIFF.replace("steps = 200", "steps = 20") + '[contact]\nsolver = "nlgs"\nmax_sweeps = 30\n')
    rc = main(["run", str(case), "--out", str(tmp_path / "out"), "--quiet"])
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    st = [sp["exit_status"] for sp in s["specimens"]]
    assert all(x in (1, 3) for x in st) and 3 in st
    assert rc == s["exit_status"] == (1 if 1 in st else 3)
    for sp in s["specimens"]:
        assert ("UNCONVERGED" if sp["exit_status"] == 3 else "run stopped") in sp["convergence"]
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert f"WARNING: exit status {rc}" in last and "do not trust" in last


def test_lab_file_through_load_case_names_the_key(tmp_path):
    """A [lab] file given to the ordinary case reader: an InputError naming `lab`, not a confusing missing key."""
    from fem_blocks.case import load_case
    f = tmp_path / "t.toml"
    f.write_text(STIFF)
    with pytest.raises(InputError, match=r"lab: a standard laboratory test"):
        load_case(str(f))


@pytest.mark.dolfinx
def test_killed_lab_run_resumes_bitwise(stiff_run, tmp_path, cli):
    """SIGKILL while the second specimen runs, then `--resume`: every specimen's history.csv and the report are
    bitwise those of the uninterrupted run (the fixture's; checkpoints do not change a run): finished specimens
    resume from their final checkpoint, the interrupted one from its last. Bug caught: a finished specimen run
    again on top of its outputs, a resumed specimen appending to its history twice. The killed run is a process of
    its own; the resume runs in this one (conftest.cli: cli.main)."""
    import signal
    import subprocess
    import sys
    import time
    ref = stiff_run[4]
    case = tmp_path / "t.toml"
    case.write_text(STIFF + "checkpoint_every = 20\n")

    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "fem_blocks.cli", "run", str(case), "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    t0 = time.monotonic()
    while not (out / "p1" / "checkpoint.npz").exists() and proc.poll() is None and time.monotonic() - t0 < 300:
        time.sleep(0.01)
    assert proc.poll() is None, "the run ended before the second specimen's first checkpoint"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "p1" / "summary.json").exists() and not (out / "p2").exists()
    p = cli("run", case, "--out", out, "--quiet", "--resume")
    assert p.returncode == 0, p.stdout + p.stderr
    for sp in ("p0", "p1", "p2"):
        assert (out / sp / "history.csv").read_bytes() == (ref / sp / "history.csv").read_bytes()
    q = json.loads((out / "summary.json").read_text())["quantities"]
    assert q == json.loads((ref / "summary.json").read_text())["quantities"]

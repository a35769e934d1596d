"""EN 1052-1 compression test (`[lab] test = "compression"`, fem_blocks/lab/compression.py).

Closed forms (issue #23), each derived here from the inputs:
(a) modulus: with frictionless platens a stack-bonded prism is in uniform compression σ; over a gauge of m whole
    courses (m expanded bricks of height H = h_b + t_j and m bed joints of normal stiffness k_n) the shortening is
    m σ (H/E_b + 1/k_n), so the standard's secant modulus is E = 1 / (1/E_b + 1/(k_n H)) (plane stress), within 1 %;
    with rigid bricks E = k_n H;
(b) strength: rigid bricks, joints with a softening compressive cap (f_c, G_fc): the only failure mode is the cap,
    the peak platen force is f_c A (A = W t), f = F_max / A = f_c within 2 %;
and the read-out formulas on hand-made arrays, the specimen's layout, one end-to-end CLI run of the prism demo
(--quick) and the wallet's modulus and strength (which found the contact detection's loss of a joint's length at
the nodes where a bed joint meets a head joint: tests/test_placement.py).
"""
import json
import os

import numpy as np
import pytest

from fem_blocks.lab.readout import peak_confirmed, secant_at_fraction

# ------------------------------------------------------------------------------------------- read-out formulas


def test_secant_at_fraction_hand_made_curve():
    """Bilinear curve σ = 2e9 ε up to ε = 1e-3 (2 MPa), then 1e9 ε + 1e6 to the peak 3 MPa at ε = 2e-3, then a
    drop: σ* = 1 MPa is reached at ε* = 5e-4 (the crossing lies between two rows: linear interpolation), so
    E = 2e9 exactly. Catches a secant taken at the peak (1.5e9), at the row after the crossing, or at a
    fraction other than 1/3."""
    eps = np.array([0.0, 0.3e-3, 0.7e-3, 1.0e-3, 1.5e-3, 2.0e-3, 2.5e-3])
    sig = np.where(eps <= 1e-3, 2e9 * eps, 1e9 * eps + 1e6)
    sig[-1] = 2.0e6   # post-peak
    r = secant_at_fraction(sig, eps)
    assert r["peak"] == pytest.approx(3.0e6, rel=1e-12)
    assert r["peak_index"] == 5
    assert r["stress"] == pytest.approx(1.0e6, rel=1e-12)
    assert r["strain"] == pytest.approx(5.0e-4, rel=1e-12)
    assert r["modulus"] == pytest.approx(2.0e9, rel=1e-12)
    half = secant_at_fraction(sig, eps, fraction=0.5)   # σ* = 1.5 MPa at ε* = 7.5e-4
    assert half["strain"] == pytest.approx(7.5e-4, rel=1e-12)


def test_secant_at_fraction_first_crossing_and_errors():
    """The crossing is the first one on the rising branch (a post-peak row at the same stress is not used); a
    curve that does not rise or starts above σ* is an error."""
    eps = np.array([0.0, 1e-3, 2e-3, 3e-3, 4e-3])
    sig = np.array([0.0, 3e6, 6e6, 2e6, 1e6])   # σ* = 2e6 first at ε = 2/3 e-3
    assert secant_at_fraction(sig, eps)["strain"] == pytest.approx(2e-3 / 3, rel=1e-12)
    with pytest.raises(ValueError):
        secant_at_fraction(np.zeros(4), eps[:4])
    with pytest.raises(ValueError):
        secant_at_fraction(np.array([5e6, 6e6, 4e6]), eps[:3])


def test_peak_confirmed():
    """A drop of more than 1 % after the peak, or a plateau, is a peak; a force still rising at the end is not."""
    d = np.linspace(0.0, 1.0, 101)
    rising = 5.0 * d
    assert not peak_confirmed(rising, d)
    softening = np.where(d < 0.5, 10.0 * d, 5.0 - 4.0 * (d - 0.5))
    assert peak_confirmed(softening, d)
    plateau = np.minimum(10.0 * d, 4.0)   # perfectly plastic: flat after d = 0.4
    assert peak_confirmed(plateau, d)
    slow = np.minimum(10.0 * d, 4.0 + 0.5 * d)   # still rising at 0.5 against a secant of 10: not a peak
    assert not peak_confirmed(slow, d)


def test_stopped_run_reads_as_no_peak():
    """A run stopped before the stress rose (history of the initial row only) gives NaN values and the specimen's
    line a WARNING, not a traceback: a result nobody should trust does not look like one."""
    from fem_blocks.lab.compression import analyse, gauge_points, layout, specimen_line
    s = _spec(courses=3)
    h = {"platen.Ry": np.zeros(1), "platen.Iy": np.zeros(1), "platen.uy": np.zeros(1)}
    h.update({f"{g['name']}.uy": np.zeros(1) for g in gauge_points(s, layout(s))})
    run = dict(history=h, info=dict(area_m2=0.021, gauge_length_m=0.124))
    c, sec, ok = analyse(s, run)
    assert not ok and np.isnan(sec["peak"]) and np.isnan(sec["modulus"])
    assert "WARNING: no peak" in specimen_line(s, run)


# ------------------------------------------------------------------------------------------- specimen layout
def _spec(**kw):
    from fem_blocks.lab.compression import CompressionSpec
    return CompressionSpec(test="compression", **kw)


def test_wallet_layout_running_bond():
    """1.5 bricks: courses [1, 1/2] and [1/2, 1] of the expanded brick l_m = L + t_j, all courses W = 1.5 l_m
    wide, head joints of neighbouring courses half a brick apart; 2 bricks: [1, 1] and [1/2, 1, 1/2]. The gauge
    lines lie inside bricks (never on a head joint) and symmetric about the middle."""
    from fem_blocks.lab.compression import gauge_points, layout
    L, tj = 0.21, 0.01
    lm = L + tj
    for nb, even, odd in ((1.5, [1.0, 0.5], [0.5, 1.0]), (2.0, [1.0, 1.0], [0.5, 1.0, 0.5])):
        s = _spec(specimen="wallet", bricks_per_course=nb, courses=5, brick_length=L, joint_thickness=tj)
        rows = layout(s)
        assert len(rows) == 5
        for i, row in enumerate(rows):
            assert [ln / lm for _, ln in row] == pytest.approx(even if i % 2 == 0 else odd, rel=1e-12)
            assert sum(ln for _, ln in row) == pytest.approx(nb * lm, rel=1e-12)
        heads = [set(round(x0 / lm, 9) for x0, _ in row[1:]) for row in rows[:2]]
        assert not heads[0] & heads[1]
        assert all(min(abs(a - b) for b in heads[1]) >= 0.5 - 1e-9 for a in heads[0])
        W = nb * lm
        g = gauge_points(s, rows)
        xs = sorted(set(p["x"] for p in g))
        assert xs[0] + xs[1] == pytest.approx(W, rel=1e-12)
        for p in g:   # strictly inside the brick named, at least a quarter of a half brick from its ends
            c = int(round(p["y"] / (s.brick_height + tj) - 0.5))
            x0, ln = [r for j, r in enumerate(rows[c]) if p["block"].endswith(f"b{j}")][0]
            assert x0 + 0.25 * 0.5 * lm <= p["x"] <= x0 + ln - 0.25 * 0.5 * lm


def test_gauge_courses_default_and_length():
    """The default gauge: the m nearest to courses/3 with both ends at the middle of a course and centred on
    mid-height (courses - m odd): 2 courses -> 1, 3 -> 2, 4 -> 1, 5 -> 2, 6 -> 3, 7 -> 2, 9 -> 4."""
    from fem_blocks.lab.compression import default_gauge_courses, gauge_points, layout
    assert [default_gauge_courses(n) for n in (2, 3, 4, 5, 6, 7, 9)] == [1, 2, 1, 2, 3, 2, 4]
    s = _spec(courses=5)
    H = s.brick_height + s.joint_thickness
    g = gauge_points(s, layout(s))
    ys = sorted(set(p["y"] for p in g))
    assert ys == pytest.approx([1.5 * H, 3.5 * H], rel=1e-12)   # centred on 2.5 H
    assert sorted(set(p["x"] for p in g)) == pytest.approx([0.25 * s.brick_length, 0.75 * s.brick_length])


def test_wallet_meshes_match_across_bed_joints():
    """The wallet's element size divides a half brick into an even number k of elements and a full brick into
    2k (matching nodes across every bed joint), also at --quick (size x 2: k/2 and k); meshing.mesh_rectangle
    takes round(l / size) divisions."""
    from fem_blocks.lab.compression import wallet_mesh_size
    for L, hb, tj, ms in ((0.21, 0.052, 0.01, None), (0.215, 0.065, 0.012, None), (0.21, 0.052, 0.01, 0.02),
                          (0.29, 0.09, 0.01, 0.05)):
        s = _spec(specimen="wallet", brick_length=L, brick_height=hb, joint_thickness=tj, mesh_size=ms)
        lm = L + tj
        for f in (1.0, 2.0):
            h = f * wallet_mesh_size(s)
            assert round(lm / h) == 2 * round(0.5 * lm / h)
        assert round(0.5 * lm / wallet_mesh_size(s)) % 2 == 0


# ------------------------------------------------------------------------------------------- runs
BRICK = """
name = "compression_test"
units = "mm-N-MPa"
[materials.brick]
E = {E}
nu = 0.15
rho = 2.0e-9
thickness = 100.0
[laws.joint]
{law}
[lab]
test = "compression"
{lab}
"""
MIXED = """law = "mixed"
k_n = 82.0
k_s = 36.0
f_t = 0.25
c = 0.35
G_I = 0.018
G_II = 0.125
tan_phi = 0.75
f_c = 10.5
G_fc = 5.0"""


def _run(tmp_path, E=16700.0, law=MIXED, lab="", quick=False):
    from fem_blocks.lab import load_lab, run_lab
    p = tmp_path / "case.toml"
    p.write_text(BRICK.format(E=E, law=law, lab=lab))
    status = run_lab(load_lab(str(p)), str(tmp_path / "out"), quick=quick, quiet=True)
    with open(tmp_path / "out" / "summary.json") as f:
        return status, json.load(f)


@pytest.mark.dolfinx
def test_prism_modulus_series_formula_elastic_no_peak(tmp_path):
    """(a) Deformable bricks (E_b = 16 700 MPa), mixed-law joints k_n = 82 N/mm³, 3 courses of 52 + 10 mm (gauge:
    2 courses), platen moved 0.05 mm (elastic: σ ≈ 1 MPa, far below the cap): the secant at one third of the largest
    force equals 1 / (1/E_b + 1/(k_n H)) within 1 %. Catches a strain over the wrong gauge length (3 courses, or
    the platen's displacement), a stress on the wrong area, or the joint's compliance counted twice. No peak was
    reached, so the standard's quantities are not measured: NaN, listed in `unmeasured`, exit status 1 (a strength
    that is only a lower bound must not read as one)."""
    status, s = _run(tmp_path, lab="courses = 3\ndisplacement = 0.05\nsteps = 6")
    Eb, kn, H = 16700e6, 82e9, 0.062
    E = 1.0 / (1.0 / Eb + 1.0 / (kn * H))   # 3 897.5 MPa
    assert s["report"]["secant_at_third_of_largest_force_Pa"] == pytest.approx(E, rel=0.01)
    assert s["report"]["gauge_courses"] == 2
    assert s["report"]["peak_reached"] is False
    assert 0 < s["report"]["lower_bound_f_Pa"] < 10.5e6
    assert status == 1 and s["exit_status"] == 1
    assert {"f", "E"} <= set(s["unmeasured"])
    assert all(sp["exit_status"] == 0 for sp in s["specimens"])   # the run itself converged


@pytest.mark.dolfinx
def test_prism_strength_is_the_cap_rigid_bricks(tmp_path):
    """(b) Rigid bricks, joints with a softening cap f_c = 10.5 MPa, G_fc = 5 N/mm: the peak is f_c A with
    A = 210 x 100 mm² (F_max = 220.5 kN), f = f_c within 2 %, a peak followed by softening (peak_reached), and
    the modulus k_n H = 82 x 62 = 5 084 MPa within 1 % (rigid bricks: the joints alone). Catches an area with the
    expanded width, a peak read from the base with the inertia, or a strength without the cap."""
    status, s = _run(tmp_path, lab='bricks = "rigid"\ncourses = 3\ndisplacement = 0.5\nsteps = 25')
    assert status == 0, s["specimens"]
    q = s["quantities"]
    assert q["f"]["value"] == pytest.approx(10.5e6, rel=0.02)
    assert q["F_max"]["value"] == pytest.approx(10.5 * 210 * 100, rel=0.02)
    assert q["E"]["value"] == pytest.approx(82e9 * 0.062, rel=0.01)
    assert s["report"]["peak_reached"] is True
    assert q["f"]["measures"] == "laws.joint.f_c" and q["f"]["input"] == pytest.approx(10.5e6)


@pytest.mark.dolfinx
@pytest.mark.parametrize("bricks", ["rigid", "deformable"])
def test_wallet_series_modulus_and_cap(tmp_path, bricks):
    """(a) and (b) on the running-bond wallet (1.5 bricks, 3 courses), loaded past its peak: a linear displacement
    field is continuous across the head joints, so the state is uniform as in the prism: f = f_c within 2 % and
    E = 1 / (1/E_b + 1/(k_n H)) (rigid bricks: k_n H) within 1 %, on A = 1.5 (L + t_j) t. Catches a wallet laid
    with gaps or overlaps, a wrong loaded width and contact areas that do not sum to the joints' overlaps."""
    steps = 25 if bricks == "rigid" else 30
    status, s = _run(tmp_path, lab=f'specimen = "wallet"\nbricks = "{bricks}"\ncourses = 3\nsteps = {steps}')
    Eb, kn, H = 16700e6, 82e9, 0.062
    E = kn * H if bricks == "rigid" else 1.0 / (1.0 / Eb + 1.0 / (kn * H))
    assert s["report"]["area_m2"] == pytest.approx(1.5 * 0.22 * 0.1, rel=1e-12)
    assert status == 0
    assert s["quantities"]["f"]["value"] == pytest.approx(10.5e6, rel=0.02)
    assert s["quantities"]["E"]["value"] == pytest.approx(E, rel=0.01)


@pytest.mark.dolfinx
def test_demo_prism_cli_short(tmp_path, demo_path):
    """The prism demo end to end through the CLI, shortened (3 courses, 30 steps: the demo itself takes 43 s):
    exit 0, the report names the standard and the input each quantity measures, f = f_c (10.5 MPa) within 2 %
    after a peak, E the series formula within 1 %, and the figures (the standard's, the crack pattern and the
    force-displacement curve of the specimen)."""
    import re

    from fem_blocks.cli import main
    with open(demo_path("compression_prism.toml"), encoding="utf-8") as f:
        text = f.read()
    text = re.sub(r"(?m)^courses = 5", "courses = 3", text)
    text = re.sub(r"(?m)^steps = 200", "steps = 30", text)
    assert "courses = 3" in text and "steps = 30" in text
    case = tmp_path / "prism.toml"
    case.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(case), "--out", str(out), "--quiet"]) == 0
    with open(out / "summary.json") as f:
        s = json.load(f)
    assert s["standard"].startswith("EN 1052-1") and s["test"] == "compression"
    q = s["quantities"]
    assert s["report"]["peak_reached"] is True
    assert q["f"]["value"] == pytest.approx(10.5e6, rel=0.02)
    assert q["f"]["measures"] == "laws.joint.f_c"
    assert q["E"]["value"] == pytest.approx(1.0 / (1.0 / 16700e6 + 1.0 / (82e9 * 0.062)), rel=0.01)
    assert q["E"]["input"] == pytest.approx(q["E"]["value"], rel=0.01)
    for f in ("compression.png", os.path.join("prism", "crack_pattern.png"),
              os.path.join("prism", "force_displacement.png")):
        assert (out / f).is_file(), f


def test_demos_listed():
    """`fem-blocks demo --list` shows both demos with their first comment line."""
    from fem_blocks.cli import list_demos
    demos = list_demos()
    assert "compression_prism" in demos and "compression_wallet" in demos

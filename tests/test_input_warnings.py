"""Issue #18 item 10: silent changes to what the user asked for become one-line warnings.

Every expectation is computed by hand from the geometry (running-bond layout, joint, cut rule) or from the
stated plausible ranges (docs/case-files.md "Warnings"), never from the code under test.
"""
import json
import os

import pytest

from fem_blocks import builders
from fem_blocks.case import parse_case
from fem_blocks.errors import InputError
from fem_blocks.expand import expand


def _material(units="SI", E=5e9, rho=1800.0):
    return {"m": {"E": E, "nu": 0.2, "rho": rho}}


def _case(units="SI", E=5e9, rho=1800.0, lx=1.0, ly=0.2, wall=None, extra=None):
    d = {"units": units, "materials": _material(units, E, rho), "stages": [{"h": 0.001, "duration": 0.002}]}
    if wall is not None:
        d["wall"] = dict(material="m", mesh_size=0.05 if units == "SI" else 50.0, **wall)
    else:
        d["block_types"] = {"t": {"geometry": "rectangle", "lx": lx, "ly": ly, "mesh_size": lx / 2, "material": "m"}}
        d["blocks"] = [{"type": "t"}]
    d.update(extra or {})
    return expand(parse_case(d, "case.toml"))  # openings: what was built is reported by expand


def _warned(case, key):
    return [w for w in case.warnings if f"case.toml: {key}" in w]


# ----------------------------------------------------------------------------- unit plausibility
@pytest.mark.parametrize("units, E, rho, lx, bad", [
    ("SI", 1e4, 1800.0, 1.0, "materials.m.E"),            # E meant in MPa in an SI file: 1e4 Pa
    ("mm-N-MPa", 10.0, 1.8e-9, 1000.0, "materials.m.E"),  # 10 MPa = 1e7 Pa: below 1e8 Pa
    ("SI", 5e9, 2.5, 1.0, "materials.m.rho"),             # rho meant in t/m^3: 2.5 kg/m^3 < 100
    ("SI", 5e9, 1800.0, 200.0, "block_types.t.lx"),       # lengths in mm in an SI file: a 200 m block
    ("mm-N-MPa", 5000.0, 1.8e-9, 0.5, "block_types.t.lx"),  # lengths in m in a mm file: 0.5 mm < 1 mm
])
def test_implausible_values_warn_in_both_unit_systems(units, E, rho, lx, bad):
    case = _case(units, E, rho, lx=lx, ly=lx / 5)
    hits = _warned(case, bad)
    assert len(hits) == 1, case.warnings
    assert f"units = {units!r}" in hits[0] and "\n" not in hits[0]


@pytest.mark.parametrize("units, E, rho, lx", [("SI", 5e9, 1800.0, 1.0), ("mm-N-MPa", 5000.0, 1.8e-9, 1000.0),
                                               ("SI", 1e8, 100.0, 1e-3 * 5), ("SI", 1e12, 2e4, 20.0)])
def test_plausible_values_do_not_warn(units, E, rho, lx):
    assert _case(units, E, rho, lx=lx, ly=lx / 5).warnings == []


def test_wall_brick_length_in_mm_in_si_file_warns():
    case = _case(wall=dict(brick_length=200.0, brick_height=0.1, courses=1, bricks_per_course=1))
    assert len(_warned(case, "wall.brick_length")) == 1
    assert _warned(case, "wall.brick_height") == []


def test_reverse_mistake_still_an_error():
    with pytest.raises(InputError, match="materials.m.E"):
        _case("mm-N-MPa", E=5e9, rho=1.8e-9, lx=1000.0)  # E in Pa in a mm-N-MPa file: 5e15 Pa


# ----------------------------------------------------------------------------- openings
# running bond, L = 0.2, H = 0.1, t = 0.01: course c at y = 0.11 c; even courses full bricks at x = 0.21 k,
# odd courses a half brick (L - t)/2 = 0.095 then full bricks at 0.105 + 0.21 k. Cut rule: a brick meeting the
# opening keeps the parts a joint (0.01) away from its sides, pieces < L/4 = 0.05 are dropped.
WALL = dict(brick_length=0.2, brick_height=0.1, joint=0.01, courses=8, bricks_per_course=6)


def test_opening_extent_by_hand():
    op = (0.5, 0.2, 0.78, 0.51)
    blocks = builders.running_bond(8, 6, 0.2, 0.1, 0.01, openings=[op])
    ext = builders.opening_extent(blocks, op, 0.01)
    # courses 1..4 meet y in (0.2, 0.51): clear height from 0.11 - 0.01 to 0.44 + 0.1 + 0.01
    assert ext["courses"] == (1, 4)
    assert ext["height"] == pytest.approx(0.45, abs=1e-12)
    # even course: left piece [0.42, 0.49] (0.07 >= 0.05 kept); brick [0.63, 0.83] leaves 0.04 on the right:
    # dropped, so the next face is the brick at 0.84 -> width 0.35. Odd course: pieces end at 0.49 and start
    # at 0.79 -> width 0.30 (the clear rectangle)
    assert ext["width_min"] == pytest.approx(0.30, abs=1e-12)
    assert ext["width_max"] == pytest.approx(0.35, abs=1e-12)
    assert ext["clear"] == pytest.approx((0.49, 0.10, 0.79, 0.55), abs=1e-12)


def test_snapped_opening_warns_with_built_size():
    case = _case(wall=dict(WALL, openings=[[0.5, 0.2, 0.78, 0.51]]))
    hits = _warned(case, "wall.openings[0]")
    assert len(hits) == 1, case.warnings
    assert "asked 0.28 x 0.31 m, built 0.3 x 0.45 m" in hits[0]
    assert "toothed jambs: course widths 0.3 to 0.35 m" in hits[0]
    assert len(case.notes) == 1 and case.notes[0] in hits[0]


def test_opening_on_brick_faces_is_not_a_warning():
    # sides on the faces of the bricks of courses 2..4 (x 0.42 and 0.83; y 0.22 and 0.54): built as asked,
    # the clear opening between the remaining faces is a joint larger on each side
    case = _case(wall=dict(WALL, openings=[[0.42, 0.22, 0.83, 0.54]]))
    assert case.warnings == []
    assert len(case.notes) == 1 and "built 0.43 x 0.34 m" in case.notes[0]


def test_opening_in_mm_file_reported_in_mm():
    wall = dict(brick_length=200.0, brick_height=100.0, joint=10.0, courses=8, bricks_per_course=6,
                openings=[[500.0, 200.0, 780.0, 510.0]])
    case = _case("mm-N-MPa", E=5000.0, rho=1.8e-9, wall=wall)
    hits = _warned(case, "wall.openings[0]")
    assert len(hits) == 1 and "asked 280 x 310 mm, built 300 x 450 mm" in hits[0], case.warnings


# ----------------------------------------------------------------------------- allow_no_interface
def test_allow_no_interface_validated():
    wall = dict(brick_length=0.2, brick_height=0.1, courses=1, bricks_per_course=1)
    case = _case(wall=wall, extra={"allow_no_interface": [["bricks", "bricks"]]})
    assert case.allow_no_interface == [("bricks", "bricks")]
    with pytest.raises(InputError, match="allow_no_interface: group 'beam' has no body"):
        _case(wall=wall, extra={"allow_no_interface": [["bricks", "beam"]]})
    with pytest.raises(InputError, match="allow_no_interface: = .*expected a list of group pairs"):
        _case(wall=wall, extra={"allow_no_interface": ["bricks", "beam"]})


# ----------------------------------------------------------------------------- groups in contact, no interface
def _beam_wall(interfaces, extra=None, joint=0.0):
    wall = dict(brick_length=0.2, brick_height=0.1, joint=joint, courses=2, bricks_per_course=2, mesh_size=0.1,
                foundation={"depth": 0.1}, beam={"depth": 0.1, "rho": 2000.0})
    d = {"materials": {"m": {"E": 1e9, "nu": 0.2, "rho": 2000.0, "thickness": 0.1}},
         "wall": dict(material="m", **wall), "stages": [{"h": 0.001, "duration": 0.002}],
         "interfaces": [{"between": list(p), "mu": 0.5, "g0": joint} for p in interfaces]}
    d.update(extra or {})
    return parse_case(d, "case.toml")


def _contact_warnings(case):
    from fem_blocks.dynamics import Simulation
    from fem_blocks.model import build_model, groups_without_interface
    model = build_model(case)
    sim = Simulation(model.bodies, h=0.001, gravity=model.gravity, contact=model.contact)
    return groups_without_interface(case, model, sim)


def test_beam_touching_wall_without_interface_warns():
    # 2 courses of a running bond: the top course (half, full, half brick) touches the beam: 3 body pairs
    w = _contact_warnings(_beam_wall([("bricks", "bricks"), ("bricks", "foundation")]))
    assert len(w) == 1, w
    assert w[0].startswith("case.toml: groups 'beam' and 'bricks': 3 pair(s) of bodies in contact")
    assert 'allow_no_interface = [["beam", "bricks"]]' in w[0]


def test_thick_joint_gap_within_search_distance_warns():
    # beam a joint (10 mm) above the wall; the search distance is the largest g0 + alert (10 mm + 1 mm)
    w = _contact_warnings(_beam_wall([("bricks", "bricks"), ("bricks", "foundation")], joint=0.01), )
    assert len(w) == 1 and "gap 0.01 m" in w[0], w


def test_no_warning_with_interface_or_allowed():
    full = [("bricks", "bricks"), ("bricks", "foundation"), ("bricks", "beam")]
    assert _contact_warnings(_beam_wall(full)) == []
    allowed = _beam_wall(full[:2], extra={"allow_no_interface": [["bricks", "beam"]]})
    assert _contact_warnings(allowed) == []


# ----------------------------------------------------------------------------- stage times
# A fixed rigid block: stage "settle" (10 ms) stops at equilibrium after its 2 minimum steps (t = 2 ms), so
# "push" runs from 2 ms to 12 ms while its displacement history (absolute times) ramps 0 -> 60 mm over
# [10 ms, 20 ms]: at 12 ms it has applied 60 mm x (12 - 10)/(20 - 10) = 12 mm.
STAGES = """name = "stage_times"
{top}
[[rigid_bodies]]
name = "block"
vertices = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]]
[rigid_bodies.drivers]
x = {{kind = "velocity", history = 0.0}}
y = {{kind = "velocity", history = 0.0}}
rz = {{kind = "velocity", history = 0.0}}

[output]
paraview = false

[[stages]]
name = "settle"
duration = 0.01
h = 0.001
[stages.stop_at_equilibrium]
min_steps = 2

[[stages]]
name = "push"
duration = 0.01
h = 0.001
[stages.drivers.block.x]
kind = "displacement"
history = {{times = {times}, values = [0.0, 0.06]}}
"""


def _run_stages(tmp_path, capsys, top="", times="[0.01, 0.02]"):
    from fem_blocks.cli import main
    from fem_blocks.output.history import read_history
    path = tmp_path / "stages.toml"
    path.write_text(STAGES.format(top=top, times=times))
    rc = main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    ux = read_history(str(tmp_path / "out" / "history.csv"))["block.ux"][-1]
    return err, summary, ux


def test_stage_ending_before_its_history_warns(tmp_path, capsys):
    err, summary, ux = _run_stages(tmp_path, capsys)
    assert ux == pytest.approx(0.012, abs=1e-12)
    lines = [ln for ln in err.splitlines() if ln.startswith("fem-blocks: warning:")]
    assert len(lines) == 1, err
    assert "stages[1].drivers.block.x: stage 'push' ended at t = 0.012 s" in lines[0]
    assert "0.012 of 0.06 m applied" in lines[0] and "stage 'settle' stopped early" in lines[0]
    assert summary["warnings"] == [lines[0][len("fem-blocks: warning: "):]]
    assert summary["stages"][1]["warnings"] == summary["warnings"]


def test_stage_relative_history_times_apply_the_whole_history(tmp_path, capsys):
    err, summary, ux = _run_stages(tmp_path, capsys, top='history_times = "stage"', times="[0.0, 0.01]")
    assert ux == pytest.approx(0.06, abs=1e-12)  # a displacement driver applies its history's value exactly
    assert "warning" not in err and summary["warnings"] == []


def test_history_longer_than_the_stages_warns_at_parse():
    # nominal times: push from 10 ms to 20 ms; the history runs to 30 ms: at 20 ms 60 mm x 10/20 = 30 mm
    import tomllib
    case = parse_case(tomllib.loads(STAGES.format(top="", times="[0.01, 0.03]")), "case.toml")
    assert len(case.warnings) == 1, case.warnings
    w = case.warnings[0]
    assert w.startswith("case.toml: stages[1].drivers.block.x: the history runs to t = 0.03 s") and \
        "ends at t = 0.02 s" in w and "0.03 of 0.06 m applied" in w


def test_quarter_brick_pieces_kept_on_both_sides():
    # demos/wall_settlement.toml: L = 0.2, H = 0.05, no joint, 12 courses of 6 bricks, window [0.45, 0.2, 0.75, 0.4].
    # Courses 4..7 meet it. Even courses: bricks [0.4, 0.6] and [0.6, 0.8] leave pieces of exactly L/4 = 0.05 on
    # both sides (kept: only pieces < L/4 are dropped). Odd courses: [0.3, 0.5] and [0.7, 0.9] leave 0.15, [0.5, 0.7]
    # goes. The window is built as asked, with straight jambs; 6 x 6 + 6 x 7 - 2 = 76 blocks.
    op = (0.45, 0.2, 0.75, 0.4)
    blocks = builders.running_bond(12, 6, 0.2, 0.05, 0.0, openings=[op])
    assert len(blocks) == 76
    ext = builders.opening_extent(blocks, op, 0.0)
    assert ext["width_min"] == pytest.approx(0.3, abs=1e-12) and ext["width_max"] == pytest.approx(0.3, abs=1e-12)
    assert ext["clear"] == pytest.approx(op, abs=1e-12) and ext["courses"] == (4, 7)


# ----------------------------------------------------------------------------- fem-blocks check
def test_check_demo_prints_what_would_be_built(capsys):
    from fem_blocks.cli import DEMO_DIR, main
    path = os.path.join(DEMO_DIR, "wall_settlement.toml")
    rc = main(["check", path])
    out, err = capsys.readouterr()
    assert rc == 0, err
    lines = out.splitlines()
    # 76 bricks (test above: full 0.2, half 0.1, pieces 0.05 and 0.15 m long) + foundation0 + foundation1
    assert "bodies: 78 (76 deformable blocks of 4 block types, 2 rigid bodies)" in lines[1]
    assert "groups: 'bricks' 76 deformable; 'foundation' 2 rigid" in lines
    assert any(ln.startswith("interface 'joints': bricks / bricks, law coulomb, mu = 0.7")
               and "placement overlap (default)" in ln for ln in lines)  # the placement the run will use
    assert any(ln.startswith("opening: wall.openings[0] = [0.45, 0.2, 0.75, 0.4]: asked 0.3 x 0.2 m, built 0.3 x "
                             "0.2 m") for ln in lines)
    # nominal stage times: 0.3 s of gravity, then 0.8 s of settlement; the settlement history (absolute times)
    assert any(ln.startswith("stage 0 'gravity': t = 0 to 0.3 s, h = 0.001 s, 300 steps") and "may stop early" in ln
               for ln in lines)
    assert any(ln.startswith("stage 1 'settlement': t = 0.3 to 1.1 s, h = 0.005 s, 160 steps") for ln in lines)
    assert "  rigid_bodies.foundation1.drivers.y: displacement, times 0.3 to 0.8 s, values 0 to -0.005" in lines
    assert lines[-1] == f"fem-blocks: {path}: valid, 0 warning(s)"
    assert err == ""


def test_check_prints_warnings_and_bad_file_exits_2(tmp_path, capsys):
    from fem_blocks.cli import main
    path = tmp_path / "beam.toml"
    doc = """[materials.m]
E = 1e9
nu = 0.2
rho = 2000.0
[wall]
material = "m"
brick_length = 0.2
brick_height = 0.1
courses = 2
bricks_per_course = 2
mesh_size = 0.1
[wall.beam]
depth = 0.1
rho = 2000.0
[[interfaces]]
between = ["bricks", "bricks"]
mu = 0.5
[[stages]]
duration = 0.002
h = 0.001
"""
    path.write_text(doc)
    assert main(["check", str(path)]) == 0
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith(f"fem-blocks: warning: {path}: groups 'beam' and 'bricks'")
    assert out.splitlines()[-1] == f"fem-blocks: {path}: valid, 1 warning(s) (on stderr)"
    path.write_text(doc.replace("brick_length", "brick_lenght"))
    assert main(["check", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == (f"fem-blocks: error: {path}: wall.brick_lenght: unknown key 'brick_lenght' — did "
                                 "you mean 'brick_length'? (wall.brick_length is required: expected a number > 0)\n")


def test_wall3d_opening_reported_like_2d():
    # the same running bond in the wall frame (x along, z up) as test_opening_extent_by_hand
    d = {"dimension": 3, "materials": {"m": {"E": 5e9, "nu": 0.2, "rho": 1800.0}},
         "wall3d": dict(material="m", brick_length=0.2, brick_height=0.1, brick_width=0.1, joint=0.01, courses=8,
                        bricks_per_course=6, divisions=[1, 1, 1], openings=[[0.5, 0.2, 0.78, 0.51]]),
         "stages": [{"h": 0.001, "duration": 0.002}]}
    case = expand(parse_case(d, "case.toml"))
    hits = _warned(case, "wall3d.openings[0]")
    assert len(hits) == 1 and "asked 0.28 x 0.31 m, built 0.3 x 0.45 m" in hits[0], case.warnings


def test_stage_relative_times_survive_resume_mid_stage(tmp_path, capsys):
    # checkpoints at the stage ends and every 3 steps: steps 2 (end of "settle"), 3, 6, 9, 12 (end). Resuming from
    # the one of step 9 (t = 9 ms, mid "push", which started at 2 ms) must shift the history by the stored 2 ms:
    # ux(t) = 60 mm x (t - 2 ms)/10 ms as without the interruption: 48, 54, 60 mm at steps 10, 11, 12 (a history
    # not shifted would reach its end value 60 mm at step 10)
    import shutil
    from fem_blocks.cli import main
    from fem_blocks.output.history import read_history
    path = tmp_path / "stages.toml"
    path.write_text(STAGES.format(top='history_times = "stage"', times="[0.0, 0.01]")
                    .replace("paraview = false", "paraview = false\ncheckpoint_every = 3"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    shutil.copy(out / "checkpoint.prev.npz", out / "checkpoint.npz")
    assert main(["run", str(path), "--out", str(out), "--quiet", "--resume"]) == 0
    hist = read_history(str(out / "history.csv"))
    assert list(hist["step"][-4:]) == [9, 10, 11, 12]
    assert list(hist["block.ux"][-3:]) == pytest.approx([0.048, 0.054, 0.06], abs=1e-12)
    assert "warning" not in capsys.readouterr().err


def test_3d_beam_touching_wall_without_interface_warns():
    # 2 courses of 2 bricks: the top course (half, full, half) touches the beam: 3 body pairs
    d = {"dimension": 3, "materials": {"m": {"E": 1e9, "nu": 0.2, "rho": 2000.0}},
         "wall3d": dict(material="m", brick_length=0.2, brick_height=0.1, brick_width=0.1, courses=2,
                        bricks_per_course=2, divisions=[1, 1, 1], foundation={"depth": 0.1},
                        beam={"depth": 0.1, "rho": 2000.0}),
         "interfaces": [{"between": ["bricks", "bricks"], "mu": 0.5},
                        {"between": ["bricks", "foundation"], "mu": 0.5}],
         "stages": [{"h": 0.001, "duration": 0.002}]}
    w = _contact_warnings(parse_case(d, "case.toml"))
    assert len(w) == 1 and w[0].startswith("case.toml: groups 'beam' and 'bricks': 3 pair(s) of bodies"), w


def test_positions_without_their_placement_are_reported(tmp_path):
    """`positions` is read only by placement = "positions": given with the 2D default ("overlap") or with "nodes"
    it would be ignored without a word, so the case says so; with placement = "positions" nothing is said."""
    from fem_blocks.case import load_case
    from test_run_contact import CASE
    text = CASE.replace('name = "bed"\nbetween = ["bricks", "bricks"]\n',
                        'name = "bed"\nbetween = ["bricks", "bricks"]\npositions = [0.5]\n')
    assert text != CASE
    for extra, expected in (("", "placement = 'overlap' (the 2D default)"), ('placement = "nodes"\n',
                                                                            "placement = 'nodes';")):
        p = tmp_path / "c.toml"
        p.write_text(text.replace("positions = [0.5]\n", "positions = [0.5]\n" + extra))
        w = [x for x in load_case(str(p)).warnings if "positions" in x]
        assert len(w) == 1 and "interfaces[0].positions = [0.5] is not used" in w[0] and expected in w[0], w
    p.write_text(text.replace("positions = [0.5]\n", 'positions = [0.5]\nplacement = "positions"\n'))
    assert not [x for x in load_case(str(p)).warnings if "positions" in x]

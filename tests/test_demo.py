"""Smoke tests of the `demo` command; the default demo (`make demo`) is the micro-model shear wall."""
import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402

from fem_blocks.cli import DEFAULT_DEMO, list_demos, main  # noqa: E402


def test_demo_command_quick(tmp_path):
    """`fem-blocks demo NAME --quick` end to end on the thesis' shear wall (≈ 1 min: the micro-model default takes
    ≈ 3-4 min, measured in docs/benchmarks.md, too long for the suite)."""
    out = tmp_path / "demo"
    p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", "demo", "shear_wall_fc_p030", "--quick", "--quiet",
                        "--out", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "ParaView files:" in p.stdout and "peak horizontal force" in p.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["name"].startswith("shear_wall_fc_p030") and s["peak_horizontal_force_kN"] > 0
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "history.csv", "force_displacement.png",
              "crack_pattern.png", "checkpoint.npz"):
        assert (out / f).exists(), f


def test_default_demo_is_the_micro_model_wall(capsys):
    """`make demo` runs the micro-model wall at p = 0.30 MPa with split bricks (issue #21), and its case file is
    valid: `check` builds it without running (exit 0) and lists the brick-crack interface (mixed law)."""
    assert DEFAULT_DEMO == "shear_wall_p030"
    path = list_demos()[DEFAULT_DEMO]
    assert path.endswith("demos/shear_wall_p030.toml")
    assert main(["check", path]) == 0
    text = capsys.readouterr().out
    assert "interface 'cracks'" in text and "orientation crack" in text and "law mixed" in text


# ----------------------------------------------------------------------------- 3D demos (Python, --quick)
def _demo(tmp_path, name, *extra):
    out = tmp_path / name
    p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", "demo", name, "--quick", "--out", str(out), *extra],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "ParaView files:" in p.stdout
    return out, json.loads((out / "summary.json").read_text())


def test_wall3d_tilt_quick(tmp_path):
    """Dry 6-course wall (t/H = 0.308, mu = 0.7) on a tilting base: it overturns (rotation, no sliding), the tilt
    at the collapse criterion is within +0/+8 % of the rigid-block closed form tan a = t/H = 17.10 deg (dynamic
    overshoot of the slow tilt: measured +3.5 %), and before collapse the base reaction balances the weight,
    N = W cos a to 1e-6 and T/N = tan a to 1e-6 (quasi-static; measured 1e-10), with the resultant at the rigid
    statics' position."""
    out, s = _demo(tmp_path, "wall3d_tilt")
    assert s["collapsed"] and s["top_slip_vs_rotation"] == "rotation"
    assert s["expected_mechanism"] == "overturning about the toe"
    assert abs(s["tilt_overturning_closed_form_deg"] - 17.1027) < 1e-3
    assert 0.0 <= s["relative_error_vs_closed_form"] <= 0.08
    assert s["tilt_at_collapse_deg"] < s["tilt_sliding_bound_deg"]
    assert abs(s["base_N_over_weight_cos_alpha_prestage"] - 1) <= 1e-6
    assert abs(s["base_T_over_N_minus_tan_alpha_prestage"]) <= 1e-6
    assert s["resultant_y_over_t_at_collapse"] <= 0.01  # the base resultant at the toe
    # before collapse the base resultant sits where rigid statics puts it: y/t = 1/2 - (H / 2t) tan a (1e-3)
    assert s["resultant_vs_rigid_statics_max_abs"] <= 1e-3
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "history.csv", "wall_at_collapse.png",
              "tilt_displacement.png"):
        assert (out / f).exists(), f


@pytest.mark.parametrize("joints", ["dry", "brittle"])
def test_dome_quick(tmp_path, joints):
    """4-course dome on 4 piers, 1 hexahedron per block (quick): dry joints let exactly the blocks over the pier
    gaps fall (10 bed blocks, 3 + 2 + 2 + 3, and the 6 course-1 blocks bridging them), the piers then carry
    the rest: pier reaction / weight = 1 - loose weight fraction to 1e-3; brittle adhesion (r_c = 0.4 MPa,
    thesis §7.2.2.a) holds every block and the piers carry the whole weight. Updated contact geometry (co-rotational
    blocks, the wedge joints' as-built offsets): every hexahedron edge within 1e-4 of its length (observed 9.0e-6 dry,
    1.2e-5 brittle: elastic, the same in frozen geometry)."""
    out, s = _demo(tmp_path, "dome", "--joints", joints)
    assert s["joints"] == joints and s["blocks"] == 88
    assert s["geometry"] == "updated" and s["max_edge_change"] <= 1e-4
    if joints == "dry":
        assert s["loose_blocks"] == 16 and s["loose_bed_blocks_not_on_piers"] == 10
        assert s["max_fall_m"] > 1e-3
    else:
        assert s["loose_blocks"] == 0 and s["max_fall_m"] < 1e-4
    assert abs(s["pier_reaction_over_weight"] - (1 - s["loose_weight_fraction"])) <= 1e-3
    for f in ("paraview/blocks.pvd", "paraview/contacts.pvd", "history.csv", "dome.png"):
        assert (out / f).exists(), f


def test_demo_options_passed_or_rejected():
    """A .py demo's own options go to its main(out, quick, argv); a demo without them, or `run`, rejects
    extra arguments with exit status 2 and one line naming them."""
    for args in (["demo", "prism", "--joints", "dry"], ["run", "x.toml", "--out", "o", "--joints", "dry"]):
        p = subprocess.run([sys.executable, "-m", "fem_blocks.cli", *args], capture_output=True, text=True, cwd=ROOT,
                           timeout=120)
        assert p.returncode == 2 and "unrecognized arguments" in p.stderr and "--joints" in p.stderr, p.stderr

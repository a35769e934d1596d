"""Smoke tests of the `demo` command; the default demo (`make demo`) is the micro-model shear wall."""
import json
import math
import subprocess
import sys

import pytest

pytestmark = pytest.mark.dolfinx
from _paths import ROOT  # noqa: E402

from fem_blocks.cli import DEFAULT_DEMO, list_demos, main  # noqa: E402


def test_demo_command_quick(tmp_path, cli):
    """`fem-blocks demo NAME --quick` end to end on the thesis' shear wall (≈ 15 s: the micro-model default takes
    ≈ 3-4 min, measured in docs/benchmarks.md, too long for the suite)."""
    out = tmp_path / "demo"
    p = cli("demo", "shear_wall_fc_p030", "--quick", "--quiet", "--out", out)  # in this process: conftest.cli
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
def _demo(tmp_path, cli, name, *extra):
    out = tmp_path / name
    p = cli("demo", name, "--quick", "--out", out, *extra)
    assert p.returncode == 0, p.stderr
    assert "ParaView files:" in p.stdout
    return out, json.loads((out / "summary.json").read_text())


def test_wall3d_tilt_case_is_valid(capsys):
    """demos/wall3d_tilt.toml (the 3D tilting table from a case file; its --quick run takes ≈ 80 s, too long for the
    suite: docs/benchmarks.md) builds without running: the slab turns about a pivot and the tilt stage may stop at a
    rotation."""
    assert main(["check", list_demos()["wall3d_tilt"]]) == 0
    text = capsys.readouterr().out
    assert "stages[1].drivers.foundation.rx.pivot: drives foundation.y" in text
    assert "may stop early at a rotation" in text


def _tipping_lag(b, h, omega, psi):
    """Tilt [rad] by which a stop at a rotation psi relative to the table lags the tipping of a rigid b x h block on a
    table turning at omega: omega tau with omega (sinh(p tau)/p - tau) = psi, p^2 = 3 g / (4 R), R = half-diagonal
    (the small-angle solution of psi'' = p^2 sin(omega tau + psi) from rest at tipping)."""
    from scipy.optimize import brentq
    p = math.sqrt(3 * 9.81 / (4 * 0.5 * math.hypot(b, h)))
    return omega * brentq(lambda t: omega * (math.sinh(p * t) / p - t) - psi, 1e-12, 50.0, xtol=1e-15)


def test_tilting_table_quick(tmp_path, cli):
    """2D case-file demo (demos/tilting_table.toml, --quick ≈ 20 s): the table turns about its hinge (pivot driver),
    the stage stops when the block has turned by 2e-4 rad relative to the table; the table's angle then, read from
    summary.json, has tan within [0, +1 %] of b/h = 1/3, and within 0.2 % once the closed-form lag of the stop
    (1.07e-3 rad at 0.005 rad/s) is taken off (measured +0.35 % and -0.007 %); the block then falls to 0.35 rad."""
    out, s = _demo(tmp_path, cli, "tilting_table")
    assert s["exit_status"] == 0
    tilt, fall = s["stages"]
    assert tilt["stopped"].startswith("rotation") and fall["stopped"].startswith("rotation")
    a = -tilt["stop_rotation"]["relative_to_rotation_rad"]  # clockwise tilt of the table
    assert 0.0 <= math.tan(a) / (0.2 / 0.6) - 1 <= 0.01
    lag = _tipping_lag(0.2, 0.6, 0.005, tilt["stop_rotation"]["relative_angle_rad"])  # to the angle recorded
    assert math.tan(a - lag) == pytest.approx(0.2 / 0.6, rel=2e-3)
    assert fall["stop_rotation"]["relative_angle_rad"] >= 0.35
    for f in ("history.csv", "rotations.png", "crack_pattern.png", "paraview/blocks.pvd"):
        assert (out / f).exists(), f


@pytest.mark.parametrize("joints", ["dry", "brittle"])
def test_dome_quick(tmp_path, cli, joints):
    """4-course dome on 4 piers, 1 hexahedron per block (quick): dry joints let exactly the blocks over the pier
    gaps fall (10 bed blocks, 3 + 2 + 2 + 3, and the 6 course-1 blocks bridging them), the piers then carry
    the rest: pier reaction / weight = 1 - loose weight fraction to 1e-3; brittle adhesion (r_c = 0.4 MPa,
    thesis §7.2.2.a) holds every block and the piers carry the whole weight. Updated contact geometry (co-rotational
    blocks, the wedge joints' as-built offsets): every hexahedron edge within 1e-4 of its length (observed 9.0e-6 dry,
    1.2e-5 brittle: elastic, the same in frozen geometry)."""
    out, s = _demo(tmp_path, cli, "dome", "--joints", joints)
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

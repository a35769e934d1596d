"""[[reference]]: measured or published curves, bands and peaks on force_displacement.png and the model/reference
peak ratio in summary.json.

* the comparison (output/summary.reference_comparison) against numbers computed by hand on small synthetic curves;
* the parser (case._parse_reference): inline points, the CSV reader (header, named columns, separators,
  comments) and the unit conversion (mm-N-MPa: mm -> m, N mm -> N m for a moment), to the figure's units
  (figures.reference_data: kN, mm);
* the figure holds the reference artists (dashed line, shaded band, horizontal peak band) with the labels;
* a run writes the block into summary.json and the PNG;
* bad input: each error names the key (the CLI side, exit status 2 and one line, is tests/bad_cases/17x-18x).
"""
import json
import os
import tomllib

import numpy as np
import pytest

from fem_blocks.case import parse_case
from fem_blocks.errors import InputError
from fem_blocks.output.figures import reference_data
from fem_blocks.output.plots import curve_figure
from fem_blocks.output.summary import reference_comparison

BASE = """
UNITS
[materials.m]
E = 1e9
nu = 0.2
rho = 1000.0
[block_types.t]
geometry = "rectangle"
lx = 1.0
ly = 0.2
mesh_size = 0.2
material = "m"
[[blocks]]
type = "t"
[[rigid_bodies]]
name = "base"
vertices = [[-1.0, -0.1], [2.0, -0.1], [2.0, 0.0], [-1.0, 0.0]]
[rigid_bodies.drivers]
x = {kind = "velocity", history = 0.0}
y = {kind = "velocity", history = 0.0}
rz = {kind = "velocity", history = 0.0}
[output.curve]
body = "base"
force = "FDOF"
displacement = "DDOF"
[[stages]]
duration = 0.002
h = 0.001
"""


MM = {"E = 1e9": "E = 1000.0", "rho = 1000.0": "rho = 1e-9", "lx = 1.0": "lx = 1000.0", "ly = 0.2": "ly = 200.0",
      "mesh_size = 0.2": "mesh_size = 200.0",  # the same case in mm-N-MPa
      "[[-1.0, -0.1], [2.0, -0.1], [2.0, 0.0], [-1.0, 0.0]]":
      "[[-1e3, -100.0], [2e3, -100.0], [2e3, 0.0], [-1e3, 0.0]]"}


def _case(tmp_path, ref: str, units: str = "", force="x", disp="x"):
    text = BASE.replace("UNITS", units).replace("FDOF", force).replace("DDOF", disp) + ref
    if units:
        for a, b in MM.items():
            text = text.replace(a, b)
    path = tmp_path / "c.toml"
    path.write_text(text)
    return parse_case(tomllib.loads(text), str(path))


def _err(tmp_path, ref: str, **kw) -> str:
    with pytest.raises(InputError) as e:
        _case(tmp_path, ref, **kw)
    return str(e.value)


# ----------------------------------------------------------------------------- the comparison, by hand
MODEL_X = np.array([0.0, 0.5, 1.0, 1.5, 2.0])      # mm
MODEL_Y = np.array([0.0, 30.0, 55.0, 52.0, 40.0])  # kN: peak 55 at 1.0


def _ref(**kw):
    d = dict(label="L", curve=None, lower=None, upper=None, band=None, peak=None, peak_band=None,
             displacement_at_peak=None)
    d.update(kw)
    return d


def test_peak_band_ratio_to_the_middle_and_inside():
    r = reference_comparison(MODEL_X, MODEL_Y, _ref(peak_band=(45.0, 55.0)))
    assert r["model_peak_kN"] == 55.0 and r["model_displacement_at_peak_mm"] == 1.0
    assert r["reference_peak_kN"] is None and r["reference_band_kN"] == [45.0, 55.0]
    assert r["ratio"] == pytest.approx(55.0 / 50.0, rel=1e-15) and r["ratio_to"] == "band middle"
    assert r["inside_band"] is True  # 55 <= 55: the upper end belongs to the band
    r = reference_comparison(MODEL_X, MODEL_Y, _ref(peak_band=(120.0, 140.0)))
    assert r["ratio"] == pytest.approx(55.0 / 130.0, rel=1e-15) and r["inside_band"] is False


def test_peak_with_relative_band_and_displacement():
    r = reference_comparison(MODEL_X, MODEL_Y, _ref(peak=50.0, band=0.1, displacement_at_peak=0.8))
    assert r["reference_peak_kN"] == 50.0 and r["reference_band_kN"] == pytest.approx([45.0, 55.0], rel=1e-15)
    assert r["ratio"] == pytest.approx(1.1, rel=1e-15) and r["ratio_to"] == "peak" and r["inside_band"] is True
    assert r["reference_displacement_at_peak_mm"] == 0.8
    r = reference_comparison(MODEL_X, MODEL_Y, _ref(peak=50.0))
    assert r["reference_band_kN"] is None and r["inside_band"] is None and r["ratio"] == pytest.approx(1.1)


def test_curve_peak_is_its_largest_magnitude_and_signs_do_not_matter():
    # a push in -x: the model and the reference both negative; the reference's peak |F| = 60 at |d| = 1.2
    ref = _ref(curve=(np.array([0.0, -0.6, -1.2, -2.0]), np.array([0.0, -40.0, -60.0, -35.0])), band=0.25)
    r = reference_comparison(-MODEL_X, -MODEL_Y, ref)
    assert r["model_peak_kN"] == 55.0 and r["model_displacement_at_peak_mm"] == 1.0
    assert r["reference_peak_kN"] == 60.0 and r["reference_displacement_at_peak_mm"] == 1.2
    assert r["ratio"] == pytest.approx(55.0 / 60.0, rel=1e-15)
    assert r["reference_band_kN"] == pytest.approx([45.0, 75.0], rel=1e-15) and r["inside_band"] is True


def test_lower_upper_band_is_their_peaks():
    ref = _ref(curve=(np.array([0.0, 1.0, 2.0]), np.array([0.0, 50.0, 45.0])),
               lower=(np.array([0.0, 1.0, 2.0]), np.array([0.0, 42.0, 30.0])),
               upper=(np.array([0.0, 0.9, 2.0]), np.array([0.0, 58.0, 50.0])))
    r = reference_comparison(MODEL_X, MODEL_Y, ref)
    assert r["reference_band_kN"] == [42.0, 58.0] and r["inside_band"] is True
    assert r["ratio"] == pytest.approx(1.1, rel=1e-15) and r["ratio_to"] == "peak"


def test_non_finite_model_points_are_skipped_and_no_data_gives_no_ratio():
    y = MODEL_Y.copy()
    y[3] = np.nan
    assert reference_comparison(MODEL_X, y, _ref(peak=50.0))["model_peak_kN"] == 55.0
    r = reference_comparison([], [], _ref(peak=50.0))
    assert r["model_peak_kN"] is None and r["ratio"] is None


def test_units_in_the_keys():
    r = reference_comparison([0.0, 0.01], [0.0, 2.0], _ref(peak=4.0), "kNm", "rad", "rotation")
    assert r["model_peak_kNm"] == 2.0 and r["model_rotation_at_peak_rad"] == 0.01 and r["ratio"] == 0.5


# ----------------------------------------------------------------------------- parsing, CSV, units
def test_inline_points_si_and_to_figure_units(tmp_path):
    c = _case(tmp_path, '[[reference]]\nlabel = "L"\npoints = [[0.0, 0.0], [0.001, 5e4], [0.002, 3e4]]\n')
    (r,) = c.references
    assert r.points == [(0.0, 0.0), (0.001, 5e4), (0.002, 3e4)] and r.key == "reference[0]"
    (d,) = reference_data(c.references, "Rx", "ux")
    assert np.allclose(d["curve"][0], [0.0, 1.0, 2.0], rtol=1e-15) and np.allclose(d["curve"][1], [0, 50, 30])


def test_csv_header_named_columns_mm(tmp_path):
    (tmp_path / "ref.csv").write_text("# test data, approximate\ntime; force_N ;disp_mm\n0;0;0\n1;2000;0.5\n"
                                      "\n2;5000;1.5\n")
    c = _case(tmp_path, '[[reference]]\nlabel = "L"\nfile = "ref.csv"\ncolumns = ["disp_mm", "force_N"]\n',
              units='units = "mm-N-MPa"')
    (r,) = c.references
    assert r.file == str(tmp_path / "ref.csv") and r.columns == ["disp_mm", "force_N"]
    assert np.allclose(r.points, [(0.0, 0.0), (0.5e-3, 2000.0), (1.5e-3, 5000.0)], rtol=1e-15, atol=0)


def test_csv_first_two_columns_no_header_and_moment_units(tmp_path):
    # mm-N-MPa: a rotation is in rad, a moment in N mm -> N m (x 1e-3)
    (tmp_path / "m.csv").write_text("0.0, 0.0, 9\n0.01, 3000.0, 9\n0.02, 4000.0, 9\n")
    c = _case(tmp_path, '[[reference]]\nlabel = "L"\nfile = "m.csv"\n[[reference]]\nlabel = "P"\npeak = 5000.0\n'
              'displacement_at_peak = 0.015\n', units='units = "mm-N-MPa"', force="rz", disp="rz")
    r, p = c.references
    assert np.allclose(r.points, [(0.0, 0.0), (0.01, 3.0), (0.02, 4.0)], rtol=1e-15, atol=0)
    assert p.peak == pytest.approx(5.0, rel=1e-15) and p.displacement_at_peak == 0.015  # rad: no conversion
    d = reference_data(c.references, "Rrz", "urz")
    assert np.allclose(d[0]["curve"][1], [0.0, 3e-3, 4e-3]) and d[1]["peak"] == pytest.approx(5e-3)


def test_peak_band_in_kN(tmp_path):
    c = _case(tmp_path, '[[reference]]\nlabel = "L"\npeak_band = [120e3, 140e3]\n')
    (d,) = reference_data(c.references, "Rx", "ux")
    assert d["peak_band"] == pytest.approx((120.0, 140.0), rel=1e-15) and d["curve"] is None


@pytest.mark.parametrize("ref, key, what", [
    ('points = [[0, 0], [1, 1]]', "reference[0].label", "missing"),
    ('label = " "\npoints = [[0, 0], [1, 1]]', "reference[0].label", "non-empty"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\nfile = "x.csv"', "reference[0].file", "not both"),
    ('label = "L"', "reference[0].points", "expected a curve"),
    ('label = "L"\nfile = "nope.csv"', "reference[0].file", "file not found"),
    ('label = "L"\npoints = [[0, 0]]', "reference[0].points", "at least 2"),
    ('label = "L"\npoints = [[0, 0], [1]]', "reference[0].points", "pairs"),
    ('label = "L"\npoints = [[0, 0], [1, 1], [1, 2]]', "reference[0].points", "strictly monotone"),
    ('label = "L"\npoints = [[0, 0], [1, 1], [0.5, 2]]', "reference[0].points", "(1 then 0.5)"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\nband = -0.1', "reference[0].band", ">= 0"),
    ('label = "L"\npeak_band = [60e3, 40e3]', "reference[0].peak_band", "Fmin < Fmax"),
    ('label = "L"\npeak_band = [-1.0, 40e3]', "reference[0].peak_band", "0 <= Fmin"),
    ('label = "L"\npeak_band = [1.0]', "reference[0].peak_band", "two finite numbers"),
    ('label = "L"\npeak = 0.0', "reference[0].peak", "> 0"),
    ('label = "L"\npeak = 5.0\npoints = [[0, 0], [1, 1]]', "reference[0].peak", "not both"),
    ('label = "L"\npeak_band = [1.0, 2.0]\nband = 0.1', "reference[0].band", "not both"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\nlower = [[0, 0], [1, 1]]', "reference[0].upper", "together"),
    ('label = "L"\npeak = 5.0\nlower = [[0, 0], [1, 1]]', "reference[0].lower", "only with a curve"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\ncolumns = ["a", "b"]', "reference[0].columns", "only with file"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\ndisplacement_at_peak = 1.0', "reference[0].displacement_at_peak",
     "peak-only"),
    ('label = "L"\npoints = [[0, 0], [1, 1]]\nlable = "x"', "reference[0].lable", "unknown key"),
])
def test_bad_reference_names_the_key(tmp_path, ref, key, what):
    msg = _err(tmp_path, "[[reference]]\n" + ref + "\n")
    assert key in msg and what in msg, msg


@pytest.mark.parametrize("csv, cols, key, what", [
    ("d,F\n0,0\n1,x\n", None, "reference[0].file", "line 3: expected finite numbers"),
    ("d,F\n0,0\n1,nan\n", None, "reference[0].file", "line 3"),
    ("d,F\n0,0\n", None, "reference[0].file", "at least 2 data rows"),
    ("d,F\n0,0\n2,1\n1,3\n", None, "reference[0].file", "strictly monotone in 'r.csv'"),
    ("d,F\n0,0\n1,1\n", '["d", "force"]', "reference[0].columns", "no column 'force'"),
    ("0,0\n1,1\n", '["d", "F"]', "reference[0].columns", "no header line"),
    ("d\n0\n1\n", None, "reference[0].file", "line 2: expected at least 2 columns"),
    ("d,F\n0,0\n1,1\n", '["d"]', "reference[0].columns", "two column names"),
])
def test_bad_csv_names_the_key(tmp_path, csv, cols, key, what):
    (tmp_path / "r.csv").write_text(csv)
    msg = _err(tmp_path, '[[reference]]\nlabel = "L"\nfile = "r.csv"\n' + (f"columns = {cols}\n" if cols else ""))
    assert key in msg and what in msg, msg


def test_unreadable_csv(tmp_path):
    (tmp_path / "r.csv").write_bytes(b"\xff\xfe\x00\x81 not text\n")
    msg = _err(tmp_path, '[[reference]]\nlabel = "L"\nfile = "r.csv"\n')
    assert "reference[0].file" in msg and "unreadable" in msg, msg


def test_reference_needs_the_curve(tmp_path):
    text = BASE.replace("UNITS", "").replace("[output.curve]\nbody = \"base\"\nforce = \"FDOF\"\n"
                                             "displacement = \"DDOF\"\n", "")
    text += '[[reference]]\nlabel = "L"\npeak = 5.0\n'
    with pytest.raises(InputError, match=r"reference\[0\]: expected an \[output.curve\]"):
        parse_case(tomllib.loads(text), str(tmp_path / "c.toml"))


# ----------------------------------------------------------------------------- the figure
def test_figure_holds_the_reference_artists():
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Polygon, Rectangle
    refs = [_ref(label="curve, +-10 %", curve=(np.array([0.0, 1.0, 2.0]), np.array([0.0, 50.0, 40.0])), band=0.1),
            _ref(label="peak band", peak_band=(45.0, 55.0)),
            _ref(label="peak", peak=52.0, displacement_at_peak=1.1)]
    fig = curve_figure(MODEL_X, -MODEL_Y, "d [mm]", "F [kN]", references=refs)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["curve, +-10 %", "peak band", "peak", "model"]
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert [ln.get_label() for ln in dashed] == ["curve, +-10 %", "peak"]
    assert np.allclose(dashed[0].get_ydata(), [0.0, 50.0, 40.0])
    assert dashed[1].get_ydata()[0] == -52.0  # a peak magnitude is drawn on the side of the model's peak (F < 0)
    assert any(isinstance(c, PolyCollection) for c in ax.collections)  # the +-10 % band around the curve
    spans = [p for p in ax.patches if isinstance(p, (Polygon, Rectangle))]
    ys = sorted(np.round(v, 9) for p in spans for v in np.asarray(p.get_xy() if isinstance(p, Polygon)
                                                                     else p.get_bbox().get_points())[:, 1])
    assert -55.0 in ys and -45.0 in ys and ax.get_ylim()[0] <= -55.0  # the band, in view
    sq = [ln for ln in ax.get_lines() if ln.get_marker() == "s"]
    assert len(sq) == 1 and sq[0].get_xdata()[0] == 1.1 and sq[0].get_ydata()[0] == -52.0


def test_figure_without_references_unchanged():
    fig = curve_figure(MODEL_X, MODEL_Y, "d", "F")
    assert fig.axes[0].get_legend() is None and tuple(fig.get_size_inches()) == (6.4, 4.2)


# ----------------------------------------------------------------------------- a run
@pytest.mark.dolfinx
def test_run_writes_the_reference_block_and_the_png(tmp_path, capsys):
    from tests.test_convergence_report import CASE
    from fem_blocks.cli import main
    ref = ('[[reference]]\nlabel = "assumed, for the test"\npeak_band = [10.0, 20.0]\n'
           '[[reference]]\nlabel = "curve"\npoints = [[0.0, 0.0], [-1e-6, -30.0]]\n')
    path = tmp_path / "r.toml"
    path.write_text(CASE.replace("SOLVER", "nlgs").replace("TOL", "1e-8").replace("max_sweeps = 1",
                                                                                  "max_sweeps = 100000") + ref)
    rc = main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert rc == 0 and os.path.getsize(tmp_path / "out" / "force_displacement.png") > 0
    band, curve = s["reference"]
    Fm = s["peak_force_kN"]
    assert band["label"] == "assumed, for the test" and band["model_peak_kN"] == Fm
    assert band["reference_band_kN"] == [0.01, 0.02] and band["ratio"] == pytest.approx(Fm / 0.015, rel=1e-12)
    assert band["inside_band"] == (0.01 <= Fm <= 0.02)
    assert curve["reference_peak_kN"] == 0.03 and curve["reference_displacement_at_peak_mm"] == pytest.approx(1e-3)
    assert curve["ratio"] == pytest.approx(Fm / 0.03, rel=1e-12) and curve["ratio_to"] == "peak"


def test_variant_replaces_or_unsets_the_base_references(tmp_path):
    from fem_blocks.case import load_case
    (tmp_path / "base.toml").write_text(BASE.replace("UNITS", "").replace("FDOF", "x").replace("DDOF", "x")
                                        + '[[reference]]\nlabel = "base"\npeak = 5.0\n')
    (tmp_path / "v.toml").write_text('extends = "base.toml"\n[[reference]]\nlabel = "v"\npeak_band = [1.0, 2.0]\n')
    (tmp_path / "u.toml").write_text('extends = "base.toml"\nunset = ["reference"]\n')
    assert [r.label for r in load_case(str(tmp_path / "base.toml")).references] == ["base"]
    assert [(r.label, r.peak_band) for r in load_case(str(tmp_path / "v.toml")).references] == [("v", (1.0, 2.0))]
    assert load_case(str(tmp_path / "u.toml")).references == []

"""The softening branch of force_displacement.png and summary.json `post_peak` (output/figures.post_peak, read once
by the figure and the summary; docs/case-files.md "[output] figures").

Closed form: a curve rising as F = k d to the peak F_p at d_p, then falling linearly with slope -s. The force is
0.85 F_p at d_85 = d_p + 0.15 F_p / s; at the end d_e it is F_p - s (d_e - d_p). Sampled on rows that do not fall
on d_85, the linear interpolation between rows is exact on the linear branch (1e-12). Catches: the first crossing
before the peak taken (the rising branch passes 0.85 F_p too), the interpolation done the wrong way round, the
signs of a curve in the third quadrant, the end taken as the last row instead of the last finite one."""
import json

import numpy as np
import pytest

from fem_blocks.output.figures import post_peak, post_peak_summary
from fem_blocks.output.plots import curve_figure


def _curve(dx=0.07, k=50.0, Fp=60.0, s=10.0, de=4.0):
    dp = Fp / k
    d = np.union1d(np.arange(0.0, de + 1e-12, dx), [dp])  # rows every dx, and the peak on a row
    return d, np.where(d <= dp, k * d, Fp - s * (d - dp)), dp


def test_linear_softening_closed_form():
    k, Fp, s = 50.0, 60.0, 10.0
    d, F, dp = _curve(k=k, Fp=Fp, s=s)
    assert np.all(np.diff(d) > 0)
    pp = post_peak(d, F)
    assert pp["peak"] == Fp and pp["d_peak"] == pytest.approx(dp, abs=1e-15)
    assert pp["d_drop"] == pytest.approx(dp + 0.15 * Fp / s, rel=1e-12)
    assert pp["f_drop"] == pytest.approx(0.85 * Fp, rel=1e-15)
    assert pp["end"] == pytest.approx(Fp - s * (d[-1] - dp), rel=1e-12) and pp["d_end"] == d[-1]
    assert pp["end_ratio"] == pytest.approx(pp["end"] / Fp, rel=1e-15)
    # third quadrant (a push in -x): magnitudes the same, the marked point signed
    nn = post_peak(-d, -F)
    assert nn["d_drop"] == pytest.approx(pp["d_drop"], rel=1e-12) and nn["x_drop"] == -nn["d_drop"]
    assert nn["y_drop"] == pytest.approx(-0.85 * Fp)
    # a NaN last row: the end is the last finite row
    d2, F2 = np.r_[d, d[-1] + 0.1], np.r_[F, np.nan]
    assert post_peak(d2, F2)["d_end"] == d[-1]
    ssum = post_peak_summary(pp, "mm", "kN")
    assert ssum == {"end_force_kN": pp["end"], "end_displacement_mm": pp["d_end"], "end_to_peak": pp["end_ratio"],
                    "drop_fraction": 0.85, "displacement_at_85_percent_post_peak_mm": pp["d_drop"]}


def test_no_drop_and_no_data():
    d = np.linspace(0, 2, 21)
    pp = post_peak(d, 10 * d)  # still rising: the peak is the end, no post-peak point
    assert pp["d_drop"] is None and pp["end_ratio"] == 1.0 and pp["k"] == 20
    pp = post_peak(d, np.minimum(10 * d, 10.0 - 0.5 * np.maximum(d - 1, 0)))  # 95 % at the end: above 85 %
    assert pp["d_drop"] is None and pp["end_ratio"] == pytest.approx(0.95)
    assert post_peak([np.nan], [1.0]) is None


def test_the_figure_marks_the_read_out():
    d, F, dp = _curve()
    pp = post_peak(d, F)
    fig = curve_figure(d, F, "d [mm]", "F [kN]", softening=pp, units=("mm", "kN"))
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[0] == f"post-peak: 85 % of the peak at {pp['d_drop']:.3g} mm"
    assert labels[1].startswith(f"end: {pp['end']:.4g} kN ({100 * pp['end_ratio']:.0f} % of the peak)")
    tri = [ln for ln in ax.get_lines() if ln.get_marker() == "v"]
    assert len(tri) == 1 and tri[0].get_xdata()[0] == pp["x_drop"] and tri[0].get_ydata()[0] == pp["y_drop"]


@pytest.mark.dolfinx
def test_run_summary_reads_the_same_numbers(tmp_path):
    """A monotone run: summary.json `post_peak` is post_peak of the curve in history.csv (beam.uy, beam.Ry)."""
    from tests.test_convergence_report import CASE
    from fem_blocks.cli import main
    from fem_blocks.output.history import read_history
    path = tmp_path / "r.toml"
    path.write_text(CASE.replace("SOLVER", "nlgs").replace("TOL", "1e-8").replace("max_sweeps = 1",
                                                                                  "max_sweeps = 100000"))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    h = read_history(tmp_path / "out" / "history.csv")
    cv = s["post_peak"]
    ref = post_peak(1e3 * np.asarray(h["beam.uy"]), 1e-3 * np.asarray(h["beam.Ry"]))  # [output.curve] of CASE
    assert cv["end_force_kN"] == ref["end"] and cv["end_to_peak"] == ref["end_ratio"]
    assert "cycles" not in s

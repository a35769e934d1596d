"""Couplet direct tension: the tensile bond strength f_t,b of a bed joint and its force–opening curve.

Standard (as recalled; its text is not in the repository): EN 1052-5 standardises the bond wrench (lab/bond_wrench.py);
the direct tension of a couplet glued to steel plates is the research test of the same property (e.g. van der
Pluijm's deformation-controlled tests, as recalled). Its read-out:

    f_t,b = F_max / A,      A = L t  (the joint's area: brick length L in the plane x the thickness t)

The specimen (lab/bond.py): two bricks and one bed joint; a steel plate `base` glued under the lower brick (fixed),
a steel plate `cap` glued on the upper brick and pulled along +y under displacement control from 0 to `pull` (x and
rotation held: a fixed-end test, the joint opens uniformly). The glue (elastic law, lab/bond.py) carries tension and
never fails; it is in series with the joint, so the force is the joint's.

Read-out: F = the cap's reaction less its inertial part (history `cap.Ry − cap.Iy`); the joint's opening δ from the
bricks (rigid: their displacements; deformable: gauges at the joint's faces at x = L/2); f_t,b = max F / A; and, when
the joint has separated (the last force ≤ SEPARATED × F_max), the work of separation per unit area
G_f = ∫ F dδ / A (trapezoidal rule over the rows), which for the mixed law measures G_I (pure mode I dissipates G_I).
Closed forms (tests/test_lab_bond.py): rigid bricks, any mesh: F_max = f_t A (every point of the joint opens by the
same δ and peaks at δ_I = f_t/k_n together); G_f = G_I.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..specs import spec
from . import bond
from .readout import peak_problems as peak_messages
from .specimen import SpecimenSpec

STANDARD = "couplet direct tension (the tensile bond strength; EN 1052-5, as recalled, standardises the bond wrench)"
SEPARATED = 0.01   # the joint counts as separated when the last force is at most this fraction of the peak (assumed)


@dataclass
class TensionSpec(SpecimenSpec):
    pull: float = spec(0.2e-3, doc="displacement of the cap plate along +y (the pull: past the peak and through the "
                                   "softening of the joint, e.g. a few times 2 G_I / f_t for the mixed law)",
                       unit="length", lo=0.0, lo_open=True)


SPEC = TensionSpec


def read_lists(t, U) -> dict:
    return {}


def check(s: TensionSpec, t) -> None:
    """Nothing beyond the keys' ranges: any positive brick holds the specimen."""


def joint_area(s, case) -> float:
    return s.brick_length * case.materials[s.material].thickness


def specimens(s: TensionSpec, emitter):
    """One specimen (module docstring)."""
    L, H = s.brick_length, bond.height(s)
    d = 0.5 * H
    e = emitter("couplet")
    e.brick("lower", 0.0, 0.0, L, H)
    e.brick("upper", 0.0, H, L, H)
    e.plate("base", 0.0, -d, L, 0.0)
    e.plate("cap", 0.0, 2 * H, L, 2 * H + d,
            drivers={"y": ("displacement", dict(times=[0.0, 1.0], values=[0.0, s.pull]))})
    bond.glue(e, s)
    e.stage("pull", s.steps)
    e.defaults("contact", solver="newton", tol=1e-10, max_sweeps=5000)
    e.defaults("output", joints=[["lower", "upper"]], curve=dict(body="cap", force="y", displacement="y"))
    bond.add_gauges(e, s, [0.5 * L])
    return [("couplet", e.data, dict(pull_m=float(s.pull)))]


def curves(s: TensionSpec, run: dict) -> dict:
    """Opening δ [m] at the joint's middle, the force F [N] (cap reaction less inertia, > 0 pulling) and the joint's
    normal force −N [N] (> 0 in tension, from the joint resultant), per row."""
    h = run["history"]
    return dict(opening=bond.opening_at(s, h, [0.5 * s.brick_length])[:, 0],
                force=h["cap.Ry"] - h["cap.Iy"], joint=-h["lower|upper.N"], pull=h["cap.uy"])


def tension_readout(opening, force, area: float) -> dict:
    """f_t,b = max F / A; the opening at the peak; G_f = ∫ F dδ / A (trapezoidal) when the last force is at most
    SEPARATED × F_max, else NaN (the joint still carries load: the work would include stored elastic energy)."""
    u, F = np.asarray(opening, dtype=float), np.asarray(force, dtype=float)
    k = int(np.argmax(F))
    sep = bool(F[-1] <= SEPARATED * F[k])
    work = float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(u)))
    return dict(F_max_N=float(F[k]), f_tb_Pa=float(F[k] / area), opening_at_peak_m=float(u[k]), peak_row=k,
                separated=sep, G_f_J_m2=work / area if sep else float("nan"), last_force_N=float(F[-1]))


def specimen_line(s: TensionSpec, run: dict) -> str:
    c = curves(s, run)
    A = joint_area(s, run["case"])
    bad = peak_problems(c["force"])
    return (f"peak F = {np.nanmax(c['force']):.6g} N, f_t,b = {np.nanmax(c['force']) / A / 1e6:.4f} MPa"
            + "".join(f"; WARNING: {b}: f_t,b is not a strength" for b in bad))


def peak_problems(force) -> list:
    """Why the largest F is no peak: it is at the last row (still rising: the pull ended before the peak) or the
    joint never carried tension (F <= 0)."""
    return peak_messages(force, "the joint never carried tension (F <= 0)",
                         "F was still rising at the end of the pull: the peak was not reached (increase lab.pull)")


def readout(s: TensionSpec, runs: list) -> dict:
    r = runs[0]
    c, A = curves(s, r), joint_area(s, r["case"])
    rep = tension_readout(c["opening"], c["force"], A)
    key, ft = bond.strength_input(s, r["case"])
    p = next(i for i in r["case"].interfaces if i.name == "joint").params
    q = {"f_tb": dict(value=rep["f_tb_Pa"], unit="Pa", name="tensile bond strength F_max / A",
                      measures=key or "the joint's tensile strength", input=ft),
         "F_max": dict(value=rep["F_max_N"], unit="N", name="peak tensile force (for the material's thickness)"),
         "opening_at_peak": dict(value=rep["opening_at_peak_m"], unit="m", name="joint opening at the peak")}
    if np.isfinite(rep["G_f_J_m2"]):
        q["G_f"] = dict(value=rep["G_f_J_m2"], unit="J/m2", name="work of separation per unit area ∫ F dδ / A",
                        measures=f"laws.{s.joint}.G_I" if "G_I" in p else "the joint's mode I fracture energy",
                        input=p.get("G_I"))
    rep["warnings"] = peak_problems(c["force"])
    if rep["warnings"]:   # no peak: the strength must not look like a result
        for k in ("f_tb", "F_max", "opening_at_peak"):
            q[k]["value"] = float("nan")
        q["f_tb"]["name"] += " — NOT REACHED: " + "; ".join(rep["warnings"])
    rep["quantities"] = q
    rep["joint_area_m2"] = A
    return rep


def plot(s: TensionSpec, report: dict, runs: list, path: str, title: str = ""):
    """PNG: the tensile stress F / A against the joint's opening, the peak f_t,b marked, the input strength dashed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c, A = curves(s, runs[0]), report["joint_area_m2"]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.plot(c["opening"] * 1e3, c["force"] / A / 1e6, "-", lw=1.3, label="F / A (cap plate)")
    k = report["peak_row"]
    ax.plot([c["opening"][k] * 1e3], [report["f_tb_Pa"] / 1e6], "o", mfc="none", ms=8,
            label=f"f_t,b = F_max / A = {report['f_tb_Pa'] / 1e6:.4f} MPa")
    ft = report["quantities"]["f_tb"].get("input")
    if ft is not None:
        ax.axhline(ft / 1e6, ls="--", lw=0.8, color="k", label=f"input {report['quantities']['f_tb']['measures']} = "
                   f"{ft / 1e6:g} MPa")
    g = report["quantities"].get("G_f")
    if g is not None:
        ax.fill_between(c["opening"] * 1e3, 0, c["force"] / A / 1e6, alpha=0.12,
                        label=f"G_f = ∫F dδ / A = {g['value'] * 1e-3:.4g} N/mm")
    ax.set(xlabel="joint opening δ [mm]", ylabel="tensile stress F / A [MPa]", ylim=(0, None),
           title=f"{title}: couplet direct tension")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

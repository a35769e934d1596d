"""ASTM E519 / RILEM diagonal compression (diagonal tension) of a square running-bond panel: the shear strength
S_s and the modulus of rigidity G of the masonry assembly, and its crack pattern.

The test (docs/lab-tests.md; the standards' texts are not in the repository, their details as recalled): a square
panel loaded in compression along one diagonal by two steel loading shoes at opposite corners; the shortening of
the loaded diagonal and the lengthening of the other are measured over a gauge length g on each diagonal.

The specimen (2D, SI; expanded bricks as the wall builders, `builders.running_bond`): `courses` courses of
`bricks_per_course` bricks, every other course offset by half a brick with half bricks at its ends; the panel is
w = bricks_per_course (L + t_j) wide and h = courses (H + t_j) high (L, H the brick's length and height, t_j the
joint thickness), lower-left corner at the origin. With `crack = LAW` every full brick is two halves joined by a
potential vertical crack (Emitter.split_brick: diagonal splitting through joints AND bricks). A shoe = two rigid
plates meeting at the panel's corner, each bearing on `shoe_length` of one face: the lower-left shoe
(`shoe_bottom`, `shoe_left`) is fixed, the upper-right one (`shoe_top`, `shoe_right`) is driven along the loaded
diagonal, e = (w, h)/D, D = sqrt(w² + h²): both plates move by -δ(t) e (x and y displacement histories together),
δ from 0 to `displacement`. Four gauges: V1, V2 on the loaded diagonal and H1, H2 on the other, at ±g/2 from the
panel's centre c along e_V = e and e_H = (-w, h)/D.

Read-out (readout.diagonal_curves, readout.secant_at_fraction):

    P   = -Σ_plates (R - I) · e              load along the diagonal [N] (driver reactions less inertia)
    S_s = 0.707 P / A_n,  A_n = (w + h)/2 · t · n      (n = 1: solid units)
    ΔV  = -(u_V2 - u_V1) · e_V   (shortening of the loaded diagonal),   ΔH = (u_H2 - u_H1) · e_H (lengthening)
    γ   = (ΔV + ΔH) / g
    G   = S_s / γ  at S_s = S_s,max / 3 on the rising branch (secant modulus from the origin: an assumed range,
          the same one-third secant as EN 1052-1's E; ASTM E519's own range as recalled is not fixed here).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import builders
from ..specs import spec
from .readout import diagonal_curves, secant_at_fraction
from .specimen import SpecimenSpec

STANDARD = "ASTM E519 / RILEM LUMB6 (diagonal compression, as recalled)"
SQUARE_TOL = 0.05        # |w - h| <= SQUARE_TOL max(w, h): "square" (assumed; whole courses and bricks rarely fit)
SHOE_FRACTION = 1 / 8    # default shoe bearing length / side (~152 mm on the 1.2 m panel, as recalled)
MAX_SHOE_FRACTION = 0.25  # shoe_length <= side / 4 (assumed: the shoes stay corner supports)
GAUGE_FRACTION = 0.5     # default gauge length / diagonal (assumed)
SECANT_FRACTION = 1 / 3  # G: secant at S_s,max / 3 (assumed, module docstring)
NET_AREA = 1.0           # n: fraction of solid area (solid units)
PLATE = 0.5              # plate thickness: PLATE x (H + t_j)
TOL = 1e-8               # [contact] tol of the specimen (numerical; the file's [contact] tol overrides it)


@dataclass
class DiagonalSpec(SpecimenSpec):
    courses: int = spec(7, doc="courses of the square panel (the standard's panel is 1.2 m x 1.2 m: the default 7 "
                               "courses x 2 bricks, 434 x 440 mm with the default bricks, keeps the demo within a "
                               "minute)", lo=2)
    bricks_per_course: int = spec(2, doc="panel width in bricks (running bond: every other course has half bricks "
                                         "at its ends)", lo=1)
    shoe_length: float | None = spec(None, doc="bearing length of each loading shoe on each of the two faces at its "
                                               "corner (default: 1/8 of the panel's side, as the standard's 152 mm "
                                               "shoe on a 1.2 m panel, as recalled)", unit="length", lo=0.0,
                                     lo_open=True)
    gauge_length: float | None = spec(None, doc="gauge length g on each diagonal, centred on the panel (default: "
                                                "half the diagonal; assumed)", unit="length", lo=0.0, lo_open=True)
    displacement: float = spec(1e-3, doc="travel of the upper loading shoe along the diagonal (displacement "
                                         "control)", unit="length", lo=0.0, lo_open=True)
    crack: str | None = spec(None, doc="potential vertical crack in the middle of every full brick: the name of a "
                                       "[laws.NAME] law joining the two halves (as [wall] split_bricks; default: "
                                       "whole bricks)")


SPEC = DiagonalSpec
NAMED_LAWS = ("crack",)   # keys naming a [laws.NAME] table, checked by lab.parse_lab


@dataclass
class Panel:
    """The specimen's geometry (SI): units [(name, x0, y0, lx, ly, split)] the bricks as laid, bricks [(name, x0, y0,
    lx, ly, parent or None)] the blocks (halves of the split ones), panel w x h, shoe bearing length, plate
    thickness, gauge points {name: (x, y, block)}, gauge length g, diagonal unit vectors."""
    units: list
    bricks: list
    w: float
    h: float
    shoe: float
    plate: float
    gauges: dict
    g: float
    e_v: np.ndarray
    e_h: np.ndarray

    @property
    def diagonal(self) -> float:
        return math.hypot(self.w, self.h)


def module_sizes(s: DiagonalSpec) -> tuple:
    """(w, h) of the panel and the expanded brick's (L + t_j, H + t_j)."""
    Lm, Hm = s.brick_length + s.joint_thickness, s.brick_height + s.joint_thickness
    return s.bricks_per_course * Lm, s.courses * Hm, Lm, Hm


def mesh_size(s: DiagonalSpec) -> float:
    return s.mesh_size if s.mesh_size is not None else 0.5 * (s.brick_height + s.joint_thickness)


def shoe_length(s: DiagonalSpec) -> float:
    w, h, _, _ = module_sizes(s)
    return s.shoe_length if s.shoe_length is not None else SHOE_FRACTION * min(w, h)


def gauge_length(s: DiagonalSpec) -> float:
    w, h, _, _ = module_sizes(s)
    return s.gauge_length if s.gauge_length is not None else GAUGE_FRACTION * math.hypot(w, h)


def read_lists(t, U) -> dict:
    return {}


def check(s: DiagonalSpec, t) -> None:
    """A square panel that holds the shoes and the gauges, deformable bricks (the gauges are material points of
    deformable blocks); InputError naming the key."""
    w, h, Lm, Hm = module_sizes(s)
    if abs(w - h) > SQUARE_TOL * max(w, h):
        best = max(2, int(round(w / Hm)))
        raise t.error("courses", f"= {s.courses}: the panel is {w * 1e3:.4g} x {h * 1e3:.4g} mm (w x h, "
                                 f"{s.bricks_per_course} bricks x {s.courses} courses): expected a square panel "
                                 f"(|w - h| <= {SQUARE_TOL:g} max(w, h)), e.g. courses = {best}")
    if s.bricks == "rigid":
        raise t.error("bricks", "= 'rigid': expected 'deformable' (the diagonal gauges are material points of "
                                "deformable bricks)")
    side = min(w, h)
    sl = shoe_length(s)
    if sl > MAX_SHOE_FRACTION * side:
        raise t.error("shoe_length", f"= {sl * 1e3:.4g} mm: the panel ({side * 1e3:.4g} mm) is too small to hold "
                                     f"the shoes: expected at most {MAX_SHOE_FRACTION:g} of the side")
    if sl < mesh_size(s) * (1 - 1e-9):
        raise t.error("shoe_length", f"= {sl * 1e3:.4g} mm: expected at least the bricks' mesh_size "
                                     f"({mesh_size(s) * 1e3:.4g} mm), else a shoe bears on a single node")
    D, g = math.hypot(w, h), gauge_length(s)
    gmax = D - 2.0 * math.sqrt(2.0) * sl
    if g > gmax * (1 + 1e-9):
        raise t.error("gauge_length", f"= {g * 1e3:.4g} mm: expected at most {gmax * 1e3:.4g} mm (the diagonal "
                                      "less 2 sqrt(2) shoe_length: the gauge points stay out of the shoes' corners)")


def panel(s: DiagonalSpec) -> Panel:
    """The bricks (builders.running_bond, expanded; halves with `crack`), the shoes and the gauge points."""
    w, h, Lm, Hm = module_sizes(s)
    lay = builders.running_bond(s.courses, s.bricks_per_course, s.brick_length, s.brick_height,
                                s.joint_thickness, expanded=True, half_bricks=True)
    units = [(f"brick{k}", b.x, b.y, b.length, b.height, s.crack is not None and b.length >= 0.75 * Lm)
             for k, b in enumerate(lay)]   # split: builders.split_bricks' rule
    bricks = []
    for k, (nm, x, y, lx, ly, split) in enumerate(units):   # blocks: halves NAMEa, NAMEb as Emitter.split_brick
        bricks += ([(f"{nm}a", x, y, 0.5 * lx, ly, k), (f"{nm}b", x + 0.5 * lx, y, 0.5 * lx, ly, k)] if split
                   else [(nm, x, y, lx, ly, None)])
    D, g = math.hypot(w, h), gauge_length(s)
    e_v, e_h = np.array([w, h]) / D, np.array([-w, h]) / D
    c = np.array([0.5 * w, 0.5 * h])
    pts = {"V1": c - 0.5 * g * e_v, "V2": c + 0.5 * g * e_v, "H1": c - 0.5 * g * e_h, "H2": c + 0.5 * g * e_h}
    gauges = {}
    for nm, p in pts.items():
        tol = 1e-9 * max(w, h)
        own = [b[0] for b in bricks if b[1] - tol <= p[0] <= b[1] + b[3] + tol and b[2] - tol <= p[1] <= b[2] + b[4]
               + tol]
        gauges[nm] = (float(p[0]), float(p[1]), own[0])
    return Panel(units, bricks, w, h, shoe_length(s), PLATE * Hm, gauges, g, e_v, e_h)


def shoe_history(s: DiagonalSpec, p: Panel) -> dict:
    """Displacement histories (SI) of the upper shoe's plates: -δ(t) e, δ linear from 0 to `displacement`."""
    return {d: ("displacement", dict(times=[0.0, 1.0], values=[0.0, -s.displacement * float(p.e_v[i])]))
            for i, d in enumerate(("x", "y"))}


def specimens(s: DiagonalSpec, emitter):
    """One case: the panel (module docstring)."""
    p = panel(s)
    e = emitter("panel")
    for k, (nm, x0, y0, lx, ly, split) in enumerate(p.units):
        if split:
            e.split_brick(nm, x0, y0, lx, ly, parent=k)
        else:
            e.brick(nm, x0, y0, lx, ly)
    w, h, sl, d = p.w, p.h, p.shoe, p.plate
    e.plate("shoe_bottom", 0.0, -d, sl, 0.0)
    e.plate("shoe_left", -d, 0.0, 0.0, sl)
    drv = shoe_history(s, p)
    e.plate("shoe_top", w - sl, h, w, h + d, drivers=drv)
    e.plate("shoe_right", w, h - sl, w + d, h, drivers=drv)
    e.interfaces(crack=s.crack)
    e.stage("load", s.steps)
    # tol 1e-8 (assumed, measured on the demo): the Newton iteration stalls between 1e-8 and 1e-10 on the panel's
    # damaging steps (184 s at 1e-10 against 25 s at 1e-8, S_s and G equal to 6 digits)
    e.defaults("contact", solver="newton", tol=TOL, max_sweeps=5000)
    e.defaults("output", gauges=[dict(name=nm, block=b, point=[e.L(x), e.L(y)]) for nm, (x, y, b) in p.gauges.items()],
               curve=dict(body="shoe_top", force="y", displacement="y"))
    return [("panel", e.data, dict(width_m=w, height_m=h, shoe_length_m=sl, gauge_length_m=p.g,
                                   bricks=len(p.units), blocks=len(p.bricks)))]


def net_area(s: DiagonalSpec, case) -> float:
    """A_n = (w + h)/2 · t · n."""
    w, h, _, _ = module_sizes(s)
    return 0.5 * (w + h) * case.materials[s.material].thickness * NET_AREA


def curves(s: DiagonalSpec, run: dict) -> dict:
    """P, S_s, ΔV, ΔH, γ per row of the panel's history (readout.diagonal_curves)."""
    h, p = run["history"], panel(s)
    R = np.zeros((len(h["shoe_top.Rx"]), 2))
    for pl in ("shoe_top", "shoe_right"):
        R += np.column_stack([h[f"{pl}.R{d}"] - h[f"{pl}.I{d}"] for d in ("x", "y")])
    u = {nm: np.column_stack([h[f"{nm}.ux"], h[f"{nm}.uy"]]) for nm in p.gauges}
    c = diagonal_curves(R, p.e_v, u["V1"], u["V2"], u["H1"], u["H2"], p.e_h, p.g, net_area(s, run["case"]))
    c["delta"] = -(np.column_stack([h["shoe_top.ux"], h["shoe_top.uy"]]) @ p.e_v)
    return c


def specimen_line(s: DiagonalSpec, run: dict) -> str:
    c = curves(s, run)
    k = int(np.nanargmax(c["S_s"]))
    return f"peak P = {c['P'][k] / 1e3:.4g} kN, S_s = {c['S_s'][k] / 1e6:.4f} MPa at gamma = {c['gamma'][k]:.4g}"


def readout(s: DiagonalSpec, runs: list) -> dict:
    run = runs[0]
    c = curves(s, run)
    k = int(np.nanargmax(c["S_s"]))
    try:
        sec = secant_at_fraction(c["S_s"], c["gamma"], SECANT_FRACTION)
    except ValueError:   # a curve that does not rise from below S_s,max / 3 (a stopped run): G not measured
        sec = dict(stress=float("nan"), strain=float("nan"), modulus=float("nan"))
    summ = run.get("summary") or {}
    p = panel(s)
    q = {"S_s": dict(value=float(c["S_s"][k]), unit="Pa", name="shear strength S_s = 0.707 P_max / A_n",
                     measures=f"the assembly's diagonal-tension strength (laws.{s.joint}"
                              + (f", laws.{s.crack}" if s.crack else "") + ")"),
         "P_max": dict(value=float(c["P"][k]), unit="N", name="peak load along the diagonal"),
         "G": dict(value=sec["modulus"], unit="Pa", name=f"modulus of rigidity G = S_s / gamma, secant at "
                                                          f"S_s,max/3 (S_s = {sec['stress'] / 1e6:.4g} MPa)",
                   measures=f"the assembly's shear stiffness (materials.{s.material} E, nu; laws.{s.joint} k_n, "
                            "k_s)"),
         "gamma_at_peak": dict(value=float(c["gamma"][k]), unit="1", name="shearing strain at S_s,max"),
         "A_n": dict(value=net_area(s, run["case"]), unit="m^2", name="net area (w + h)/2 t n")}
    cb = summ.get("cracked_bricks")
    if cb:
        q["cracked_bricks"] = dict(value=cb["count"], unit="1", name=f"bricks split by their crack interface (of "
                                   f"{cb['of']}; opening > {cb['threshold_mm']:g} mm: crack_pattern.png)")
    return dict(quantities=q, secant=sec, peak_row=k, panel=dict(width_m=p.w, height_m=p.h, shoe_length_m=p.shoe,
                                                                 gauge_length_m=p.g,
                                                                 gauges={nm: [x, y, b] for nm, (x, y, b)
                                                                         in p.gauges.items()}),
                crack_pattern=f"{run['dir']}/crack_pattern.png" if summ.get("crack_pattern") else None)


def plot(s: DiagonalSpec, report: dict, runs: list, path: str, title: str = ""):
    """PNG: left, S_s against γ with the peak and the secant at S_s,max / 3 (G); right, the panel with its
    bricks, the two shoes and the two gauge lines (the standard's set-up)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle
    c = curves(s, runs[0])
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.6), gridspec_kw=dict(width_ratios=[1.4, 1]))
    ax[0].plot(c["gamma"] * 1e3, c["S_s"] / 1e6, "-", lw=1.4, label="S_s = 0.707 P / A_n")
    k, sec = report["peak_row"], report["secant"]
    ax[0].plot([c["gamma"][k] * 1e3], [c["S_s"][k] / 1e6], "o", mfc="none", label=f"peak S_s = "
               f"{c['S_s'][k] / 1e6:.4g} MPa")
    if np.isfinite(sec["modulus"]):
        gg = np.array([0.0, min(np.nanmax(c["gamma"]), 1.5 * sec["stress"] / sec["modulus"] * 3)])
        ax[0].plot(gg * 1e3, sec["modulus"] * gg / 1e6, "--", lw=1,
                   label=f"secant at S_s,max/3: G = {sec['modulus'] / 1e6:.5g} MPa")
        ax[0].plot([sec["strain"] * 1e3], [sec["stress"] / 1e6], "s", ms=4)
    ax[0].set(xlabel="shearing strain γ = (ΔV + ΔH)/g [‰]", ylabel="shear stress S_s [MPa]",
              title=f"{title}: S_s–γ", xlim=(0, None), ylim=(0, None))
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    pnl = report["panel"]
    p = panel(s)
    for nm, x0, y0, lx, ly, parent in p.bricks:
        ax[1].add_patch(Rectangle((x0 * 1e3, y0 * 1e3), lx * 1e3, ly * 1e3, fill=False, lw=0.6,
                                  ls=":" if parent is not None and nm.endswith("b") else "-"))
    w, h, sl, d = p.w * 1e3, p.h * 1e3, p.shoe * 1e3, p.plate * 1e3
    for (x0, y0, lx, ly) in ((0, -d, sl, d), (-d, 0, d, sl), (w - sl, h, sl, d), (w, h - sl, d, sl)):
        ax[1].add_patch(Rectangle((x0, y0), lx, ly, color="0.4"))
    ax[1].annotate("", xy=(w - 0.1 * w, h - 0.1 * h), xytext=(w + 0.1 * w, h + 0.1 * h),
                   arrowprops=dict(arrowstyle="->", lw=1.5))
    G = pnl["gauges"]
    for a, b, col in (("V1", "V2", "C3"), ("H1", "H2", "C0")):
        ax[1].plot([G[a][0] * 1e3, G[b][0] * 1e3], [G[a][1] * 1e3, G[b][1] * 1e3], "o-", color=col, lw=1.2, ms=3,
                   label=f"gauge {a}–{b} ({'shortening ΔV' if a == 'V1' else 'lengthening ΔH'})")
    ax[1].set(aspect="equal", xlabel="x [mm]", ylabel="y [mm]", title=f"panel {w:.4g} x {h:.4g} mm, shoes "
              f"{sl:.3g} mm, g = {p.g * 1e3:.4g} mm")
    ax[1].set_xlim(-1.5 * d, w + 2.5 * d)
    ax[1].set_ylim(-1.5 * d, h + 2.5 * d)
    ax[1].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

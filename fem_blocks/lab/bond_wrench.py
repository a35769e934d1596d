"""EN 1052-5 bond wrench: the flexural bond strength f_w of a bed joint, its failure moment and moment–rotation curve.

Standard (EN 1052-5, as recalled; its text is not in the repository): the lower brick of a couplet is clamped, a
lever clamped to the upper brick is loaded by a force F1 at the lever arm e1 from the centre line of the joint until
the joint fails in bending. With F2 the weight of the clamp (lever) and the upper brick and e2 the lever arm of their
centre of gravity,

    f_w = (F1 e1 + F2 e2) / Z − (F1 + F2) / A_j,      Z = b d² / 6,  A_j = b d,

b the joint's width and d its depth in the direction of bending: the edge stress of a linear distribution under the
moment M = F1 e1 + F2 e2 and the compression N = F1 + F2 about the joint's centre line (the test's read-out assumes
an elastic–brittle joint: the moment at the first crack).

The specimen (2D section across the joint, lab/bond.py): the joint's depth d is the brick's dimension in the plane
(`brick_length`, here the brick's width across which it bends, default 0.1 m) and b the material's thickness. Bricks
`lower` [0, d] x [0, H] and `upper` [0, d] x [H, 2H]; a steel plate `base` glued under the lower brick (fixed: the
clamp of the lower brick); the `lever`, a free steel plate [0, d/2 + e1 + w] x [2H, 2H + H/2] glued on the upper
brick (the clamp and its arm; steel density 7850 kg/m³, assumed); the `knife`, a narrow rigid plate of width
w = d/100 on the lever at x = d/2 + e1, driven down (−y) under displacement control from 0 to `deflection` (x and
rotation held), touching the lever through a frictionless unilateral contact: F1 is its reaction. The load F1 points
down on the right of the joint, so the joint opens at x = 0. With gravity (the file's `gravity`) F2 is the weight of
the lever and the upper brick; without it (the default of a [lab] file) F2 = 0.

Read-out per row: F1 = −(knife.Ry − knife.Iy) (its reaction less its inertial part, > 0 pushing down);
M = F1 e1 + F2 e2 (the standard's moment about the joint's centre line); the joint's own moment from its resultant
M_j = −e N (`[output] joints`, about the joint's middle; the same when the knife bears at e1); the joint rotation
φ = (δ(0) − δ(d)) / d from the openings at its two ends (rigid bricks: their displacements; deformable: gauges at the
joint's faces). Failure: the row of the largest F1; the report gives F1, M and f_w there, and f_w Z = M − N d / 6, the
equivalent pure-bending failure moment (the issue's f_t b d²/6 for an elastic–brittle joint).

Closed form and the number of contact points (tests/test_lab_bond.py, docs/lab-tests.md): with rigid bricks and n
equal divisions of the joint (n + 1 points, trapezoidal weights) the joint's section modulus is
Z_n = I_n/(d/2), I_n = b (d³/12 + s² d/6) = (b d³/12)(1 + 2/n²), s = d/n; a brittle joint first cracks at the edge
when M/Z_n − N/A_j = f_t, so the simulated f_w = f_t (1 + 2/n²) + (2/n²) N/A_j. "Brittle" needs the edge point to
lose its strength before its neighbour reaches it: for the mixed law (linear softening, final opening
λ_f δ_I, λ_f = 2 G_I k_n / f_t², docs/laws.md) λ_f − 1 < s/(d/2) = 2/n; the law accepts any λ_f > 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..specs import spec
from . import bond
from .readout import peak_problems as peak_messages
from .specimen import PLATES, SpecimenSpec

STANDARD = "EN 1052-5 (bond wrench, as recalled)"
LEVER = "lever"            # group of the lever (glued to the bricks; touched by the knife)
KNIFE_WIDTH = 0.01         # knife width w = KNIFE_WIDTH d (its force acts within w/2 of e1; assumed)
LEVER_DEPTH = 0.5          # lever height = LEVER_DEPTH H (rigid: only its weight depends on it)
STEEL = 7850.0             # kg/m³, the lever's density (assumed)


@dataclass
class WrenchSpec(SpecimenSpec):
    brick_length: float = spec(0.1, doc="the joint's depth d in the direction of bending (the brick's dimension in the "
                                        "plane of the model: its width in the laboratory's set-up)",
                               unit="length", lo=0.0, lo_open=True)
    lever_arm: float = spec(0.25, doc="e1: the distance of the load from the joint's centre line; the load acts "
                                      "outside the brick, e1 > brick_length / 2 (0.25 m assumed)",
                            unit="length", lo=0.0, lo_open=True)
    deflection: float = spec(0.5e-3, doc="displacement of the loading knife along −y (past the failure; the "
                                         "lever's rotation times e1 plus the compliance of the set-up)",
                             unit="length", lo=0.0, lo_open=True)
    divisions: int = spec(20, doc="contact points through the joint's depth: rigid bricks get `divisions` equal edges "
                                  "on their bed faces (divisions + 1 points); deformable bricks a mesh size "
                                  "brick_length / divisions unless `mesh_size` is given", lo=2)

    def __post_init__(self):
        if self.mesh_size is None and self.bricks == "deformable":
            self.mesh_size = self.brick_length / self.divisions


SPEC = WrenchSpec


def read_lists(t, U) -> dict:
    return {}


def check(s: WrenchSpec, t) -> None:
    """The load acts outside the brick: e1 > d/2 (plus the knife's half-width)."""
    half = 0.5 * s.brick_length * (1.0 + KNIFE_WIDTH)
    if s.lever_arm <= half:
        u = t.units["length"]
        raise t.error("lever_arm", f"= {s.lever_arm / u:g}: the load point lies inside the brick; expected a lever arm "
                                   f"> {half / u:g} (half the brick_length {s.brick_length / u:g} and half the knife, "
                                   "from the joint's centre line)")


def geometry(s: WrenchSpec) -> dict:
    """The specimen's bodies [m] (module docstring)."""
    d, H = s.brick_length, bond.height(s)
    w = KNIFE_WIDTH * d
    xe = 0.5 * d + s.lever_arm
    hl = LEVER_DEPTH * H
    return dict(d=d, H=H, w=w, xe=xe, lever=(0.0, 2 * H, xe + w, 2 * H + hl),
                knife=(xe - 0.5 * w, 2 * H + hl, xe + 0.5 * w, 2 * H + hl + w), base=(0.0, -0.5 * H, d, 0.0))


def specimens(s: WrenchSpec, emitter):
    """One specimen (module docstring)."""
    g = geometry(s)
    d, H = g["d"], g["H"]
    e = emitter("couplet")
    n = s.divisions if s.bricks == "rigid" else 1
    e.brick("lower", 0.0, 0.0, d, H, divisions=n)
    e.brick("upper", 0.0, H, d, H, divisions=n)
    e.plate("base", *g["base"])
    x0, y0, x1, y1 = g["lever"]
    lever = dict(name="lever", group=LEVER, rho=STEEL / e.U["density"],
                 vertices=[[e.L(x0), e.L(y0)], [e.L(x1), e.L(y0)], [e.L(x1), e.L(y1)], [e.L(x0), e.L(y1)]])
    if e.thickness is not None:
        lever["thickness"] = e.thickness
    e.data["rigid_bodies"].append(lever)
    e.plate("knife", *g["knife"], drivers={"y": ("displacement", dict(times=[0.0, 1.0], values=[0.0, -s.deflection]))})
    bond.glue(e, s, groups=(PLATES, LEVER))
    e.data["interfaces"].append(dict(name="load", between=[LEVER, PLATES], mu=0.0))
    e.stage("load", s.steps)
    e.defaults("contact", solver="newton", tol=1e-10, max_sweeps=5000)
    e.defaults("output", joints=[["lower", "upper"]], curve=dict(body="knife", force="y", displacement="y"))
    bond.add_gauges(e, s, [0.0, d])
    return [("couplet", e.data, dict(lever_arm_m=float(s.lever_arm)))]


def dead_load(s: WrenchSpec, case) -> tuple:
    """(F2 [N], e2 [m]): the weight of the lever and the upper brick (−g_y times their masses) and the lever arm of
    their centre of gravity from the joint's centre line x = d/2 (masses from the geometry, the material's density
    and thickness, the lever's STEEL). F2 = 0, e2 = 0 without gravity."""
    g = geometry(s)
    gy = -float(np.asarray(case.gravity, dtype=float)[1]) if case.gravity is not None else 0.0
    mat = case.materials[s.material]
    t = mat.thickness
    x0, y0, x1, y1 = g["lever"]
    m_l, x_l = STEEL * (x1 - x0) * (y1 - y0) * t, 0.5 * (x0 + x1)
    m_b, x_b = mat.rho * g["d"] * g["H"] * t, 0.5 * g["d"]
    F2 = gy * (m_l + m_b)
    e2 = (m_l * x_l + m_b * x_b) / (m_l + m_b) - 0.5 * g["d"]
    return float(F2), float(e2)


def section(s: WrenchSpec, case) -> tuple:
    """(A_j, Z) of the joint: b d and b d²/6 (b the material's thickness)."""
    b, d = case.materials[s.material].thickness, s.brick_length
    return b * d, b * d * d / 6.0


def curves(s: WrenchSpec, run: dict) -> dict:
    """Per row: F1 [N] (> 0 down), the standard's moment M = F1 e1 + F2 e2 [N m], the joint's moment M_j = −e N and
    normal force N [N] from its resultant, the rotation φ [rad] (> 0 opening at x = 0) and the opening at x = 0."""
    h, case = run["history"], run["case"]
    F2, e2 = dead_load(s, case)
    F1 = -(h["knife.Ry"] - h["knife.Iy"])
    N = h["lower|upper.N"]
    Mj = -np.nan_to_num(h["lower|upper.e"]) * N
    op = bond.opening_at(s, h, [0.0, s.brick_length])
    return dict(F1=F1, M=F1 * s.lever_arm + F2 * e2, Mj=Mj, N=N, rotation=(op[:, 0] - op[:, 1]) / s.brick_length,
                opening=op[:, 0], deflection=-h["knife.uy"])


def wrench_readout(F1, e1: float, F2: float, e2: float, A: float, Z: float) -> dict:
    """The standard's read-out at the failure load (the largest F1): M = F1 e1 + F2 e2, N = F1 + F2,
    f_w = M / Z − N / A, and the equivalent pure-bending moment f_w Z = M − N Z / A."""
    F = np.asarray(F1, dtype=float)
    k = int(np.nanargmax(F))
    F1m = float(F[k])
    M, N = F1m * e1 + F2 * e2, F1m + F2
    fw = M / Z - N / A
    return dict(F1_N=F1m, failure_row=k, F2_N=float(F2), e1_m=float(e1), e2_m=float(e2), M_fail_Nm=M, N_fail_N=N,
                f_w_Pa=fw, fwZ_Nm=fw * Z, Z_m3=Z, A_j_m2=A)


def failure_problems(F1) -> list:
    """Why the largest F1 is no failure load: the knife never pushed (F1 <= 0: the specimen failed under its own
    weight, or never met the knife), or F1 was largest at the last row (still rising: the deflection ended before
    the failure)."""
    return peak_messages(F1, "the knife never loaded the lever (F1 <= 0): the joint failed before the load (e.g. "
                             "under the dead load) or the knife never reached the lever",
                         "F1 was still rising at the end of the deflection: the failure load was not reached "
                         "(increase lab.deflection)")


def specimen_line(s: WrenchSpec, run: dict) -> str:
    c = curves(s, run)
    A, Z = section(s, run["case"])
    F2, e2 = dead_load(s, run["case"])
    r = wrench_readout(c["F1"], s.lever_arm, F2, e2, A, Z)
    bad = failure_problems(c["F1"])
    return (f"failure load F1 = {r['F1_N']:.6g} N, M = {r['M_fail_Nm']:.6g} N m, f_w = {r['f_w_Pa'] / 1e6:.4f} MPa"
            + "".join(f"; WARNING: {b}: f_w is not a failure value" for b in bad))


def readout(s: WrenchSpec, runs: list) -> dict:
    r = runs[0]
    c = curves(s, r)
    A, Z = section(s, r["case"])
    F2, e2 = dead_load(s, r["case"])
    rep = wrench_readout(c["F1"], s.lever_arm, F2, e2, A, Z)
    k = rep["failure_row"]
    rep["Mj_fail_Nm"] = float(c["Mj"][k])
    rep["Mj_max_Nm"] = float(np.nanmax(c["Mj"]))
    rep["rotation_at_failure_rad"] = float(c["rotation"][k])
    key, ft = bond.strength_input(s, r["case"])
    q = {"f_w": dict(value=rep["f_w_Pa"], unit="Pa", name="flexural bond strength (F1 e1 + F2 e2)/Z − (F1 + F2)/A_j",
                     measures=key or "the joint's tensile strength", input=ft),
         "F1": dict(value=rep["F1_N"], unit="N", name="failure load (for the material's thickness)"),
         "M_fail": dict(value=rep["M_fail_Nm"], unit="N m", name="failure moment F1 e1 + F2 e2 about the joint's "
                                                                  "centre line"),
         "fwZ": dict(value=rep["fwZ_Nm"], unit="N m", name="equivalent pure-bending failure moment f_w Z = M − N Z/A_j",
                     measures=f"f_t b d²/6 ({key})" if key else "f_t b d²/6",
                     input=None if ft is None else ft * Z),
         "rotation_at_failure": dict(value=rep["rotation_at_failure_rad"], unit="rad",
                                     name="joint rotation at the failure load")}
    rep["warnings"] = failure_problems(c["F1"])
    if rep["warnings"]:   # no failure load: the standard's quantities must not look like results
        for k in ("f_w", "F1", "M_fail", "fwZ", "rotation_at_failure"):
            q[k]["value"] = float("nan")
        q["f_w"]["name"] += " — NOT REACHED: " + "; ".join(rep["warnings"])
    rep["quantities"] = q
    return rep


def plot(s: WrenchSpec, report: dict, runs: list, path: str, title: str = ""):
    """PNG: left, the moment about the joint's centre line against the joint's rotation (the standard's M and the
    joint resultant's M_j), the failure point and the input's elastic–brittle moment f_t Z + N Z/A_j; right, the edge
    stress M/Z − N/A_j of the standard's formula against the rotation, its maximum f_w and the input f_t."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = curves(s, runs[0])
    k, Z, A = report["failure_row"], report["Z_m3"], report["A_j_m2"]
    F2 = report["F2_N"]
    ft = report["quantities"]["f_w"].get("input")
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.4))
    r = c["rotation"] * 1e3
    ax[0].plot(r, c["M"], "-", lw=1.3, label="M = F1 e1 + F2 e2 (the standard's)")
    ax[0].plot(r, c["Mj"], "--", lw=1, label="M_j = −e N (joint resultant)")
    ax[0].plot([r[k]], [report["M_fail_Nm"]], "o", mfc="none", ms=8,
               label=f"failure: M = {report['M_fail_Nm']:.4g} N m")
    if ft is not None:
        ax[0].axhline(ft * Z + report["N_fail_N"] * Z / A, ls=":", color="k", lw=0.8,
                      label="elastic–brittle: f_t Z + N Z / A_j")
    ax[0].set(xlabel="joint rotation φ [mrad]", ylabel="moment [N m]", ylim=(0, None),
              title=f"{title}: moment–rotation")
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    sig = (c["M"] / Z - (c["F1"] + F2) / A) / 1e6
    ax[1].plot(r, sig, "-", lw=1.3, label="(F1 e1 + F2 e2)/Z − (F1 + F2)/A_j")
    ax[1].plot([r[k]], [report["f_w_Pa"] / 1e6], "o", mfc="none", ms=8,
               label=f"f_w = {report['f_w_Pa'] / 1e6:.4f} MPa")
    if ft is not None:
        ax[1].axhline(ft / 1e6, ls="--", color="k", lw=0.8, label=f"input {report['quantities']['f_w']['measures']} = "
                      f"{ft / 1e6:g} MPa")
    ax[1].set(xlabel="joint rotation φ [mrad]", ylabel="edge stress [MPa]", title="EN 1052-5: f_w at the failure load")
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

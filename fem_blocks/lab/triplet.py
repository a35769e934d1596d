"""EN 1052-3 triplet shear test: the initial shear strength f_vo and the friction coefficient tan α of a bed joint.

The test (docs/lab-tests.md): three bricks joined by two bed joints; a pre-compression σ_p normal to the joints,
held constant by a force-controlled platen; the middle brick pushed along the joints under displacement control
while the outer bricks are supported. One fresh specimen per level (a joint sheared past its peak keeps its damage).

The specimen (2D, laid on its side: bed joints horizontal, pre-compression along -y, shear along +x), SI:
bricks `lower`, `middle`, `upper` of L x H (H = brick_height + joint_thickness, expanded bricks) at y = 0, H, 2H;
plates: `base` under the lower brick (fixed), `press` on the upper brick (x and rotation held, the force -σ_p A in
y), `ram` at the middle brick's left face (pushed in x from 0 to `slip` after the pre-compression steps) and the
`stop_lower`, `stop_upper` at the outer bricks' right faces (fixed). Plates stop a tenth of H short of the
neighbouring brick, so each loads one brick only. A = L t (t the material's thickness).

Read-out (standard's notation as recalled; its text is not in the repository): per joint i, τ_i = T_i / A from the
joint resultant (`[output] joints`, output/joints.py) and the standard's F / 2A from the ram's reaction less its
inertial part; peak and residual per joint and level (readout.peak_and_residual); the least-squares lines
τ = f_vo + σ tan α through the (σ_p, τ_peak) points of both joints, and the residual line through the residual
points (readout.fit_line). For the mixed-mode law (docs/laws.md) the strength under a compression p is
c + tan_phi p and the residual tan_phi p: with uniform joints f_vo -> c, tan α -> tan_phi, residual slope -> tan_phi.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..specs import spec
from .readout import MIN_LEVELS, check_levels, fit_line, triplet_readout
from .specimen import SpecimenSpec

STANDARD = "EN 1052-3:2002 (procedure A)"
PRELOAD_STEPS = 10   # steps of the pre-compression alone (ram held) before the push
MARGIN = 0.1         # plates stop MARGIN x H short of the neighbouring brick


@dataclass
class TripletSpec(SpecimenSpec):
    precompressions: tuple = spec((0.2e6, 0.6e6, 1.0e6), unit="stress",
                                  doc="pre-compression levels normal to the joints, increasing, at least 3 (EN 1052-3 "
                                      "as recalled: 0.2, 0.6, 1.0 MPa for f_b > 10 MPa), one specimen per level")
    slip: float = spec(1e-3, doc="displacement of the ram (the middle brick's push: peak and post-peak)",
                       unit="length", lo=0.0, lo_open=True)


SPEC = TripletSpec


def read_lists(t, U) -> dict:
    """`precompressions` (file units -> Pa), checked by readout.check_levels."""
    k = "precompressions"
    t.used.add(k)
    if not t.has(k):
        return {}
    from .. import casefile
    where = f"{casefile.origin(t.source, t.key(k))}: {t.key(k)}"
    return {k: tuple(float(v) * U["stress"] for v in check_levels(t.raw(k), where, MIN_LEVELS))}


def check(s: TripletSpec, t) -> None:
    """Nothing beyond the keys' ranges: any positive brick holds the specimen."""


def joint_area(s: TripletSpec, case) -> float:
    return s.brick_length * case.materials[s.material].thickness


def specimens(s: TripletSpec, emitter):
    """One case per pre-compression level (module docstring)."""
    L, H = s.brick_length, s.brick_height + s.joint_thickness
    d, m = 0.5 * H, MARGIN * H
    out = []
    for k, sp in enumerate(s.precompressions):
        e = emitter(f"p{k}")
        A = s.brick_length * (e.thickness * e.U["length"] if e.thickness is not None else 1.0)
        for i, nm in enumerate(("lower", "middle", "upper")):
            e.brick(nm, 0.0, i * H, L, H)
        t0 = PRELOAD_STEPS / (s.steps + PRELOAD_STEPS)
        e.plate("base", 0.0, -d, L, 0.0)
        e.plate("press", 0.0, 3 * H, L, 3 * H + d, forces={"y": -sp * A})
        e.plate("ram", -d, H + m, 0.0, 2 * H - m,
                drivers={"x": ("displacement", dict(times=[0.0, t0, 1.0], values=[0.0, 0.0, s.slip]))})
        e.plate("stop_lower", L, m, L + d, H - m)
        e.plate("stop_upper", L, 2 * H + m, L + d, 3 * H - m)
        e.interfaces()
        e.stage("push", s.steps + PRELOAD_STEPS)
        e.defaults("contact", solver="newton", tol=1e-10, max_sweeps=5000)
        e.defaults("output", joints=[["lower", "middle"], ["middle", "upper"]],
                   curve=dict(body="ram", force="x", displacement="x"))
        out.append((f"p{k}", e.data, dict(precompression_Pa=float(sp))))
    return out


def curves(s: TripletSpec, run: dict) -> dict:
    """The push of one specimen from its history: slip (ram x [m]) and the shear stresses [Pa] of the lower and
    upper joints (|T| / A) and F / 2A of the ram (reaction less its inertial part), after the pre-compression."""
    h, A = run["history"], joint_area(s, run["case"])
    k = PRELOAD_STEPS + 1   # row 0 = initial state, rows 1..PRELOAD_STEPS = pre-compression
    return dict(slip=h["ram.ux"][k:], lower=np.abs(h["lower|middle.T"][k:]) / A,
                upper=np.abs(h["middle|upper.T"][k:]) / A,
                total=np.abs(h["ram.Rx"][k:] - h["ram.Ix"][k:]) / (2 * A),
                normal=np.abs(h["middle|upper.N"][k:]) / A)


def specimen_line(s: TripletSpec, run: dict) -> str:
    c = curves(s, run)
    return (f"sigma_p = {run['info']['precompression_Pa'] / 1e6:g} MPa: peak F/2A = {np.nanmax(c['total']) / 1e6:.4f}"
            f" MPa")


def readout(s: TripletSpec, runs: list) -> dict:
    cs = [curves(s, r) for r in runs]
    rep = triplet_readout([r["info"]["precompression_Pa"] for r in runs], cs)
    p = runs[0]["case"].interfaces[0].params   # the joint law, SI
    pk, rs = rep["peak_line"], rep["residual_line"]
    q = {"f_vo": dict(value=pk["intercept"], unit="Pa", name="initial shear strength (intercept of the peak line)",
                      measures=f"laws.{s.joint}.c", input=p.get("c")),
         "tan_alpha": dict(value=pk["slope"], unit="1", name="friction coefficient (slope of the peak line)",
                           measures=f"laws.{s.joint}.tan_phi", input=p.get("tan_phi")),
         "peak_line_r2": dict(value=pk["r2"], unit="1", name="R² of the peak line")}
    if rs is not None:
        q["residual_intercept"] = dict(value=rs["intercept"], unit="Pa", name="intercept of the residual line",
                                       measures="0 for a joint that lost its cohesion", input=0.0)
        q["residual_slope"] = dict(value=rs["slope"], unit="1", name="slope of the residual line (residual "
                                   "friction)", measures=f"laws.{s.joint}.tan_phi", input=p.get("tan_phi"))
    rep["quantities"] = q
    rep["joint_area_m2"] = joint_area(s, runs[0]["case"])
    return rep


def plot(s: TripletSpec, report: dict, runs: list, path: str, title: str = ""):
    """PNG: left, τ of each joint against the ram's displacement per level; right, the peak and residual points
    (σ_p, τ) of both joints with the fitted lines τ = f_vo + σ tan α (peak) and the residual line."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.4))
    for row, r in zip(report["levels"], runs):
        c = curves(s, r)
        line, = ax[0].plot(c["slip"] * 1e3, c["upper"] / 1e6, "-", lw=1.2,
                           label=f"σ_p = {row['precompression_Pa'] / 1e6:g} MPa (upper joint)")
        ax[0].plot(c["slip"] * 1e3, c["lower"] / 1e6, "--", lw=1, color=line.get_color(), label="lower joint")
    ax[0].set(xlabel="displacement of the ram [mm]", ylabel="shear stress τ [MPa]", title=f"{title}: τ per level")
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    sig = np.array([r["precompression_Pa"] for r in report["levels"]])
    ss = np.linspace(0.0, 1.1 * sig.max(), 50)
    for key, mk in (("peak", "o"), ("residual", "s")):
        pts = [(r["precompression_Pa"], r[f"{key}_{j}_Pa"]) for r in report["levels"] for j in ("upper", "lower")]
        pts = np.array([p for p in pts if np.isfinite(p[1])])
        fit = report[f"{key}_line"]
        color = None
        if len(pts):
            color = ax[1].plot(pts[:, 0] / 1e6, pts[:, 1] / 1e6, mk, ms=5, mfc="none",
                               label=f"{key} (both joints)")[0].get_color()
        if fit is not None:
            ax[1].plot(ss / 1e6, (fit["intercept"] + fit["slope"] * ss) / 1e6, "-", color=color,
                       label=f"{key} line: τ = {fit['intercept'] / 1e6:.3f} + {fit['slope']:.3f} σ  (R² = "
                             f"{fit['r2']:.4f})")
    ax[1].set(xlabel="pre-compression σ_p [MPa]", ylabel="shear stress τ [MPa]", xlim=(0, None), ylim=(0, None),
              title="EN 1052-3: τ = f_vo + σ tan α (least squares)")
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

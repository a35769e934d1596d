"""EN 1052-1 compression test: the compressive strength f and the modulus E of masonry (prism or wallet).

The test (docs/lab-tests.md, "compression"): a specimen of `courses` courses between a fixed base plate and a top
platen driven down under displacement control (x and rotation held: a locked seat), platen friction `plate_mu`
(default 0, greased platens). Two specimens (`specimen`):

* "prism": stack-bonded, one brick per course (no head joints): W = brick_length wide;
* "wallet": running bond, `bricks_per_course` = n_b bricks per course (a multiple of 1/2, at least 1.5): even
  courses (from the base, 0, 2, ...) start with a full brick at the left, odd courses with a half brick, so the head
  joints of neighbouring courses are half a brick apart and the half bricks sit at the ends of alternate courses
  (n_b = 1.5: courses [1, 1/2] and [1/2, 1]). Expanded bricks in both directions (specimen.py): a brick is
  (brick_length + joint_thickness) x (brick_height + joint_thickness), a half brick half as long, so the
  wallet is W = n_b (brick_length + joint_thickness) wide, one joint thickness wider than the real one (half a
  joint at each end). The wallet's element size is adjusted so that the meshes of the full and half bricks match
  across the bed joints (a half brick in an even number of elements, `wallet_mesh_size`): with non-matching
  meshes the contact points of a bed joint (node to segment) do not pass the patch test, a uniform pressure is not
  transmitted exactly. The nodes where a bed joint meets a head joint carry one contact point per brick they face
  (contact/detection_2d.py), so every joint's points sum to its overlap and the wallet's state is uniform.

Course height H = brick_height + joint_thickness; specimen height h_s = courses H; loaded area A = W t (t the
material's thickness: the model's bed-joint area).

Read-out (EN 1052-1 as recalled; its text is not in the repository):

    f = F_max / A                       compressive strength (F_max the largest platen force less its inertial part)
    E = F_max / (3 A eps_1/3)           secant modulus at one third of the peak (eps_1/3 the gauge strain there)

The strain is measured by displacement gauges (`[output] gauges`): two vertical gauge lines at x = x_l and
W - x_l (x_l the middle of the half-brick slot holding W/4, never on a head joint; in 2D the standard's gauges on
both faces are one and the same line, so the two lines stand for the pair of gauges the standard averages — they
also cancel an in-plane rotation), each from the middle of course a to the middle of course a + m: m whole courses
(`gauge_courses`, default the m nearest to courses/3 centred on mid-height), i.e. exactly m bricks and m bed joints.
eps = -mean over the two lines of (u_y,top - u_y,bottom) / (m H). With rigid bricks the gauge points move with
their brick (u = d + (R(phi) - I)(X - X_c), the brick's history columns).

Closed forms of the model (tests/test_lab_compression.py): with frictionless platens the state is uniform (the
wallet's too: a linear displacement field is continuous across the head joints, which stay unloaded), so over the
gauge eps = sigma (m H / E_b + m / k_n) / (m H), the series formula

    E = 1 / (1/E_b + 1/(k_n H))          (E_b -> E_b / (1 - nu^2) in plane strain; rigid bricks: E = k_n H),

and the only failure mode is the joints' compressive cap (docs/laws.md): f = f_c. The interface model has no
lateral expansion of the mortar, so the splitting of real prisms (soft mortar pushing the bricks apart) is not
represented: f is the cap's, a property given to the joints, not a prediction of the composite's strength.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..specs import spec
from .readout import peak_confirmed, secant_at_fraction
from .specimen import SpecimenSpec

STANDARD = "EN 1052-1:1998"
DEFAULT_SHORTENING = 0.003   # default platen displacement / specimen height: assumed (past the peak strain of
#                              ordinary masonry, about 0.2-0.4 % as recalled)
OVERHANG = 0.1               # the plates stick out OVERHANG x H on both sides of the specimen
PLATE_DEPTH = 0.5            # plates are PLATE_DEPTH x H deep
PLATEN, BASE = "platen", "base"
STEP_TIME = 5e-3             # s, the pseudo-time of a loading step: numerical. With velocity reset the inertia
#                              M/h^2 is what holds the modes the frictionless platens leave free (the specimen's
#                              sideways translation): with h = 1/6 s (6 steps over 1 s) Newton stalled at a
#                              residual 0.45 on the 3-course prism, with 5 ms it converges; the inertial part of the
#                              platen's force (m du/h^2, < 1e-3 of it here) is subtracted in the read-out.


@dataclass
class CompressionSpec(SpecimenSpec):
    specimen: str = spec("prism", doc="'prism' (stack-bonded, one brick per course) or 'wallet' (running bond, "
                                      "`bricks_per_course` wide)", choices=("prism", "wallet"))
    courses: int = spec(5, doc="courses of the specimen (at least 2: a bed joint to load; EN 1052-1 as recalled "
                               "asks at least 5 courses for ordinary bricks)", lo=2)
    bricks_per_course: float | None = spec(None, doc="wallet: bricks per course, a multiple of 1/2, at least 1.5 "
                                                     "(default 1.5); prism: 1 (its only value)", lo=0.0,
                                           lo_open=True)
    displacement: float | None = spec(None, doc="downward displacement of the top platen over the loading "
                                                "(positive; default 0.3 % of the specimen's height, assumed)",
                                      unit="length", lo=0.0, lo_open=True)
    gauge_courses: int | None = spec(None, doc="gauge length in whole courses, from the middle of a course to the "
                                               "middle of another (default: the m nearest to courses/3 with the "
                                               "gauge centred on mid-height); 1 to courses - 1", lo=1)


SPEC = CompressionSpec


def read_lists(t, U) -> dict:
    """No list keys."""
    return {}


def width_in_bricks(s: CompressionSpec) -> float:
    if s.bricks_per_course is not None:
        return float(s.bricks_per_course)
    return 1.0 if s.specimen == "prism" else 1.5


def default_gauge_courses(n: int) -> int:
    """The m in 1..n-1 nearest to n/3 with n - m odd (both gauge points at the middle of a course and the gauge
    centred on mid-height); on a tie the longer."""
    cands = [m for m in range(1, n) if (n - m) % 2 == 1]
    return min(cands, key=lambda m: (abs(m - n / 3.0), -m))


def gauge_courses(s: CompressionSpec) -> int:
    return s.gauge_courses if s.gauge_courses is not None else default_gauge_courses(s.courses)


def check(s: CompressionSpec, t) -> None:
    """The specimen must be buildable: a wallet of at least 1.5 bricks in halves, a prism one brick wide, a gauge
    inside the specimen, a platen displacement smaller than the specimen's height."""
    nb = s.bricks_per_course
    if s.specimen == "prism" and nb is not None and nb != 1.0:
        raise t.error("bricks_per_course", f"= {nb:g}: a stack-bonded prism is one brick per course (1); use "
                                           "specimen = \"wallet\" for a running-bond specimen")
    if s.specimen == "wallet" and nb is not None:
        if abs(2 * nb - round(2 * nb)) > 1e-9:
            raise t.error("bricks_per_course", f"= {nb:g}: expected a multiple of 1/2 (whole and half bricks)")
        if nb < 1.5:
            raise t.error("bricks_per_course", f"= {nb:g}: a running-bond wallet needs at least 1.5 bricks per "
                                               "course (a full and a half brick, the head joints of neighbouring "
                                               "courses half a brick apart)")
    m = s.gauge_courses
    if m is not None and m > s.courses - 1:
        raise t.error("gauge_courses", f"= {m}: expected at most courses - 1 = {s.courses - 1} (the gauge runs from "
                                       "the middle of one course to the middle of another)")
    hs = s.courses * (s.brick_height + s.joint_thickness)
    if s.displacement is not None and s.displacement >= hs:
        raise t.error("displacement", f"= {s.displacement / t.units['length']:g}: expected less than the "
                                      f"specimen's height {hs / t.units['length']:g} (the file's length unit)")


def layout(s: CompressionSpec) -> list:
    """The bricks of each course from the base: [[(x0, length), ...], ...] (SI, expanded bricks)."""
    if s.specimen == "prism":
        return [[(0.0, s.brick_length)] for _ in range(s.courses)]
    nb, lm = width_in_bricks(s), s.brick_length + s.joint_thickness
    out = []
    for i in range(s.courses):
        units = [1.0] * int(nb) + ([0.5] if nb % 1 else []) if i % 2 == 0 else \
            [0.5] + [1.0] * int(nb - 0.5) + ([0.5] if (nb - 0.5) % 1 else [])
        x, row = 0.0, []
        for u in units:
            row.append((x, u * lm))
            x += u * lm
        out.append(row)
    return out


def wallet_mesh_size(s: CompressionSpec) -> float:
    """The element size of a wallet's bricks: a half brick (brick_length + joint_thickness)/2 in an even number
    k of elements, the nearest to the asked size (mesh_size, default half the course height), so that a full
    brick has 2k and the nodes of the two faces of every bed joint match, with `--quick` too (k/2 and k)."""
    h = s.mesh_size if s.mesh_size is not None else 0.5 * (s.brick_height + s.joint_thickness)
    half = 0.5 * (s.brick_length + s.joint_thickness)
    return half / (2 * max(1, round(0.5 * half / h)))


def gauge_points(s: CompressionSpec, rows: list) -> list:
    """The four gauge points: dict(name, block, x, y, line, end) (SI, reference configuration); lines "L" and "R"
    at x_l and W - x_l, ends 0 (bottom: middle of course a) and 1 (top: middle of course a + m)."""
    H = s.brick_height + s.joint_thickness
    W = sum(ln for _, ln in rows[0])
    slot = 0.5 * (s.brick_length + s.joint_thickness) if s.specimen == "wallet" else 0.5 * W
    xl = (np.floor(0.25 * W / slot) + 0.5) * slot   # middle of the half-brick slot holding W/4: no head joint
    m = gauge_courses(s)
    a = (s.courses - 1 - m) // 2
    pts = []
    for line, x in (("L", xl), ("R", W - xl)):
        for end, c in ((0, a), (1, a + m)):
            j = next(j for j, (x0, ln) in enumerate(rows[c]) if x0 < x < x0 + ln)
            pts.append(dict(name=f"g{line}{end}", block=brick_name(s, c, j), x=float(x), y=float((c + 0.5) * H),
                            line=line, end=end, xc=float(rows[c][j][0] + 0.5 * rows[c][j][1]),
                            yc=float((c + 0.5) * H)))
    return pts


def brick_name(s: CompressionSpec, course: int, j: int) -> str:
    return f"c{course}" if s.specimen == "prism" else f"c{course}b{j}"


def specimens(s: CompressionSpec, emitter):
    """One case: the specimen between the base plate (fixed) and the platen (driven down by `displacement`)."""
    H = s.brick_height + s.joint_thickness
    rows = layout(s)
    W = sum(ln for _, ln in rows[0])
    hs = s.courses * H
    d = s.displacement if s.displacement is not None else DEFAULT_SHORTENING * hs
    e = emitter(s.specimen)
    t = e.thickness * e.U["length"] if e.thickness is not None else 1.0
    for i, row in enumerate(rows):
        for j, (x0, ln) in enumerate(row):
            e.brick(brick_name(s, i, j), x0, i * H, ln, H)
    if s.specimen == "wallet" and s.bricks == "deformable":
        for bt in e.data["block_types"].values():   # matching meshes across the bed joints (module docstring)
            bt["mesh_size"] = e.L(wallet_mesh_size(s))
    o, dp = OVERHANG * H, PLATE_DEPTH * H
    e.plate(BASE, -o, -dp, W + o, 0.0)
    e.plate(PLATEN, -o, hs, W + o, hs + dp,
            drivers={"y": ("displacement", dict(times=[0.0, s.steps * STEP_TIME], values=[0.0, -d]))})
    e.interfaces()
    e.stage("compression", s.steps, duration=s.steps * STEP_TIME)
    e.defaults("contact", solver="newton", tol=1e-10, max_sweeps=5000)
    gauges = gauge_points(s, rows)
    out = dict(curve=dict(body=PLATEN, force="y", displacement="y"))
    if s.bricks == "deformable":
        out["gauges"] = [dict(name=g["name"], block=g["block"], point=[e.L(g["x"]), e.L(g["y"])]) for g in gauges]
    e.defaults("output", **out)
    r12 = lambda v: float(f"{v:.12g}")   # noqa: E731  (the sums of SI lengths, without their round-off digits)
    info = dict(specimen=s.specimen, courses=s.courses, bricks_per_course=width_in_bricks(s), width_m=r12(W),
                height_m=r12(hs), area_m2=r12(W * t), displacement_m=r12(d), gauge_courses=gauge_courses(s),
                gauge_length_m=r12(gauge_courses(s) * H))
    return [(s.specimen, e.data, info)]


def gauge_uy(s: CompressionSpec, h: dict, g: dict) -> np.ndarray:
    """u_y [m] of a gauge point per history row: its column (deformable bricks, `[output] gauges`) or the rigid
    motion of its brick, u = d + (R(phi) - I)(X - X_c)."""
    if s.bricks == "deformable":
        return np.asarray(h[f"{g['name']}.uy"], dtype=float)
    b = g["block"]
    phi = np.asarray(h[f"{b}.urz"], dtype=float)
    return (np.asarray(h[f"{b}.uy"], dtype=float) + np.sin(phi) * (g["x"] - g["xc"])
            + (np.cos(phi) - 1.0) * (g["y"] - g["yc"]))


def curves(s: CompressionSpec, run: dict) -> dict:
    """From one specimen's history: force F [N] (platen reaction less its inertial part, > 0 in compression),
    stress F/A [Pa], platen displacement [m] (> 0 down), gauge strain [1] (> 0 shortening; mean of the two lines)
    and the strain of each line."""
    h, info = run["history"], run["info"]
    gauges = gauge_points(s, layout(s))
    F = -(np.asarray(h[f"{PLATEN}.Ry"], dtype=float) - np.asarray(h[f"{PLATEN}.Iy"], dtype=float))
    lines = {}
    for line in ("L", "R"):
        g0, g1 = [next(g for g in gauges if g["line"] == line and g["end"] == k) for k in (0, 1)]
        lines[line] = -(gauge_uy(s, h, g1) - gauge_uy(s, h, g0)) / info["gauge_length_m"]
    return dict(force=F, stress=F / info["area_m2"], platen=-np.asarray(h[f"{PLATEN}.uy"], dtype=float),
                strain=0.5 * (lines["L"] + lines["R"]), strain_L=lines["L"], strain_R=lines["R"])


def series_modulus(s: CompressionSpec, case) -> float | None:
    """The series formula of the model over whole courses, 1 / (1/E_b + 1/(k_n H)) (module docstring), from the
    case's material and joint law (k_n, or c_N of the elastic law); None when the law has neither."""
    p = case.interfaces[0].params
    kn = p.get("k_n", p.get("c_N"))
    if kn is None:
        return None
    H = s.brick_height + s.joint_thickness
    if s.bricks == "rigid":
        return float(kn * H)
    m = case.materials[s.material]
    Eb = m.E if getattr(m, "plane", "stress") == "stress" else m.E / (1.0 - m.nu ** 2)
    return float(1.0 / (1.0 / Eb + 1.0 / (kn * H)))


def analyse(s: CompressionSpec, run: dict) -> tuple:
    """(curves, secant, peak reached) of one specimen; a curve that cannot be read (a run stopped before the stress
    rose: readout.secant_at_fraction's ValueError) gives NaN values and no peak."""
    c = curves(s, run)
    try:
        return c, secant_at_fraction(c["stress"], c["strain"]), peak_confirmed(c["force"], c["platen"])
    except ValueError:
        nan = float("nan")
        return c, dict(peak=nan, peak_index=0, stress=nan, strain=nan, modulus=nan), False


def specimen_line(s: CompressionSpec, run: dict) -> str:
    c, sec, ok = analyse(s, run)
    return (f"{s.specimen}, {s.courses} courses x {width_in_bricks(s):g} bricks: f = F_max/A = {sec['peak'] / 1e6:.4f}"
            f" MPa, E (secant at f/3) = {sec['modulus'] / 1e6:.1f} MPa"
            + ("" if ok else "; WARNING: no peak (the force still rises at the end of the loading, or the run "
                             "stopped): f is a lower bound; increase lab.displacement"))


def readout(s: CompressionSpec, runs: list) -> dict:
    r = runs[0]
    c, sec, ok = analyse(s, r)
    k = sec["peak_index"]
    p = r["case"].interfaces[0].params   # the joint law, SI
    Es = series_modulus(s, r["case"])
    fc = p.get("f_c")
    q = {"f": dict(value=sec["peak"], unit="Pa", name="compressive strength F_max / A",
                   measures=f"laws.{s.joint}.f_c" if fc is not None else
                   f"laws.{s.joint}.f_c (absent: the joints have no compressive failure mode)", input=fc),
         "E": dict(value=sec["modulus"], unit="Pa", name="secant modulus at one third of the peak, F_max / (3 A "
                   "eps_1/3)", measures=f"materials.{s.material}.E and laws.{s.joint}.k_n in series over a course: "
                   "1/(1/E_b + 1/(k_n H))" if s.bricks == "deformable" else f"laws.{s.joint}.k_n over a course: "
                   "k_n H (rigid bricks)", input=Es),
         "F_max": dict(value=float(c["force"][k]), unit="N", name="peak force of the platen (less its inertial part)"),
         "strain_at_peak": dict(value=float(c["strain"][k]), unit="1", name="gauge strain at the peak"),
         "strain_one_third": dict(value=sec["strain"], unit="1", name="gauge strain at one third of the peak "
                                  "(eps_1/3)")}
    lines = None
    if np.isfinite(sec["strain"]):   # each gauge line's strain at f/3 (their spread: the specimen's bending)
        lines = [secant_at_fraction(c["stress"], c[f"strain_{ln}"])["strain"] for ln in ("L", "R")]
    extra = {}
    if not ok:   # no peak: the standard's quantities are not measured (NaN: exit status 1, summary "unmeasured")
        extra = dict(lower_bound_f_Pa=sec["peak"], secant_at_third_of_largest_force_Pa=sec["modulus"])
        for v in q.values():
            v["value"] = float("nan")
    info = r["info"]
    return dict(quantities=q, peak_reached=bool(ok), peak_index=int(k), area_m2=info["area_m2"],
                width_m=info["width_m"], height_m=info["height_m"], gauge_length_m=info["gauge_length_m"],
                gauge_courses=info["gauge_courses"], displacement_m=info["displacement_m"],
                stress_one_third_Pa=sec["stress"], series_modulus_Pa=Es, strain_lines_at_one_third=lines, **extra)


def plot(s: CompressionSpec, report: dict, runs: list, path: str, title: str = ""):
    """PNG: left, the stress-strain curve (gauge strain) with the peak, the one-third level and the secant
    E = F_max / (3 A eps_1/3) drawn through the origin; right, the stress against the platen's displacement over
    the specimen's height (nominal strain of the whole specimen)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = curves(s, runs[0])
    q = report["quantities"]
    f, E, e3 = q["f"]["value"], q["E"]["value"], q["strain_one_third"]["value"]
    k = report["peak_index"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.4))
    ax[0].plot(c["strain"] * 1e3, c["stress"] / 1e6, "-", lw=1.4, label="model (mean of the two gauge lines)")
    ax[0].plot(c["strain"][k] * 1e3, f / 1e6, "o", mfc="none", ms=7, label=f"peak: f = {f / 1e6:.3f} MPa")
    emax = 1.15 * max(float(np.nanmax(c["strain"])), 3 * e3)
    xs = np.array([0.0, min(emax, 1.2 * f / E) if E > 0 else emax])
    ax[0].plot(xs * 1e3, E * xs / 1e6, "k--", lw=1, label=f"secant at f/3: E = {E / 1e6:.0f} MPa")
    ax[0].axhline(f / 3e6, color="0.5", lw=0.8, ls=":", label="f/3")
    ax[0].plot(e3 * 1e3, f / 3e6, "ks", ms=5, mfc="none", label=f"ε_1/3 = {e3 * 1e3:.4f} ‰")
    Es = report.get("series_modulus_Pa")
    if Es:
        ax[0].plot(xs * 1e3, Es * xs / 1e6, ":", color="tab:red", lw=1,
                   label=f"series formula: {Es / 1e6:.0f} MPa")
    ax[0].set(xlabel=f"strain over {report['gauge_courses']} course(s) ({report['gauge_length_m'] * 1e3:g} mm) [‰]",
              ylabel="stress F/A [MPa]", xlim=(0, None), ylim=(0, None),
              title=f"{title}: EN 1052-1, E = F_max / (3 A ε_1/3)")
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    ax[1].plot(c["platen"] / report["height_m"] * 1e3, c["stress"] / 1e6, "-", lw=1.2)
    ax[1].set(xlabel="platen displacement / specimen height [‰]", ylabel="stress F/A [MPa]", xlim=(0, None),
              ylim=(0, None), title=f"whole specimen ({report['height_m'] * 1e3:g} mm high)")
    ax[1].grid(alpha=0.3)
    if not report["peak_reached"]:
        ax[0].text(0.5, 0.5, "NO PEAK: f is a lower bound", transform=ax[0].transAxes, color="red", ha="center")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Run figures: force–displacement curve (from the run's history columns, kept in memory), crack pattern (deformed blocks, joints
coloured by damage, or by opening for dry joints, drawn thicker where they open or slip; on split-brick walls the
cracked bricks shaded and their cracks in their own colour, brick_cracks) and 3D views of 3D bodies
(write_blocks_3d)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from .plots import plot_crack_pattern, plot_curve, plot_hysteresis, plot_rotations, plot_polygons_3d, plot_polygons_3d_pyvista


def _loop(edges: np.ndarray) -> np.ndarray:
    """Node sequence of the boundary loop containing edge 0 (edges oriented, body on the left)."""
    nxt = {int(a): int(b) for a, b in edges}
    start = int(edges[0, 0])
    seq = [start]
    k = nxt[start]
    while k != start and len(seq) <= len(edges):
        seq.append(k)
        k = nxt.get(k, start)
    return np.array(seq)


def body_outlines(sim, amplification: float):
    polys, loops = [], {}  # boundary loop per block type (computed once per call, not cached on the type)
    for b in sim.bodies:
        if b.kind == 0:
            loop = loops.get(id(b.type))
            if loop is None:
                loop = loops[id(b.type)] = _loop(b.type.mesh.boundary_edges)
            X = b.reference_points[loop]
            D = b.displacement_global()[loop]
            polys.append(X + amplification * D)
        else:
            ref = b.center0 + b.vertices_rel
            polys.append(ref + amplification * (b.current_vertices() - ref))
    return polys


def crack_width(state: np.ndarray) -> np.ndarray:
    """Width of the crack at each contact point [m]: w = sqrt(<u_N>+^2 + u_T^2), the joint's opening and slip
    since the reference state (state columns S_UN, S_UT; 2D). A closed joint that does not slide has w ~ 0 (its
    elastic jump only), whatever its damage."""
    from ..laws import S_UN, S_UT
    st = np.asarray(state, dtype=float)
    return np.hypot(np.maximum(st[:, S_UN], 0.0), st[:, S_UT])


def segment_widths(width: np.ndarray, thin: float = 0.8, thick: float = 5.0):
    """Line widths [pt] of the joint segments: thin + (thick - thin) w / w_max (w_max = largest crack width;
    all thin when nothing opens). Returns (widths, w_max)."""
    w = np.nan_to_num(np.asarray(width, dtype=float), nan=0.0)
    wmax = float(w.max()) if w.size else 0.0
    if wmax <= 0.0:
        return np.full(w.shape, thin), 0.0
    return thin + (thick - thin) * np.clip(w / wmax, 0.0, 1.0), wmax


def joint_segments(result, x_ref, x_cur, length, amplification: float):
    """Short segments along each joint at the contact points of `result` (a contact.result.ContactResult, 2D),
    their crack value in [0, 1], its label and the crack width at each point (crack_width). x_ref, x_cur (nc, 2):
    the contact points in the reference and current configurations; length (nc,): tributary joint lengths; the
    segment is centred at x_ref + amplification (x_cur - x_ref), along t, of that length."""
    cs = None if result is None else result.cs
    if cs is None or len(cs.gap) == 0:
        return np.zeros((0, 2, 2)), np.zeros(0), "damage", np.zeros(0)
    half = 0.5 * np.asarray(length)
    x = x_ref + amplification * (x_cur - x_ref)
    seg = np.stack([x - half[:, None] * cs.t, x + half[:, None] * cs.t], axis=1)
    law = np.zeros(len(cs.gap), int) if result.law is None else result.law
    if np.any(law >= 2):
        from ..laws import MIXED, S_BETA
        st = result.state
        val = np.where(law == MIXED, st[:, S_BETA], np.where(law >= 2, 1.0 - st[:, S_BETA], 0.0))
        label = "joint damage"
    else:
        opening = np.maximum(np.asarray(result.gt_end), 0.0)
        ref = max(float(np.percentile(opening, 99)) if opening.size else 0.0, 1e-12)
        val = np.clip(opening / ref, 0.0, 1.0)
        label = f"joint opening / {ref:.2g} m"
    width = crack_width(result.state) if result.state is not None else np.zeros(len(cs.gap))
    return seg, val, label, width


def auto_amplification(sim) -> float:
    pts, disp = [], []
    for b in sim.bodies:
        if b.kind == 0:
            pts.append(b.reference_points)
            disp.append(b.displacement_global())
    if not pts:
        return 1.0
    P = np.concatenate(pts)
    dmax = float(np.abs(np.concatenate(disp)).max())
    size = float(np.ptp(P, axis=0).max())
    if dmax <= 0:
        return 1.0
    amp = 0.03 * size / dmax
    mag = 10 ** np.floor(np.log10(amp))
    return float(np.floor(amp / mag) * mag) if amp > 1 else 1.0


# A brick of a split-brick wall counts as cracked when the crack between its two halves (the "crack" interface) has
# opened or slid by at least this width somewhere: w = sqrt(<u_N>+^2 + u_T^2) >= 0.1 mm (assumed: about the narrowest
# crack read by eye on a tested wall, approximate; the brick cracks' own softening ends at u_f = 2 G_I / f_t = 0.08 mm
# in pure mode I with the micro-model's values, so a counted crack carries no tension any more).
BRICK_CRACK_WIDTH = 0.1e-3  # m


def brick_cracks(result, geometry, threshold: float = BRICK_CRACK_WIDTH):
    """The split bricks and which of them are cracked, from the 2D contact record `result` and the contact step
    `geometry` (its `interfaces`, `body_parent`: the two halves of a brick share a parent id >= 0, and `body_names`).
    A contact belongs to a brick crack when its interface has orientation "crack"; a brick is cracked when one of its
    crack contacts has a crack width (crack_width) >= `threshold` [m]. None when the model has no brick crack
    (no "crack" interface or no split brick). Returns dict(threshold_m, n_bricks, n_cracked, cracked (parent ids,
    sorted), cracked_bodies (body indices of their halves), cracked_names (per cracked brick, its halves' names),
    crack (nc,) bool: crack contacts, open (nc,) bool: crack contacts at or above the threshold, max_width_m)."""
    itfs = list(getattr(geometry, "interfaces", []) or [])
    parent = np.asarray(getattr(geometry, "body_parent", np.zeros(0, dtype=np.int64)), dtype=np.int64)
    is_crack = np.array([getattr(itf, "orientation", "any") == "crack" for itf in itfs], dtype=bool)
    bricks = np.unique(parent[parent >= 0])
    if not is_crack.any() or bricks.size == 0:
        return None
    cs = None if result is None else result.cs
    nc = 0 if cs is None else len(cs.gap)
    if nc == 0 or result.state is None:
        crack, width = np.zeros(nc, bool), np.zeros(nc)
    else:
        crack = is_crack[cs.interface]
        width = crack_width(result.state)
    opened = crack & (width >= threshold)
    cracked = np.unique(parent[cs.cand_body[opened]]) if opened.any() else np.zeros(0, dtype=np.int64)
    bodies = np.flatnonzero(np.isin(parent, cracked))
    names = getattr(geometry, "body_names", None) or [str(i) for i in range(len(parent))]
    return dict(threshold_m=float(threshold), n_bricks=int(bricks.size), n_cracked=int(cracked.size),
                cracked=cracked, cracked_bodies=bodies,
                cracked_names=[[names[b] for b in np.flatnonzero(parent == p)] for p in cracked],
                crack=crack, open=opened, max_width_m=float(width[crack].max()) if crack.any() else 0.0)


def crack_pattern_data(sim, result, geometry=None) -> dict:
    """What crack_pattern.png draws, from the simulation `sim` (deformed bodies), its 2D contact record `result`
    (None: no contact step yet) and the contact step `geometry` (contact_points, joint_lengths, interfaces,
    body_parent; None: a model without contact): amplification, body outlines, the joints' segments (seg, val,
    label, widths [pt], the largest crack width w_max [m]; brick-crack contacts excluded) and, on a split-brick wall,
    `bricks` (brick_cracks) with the segments of the cracks at or above its threshold (crack_seg, crack_widths) and
    the legend's title `crack_label` ("brick cracks: n of N bricks cracked (crack width ≥ 0.1 mm)"; None without)."""
    amp = auto_amplification(sim)
    polys = body_outlines(sim, amp)
    empty = np.zeros((0, 2, 2))
    if geometry is None:  # a model without contact
        seg, val, label, width = empty, np.zeros(0), "", np.zeros(0)
    elif result is None or result.cs is None or len(result.cs.gap) == 0:
        seg, val, label, width = joint_segments(result, None, None, None, amp)
    else:
        cs = result.cs
        seg, val, label, width = joint_segments(result, geometry.contact_points(cs, reference=True),
                                                geometry.contact_points(cs), geometry.joint_lengths(cs), amp)
    bricks = None if geometry is None else brick_cracks(result, geometry)
    lw, wmax = segment_widths(width)
    out = dict(amplification=amp, polygons=polys, bricks=bricks, crack_seg=empty, crack_widths=np.zeros(0))
    if bricks is not None and len(seg):
        joint = ~bricks["crack"]
        out.update(crack_seg=seg[bricks["open"]], crack_widths=np.maximum(lw[bricks["open"]], 2.0))  # >= 2 pt: visible
        seg, val, width, lw = seg[joint], np.asarray(val)[joint], width[joint], lw[joint]
    out.update(seg=seg, val=np.asarray(val, dtype=float), label=label, widths=lw, w_max=wmax,
               crack_label=None if bricks is None else
               f"brick cracks: {bricks['n_cracked']} of {bricks['n_bricks']} bricks cracked "
               f"(crack width ≥ {1e3 * bricks['threshold_m']:.2g} mm)")
    return out


def write_crack_pattern(path, sim, result, geometry=None, title=""):
    """crack_pattern.png: the deformed blocks of `sim` and the joints of the 2D contact record `result` (None:
    no contact step yet); on a split-brick wall the cracked bricks shaded and their cracks drawn in their own colour,
    with the count in the legend (crack_pattern_data). `geometry`: the contact step (None: a model without contact).
    Returns the data drawn (crack_pattern_data)."""
    d = crack_pattern_data(sim, result, geometry)
    b = d["bricks"]
    note = (f"line width: joint opening + slip (thickest {1e3 * d['w_max']:.3g} mm)" if d["w_max"] > 0 else "")
    plot_crack_pattern(path, d["polygons"], d["seg"], d["val"], d["amplification"], title=title,
                       value_label=d["label"], widths=d["widths"], width_note=note,
                       shaded=None if b is None else b["cracked_bodies"],
                       crack_segments=None if b is None else d["crack_seg"],
                       crack_widths=None if b is None else d["crack_widths"],
                       crack_label=d["crack_label"])
    return d


def write_rotations(path, history: dict, stages=(), title=""):
    """rotations.png: the rotation columns of history.csv against time — the `[output] rotations` blocks (2D
    NAME.rot; 3D the angle |(NAME.rotx, NAME.roty, NAME.rotz)|) and the rigid bodies' rotation dofs that move (2D
    NAME.urz; 3D NAME.urx, .ury, .urz) — with the stops at a rotation of `stages` (summary.json "stages", entries
    with "stop_rotation") marked: the relative angle reached and the reference body's rotation then."""
    t = np.asarray(history["time"], dtype=float)
    series = {}
    for c in history:
        if c.endswith(".rot"):
            series[f"{c} (block)"] = history[c]
        elif c.endswith(".rotx"):
            b = c[:-5]
            v = np.column_stack([np.asarray(history[f"{b}.rot{k}"], dtype=float) for k in "xyz"])
            series[f"|{b}.rot| (block)"] = np.linalg.norm(v, axis=1)
        elif c.rsplit(".", 1)[-1] in ("urx", "ury", "urz") and np.any(np.asarray(history[c], dtype=float) != 0):
            series[f"{c} (rigid)"] = history[c]
    stops = []
    for st in stages or ():
        r = st.get("stop_rotation")
        if r:
            ref = r["relative_to_rotation_rad"]
            ref = "" if ref is None else (f", reference at {ref:.5g} rad" if np.isscalar(ref) else
                                          f", reference at {np.linalg.norm(ref):.5g} rad (|rotation vector|)")
            stops.append((r["time"], f"stage {st['name']!r} stop: relative {r['relative_angle_rad']:.3g} rad at "
                                     f"t = {r['time']:.4g} s{ref}"))
    return plot_rotations(path, t, series, stops, title)


def dof_unit(column: str):
    """Plot scale and unit of a rigid-body history column `uD` / `RD` (history values are SI): translations
    `ux, uy, uz` [m] -> mm, rotations `urx, ury, urz` [rad] -> rad, forces `Rx, Ry, Rz` [N] -> kN, moments
    `Rrx, Rry, Rrz` [N m] -> kN·m. Returns (scale, unit, quantity)."""
    kind, dof = column[:1], column[1:]
    rot = dof.startswith("r")
    if kind == "u":
        return (1.0, "rad", "rotation") if rot else (1e3, "mm", "displacement")
    if kind == "R":
        return (1e-3, "kN·m", "moment") if rot else (1e-3, "kN", "reaction")
    from ..errors import InputError
    raise InputError(f"history column {column!r}: expected a rigid-body dof column uD or RD (D in x, y, z, rx, ry, "
                     "rz)")


def curve_data(history: dict, body: str, force: str, displacement: str) -> dict:
    """Data of the force–displacement figure: signed values (no abs: a cyclic test keeps its loops in all four
    quadrants) in the unit of each dof (dof_unit), axis labels, and the rows whose contact solve did not converge
    (`converged` = 0 in history.csv; all False without contact). `force`/`displacement`: columns without the body,
    e.g. "Rx", "urz". Returns dict(x, y, xlabel, ylabel, xunit, yunit, unconverged)."""
    sx, ux, qx = dof_unit(displacement)
    sy, uy, qy = dof_unit(force)
    x = np.asarray(history[f"{body}.{displacement}"], float) * sx
    y = np.asarray(history[f"{body}.{force}"], float) * sy
    conv = history.get("converged")
    bad = np.zeros(x.shape, bool) if conv is None else (np.asarray(conv, float) == 0)
    return dict(x=x, y=y, xlabel=f"{body} {qx} {displacement} [{ux}]", ylabel=f"{body} {qy} {force} [{uy}]",
                xunit=ux, yunit=uy, unconverged=bad)


POST_PEAK_FRACTION = 0.85  # the post-peak read-out: where the force has fallen to 85 % of the peak (a common
                           # definition of the ultimate displacement of a masonry wall, e.g. in pushover analyses)


def post_peak(x, y, fraction: float = POST_PEAK_FRACTION) -> dict | None:
    """The softening branch of a monotone force–displacement curve (signed x, y in the figure's units; rows in time
    order), read once for the figure and summary.json: the peak (largest |y|, row k), the end of the run (the last
    finite row: |y_end|, |x_end|, |y_end| / |y_k|) and the post-peak point where |y| first falls to `fraction` of the
    peak after it — linear between the last row above and the first row at or below, |x| there (None when the force
    never falls that far within the run). Magnitudes, as the peak of summary.json. None without a finite point.
    Returns dict(k, peak, d_peak, end, d_end, end_ratio, fraction, d_drop, f_drop, x_drop (signed), y_drop)."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    if ok.size == 0:
        return None
    F = np.abs(y[ok])
    j = int(np.argmax(F))
    k, peak, e = int(ok[j]), float(F[j]), int(ok[-1])
    out = dict(k=k, peak=peak, d_peak=float(abs(x[k])), end=float(abs(y[e])), d_end=float(abs(x[e])),
               end_ratio=float(abs(y[e]) / peak) if peak > 0 else None, fraction=float(fraction), d_drop=None,
               f_drop=None, x_drop=None, y_drop=None)
    target = fraction * peak
    below = np.flatnonzero(F[j:] <= target)
    if peak > 0 and below.size:
        i = j + int(below[0])  # first row at or below the target after the peak; F[i - 1] > target
        a, b = ok[i - 1], ok[i]
        s = (F[i - 1] - target) / (F[i - 1] - F[i])
        xd = float(x[a] + s * (x[b] - x[a]))
        out.update(d_drop=abs(xd), f_drop=float(target), x_drop=xd, y_drop=float(np.sign(y[k]) * target))
    return out


def post_peak_summary(pp: dict, xunit: str, yunit: str, dname: str = "displacement") -> dict:
    """summary.json `post_peak` from post_peak's dict (keys with the figure's units, e.g. `end_force_kN`)."""
    pct = int(round(100 * pp["fraction"]))
    return {f"end_force_{yunit}": pp["end"], f"end_{dname}_{xunit}": pp["d_end"], "end_to_peak": pp["end_ratio"],
            "drop_fraction": pp["fraction"], f"{dname}_at_{pct}_percent_post_peak_{xunit}": pp["d_drop"]}


def curve_arrays(history: dict, body: str, force: str, displacement: str):
    """(displacement, force) of `body`, signed, in the units of dof_unit."""
    c = curve_data(history, body, force, displacement)
    return c["x"], c["y"]


def reference_data(references, force: str, displacement: str) -> list:
    """The [[reference]] entries (specs.ReferenceSpec, SI) in the units of the force–displacement figure
    (dof_unit of the curve's `force` and `displacement` columns, e.g. "Rx", "ux": kN and mm): dicts for
    plots.draw_references and summary.reference_comparison."""
    sx, sy = dof_unit(displacement)[0], dof_unit(force)[0]

    def curve(pts):
        if pts is None:
            return None
        a = np.asarray(pts, dtype=float).reshape(-1, 2)
        return a[:, 0] * sx, a[:, 1] * sy

    return [dict(label=r.label, curve=curve(r.points), lower=curve(r.lower), upper=curve(r.upper), band=r.band,
                 peak=None if r.peak is None else r.peak * sy,
                 peak_band=None if r.peak_band is None else (r.peak_band[0] * sy, r.peak_band[1] * sy),
                 displacement_at_peak=None if r.displacement_at_peak is None else r.displacement_at_peak * sx)
            for r in references or []]


def write_curve(path, history: dict, body: str, force: str, displacement: str, title="", note="", references=None,
                softening=None):
    """force_displacement.png: signed curve (curve_data), unconverged steps marked; `note` (e.g. the count and
    worst residual of the unconverged steps) is added under the title; `references`: the case's [[reference]]
    entries (specs.ReferenceSpec, SI), drawn in the figure's units (reference_data); `softening`: the post-peak
    read-out (post_peak of the same curve) marked on the softening branch."""
    c = curve_data(history, body, force, displacement)
    return plot_curve(path, c["x"], c["y"], c["xlabel"], c["ylabel"], title=title,
                      marks=c["unconverged"] if c["unconverged"].any() else None,
                      marks_label=f"unconverged step ({int(c['unconverged'].sum())})", note=note,
                      references=reference_data(references, force, displacement) or None,
                      softening=softening, units=(c["xunit"], c["yunit"]))


def write_hysteresis(path, history: dict, body: str, force: str, displacement: str, cycles: dict, title=""):
    """hysteresis.png: the signed curve (curve_data) with each cycle of `cycles` (summary.cycles_block) in its own
    colour and legend entry (number, amplitude, ∮ F du and, with the history column friction_dissipated, the cycle's
    friction work), the rows before the first cycle in grey, unconverged steps marked."""
    c = curve_data(history, body, force, displacement)
    t = np.asarray(history.get("time", np.arange(len(c["x"]))), dtype=float)
    pieces, labels = [], []
    for cyc in cycles["cycles"]:
        i0 = int(np.searchsorted(t, cyc["t_start"], side="right")) - 1  # the row at or before the start
        i1 = min(int(np.searchsorted(t, cyc["t_end"], side="left")), len(t) - 1)  # at or after the end
        amp = max(abs(cyc[f"displacement_pos_{c['xunit']}"]), abs(cyc[f"displacement_neg_{c['xunit']}"])) \
            if f"displacement_pos_{c['xunit']}" in cyc else float("nan")
        pieces.append((max(i0, 0), i1))
        labels.append(f"cycle {cyc['index']}: ±{amp:.3g} {c['xunit']}, {cyc['energy_J']:.3g} J"
                      + (f" (friction {cyc['friction_J']:.3g} J)" if "friction_J" in cyc else "")
                      + ("" if cyc["complete"] else " (incomplete)"))
    bad = c["unconverged"]
    return plot_hysteresis(path, c["x"], c["y"], pieces, labels, c["xlabel"], c["ylabel"],
                           title=f"{title}: {cycles['count']} cycles, ∮F du = {cycles['energy_total_J']:.3g} J",
                           marks=bad if bad.any() else None, marks_label=f"unconverged step ({int(bad.sum())})")


def body_faces_3d(bodies, amplification: float = 1.0):
    """Boundary faces of 3D bodies at the reference position + amplification x displacement: list of (k, 3)
    corner arrays, the body of each face, and the mean |displacement| of its corners (m, not amplified)."""
    polys, owner, dmag = [], [], []
    for i, b in enumerate(bodies):
        if b.kind == 0:
            X, D, F = b.reference_points, b.displacement_global(), b.type.mesh.boundary_faces
        else:
            X = b.center0 + b.points_rel
            D, F = b.current_points() - X, b.boundary_faces
        Y = X + amplification * D
        n = np.linalg.norm(D, axis=1)
        for f in F:
            f = f[f >= 0]
            polys.append(Y[f])
            owner.append(i)
            dmag.append(float(n[f].mean()))
    return polys, np.array(owner, dtype=np.int64), np.array(dmag)


def write_blocks_3d(path, bodies, body_values=None, value_label="", title="", amplification=None,
                    view=(25.0, -60.0), size=(1000, 800), backend: str = "auto"):
    """PNG of 3D bodies (list, or an object with .bodies) rendered off-screen, deformed with `amplification`
    (default auto_amplification), each face coloured by the mean |displacement| of its corners, or by
    `body_values` (one value per body, e.g. the damage of its joints). backend "pyvista" (VTK, off-screen EGL;
    the optional extra `make pyvista`), "matplotlib" (mplot3d, plots.plot_polygons_3d) or "auto" (pyvista when
    it is installed)."""
    if backend not in ("auto", "pyvista", "matplotlib"):
        from ..errors import InputError
        raise InputError(f"backend = {backend!r}: expected 'auto', 'pyvista' or 'matplotlib'")
    if backend == "auto":
        from .plots import has_pyvista
        backend = "pyvista" if has_pyvista() else "matplotlib"
    bodies = list(getattr(bodies, "bodies", bodies))
    amp = auto_amplification(SimpleNamespace(bodies=bodies)) if amplification is None else float(amplification)
    polys, owner, dmag = body_faces_3d(bodies, amp)
    if body_values is None:
        vals, label = dmag, value_label or "|displacement| [m]"
    else:
        bv = np.asarray(body_values, dtype=float).ravel()
        if len(bv) != len(bodies):
            from ..errors import InputError
            raise InputError(f"body_values: expected {len(bodies)} values (one per body), got {len(bv)}")
        vals, label = bv[owner], value_label
    plot = plot_polygons_3d_pyvista if backend == "pyvista" else plot_polygons_3d
    return plot(path, polys, vals, label, title=title, view=view, size=size, note=f"displacements x{amp:g}")


def line_of_thrust_data(sim, result, geometry, names=None) -> dict:
    """What line_of_thrust.png draws (2D): the blocks (current outlines), per joint (output/joints.py, all contact
    points of a pair of bodies at the current points, ContactStep.contact_points / joint_lengths) its extent
    `joint_seg` (middle ± half_width · tangent), the point of application `points` (compressed joints), its line of
    action `action` (through the point along F, one joint width long) and `inside`; `chain`: per deformable block
    with exactly two compressed joints, the segment joining their points (the line of thrust of an arch or a pier).
    `outside`: "A|B" names of the compressed joints whose point is outside the joint."""
    from .joints import record_joints
    polys = body_outlines(sim, 1.0)
    j = record_joints(result, geometry.contact_points, geometry.joint_lengths) if geometry is not None else None
    names = names or [f"body{i}" for i in range(len(polys))]
    if j is None or not len(j):
        z = np.zeros((0, 2, 2))
        return dict(polygons=polys, joint_seg=z, points=np.zeros((0, 2)), action=z, chain=z, inside=np.zeros(0, bool),
                    n_joints=0, n_compressed=0, outside=[])
    comp = j.N > 0
    hw = j.half_width[:, None] * j.tangent
    seg = np.stack([j.middle - hw, j.middle + hw], axis=1)
    fdir = j.force / np.maximum(np.linalg.norm(j.force, axis=1), 1e-300)[:, None]
    half = j.half_width[:, None] * fdir
    act = np.stack([j.point - half, j.point + half], axis=1)[comp]
    chain = []
    for b in range(len(polys)):
        if sim.bodies[b].kind != 0:
            continue
        k = np.flatnonzero(comp & ((j.bodies[:, 0] == b) | (j.bodies[:, 1] == b)))
        if len(k) == 2:
            chain.append(j.point[k])
    inside = j.inside[comp]
    out = [f"{names[a]}|{names[b]}" for (a, b), c, i in zip(j.bodies, comp, j.inside) if c and not i]
    return dict(polygons=polys, joint_seg=seg, points=j.point[comp], action=act,
                chain=np.array(chain).reshape(-1, 2, 2), inside=inside, n_joints=len(j),
                n_compressed=int(comp.sum()), outside=out)


def write_line_of_thrust(path, sim, result, geometry, names=None, title=""):
    """line_of_thrust.png (plots.plot_line_of_thrust) of line_of_thrust_data; returns the data."""
    from .plots import plot_line_of_thrust
    d = line_of_thrust_data(sim, result, geometry, names)
    plot_line_of_thrust(path, d["polygons"], d["joint_seg"], d["points"], d["action"], d["chain"], d["inside"],
                        title=title)
    return d

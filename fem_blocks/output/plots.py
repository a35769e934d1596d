"""PNG figures of a run, drawn with matplotlib's Agg canvas (`matplotlib.figure.Figure`, no pyplot: never
opens a window and does not touch the global backend), written atomically. Empty data gives a figure that
says "no data" instead of an error."""
from __future__ import annotations

import io

import os

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes


def _figure(size):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path, dpi):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    atomic_write_bytes(path, buf.getvalue())
    return path


def _no_data(ax):
    ax.text(0.5, 0.5, "no data", ha="center", va="center", fontsize=16, color="0.4", transform=ax.transAxes)


def plot_curve(path, x, y, xlabel, ylabel, title="", peak=True, marks=None, marks_label="", note="",
               references=None, softening=None, units=("", "")):
    """Curve y(x) (e.g. force–displacement); with peak=True the point of largest |y| is marked and annotated
    "peak y at x". `marks` (bool, one per point): points drawn as red crosses with a legend entry `marks_label`
    (e.g. unconverged steps); `note`: a second title line (in red); `references`: reference curves, bands and
    peaks in the units of x and y (draw_references); `softening`: the post-peak read-out (figures.post_peak of the
    same curve): the level fraction × peak dashed from the peak to where the force falls to it (a triangle there,
    its displacement in the legend) and the end of the run ("end: F (r % of the peak) at d"); `units` = (x unit,
    y unit) for its labels. Non-finite points are skipped. Returns `path`."""
    return _save(curve_figure(x, y, xlabel, ylabel, title, peak, marks, marks_label, note, references, softening,
                              units), path, 120)


def curve_figure(x, y, xlabel, ylabel, title="", peak=True, marks=None, marks_label="", note="", references=None,
                 softening=None, units=("", "")):
    """The matplotlib Figure of plot_curve (not saved)."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise InputError(f"plot_curve: x and y must have the same length, got {x.size} and {y.size}")
    if marks is not None:
        marks = np.asarray(marks, dtype=bool).ravel()
        if marks.shape != x.shape:
            raise InputError(f"plot_curve: marks must have one flag per point ({x.size}), got {marks.size}")
    ok = np.isfinite(x) & np.isfinite(y)
    fig = _figure((6.4, 4.4 if note else 4.2) if not references else (6.4, 4.8 + 0.25 * len(references)))
    ax = fig.add_subplot()
    k = int(np.flatnonzero(ok)[np.argmax(np.abs(y[ok]))]) if ok.any() else -1  # the peak: largest |y|
    if references:  # drawn first, under the model's curve
        draw_references(ax, references, (1.0 if k < 0 or x[k] >= 0 else -1.0, 1.0 if k < 0 or y[k] >= 0 else -1.0))
    if not ok.any():
        _no_data(ax)
    else:
        ax.plot(x, y, "-", lw=1.5, color="C0", label="model" if references else None)
        if marks is not None and (marks & ok).any():
            m = marks & ok
            ax.plot(x[m], y[m], "x", color="red", ms=7, mew=1.8, zorder=4, label=marks_label or "marked")
        if peak:
            ax.plot([x[k]], [y[k]], "o", color="C3", ms=7, zorder=3)
            xs = x[ok]
            right = x[k] > 0.5 * (xs.min() + xs.max())  # put the label on the side with room
            ax.annotate(f"peak {y[k]:.4g} at {x[k]:.4g}", (x[k], y[k]), textcoords="offset points",
                        xytext=(-10 if right else 10, -16 if y[k] >= 0 else 12), ha="right" if right else "left",
                        color="C3", bbox=dict(facecolor="white", alpha=0.8, edgecolor="none", pad=1))
        if softening is not None:
            _draw_softening(ax, x, y, softening, units)
        ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=7 if references else 9)
    ax.set(xlabel=xlabel, ylabel=ylabel)
    if note:
        ax.set_title(note, color="red", fontsize=9)
        fig.suptitle(title, fontsize=12)
    else:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def _draw_softening(ax, x, y, pp, units):
    """The post-peak read-out of plot_curve on `ax` (pp: figures.post_peak)."""
    xu, yu = units
    k = pp["k"]
    pct = int(round(100 * pp["fraction"]))
    if pp["x_drop"] is not None:
        ax.plot([x[k], pp["x_drop"]], [pp["y_drop"]] * 2, ":", color="C1", lw=1.2)
        ax.plot([pp["x_drop"]], [pp["y_drop"]], "v", color="C1", ms=8, zorder=4,
                label=f"post-peak: {pct} % of the peak at {pp['d_drop']:.3g} {xu}")
    else:
        ax.plot([], [], "v", color="C1", ms=8, label=f"the force stays above {pct} % of the peak after it")
    e = int(np.flatnonzero(np.isfinite(x) & np.isfinite(y))[-1])
    if e != k:
        ratio = "" if pp["end_ratio"] is None else f" ({100 * pp['end_ratio']:.0f} % of the peak)"
        ax.plot([x[e]], [y[e]], "s", color="C1", ms=6, mfc="white", mew=1.5, zorder=4,
                label=f"end: {pp['end']:.4g} {yu}{ratio} at {pp['d_end']:.3g} {xu}")


_REF_COLOURS = ("C2", "C4", "C1", "C5", "C6", "C8", "C9")


def draw_references(ax, references, sign=(1.0, 1.0)):
    """Draw reference data on `ax` (units of the plot), one legend entry each (its label, wrapped): a dict with
    `label` and `curve` (d, F) -> dashed line; `band` (relative r) -> shaded F(1 ± r) around the curve or the
    peak; `lower`, `upper` (d, F) -> shaded area between them; the peak-only form `peak` -> dashed horizontal
    line, `peak_band` (Fmin, Fmax) -> shaded horizontal band, `displacement_at_peak` -> a square marker. Peaks are
    magnitudes: drawn at sign = (sign of d, sign of F) of the model's peak. Returns the artists drawn."""
    import textwrap
    arts = []
    for i, r in enumerate(references):
        c = _REF_COLOURS[i % len(_REF_COLOURS)]
        lab = textwrap.fill(str(r["label"]), 70)
        if r.get("curve") is not None:
            d, F = (np.asarray(a, dtype=float) for a in r["curve"])
            arts += ax.plot(d, F, "--", lw=1.5, color=c, label=lab)
            if r.get("band") is not None:
                arts.append(ax.fill_between(d, F * (1 - r["band"]), F * (1 + r["band"]), color=c, alpha=0.18, lw=0))
            if r.get("lower") is not None:
                (dl, Fl), (du, Fu) = ((np.asarray(a, dtype=float) for a in r[k]) for k in ("lower", "upper"))
                arts += ax.fill(np.r_[dl, du[::-1]], np.r_[Fl, Fu[::-1]], color=c, alpha=0.18, lw=0)
            continue
        sx, sy = sign
        P, band = r.get("peak"), r.get("peak_band")
        if band is None and P is not None and r.get("band") is not None:
            band = (P * (1 - r["band"]), P * (1 + r["band"]))
        if band is not None:
            lo, hi = sorted((sy * band[0], sy * band[1]))
            arts.append(ax.axhspan(lo, hi, color=c, alpha=0.2, lw=0, label=None if P is not None else lab))
        if P is not None:
            arts.append(ax.axhline(sy * P, ls="--", lw=1.3, color=c, label=lab))
        if r.get("displacement_at_peak") is not None:
            yp = P if P is not None else 0.5 * (band[0] + band[1])
            arts += ax.plot([sx * r["displacement_at_peak"]], [sy * yp], "s", color=c, ms=6, zorder=3)
    return arts


def plot_rotations(path, t, series: dict, stops=(), title=""):
    """Rotations against time: `series` label -> values [rad] (one per time of `t`); `stops`: (time, label) of the
    stage stops at a rotation, drawn as dotted vertical lines with their label in the legend. Returns `path`."""
    t = np.asarray(t, dtype=float).ravel()
    fig = _figure((6.4, 4.2))
    ax = fig.add_subplot(111)
    if not series:
        _no_data(ax)
    for label, y in series.items():
        ax.plot(t, np.asarray(y, dtype=float).ravel(), lw=1.2, label=label)
    for i, (ts, label) in enumerate(stops):
        ax.axvline(ts, color="k", ls=":", lw=1, alpha=0.4 + 0.6 * (i + 1) / len(stops), label=label)
    ax.set(xlabel="time [s]", ylabel="rotation since placement [rad]", title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return _save(fig, path, 120)


def plot_hysteresis(path, x, y, pieces, labels, xlabel, ylabel, title="", marks=None, marks_label=""):
    """Hysteresis loops: the curve y(x) drawn piece by piece, `pieces` a list of (i0, i1) point ranges (inclusive),
    piece k coloured along a sequential colour map and named `labels[k]` in the legend (e.g. "cycle 3: ±2 mm,
    41 J"); the points outside every piece in grey (e.g. the pre-compression). `marks` (bool per point): red
    crosses (unconverged steps). Returns `path`."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise InputError(f"plot_hysteresis: x and y must have the same length, got {x.size} and {y.size}")
    if len(labels) != len(pieces):
        raise InputError(f"plot_hysteresis: expected one label per piece ({len(pieces)}), got {len(labels)}")
    fig = _figure((7.2, 5.0))
    ax = fig.add_subplot()
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        _no_data(ax)
    else:
        from matplotlib import colormaps
        cmap = colormaps["viridis"]
        ax.plot(x[ok], y[ok], "-", lw=0.8, color="0.75", zorder=1)
        n = max(len(pieces), 1)
        for k, ((i0, i1), lab) in enumerate(zip(pieces, labels)):
            sl = slice(int(i0), int(i1) + 1)
            ax.plot(x[sl], y[sl], "-", lw=1.4, color=cmap(0.9 * k / max(n - 1, 1)), label=lab, zorder=2)
        if marks is not None:
            m = np.asarray(marks, dtype=bool).ravel() & ok
            if m.any():
                ax.plot(x[m], y[m], "x", color="red", ms=6, mew=1.5, zorder=4, label=marks_label or "marked")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.axvline(0.0, color="0.5", lw=0.6)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=7, ncol=1 if n <= 8 else 2, framealpha=0.85)
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    fig.tight_layout()
    return _save(fig, path, 120)


BRICK_FACE, BRICK_EDGE, CRACK_COLOUR = "#f3a48c", "#a8321e", "#1565c0"  # cracked bricks, brick cracks


def plot_crack_pattern(path, polygons, segments, values, amplification, title="", value_label="damage",
                       widths=None, width_note="", shaded=None, crack_segments=None, crack_widths=None,
                       crack_label=None):
    """Deformed block outlines (displacements already amplified by `amplification`) and joint/contact
    segments (m, 2, 2) coloured by `values` (m,) clipped to [0, 1] (NaN drawn grey), `widths` (m,) their line
    widths [pt] (default 2.2; `width_note` says what they mean), with a colourbar and the text
    "displacements x{amplification:g}". Split-brick walls: `shaded` (indices into `polygons`) are filled in a
    distinct colour (cracked bricks), `crack_segments` (k, 2, 2) with `crack_widths` (k,) [pt] are drawn in one
    colour of their own, on top (brick cracks), and `crack_label` (e.g. "brick cracks: 3 of 64 bricks cracked")
    heads a legend of the two. Returns `path`."""
    try:
        amp = float(amplification)
    except (TypeError, ValueError):
        raise InputError(f"amplification = {amplification!r}: expected a number") from None
    polys = []
    for i, p in enumerate(polygons if polygons is not None else []):
        p = np.asarray(p, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise InputError(f"polygons[{i}]: expected a (k, 2) array of outline points, got shape {p.shape}")
        if len(p):
            polys.append(p)
    seg = np.asarray(segments if segments is not None else np.zeros((0, 2, 2)), dtype=float)
    if seg.size == 0:
        seg = np.zeros((0, 2, 2))
    if seg.ndim != 3 or seg.shape[1:] != (2, 2):
        raise InputError(f"segments: expected an (m, 2, 2) array, got shape {seg.shape}")
    val = np.asarray(values if values is not None else [], dtype=float).ravel()
    if len(val) != len(seg):
        raise InputError(f"values: expected {len(seg)} values (one per segment), got {len(val)}")
    lw = np.full(len(seg), 2.2) if widths is None else np.asarray(widths, dtype=float).ravel()
    if len(lw) != len(seg):
        raise InputError(f"widths: expected {len(seg)} line widths (one per segment), got {len(lw)}")
    if np.any(~np.isfinite(lw)) or np.any(lw <= 0):
        raise InputError("widths: expected finite line widths > 0 [pt]")
    cseg = np.asarray(crack_segments if crack_segments is not None else np.zeros((0, 2, 2)), dtype=float)
    cseg = cseg.reshape(-1, 2, 2) if cseg.size else np.zeros((0, 2, 2))
    clw = np.full(len(cseg), 2.2) if crack_widths is None else np.asarray(crack_widths, dtype=float).ravel()
    if len(clw) != len(cseg):
        raise InputError(f"crack_widths: expected {len(cseg)} line widths (one per crack segment), got {len(clw)}")
    shade = np.zeros(len(polys), bool)
    if shaded is not None:
        idx = np.asarray(shaded, dtype=np.int64).ravel()
        if idx.size and (idx.min() < 0 or idx.max() >= len(polys)):
            raise InputError(f"shaded: expected polygon indices in [0, {len(polys)}), got {idx.tolist()}")
        shade[idx] = True

    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.colors import Normalize
    fig = _figure((7.5, 6.0))
    ax = fig.add_subplot()
    norm = Normalize(0.0, 1.0)
    cmap = colormaps["inferno_r"].with_extremes(bad="0.6")
    if not polys and not len(seg):
        _no_data(ax)
    else:
        if polys:
            ax.add_collection(PolyCollection(polys, facecolors=np.where(shade[:, None], _rgba(BRICK_FACE),
                                                                        _rgba("#e8d5c0")),
                                             edgecolors=np.where(shade[:, None], _rgba(BRICK_EDGE), _rgba("#7a5c3e")),
                                             linewidths=np.where(shade, 1.0, 0.4)))
        if len(seg):
            order = np.argsort(lw, kind="stable")  # widest (open cracks) drawn last, on top
            ax.add_collection(LineCollection(seg[order], array=np.clip(val[order], 0.0, 1.0), cmap=cmap,
                                             norm=norm, linewidths=lw[order]))
        if len(cseg):
            ax.add_collection(LineCollection(cseg, colors=CRACK_COLOUR, linewidths=clw, zorder=3))
        if crack_label is not None:
            from matplotlib.lines import Line2D
            from matplotlib.patches import Patch
            ax.legend(handles=[Patch(facecolor=BRICK_FACE, edgecolor=BRICK_EDGE, label="cracked brick"),
                               Line2D([], [], color=CRACK_COLOUR, lw=2.5, label="brick crack")],
                      title=crack_label, title_fontsize=8, fontsize=8, loc="upper center",
                      bbox_to_anchor=(0.5, -0.06), ncol=2, framealpha=0.9)
        seg = np.concatenate([seg, cseg])
        pts = np.concatenate(polys + [seg.reshape(-1, 2)])
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            pad = 0.03 * max(float((hi - lo).max()), 1e-300) if (hi - lo).max() > 0 else max(abs(lo).max(), 1.0)
            ax.set_xlim(lo[0] - pad, hi[0] + pad)
            ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7, label=value_label)
    ax.set_title(title)
    fig.text(0.01, 0.01, f"displacements x{amp:g}" + (f"; {width_note}" if width_note else ""), fontsize=10)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, path, 130)


def _rgba(colour):
    from matplotlib.colors import to_rgba
    return np.array(to_rgba(colour))


def _subdivide(polys, rgba):
    """Split quadrilaterals much larger than the median face into n x n bilinear sub-quads (same colour, no
    inner edges drawn), so that the painter's depth sort of mplot3d works on faces of similar sizes."""
    diam = np.array([np.ptp(p, axis=0).max() for p in polys])
    ref = float(np.median(diam)) if len(diam) else 0.0
    out, col, edge = [], [], []
    for p, c, d in zip(polys, rgba, diam):
        n = int(min(np.ceil(d / (2.0 * ref)), 12)) if ref > 0 else 1
        if len(p) != 4 or n <= 1:
            out.append(p)
            col.append(c)
            edge.append((0.25, 0.2, 0.15, 0.6))
            continue
        g = np.linspace(0.0, 1.0, n + 1)
        P = ((1 - g)[:, None, None] * ((1 - g)[None, :, None] * p[0] + g[None, :, None] * p[1])
             + g[:, None, None] * ((1 - g)[None, :, None] * p[3] + g[None, :, None] * p[2]))  # (n+1, n+1, 3)
        for i in range(n):
            for j in range(n):
                out.append(np.array([P[i, j], P[i, j + 1], P[i + 1, j + 1], P[i + 1, j]]))
                col.append(c)
                edge.append((0, 0, 0, 0))
    return out, np.array(col), edge


def has_pyvista() -> bool:
    """True when the optional pyvista/VTK renderer is importable (`make pyvista`)."""
    import importlib.util
    return importlib.util.find_spec("pyvista") is not None


def _check_polygons(polygons, values, size):
    """Validated (polygons, width, height, values) for the 3D renderers."""
    polys = []
    for i, p in enumerate(polygons if polygons is not None else []):
        p = np.asarray(p, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
            raise InputError(f"polygons[{i}]: expected a (k >= 3, 3) array of face corners, got shape {p.shape}")
        polys.append(p)
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise InputError(f"size = {size!r}: expected (width, height) in pixels") from None
    if not (16 <= w <= 10000 and 16 <= h <= 10000) or (w, h) != tuple(size):
        raise InputError(f"size = {size!r}: expected integer (width, height) between 16 and 10000 pixels")
    val = None
    if values is not None:
        val = np.asarray(values, dtype=float).ravel()
        if len(val) != len(polys):
            raise InputError(f"values: expected {len(polys)} values (one per polygon), got {len(val)}")
    return polys, w, h, val


def plot_polygons_3d(path, polygons, values=None, value_label="", title="", view=(25.0, -60.0),
                     size=(1000, 800), dpi=100, vmin=None, vmax=None, note=""):
    """Off-screen 3D rendering of planar polygons (block boundary faces) with matplotlib's mplot3d
    (Poly3DCollection, depth-sorted by the painter's algorithm, light shading by the face normal), coloured
    by `values` (one per polygon, viridis between vmin and vmax, default their range; NaN grey; None: one
    masonry colour). `view` = (elevation, azimuth) in degrees; the PNG is exactly size = (width, height)
    pixels; equal scales on x, y, z. `polygons`: a (m, k, 3) array or a list of (k_i, 3) arrays. Returns path."""
    polys, w, h, val = _check_polygons(polygons, values, size)
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LightSource, Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    fig = _figure((w / dpi, h / dpi))
    ax = fig.add_axes((0.0, 0.0, 0.86 if val is not None else 1.0, 0.93), projection="3d")
    ax.view_init(elev=float(view[0]), azim=float(view[1]))
    if not polys:
        _no_data(ax)
    else:
        cmap = colormaps["viridis"].with_extremes(bad="0.6")
        if val is not None:
            fin = val[np.isfinite(val)]
            lo = float(vmin) if vmin is not None else (float(fin.min()) if fin.size else 0.0)
            hi = float(vmax) if vmax is not None else (float(fin.max()) if fin.size else 1.0)
            norm = Normalize(lo, hi if hi > lo else lo + 1.0)
            rgba = cmap(norm(np.ma.masked_invalid(val)))
        else:
            rgba = np.tile(np.array([0.91, 0.84, 0.75, 1.0]), (len(polys), 1))
        # Lambert shading by the face normal (Newell's normal of each polygon), light from the viewer's upper left
        nrm = np.array([np.sum(np.cross(p, np.roll(p, -1, axis=0)), axis=0) for p in polys])
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        ls = LightSource(azdeg=float(view[1]) + 135.0, altdeg=45.0)
        light = np.array(ls.direction)
        shade = 0.55 + 0.45 * np.abs(nrm @ light)
        rgba[:, :3] *= shade[:, None]
        polys, rgba, edge = _subdivide(polys, rgba)
        ax.add_collection3d(Poly3DCollection(polys, facecolors=rgba, edgecolors=edge, linewidths=0.3))
        P = np.concatenate(polys)
        P = P[np.all(np.isfinite(P), axis=1)]
        lo3, hi3 = P.min(axis=0), P.max(axis=0)
        c, r = 0.5 * (lo3 + hi3), 0.5 * max(float((hi3 - lo3).max()), 1e-300)
        ax.set(xlim=(c[0] - r, c[0] + r), ylim=(c[1] - r, c[1] + r), zlim=(c[2] - r, c[2] + r))
        ax.set_box_aspect((1, 1, 1))
        ax.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
        if val is not None:
            cax = fig.add_axes((0.88, 0.15, 0.025, 0.65))
            fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, label=value_label)
    fig.text(0.5, 0.965, title, ha="center", va="center", fontsize=12)
    if note:
        fig.text(0.01, 0.01, note, fontsize=10)
    return _save(fig, path, dpi)


def plot_polygons_3d_pyvista(path, polygons, values=None, value_label="", title="", view=(25.0, -60.0),
                             size=(1000, 800), vmin=None, vmax=None, note=""):
    """Same picture as plot_polygons_3d rendered with pyvista/VTK off-screen (EGL, no X server needed): the
    polygons as one PolyData, coloured by `values` (viridis, NaN grey) with a scalar bar, camera at (elevation,
    azimuth) = `view` looking at the model's centre, title and note as text; PNG of exactly `size` pixels.
    VTK's renderer aborts in a process that has imported dolfinx (measured with vtk 9.7 / dolfinx 0.5.2), so the
    picture is then drawn in a child process (`python -m fem_blocks.output.plots ARGS.npz`)."""
    import sys
    polys, w, h, val = _check_polygons(polygons, values, size)
    if "dolfinx" in sys.modules:
        import subprocess
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            f = os.path.join(tmp, "args.npz")
            np.savez(f, n=np.array([len(p) for p in polys], dtype=np.int64),
                     pts=np.concatenate(polys) if polys else np.zeros((0, 3)),
                     val=np.array([]) if val is None else val, has_val=val is not None,
                     meta=np.array([os.path.abspath(path), value_label, title, note]),
                     num=np.array([view[0], view[1], w, h, np.nan if vmin is None else vmin,
                                   np.nan if vmax is None else vmax], dtype=float))
            r = subprocess.run([sys.executable, "-m", "fem_blocks.output.plots", f], capture_output=True, text=True)
            if r.returncode != 0 or not os.path.exists(path):
                raise RuntimeError(f"pyvista rendering of {path} failed (exit {r.returncode}): "
                                   f"{(r.stderr or '').strip().splitlines()[-1:]}")
        return path
    import pyvista as pv
    pl = pv.Plotter(off_screen=True, window_size=(w, h))
    pl.set_background("white")
    if polys:
        pts = np.concatenate(polys)
        faces = np.concatenate([np.r_[len(p), np.arange(len(p)) + o]
                                for p, o in zip(polys, np.cumsum([0] + [len(p) for p in polys[:-1]]))])
        mesh = pv.PolyData(pts, faces)
        if val is not None:
            fin = val[np.isfinite(val)]
            lo = float(vmin) if vmin is not None else (float(fin.min()) if fin.size else 0.0)
            hi = float(vmax) if vmax is not None else (float(fin.max()) if fin.size else 1.0)
            mesh.cell_data[value_label or "value"] = val
            pl.add_mesh(mesh, scalars=value_label or "value", cmap="viridis", clim=(lo, hi if hi > lo else lo + 1.0),
                        nan_color="grey", show_edges=True, edge_color="black", line_width=0.3,
                        scalar_bar_args=dict(title=value_label, color="black", vertical=True))
        else:
            pl.add_mesh(mesh, color=(0.91, 0.84, 0.75), show_edges=True, edge_color="black", line_width=0.3)
        lo3, hi3 = pts.min(axis=0), pts.max(axis=0)
        c, r = 0.5 * (lo3 + hi3), float(np.linalg.norm(hi3 - lo3))
        el, az = np.radians(float(view[0])), np.radians(float(view[1]))
        eye = c + 2.0 * r * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        pl.camera_position = [tuple(eye), tuple(c), (0.0, 0.0, 1.0)]
        pl.reset_camera_clipping_range()
    if title:
        pl.add_text(title, position="upper_edge", font_size=12, color="black")
    if note:
        pl.add_text(note, position="lower_left", font_size=9, color="black")
    pl.screenshot(path)
    pl.close()
    return path


if __name__ == "__main__":  # child process of plot_polygons_3d_pyvista (no dolfinx here)
    import sys
    a = np.load(sys.argv[1])
    polys = np.split(a["pts"], np.cumsum(a["n"])[:-1]) if len(a["n"]) else []
    path, label, title, note = (str(x) for x in a["meta"])
    el, az, w, h, lo, hi = a["num"]
    plot_polygons_3d_pyvista(path, polys, a["val"] if bool(a["has_val"]) else None, label, title, (el, az),
                             (int(w), int(h)), None if np.isnan(lo) else lo, None if np.isnan(hi) else hi, note)


def plot_line_of_thrust(path, polygons, joint_seg, points, action, chain, inside, title=""):
    """The blocks (outlines), the joints (grey segments), the points of application of the joint resultants
    (dots: black inside the joint, red outside), their lines of action (thin) and the line of thrust (segments
    joining the two points of blocks with two compressed joints). Returns `path`."""
    fig = _figure((7.0, 5.0))
    ax = fig.add_subplot(111)
    for p in polygons:
        q = np.vstack([p, p[:1]])
        ax.fill(q[:, 0], q[:, 1], color="0.92", lw=0)
        ax.plot(q[:, 0], q[:, 1], color="0.55", lw=0.6)
    for s in joint_seg:
        ax.plot(s[:, 0], s[:, 1], color="0.35", lw=2.2, solid_capstyle="butt")
    for s in action:
        ax.plot(s[:, 0], s[:, 1], color="tab:blue", lw=0.8, alpha=0.7)
    for k, s in enumerate(chain):
        ax.plot(s[:, 0], s[:, 1], color="tab:red", lw=1.6, label="line of thrust" if k == 0 else None)
    inside = np.asarray(inside, bool)
    if len(points):
        ax.plot(points[inside, 0], points[inside, 1], "o", ms=3.5, color="k",
                label=f"point of application, inside ({int(inside.sum())})")
        if (~inside).any():
            ax.plot(points[~inside, 0], points[~inside, 1], "o", ms=5, color="red",
                    label=f"outside the joint ({int((~inside).sum())})")
    else:
        _no_data(ax)
    ax.plot([], [], color="tab:blue", lw=0.8, label="line of action of the joint resultant")
    ax.set_aspect("equal")
    ax.set(xlabel="x [m]", ylabel="y [m]", title=title)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return _save(fig, path, 130)

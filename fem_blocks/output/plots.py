"""PNG figures of a run, drawn with matplotlib's Agg canvas (`matplotlib.figure.Figure`, no pyplot: never
opens a window and does not touch the global backend), written atomically. Empty data gives a figure that
says "no data" instead of an error."""
from __future__ import annotations

import io

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


def plot_curve(path, x, y, xlabel, ylabel, title="", peak=True):
    """Curve y(x) (e.g. force–displacement); with peak=True the point of largest |y| is marked and annotated
    "peak y at x". Non-finite points are skipped. Returns `path`."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise InputError(f"plot_curve: x and y must have the same length, got {x.size} and {y.size}")
    ok = np.isfinite(x) & np.isfinite(y)
    fig = _figure((6.4, 4.2))
    ax = fig.add_subplot()
    if not ok.any():
        _no_data(ax)
    else:
        ax.plot(x, y, "-", lw=1.5, color="C0")
        if peak:
            k = int(np.flatnonzero(ok)[np.argmax(np.abs(y[ok]))])
            ax.plot([x[k]], [y[k]], "o", color="C3", ms=7, zorder=3)
            xs = x[ok]
            right = x[k] > 0.5 * (xs.min() + xs.max())  # put the label on the side with room
            ax.annotate(f"peak {y[k]:.4g} at {x[k]:.4g}", (x[k], y[k]), textcoords="offset points",
                        xytext=(-10 if right else 10, -16 if y[k] >= 0 else 12), ha="right" if right else "left",
                        color="C3", bbox=dict(facecolor="white", alpha=0.8, edgecolor="none", pad=1))
        ax.grid(alpha=0.3)
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    fig.tight_layout()
    return _save(fig, path, 120)


def plot_crack_pattern(path, polygons, segments, values, amplification, title="", value_label="damage"):
    """Deformed block outlines (displacements already amplified by `amplification`) and joint/contact
    segments (m, 2, 2) coloured by `values` (m,) clipped to [0, 1] (NaN drawn grey), with a colourbar and the
    text "displacements x{amplification:g}". Returns `path`."""
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
            ax.add_collection(PolyCollection(polys, facecolors="#e8d5c0", edgecolors="#7a5c3e", linewidths=0.4))
        if len(seg):
            ax.add_collection(LineCollection(seg, array=np.clip(val, 0.0, 1.0), cmap=cmap, norm=norm,
                                             linewidths=2.2))
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
    fig.text(0.01, 0.01, f"displacements x{amp:g}", fontsize=10)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return _save(fig, path, 130)

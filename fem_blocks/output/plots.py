"""PNG figures of a run (matplotlib, Agg backend: never opens a window)."""
from __future__ import annotations

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_curve(path, x, y, xlabel, ylabel, title="", mark_peak=True):
    """Force–displacement curve with the peak marked; writes a figure saying 'no data' when empty."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size == 0:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    else:
        ax.plot(x, y, "-", lw=1.5)
        if mark_peak:
            k = int(np.argmax(np.abs(y)))
            ax.plot(x[k], y[k], "o", color="C3")
            ax.annotate(f"peak {y[k]:.4g} at {x[k]:.4g}", (x[k], y[k]), textcoords="offset points", xytext=(8, -14))
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_crack_pattern(path, polygons, segments, values, amplification, title="", value_label="damage"):
    """Deformed block outlines (displacements amplified) and joint segments coloured by `values` in [0, 1]."""
    plt = _plt()
    from matplotlib.collections import LineCollection, PolyCollection
    fig, ax = plt.subplots(figsize=(7.5, 6.0))
    if len(polygons) == 0:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    else:
        ax.add_collection(PolyCollection(polygons, facecolors="#e8d5c0", edgecolors="#7a5c3e", linewidths=0.4))
        if len(segments):
            lc = LineCollection(segments, array=np.clip(np.asarray(values, float), 0, 1), cmap="inferno_r",
                                linewidths=2.2, norm=_norm())
            ax.add_collection(lc)
            fig.colorbar(lc, ax=ax, shrink=0.7, label=value_label)
        allp = np.concatenate(polygons)
        ax.set_xlim(allp[:, 0].min() - 0.02 * np.ptp(allp[:, 0]), allp[:, 0].max() + 0.02 * np.ptp(allp[:, 0]))
        ax.set_ylim(allp[:, 1].min() - 0.02 * np.ptp(allp[:, 1]), allp[:, 1].max() + 0.02 * np.ptp(allp[:, 1]))
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.text(0.01, 0.01, f"displacements x{amplification:g}", transform=ax.transAxes, fontsize=10,
            bbox=dict(facecolor="white", alpha=0.8, edgecolor="none"))
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def _norm():
    from matplotlib.colors import Normalize
    return Normalize(0.0, 1.0)

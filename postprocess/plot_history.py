"""Plot columns of a run's history.csv against each other.

    .venv/bin/python postprocess/plot_history.py out/shear/history.csv beam.ux beam.Rx beam.Ry -o curves.png

The first column named is the abscissa; the others are plotted against it (absolute values with --abs).
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from fem_blocks.output.history import read_history  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("history")
    p.add_argument("x")
    p.add_argument("y", nargs="+")
    p.add_argument("-o", "--output", default="history.png")
    p.add_argument("--abs", action="store_true")
    a = p.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    h = read_history(a.history)
    for c in [a.x] + a.y:
        if c not in h:
            sys.exit(f"plot_history: column {c!r} not in {a.history}; columns: {', '.join(h)}")
    f = np.abs if a.abs else (lambda v: v)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for c in a.y:
        ax.plot(f(h[a.x]), f(h[c]), label=c)
    ax.set_xlabel(a.x)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(a.output, dpi=120)
    print(a.output)


if __name__ == "__main__":
    main()

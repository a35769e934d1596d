"""Compile the numba kernels once, at set-up time, so that a user's first run does not pay for it.

numba compiles a kernel the first time it is called with a given signature and, with ``cache=True``, keeps the
machine code in ``fem_blocks/**/__pycache__/*.nbi|*.nbc``. A fresh clone has no cache: its first Newton /
mixed-law run spent about 80 s compiling. `make demo` and `make test` run ``python -m fem_blocks.warmup`` once
(scripts/setup.sh), which runs a few shipped demos for two time steps per stage, at reduced resolution, in a
temporary directory: every 2D and 3D detection, kinematics, Delassus, law, NLGS (Coulomb and cohesive) and
Newton kernel that those paths call is compiled and cached. Nothing is kept but numba's cache.
"""
from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
import time

# Demos chosen for the kernels they reach: Frémond-Cangémi joints with the global Newton (shear_wall_fc_p030),
# the mixed-mode law with its softening cap and viscous damage, brick cracks (shear_wall_p030, the micro-model),
# dry 2D Coulomb joints with NLGS (arch), dry 3D joints (wall3d_push).
DEMOS = ("shear_wall_fc_p030.toml", "shear_wall_p030.toml", "arch.toml", "wall3d_push.toml")
# ... and again with the colour-order Gauss-Seidel of runs on several MPI ranks ([contact] order = "colours": its
# exact sums and per-contact residual terms, 2D cohesive, 2D and 3D Coulomb), the interface coarse correction
# (2D Coulomb) and the updated 3D geometry (a re-detection every other step, so that the steps in between update
# the contact geometry: detection_3d.update_geometry)
COLOURS = ("shear_wall_p030.toml", "arch.toml", "wall3d_push.toml")
VARIANTS = {
    "colours": dict(solver="nlgs", fallback="none", coarse="none", order="colours", criterion="residual",
                    max_sweeps=20),
    "coarse": dict(solver="nlgs", fallback="none", coarse="interfaces", max_sweeps=40),
    "updated": dict(geometry="updated", redetect_every=2),
}
EXTRA = ("arch.toml:coarse", "wall3d_push.toml:updated")
STEPS_PER_STAGE = 2


def _demo_dir() -> str:
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "demos")


def warm(demos=DEMOS, out=None, verbose: bool = True, colours=COLOURS, extra=EXTRA) -> float:
    """Run each demo for STEPS_PER_STAGE steps per stage (``--quick`` resolution), then each of `colours` with the
    colour-order Gauss-Seidel and the `extra` "demo:variant" runs (VARIANTS: the [contact] keys replaced); return
    the seconds taken."""
    import dataclasses
    from .case import load_case, quick
    from .runner import run_case
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fem_blocks_warmup_") as tmp:
        for name in list(demos) + [f"{c}:colours" for c in colours] + list(extra):
            name, _, variant = name.partition(":")
            path = os.path.join(_demo_dir(), name)
            if not os.path.exists(path):
                continue
            case = quick(load_case(path))
            if variant:
                case.contact = dataclasses.replace(case.contact, **VARIANTS[variant])
                name = f"{name} ({variant})"
            for st in case.stages:
                st.duration = min(st.duration, STEPS_PER_STAGE * st.h)
                st.output_every = STEPS_PER_STAGE
            t1 = time.perf_counter()
            log = io.StringIO()
            try:  # the two-step runs' own warnings (unconverged steps...) mean nothing here: kept out of sight
                with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                    run_case(case, os.path.join(out or tmp, os.path.splitext(name)[0].replace(" ", "_")),
                             progress=False)
            except Exception as e:  # a failed warm-up only costs compile time later: say so, do not stop the set-up
                print(f"[setup] warning: warm-up run of {name} stopped ({type(e).__name__}: {e}); its kernels "
                      "compile at the first run instead", flush=True)
            if verbose:
                print(f"[setup] numba kernels of {name}: {time.perf_counter() - t1:.0f} s", flush=True)
    return time.perf_counter() - t0


def main() -> int:
    import warnings
    warnings.simplefilter("ignore")
    dt = warm()
    print(f"[setup] numba kernels compiled and cached in {dt:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How much the shear term C_ss τ² of Lourenço's elliptic cap would lower the crushing stress, measured on the
contacts output of a converged run (docs/laws.md "Shear term of Lourenço's cap").

    .venv/bin/python bench/cap_shear_ratio.py OUT_DIR [--f_c 10.5e6] [--G_fc 5000] [--C_ss 9]

OUT_DIR is the output directory of a run (`fem-blocks run CASE --out OUT_DIR`) whose contacts frames are in
OUT_DIR/paraview/contacts_*.vtu. A contact is "on the cap" in a frame when it has crushed (u_p < 0) and its normal
stress r_N/A is at least 0.99 of the softening cap f_c exp(-f_c |u_p| / G_fc) at its closure (the cap of the
shipped mixed-mode files; no hardening branch). For those, with σ = r_N/A and τ = r_T/A, the script prints per
interface the ratio C_ss τ²/σ² and the factor 1/√(1 + C_ss τ²/σ²) by which the ellipse C_nn σ² + C_ss τ² = σ_c²
(C_nn = 1, C_n = 0) would lower the crushing stress along the same traction direction, and writes the rows to
OUT_DIR_capshear.csv.
"""
from __future__ import annotations

import argparse
import glob
import re

import meshio
import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--f_c", type=float, default=10.5e6, help="cap f_c [Pa] of the run (default: mixed-mode walls)")
    ap.add_argument("--G_fc", type=float, default=5000.0, help="G_fc [J/m^2] of the run (0: perfectly plastic)")
    ap.add_argument("--C_ss", type=float, default=9.0, help="Lourenco's C_ss (9 as we recall it, approximate)")
    a = ap.parse_args(argv)
    frames = sorted(glob.glob(a.out + "/paraview/contacts_*.vtu"))
    with open(a.out + "/paraview/contacts.pvd", encoding="utf-8") as f:
        times = [float(t) for t in re.findall(r'timestep="([^"]+)"', f.read())]
    rows = []
    for path, t in zip(frames, times):
        d = meshio.read(path).point_data
        if "crushing" not in d or len(d["r_N"]) == 0:
            continue
        up, area = d["crushing"], d["area"]
        cap = a.f_c * (np.maximum(np.exp(-a.f_c * np.abs(up) / a.G_fc), 1e-6) if a.G_fc > 0 else 1.0)
        sig, tau = d["r_N"] / area, d["r_T"] / area
        on = (up < 0) & (sig >= 0.99 * cap)
        for i in np.nonzero(on)[0]:
            rows.append((t, int(d["interface"][i]), up[i], sig[i], tau[i], a.C_ss * tau[i] ** 2 / sig[i] ** 2))
    print(f"{len(frames)} frames, {len(rows)} contact-frames on the cap")
    if not rows:
        return 0
    r = np.array(rows)
    for itf in np.unique(r[:, 1]):
        b = r[r[:, 1] == itf]
        ratio = b[:, 5]
        shear = np.abs(b[:, 4]) / b[:, 3]
        print(f"interface {int(itf)}: {len(b)} contact-frames; |tau|/sigma median {np.median(shear):.3f} "
              f"max {shear.max():.3f}; C_ss tau^2/sigma^2 median {np.median(ratio):.3f} max {ratio.max():.3f}; "
              f"elliptic cap / ours: median {np.median(1 / np.sqrt(1 + ratio)):.3f} min {np.min(1 / np.sqrt(1 + ratio)):.3f}")
    np.savetxt(a.out.rstrip("/") + "_capshear.csv", r, delimiter=",",
               header="time,interface,u_p,sigma,tau,C_ss_tau2_over_sigma2")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

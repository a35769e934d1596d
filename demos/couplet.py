"""Brick couplet with a Fremond-Cangemi mortar joint: pulled apart, then sheared at three pre-compressions; curves vs closed forms."""
import os
import sys

import numpy as np

from fem_blocks.bodies import BlockType, Clamp, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.laws import S_UN, S_UT
from fem_blocks.meshing import mesh_rectangle

L, H, T = 0.21, 0.05, 0.1          # brick [m], thickness [m]
A = L * T                          # joint area [m^2]
CN, CT, W, MU = 2e11, 8e10, 20.0, 0.7   # joint: c_N, c_T [N/m^3], w [J/m^2], friction
BRICK = Material(E=1.2e10, nu=0.2, rho=1800.0, thickness=T, plane="stress")


def couplet(drive_x=None, drive_y=None, pressure=0.0, steps=150):
    """Lower brick (deformable, clamped on its bottom face) and upper brick (rigid, the testing machine's
    grip: driven in x and/or y, rotation held, vertical force for the pre-compression) joined by a
    Frémond–Cangémi mortar joint. Returns the mean joint jump and the stress on the joint."""
    bt = BlockType(mesh_rectangle(L, H, 0.025), BRICK)
    low = DeformableBody(bt, (0.0, 0.0), clamps=[Clamp(tag="bottom")], name="lower")
    drivers = {"rz": Driver("velocity", 0.0)}
    forces = {}
    for dof, hist in (("x", drive_x), ("y", drive_y)):
        if hist is not None:
            drivers[dof] = Driver("displacement", hist)
    if drive_y is None:
        forces["y"] = -pressure * A
    if drive_x is None:
        drivers["x"] = Driver("velocity", 0.0)
    up = RigidBody([(0.0, H), (L, H), (L, 2 * H), (0.0, 2 * H)], rho=BRICK.rho, thickness=T, drivers=drivers,
                   forces=forces, name="upper")
    cs = ContactStep([InterfaceSpec("joint", ("b", "u"), law="fremond", params=dict(c_N=CN, c_T=CT, w=W, mu=MU))],
                     ["b", "u"], ContactOptions(tol=1e-9, max_sweeps=50000))
    sim = Simulation([low, up], h=1.0 / steps, theta=1.0, contact=cs, gravity=(0.0, 0.0), velocity_reset=True)
    jump, force = [], []
    k = 1 if drive_y is not None else 0
    for _ in range(steps):
        sim.step()
        jump.append(np.abs(cs.state[:, S_UN if k == 1 else S_UT]).mean())
        force.append(abs(up.reaction[k]) / A)
    return np.array(jump), np.array(force)


def closed_form(u, c, base=0.0):
    uc = np.sqrt(W / c)
    return base + np.where(u <= uc, c * u, W ** 2 / (c * np.maximum(u, 1e-300) ** 3))


def main(out_dir: str) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    os.makedirs(out_dir, exist_ok=True)
    res = {}
    ucN, ucT = np.sqrt(W / CN), np.sqrt(W / CT)
    u, s = couplet(drive_y={"times": [0, 1], "values": [0, 6 * ucN]})
    res["tension"] = (u, s)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].plot(u * 1e6, s / 1e6, "o", ms=3, label="fem_blocks (joint opening)")
    uu = np.linspace(1e-12, u.max(), 400)
    ax[0].plot(uu * 1e6, closed_form(uu, CN) / 1e6, "k-", label="closed form (Frémond–Cangémi)")
    ax[0].set(xlabel="joint opening u_N [µm]", ylabel="tensile stress [MPa]", title="Couplet pulled apart")
    ax[0].legend()
    for p in (0.1e6, 0.3e6, 0.6e6):
        u, s = couplet(drive_x={"times": [0, 1], "values": [0, 8 * ucT]}, pressure=p)
        res[f"shear_p{p / 1e6:g}MPa"] = (u, s)
        line, = ax[1].plot(u * 1e6, s / 1e6, "o", ms=3, label=f"p = {p / 1e6:g} MPa")
        uu = np.linspace(1e-12, max(u.max(), 1e-12), 400)
        ax[1].plot(uu * 1e6, closed_form(uu, CT, MU * p) / 1e6, "-", color=line.get_color(), lw=1)
    ax[1].set(xlabel="joint slip u_T [µm]", ylabel="shear stress [MPa]",
              title="Couplet sheared at three pre-compressions\n(lines: μp + closed form)")
    ax[1].legend()
    fig.tight_layout()
    png = os.path.join(out_dir, "couplet_curves.png")
    fig.savefig(png, dpi=120)
    plt.close(fig)
    with open(os.path.join(out_dir, "couplet_curves.csv"), "w") as f:
        f.write("test,jump_m,stress_Pa\n")
        for name, (u, s) in res.items():
            for a, b in zip(u, s):
                f.write(f"{name},{a:.17g},{b:.17g}\n")
    peaks = {k: float(v[1].max()) for k, v in res.items()}
    print(f"couplet: peak tensile stress {peaks['tension'] / 1e6:.4f} MPa (closed form "
          f"{np.sqrt(W * CN) / 1e6:.4f}); shear peaks " +
          ", ".join(f"{k}: {v / 1e6:.4f} MPa" for k, v in peaks.items() if k != "tension"))
    print(f"curves: {png}")
    return peaks


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "demo-couplet"))

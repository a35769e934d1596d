"""Compression prism: 5 stack-bonded bricks (E_b = 16 700 MPa, 52 mm courses, 10 mm joints, k_n = 82 N/mm^3) under a platen; modulus and stress-strain curve."""
import os
import sys

import numpy as np

from fem_blocks.bodies import BlockType, DeformableBody, Driver, Material, RigidBody
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import mesh_rectangle

Eb, hb, tj, T, Lb = 16.7e9, 0.052, 0.010, 0.1, 0.21
KN = 82e9  # N/m^3 (82 N/mm^3, Lourenco's joint normal stiffness)
MIXED = dict(k_n=KN, k_s=36e9, f_t=2.5e5, c=3.5e5, G_I=18.0, G_II=125.0, tan_phi=0.75)


def main(out_dir: str) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    os.makedirs(out_dir, exist_ok=True)
    n, h, steps, d = 5, 2e-5, 800, 1.5e-4
    mat = Material(E=Eb, nu=0.15, rho=2500.0, thickness=T)
    bt = BlockType(mesh_rectangle(Lb, hb + tj, 0.031), mat)  # expanded bricks: brick + joint height
    blocks = [DeformableBody(bt, (0.0, i * (hb + tj))) for i in range(n)]
    H = n * (hb + tj)
    base = RigidBody([(-0.05, -0.05), (Lb + 0.05, -0.05), (Lb + 0.05, 0), (-0.05, 0)], thickness=T,
                     drivers={k: Driver("velocity", 0.0) for k in ("x", "y", "rz")})
    platen = RigidBody([(-0.05, H), (Lb + 0.05, H), (Lb + 0.05, H + 0.05), (-0.05, H + 0.05)], thickness=T,
                       drivers={"x": Driver("velocity", 0.0), "rz": Driver("velocity", 0.0),
                                "y": Driver("displacement", {"times": [0, steps * h], "values": [0, -d]})})
    cs = ContactStep([InterfaceSpec("bed", ("b", "b"), law="mixed", params=MIXED),
                      InterfaceSpec("platens", ("b", "r"), mu=0.0)], ["b"] * n + ["r", "r"],
                     ContactOptions(tol=1e-10, max_sweeps=5000))
    sim = Simulation(blocks + [base, platen], h=h, theta=1.0, contact=cs, gravity=(0.0, 0.0))
    mid = np.isclose(bt.mesh.points[:, 1], 0.5 * (hb + tj))
    eps, sig = [0.0], [0.0]
    for _ in range(steps):
        sim.step()
        u1 = blocks[0].displacement_global()[mid, 1].mean()
        u4 = blocks[3].displacement_global()[mid, 1].mean()
        eps.append(-(u4 - u1) / (3 * (hb + tj)))
        sig.append(-platen.reaction[1] / (Lb * T))
    eps, sig = np.array(eps), np.array(sig)
    E = np.polyfit(eps[len(eps) // 4:], sig[len(sig) // 4:], 1)[0]
    Ej = tj * Eb * KN / (Eb + tj * KN)  # joint modulus equivalent to k_n: k_n = E_b E_j / (t_j (E_b - E_j))
    E_series = (hb + tj) / (hb / Eb + tj / Ej)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(eps * 1e3, sig / 1e6, label=f"fem_blocks, E = {E / 1e6:.0f} MPa")
    ax.plot(eps * 1e3, E_series * eps / 1e6, "k--", lw=1, label=f"series formula, E = {E_series / 1e6:.0f} MPa")
    ax.set(xlabel="strain (gauge over 3 brick + joint units) [‰]", ylabel="stress [MPa]",
           title="Stack-bonded prism, 5 bricks, mixed-mode joints (k_n = 82 N/mm³)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    png = os.path.join(out_dir, "prism_stress_strain.png")
    fig.savefig(png, dpi=120)
    plt.close(fig)
    print(f"prism modulus {E / 1e6:.1f} MPa (series formula {E_series / 1e6:.1f} MPa, brick {Eb / 1e6:.0f} MPa, "
          f"equivalent joint modulus E_j = {Ej / 1e6:.0f} MPa); curve: {png}")
    return dict(E=E, E_series=E_series)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "demo-prism"))

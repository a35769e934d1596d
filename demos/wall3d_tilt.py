"""3D tilting table: a dry running-bond wall of deformable bricks on a rigid base tilted about the wall's long axis until it overturns; tilt at collapse vs tan(alpha) = t/H."""
import dataclasses
import math
import os
import sys
import time

import numpy as np

from fem_blocks.bodies import BlockType3D, DeformableBody3D, Material, RigidBody3D
from fem_blocks.builders3d import running_bond_wall
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.meshing import box_corners, mesh_hexahedron

G = 9.81
MU = 0.7                                  # dry joints (brick on brick, brick on base)
BRICK = Material(E=5e9, nu=0.2, rho=2000.0, name="brick")
FIXED = {k: ("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")}
# full / quick: wall size, mesh of a brick, time step, tilt schedule (fast ramp to alpha_1, then slow)
CONFIG = {
    False: dict(courses=8, bricks=3, divisions=(2, 1, 1), h=0.02, alpha1=10.0, fast=10.0, slow=0.01, t_max=20.0),
    True: dict(courses=6, bricks=2, divisions=(2, 1, 1), h=0.02, alpha1=13.0, fast=10.0, slow=0.02, t_max=12.0),
}
L, T, HB = 0.25, 0.12, 0.065             # brick length (x), width = wall thickness t (y), height (z) [m]
THRESHOLD = 0.05                          # collapse: mean out-of-plane top displacement > THRESHOLD * t


def tilt_angle(t, cfg):
    """Tilt alpha(t) [rad]: ramp at `fast` deg/s up to alpha_1 deg, then `slow` rad/s."""
    a1, t1 = math.radians(cfg["alpha1"]), cfg["alpha1"] / cfg["fast"]
    return math.radians(cfg["fast"]) * t if t <= t1 else a1 + cfg["slow"] * (t - t1)


def set_gravity(sim, g):
    """Gravity of the base frame g = G (0, -sin a, -cos a): the load vectors of the deformable groups
    (Simulation.set_step computes them once) and the rigid bodies' (read from sim.g every step)."""
    sim.g[:] = g
    for gr in sim.groups:
        gr.Fg = np.column_stack([sim.bodies[b].type.gravity_load(sim.bodies[b].R.T @ sim.g) for b in gr.members])


def build(cfg):
    lay = running_bond_wall(cfg["courses"], cfg["bricks"], L, HB, T, joint=0.0)
    types = {k: BlockType3D(mesh_hexahedron(c, divisions=cfg["divisions"]), BRICK, name=f"brick{k[1]:.3f}")
             for k, c in lay.prototypes.items()}
    bricks = [DeformableBody3D(types[b.key], b.position, b.R, name=f"c{b.course}b{b.index}") for b in lay.blocks]
    Lw = lay.corners()[:, :, 0].max()
    base = RigidBody3D(box_corners(Lw + 0.4, T + 0.4, 0.1, (-0.2, -0.2, -0.1)), rho=2000.0, drivers=FIXED,
                       name="base")
    itfs = [InterfaceSpec("bed_base", ("brick", "base"), mu=MU, candidate="brick", placement="nodes"),
            InterfaceSpec("joints", ("brick", "brick"), mu=MU, placement="nodes")]
    cst = ContactStep(itfs, ["brick"] * len(bricks) + ["base"],
                      ContactOptions(tol=1e-8, max_sweeps=20000, criterion="residual", solver="newton"))
    sim = Simulation(bricks + [base], h=cfg["h"], theta=1.0, contact=cst)
    return lay, bricks, base, sim, cst


def main(out_dir: str, quick: bool = False, argv=None) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from fem_blocks.output.contacts import ContactsWriter
    from fem_blocks.output.figures import write_blocks_3d
    from fem_blocks.output.history import HistoryWriter
    from fem_blocks.output.paraview import BodiesWriter3D
    from fem_blocks.output.summary import write_summary
    if argv:
        from fem_blocks.errors import InputError
        raise InputError(f"demo wall3d_tilt: unrecognized arguments {' '.join(argv)}; expected none (--out, --quick)")
    cfg = CONFIG[bool(quick)]
    os.makedirs(out_dir, exist_ok=True)
    wall0 = time.perf_counter()
    lay, bricks, base, sim, cst = build(cfg)
    H = cfg["courses"] * HB
    top = [i for i, b in enumerate(lay.blocks) if b.course == cfg["courses"] - 1]
    weight = sum(b.type.M.diagonal().sum() / 3 for b in bricks) * G
    alpha_tip, alpha_slide = math.atan(T / H), math.atan(MU)
    pv = os.path.join(out_dir, "paraview")
    bw, cw = BodiesWriter3D(sim, pv), ContactsWriter(pv, 3)
    cols = ["step", "time", "tilt_deg", "top_uy", "top_uz", "base_N", "base_T", "base_T_over_N", "tan_tilt",
            "resultant_y_over_t", "base_contacts_closed", "sweeps"]
    hist = HistoryWriter(os.path.join(out_dir, "history.csv"), cols, flush_every=50)
    rows, n_frames, every = [], 0, max(1, int(round(0.5 / cfg["h"])))
    collapsed, k = False, 0
    while sim.time < cfg["t_max"]:
        a = tilt_angle(sim.time + sim.h, cfg)
        set_gravity(sim, G * np.array([0.0, -math.sin(a), -math.cos(a)]))
        info = sim.step()
        k += 1
        if not info.contact["converged"]:
            print(f"wall3d_tilt: step {k}: NLGS not converged (residual {info.contact['residual']:.2g})",
                  file=sys.stderr)
        res = sim.last_contact  # the step's contact record (contact/result.py)
        cs, r = res.cs, res.r
        on_base = cs.ant_body == len(bricks)
        F = r[:, :1] * cs.n + r[:, 1:2] * cs.t + r[:, 2:] * cs.s  # force of the antagonist on the candidate
        Fb = F[on_base].sum(axis=0)  # base on the wall
        yc = float((F[on_base, 2] * cs.point[on_base, 1]).sum() / max(Fb[2], 1e-300))
        uy = float(np.mean([bricks[i].displacement_global()[:, 1].mean() for i in top]))
        uz = float(np.mean([bricks[i].displacement_global()[:, 2].mean() for i in top]))
        row = dict(step=k, time=sim.time, tilt_deg=math.degrees(a), top_uy=uy, top_uz=uz, base_N=Fb[2],
                   base_T=Fb[1], base_T_over_N=Fb[1] / Fb[2], tan_tilt=math.tan(a), resultant_y_over_t=yc / T,
                   base_contacts_closed=int((r[on_base, 0] > 0).sum()), sweeps=info.contact["sweeps"])
        rows.append(row)
        hist.write(row)
        collapsed = -uy > THRESHOLD * T
        if k % every == 0 or collapsed:
            bw.write(sim.time)
            # gap field: the contact set's g - g0, as this demo has always written (gt_end=None); the runner
            # writes the end-of-step gap result.gt_end
            cw.write(sim.time, dataclasses.replace(res, gt_end=None))
            n_frames += 1
        if collapsed:
            break
    hist.close()
    run_time = time.perf_counter() - wall0
    R = {c: np.array([row[c] for row in rows]) for c in cols}
    alpha_c = float(R["tilt_deg"][-1])
    # quasi-static check before collapse: base reaction = weight, T/N = tan(alpha) (last step under alpha_1)
    pre = np.flatnonzero(R["tilt_deg"] <= 0.9 * math.degrees(alpha_tip))[-1]
    png = os.path.join(out_dir, "wall_at_collapse.png")
    write_blocks_3d(png, sim, title=f"Wall at collapse, tilt {alpha_c:.2f}° (gravity in the base frame)",
                    view=(20.0, -30.0))
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(R["tilt_deg"], -R["top_uy"] * 1e3, label="fem_blocks: mean top displacement (toward the toe)")
    ax.axvline(math.degrees(alpha_tip), color="k", ls="--", lw=1, label=f"rigid overturning tan α = t/H: "
                                                                         f"{math.degrees(alpha_tip):.2f}°")
    ax.axhline(THRESHOLD * T * 1e3, color="r", ls=":", lw=1, label=f"collapse criterion {THRESHOLD:g} t")
    ax.set(xlabel="tilt α [°]", ylabel="top displacement [mm]", yscale="symlog",
           title=f"Dry wall {cfg['courses']} courses (t/H = {T / H:.3f}, μ = {MU}) on a tilting base")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    curve = os.path.join(out_dir, "tilt_displacement.png")
    fig.savefig(curve, dpi=120)
    plt.close(fig)
    mech = "overturning about the toe" if alpha_tip < alpha_slide else "sliding"
    summary = dict(
        name="wall3d_tilt" + ("_quick" if quick else ""), quick=bool(quick), collapsed=bool(collapsed),
        bricks=len(bricks), courses=cfg["courses"], wall_height_m=H, wall_thickness_m=T, mu=MU,
        mesh_divisions=list(cfg["divisions"]), dofs=int(sum(3 * b.type.n_nodes for b in bricks)),
        contacts=int(len(cst.cs.gap)), h=cfg["h"], steps=k,
        tilt_at_collapse_deg=alpha_c, tilt_overturning_closed_form_deg=math.degrees(alpha_tip),
        tilt_sliding_bound_deg=math.degrees(alpha_slide), expected_mechanism=mech,
        relative_error_vs_closed_form=alpha_c / math.degrees(alpha_tip) - 1,
        weight_N=weight, base_N_over_weight_cos_alpha_prestage=float(R["base_N"][pre] / (weight * math.cos(
            math.radians(R["tilt_deg"][pre])))),
        base_T_over_N_minus_tan_alpha_prestage=float(R["base_T_over_N"][pre] - R["tan_tilt"][pre]),
        resultant_y_over_t_at_collapse=float(R["resultant_y_over_t"][-1]),
        resultant_vs_rigid_statics_max_abs=float(np.abs(R["resultant_y_over_t"][:pre + 1] - (
            0.5 - 0.5 * H / T * R["tan_tilt"][:pre + 1])).max()),
        tilt_resultant_at_toe_deg=float(R["tilt_deg"][np.argmax(R["resultant_y_over_t"] <= 0.01)]),
        collapse_criterion=f"mean out-of-plane displacement of the top course > {THRESHOLD:g} t",
        run_time_s=run_time, paraview_frames=n_frames,
        outputs=dict(paraview="paraview/blocks.pvd", contacts="paraview/contacts.pvd", history="history.csv",
                     png="wall_at_collapse.png", curve="tilt_displacement.png"))
    # mechanism seen in the run: rotation (top moves much more than the bottom course) or sliding at the base
    bot = [i for i, b in enumerate(lay.blocks) if b.course == 0]
    ub = float(np.mean([bricks[i].displacement_global()[:, 1].mean() for i in bot]))
    summary["bottom_course_uy_over_top_uy"] = ub / R["top_uy"][-1]
    summary["top_slip_vs_rotation"] = "rotation" if abs(ub) < 0.2 * abs(R["top_uy"][-1]) else "sliding"
    write_summary(os.path.join(out_dir, "summary.json"), summary)
    print(f"wall3d_tilt: {'collapse' if collapsed else 'NO collapse'} at tilt {alpha_c:.2f}° after {k} steps "
          f"({run_time:.1f} s); rigid overturning tan α = t/H: {math.degrees(alpha_tip):.2f}°, sliding tan α = μ: "
          f"{math.degrees(alpha_slide):.2f}°; mechanism: {summary['top_slip_vs_rotation']}")
    print(f"ParaView files: {os.path.join(os.path.abspath(pv), 'blocks.pvd')}")
    print(f"figures: {png}, {curve}")
    return summary


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "demo-wall3d_tilt"), "--quick" in sys.argv)

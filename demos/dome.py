"""Thesis dome (§7.2.1.c, 12 courses of 22 voussoirs, span 4 m) on 4 piers (§7.2.2.a) under gravity: dry joints let the blocks between the piers come loose, brittle adhesion holds them (--joints dry|brittle).

Contact geometry "updated" by default (--geometry frozen|updated): the voussoirs are co-rotational (rigid rotation plus
small deformation, docs/method.md §7) and the wedge bed joints, closed as built, carry their initial gap as an offset
(`reference = "as_built"`, contact/step.py). The summary reports the largest relative change of any hexahedron edge
length of any block at the end (`max_edge_change`: the picture's blocks keep their size) and the largest block
rotation (`max_rotation_rad`, |body.rotation()|)."""
import argparse
import dataclasses
import os
import sys
import time

import numpy as np

from fem_blocks.bodies import BlockType3D, DeformableBody3D, Material, RigidBody3D
from fem_blocks.builders3d import dome
from fem_blocks.contact.step import ContactOptions, ContactStep, InterfaceSpec
from fem_blocks.dynamics import Simulation
from fem_blocks.laws import S_BROKEN
from fem_blocks.meshing import mesh_hexahedron

G = 9.81
STONE = Material(E=1e10, nu=0.2, rho=2500.0, name="stone")   # 2500 kg/m^3: bed-course block 173 kg (thesis ~170)
MU = 0.6
R_C = 0.40e6        # thesis §7.2.2.a: cohesion threshold 0.40 MPa ("adhesif fragile sans flexibilite", §5.3.3)
L_C = 1e-4          # our choice: the rigid-brittle joint breaks after 0.1 mm of opening (thesis: no flexibility)
ALERT = 0.02        # > the 1.15 cm wedge of the staggered bed joints (builders3d.dome)
FIXED = {k: ("velocity", 0.0) for k in ("x", "y", "z", "rx", "ry", "rz")}
# Full dome: h = 1 ms (not 10 ms): the step's Delassus operator is better conditioned (h²K/M is 100x smaller for
# these nearly rigid blocks with 4 contact points per face), and the NLGS (shuffled order) reaches the residual
# 1e-4 in 5 000-7 000 sweeps per step; with h = 10 ms it stalls near 1e-4 after 20 000 (docs/benchmarks.md).
CONFIG = {False: dict(courses=12, divisions=(2, 2, 2), h=0.001, steps=16, max_sweeps=20000, tol=1e-4,
                      order="shuffled"),
          True: dict(courses=4, divisions=(1, 1, 1), h=0.01, steps=4, max_sweeps=5000, tol=1e-6, order="given")}


def edge_change(blocks) -> float:
    """Largest relative change of any hexahedron edge length of the blocks, current against reference."""
    worst = 0.0
    for b in blocks:
        c = b.type.mesh.cells
        X, x = b.reference_points, b.current_points()
        for i, j in HEX_EDGES:
            l0 = np.linalg.norm(X[c[:, j]] - X[c[:, i]], axis=1)
            worst = max(worst, float(np.abs(np.linalg.norm(x[c[:, j]] - x[c[:, i]], axis=1) / l0 - 1).max()))
    return worst


HEX_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))


def build(joints: str, cfg, geometry: str = "updated"):
    lay = dome(n_courses=cfg["courses"], piers=4)
    types = {k: BlockType3D(mesh_hexahedron(c, divisions=cfg["divisions"]), STONE, name=f"voussoir{k[1]}")
             for k, c in lay.prototypes.items()}
    blocks = [DeformableBody3D(types[b.key], b.position, b.R, name=f"c{b.course}j{b.index}") for b in lay.blocks]
    piers = [RigidBody3D(p.corners, rho=2500.0, drivers=FIXED, name=p.name) for p in lay.rigid]
    if joints == "dry":
        law = dict(law="coulomb", mu=MU)
    else:
        law = dict(law="brittle", params=dict(variant="dugdale", r_c=R_C, l_c=L_C, mu=MU))
    itfs = [InterfaceSpec("joints", ("dome", "dome"), g0=lay.joint, alert=ALERT, reference="as_built", **law),
            InterfaceSpec("piers", ("dome", "piers"), g0=lay.joint, alert=ALERT, candidate="dome",
                          reference="as_built", **law)]
    cst = ContactStep(itfs, ["dome"] * len(blocks) + ["piers"] * len(piers),
                      ContactOptions(tol=cfg["tol"], max_sweeps=cfg["max_sweeps"], criterion="residual", check_every=5,
                                     order=cfg["order"], geometry=geometry))
    sim = Simulation(blocks + piers, h=cfg["h"], theta=1.0, velocity_reset=True, contact=cst)
    return lay, blocks, piers, sim, cst


def main(out_dir: str, quick: bool = False, argv=None) -> dict:
    from fem_blocks.output.contacts import ContactsWriter
    from fem_blocks.output.figures import write_blocks_3d
    from fem_blocks.output.history import HistoryWriter
    from fem_blocks.output.paraview import BodiesWriter3D
    from fem_blocks.output.summary import write_summary
    ap = argparse.ArgumentParser(prog="fem-blocks demo dome")
    ap.add_argument("--joints", choices=("dry", "brittle"), default="dry")
    ap.add_argument("--max-sweeps", type=int, default=None,
                    help="NLGS sweeps per step (default 20000 dry, 8000 brittle; quick 5000)")
    ap.add_argument("--tol", type=float, default=None,
                    help="NLGS residual tolerance ||F||/||q|| (default 1e-4; quick 1e-6)")
    ap.add_argument("--order", choices=("given", "reversed", "shuffled"), default=None,
                    help="NLGS contact order (default shuffled; quick given)")
    ap.add_argument("--steps", type=int, default=None, help="time steps (default 16 dry, 6 brittle; quick 4)")
    ap.add_argument("--geometry", choices=("updated", "frozen"), default="updated",
                    help="contact geometry (default updated: co-rotational blocks; frozen: the small-rotation path)")
    opts = ap.parse_args(argv or [])
    cfg = dict(CONFIG[bool(quick)])
    if opts.joints == "brittle" and not quick:
        # the brittle joints hold every block: nothing to resolve in time, and the cohesive NLGS does not converge
        # faster with h = 1 ms (residual 1.1e-3 after 20 000 sweeps of the first step, against 4e-4 after 6 x 4 000
        # with h = 10 ms): 6 steps of 10 ms
        cfg.update(h=0.01, steps=6, max_sweeps=8000)
    for k in ("max_sweeps", "tol", "order", "steps"):
        if getattr(opts, k) is not None:
            cfg[k] = getattr(opts, k)
    os.makedirs(out_dir, exist_ok=True)
    wall0 = time.perf_counter()
    lay, blocks, piers, sim, cst = build(opts.joints, cfg, opts.geometry)
    nb = len(blocks)
    mass = np.array([b.type.M.diagonal().sum() / 3 for b in blocks])
    weight = float(mass.sum() * G)
    pv = os.path.join(out_dir, "paraview")
    bw, cw = BodiesWriter3D(sim, pv), ContactsWriter(pv, 3)
    cols = ["step", "time", "pier_reaction_z", "pier_reaction_over_weight", "max_fall", "loose_blocks",
            "open_contacts", "broken_contacts", "sweeps", "residual"]
    hist = HistoryWriter(os.path.join(out_dir, "history.csv"), cols)
    bw.write(0.0)
    zprev = np.zeros(nb)
    hstep = cfg["h"]
    max_res = 0.0
    sweeps_total = 0
    for k in range(1, cfg["steps"] + 1):
        info = sim.step()
        max_res = max(max_res, float(info.contact["residual"]))
        sweeps_total += int(info.contact["sweeps"])
        if not info.contact["converged"]:
            print(f"dome: step {k}: NLGS not converged (residual {info.contact['residual']:.2g})", file=sys.stderr)
        uz = np.array([b.displacement_global()[:, 2].mean() for b in blocks])
        # velocity reset (θ = 1): an unsupported block moves down by h^2 g per step, a supported one not at all
        loose = (zprev - uz) > 0.5 * hstep * hstep * G
        zprev = uz
        Rz = float(sum(p.reaction[2] - p.mass * G for p in piers))  # driver reaction minus the pier's own weight
        res = sim.last_contact  # the step's contact record (contact/result.py)
        broken = int((res.state[:, S_BROKEN] > 0).sum()) if opts.joints == "brittle" else 0
        hist.write(dict(step=k, time=sim.time, pier_reaction_z=Rz, pier_reaction_over_weight=Rz / weight,
                        max_fall=float(-uz.min()), loose_blocks=int(loose.sum()),
                        open_contacts=int((res.r[:, 0] <= 0).sum()), broken_contacts=broken,
                        sweeps=info.contact["sweeps"], residual=info.contact["residual"]))
        bw.write(sim.time)
        # gap field: the contact set's g - g0, as this demo has always written (gt_end=None); the runner
        # writes the end-of-step gap result.gt_end
        cw.write(sim.time, dataclasses.replace(res, gt_end=None))
        print(f"dome: step {k}/{cfg['steps']}: {int(loose.sum())} loose blocks, max fall {-uz.min() * 1e3:.3f} mm, "
              f"{info.contact['sweeps']} sweeps", flush=True)
    hist.close()
    run_time = time.perf_counter() - wall0
    png = os.path.join(out_dir, "dome.png")
    write_blocks_3d(png, sim, body_values=np.r_[-uz * 1e3, np.zeros(len(piers))],
                    value_label="fall [mm]", amplification=1.0 if loose.any() else None,
                    title=f"Dome on 4 piers, {opts.joints} joints, after {cfg['steps']} steps (velocity reset)",
                    view=(15.0, -80.0))
    # where the loose blocks are: course and azimuthal index, and which gap between the piers
    idx = np.flatnonzero(loose)
    pier_blocks = {j for p in range(4) for j in range(int(round(p * 22 / 4)), int(round(p * 22 / 4)) + 3)}
    summary = dict(
        name=f"dome_{opts.joints}" + ("_quick" if quick else ""), quick=bool(quick), joints=opts.joints,
        geometry=opts.geometry,
        courses=cfg["courses"], blocks=nb, hexahedra_per_block=int(np.prod(cfg["divisions"])),
        dofs=int(sum(3 * b.type.n_nodes for b in blocks)), contacts=int(len(cst.cs.gap)),
        # joints closed as built: frozen, the reference contact set's g - g0; updated, the offsets carried
        max_initial_wedge_m=float(np.abs(cst.g_built if opts.geometry == "updated" else cst.cs.gap - cst.cs.g0).max()),
        h=hstep, steps=cfg["steps"], velocity_reset=True, mu=MU,
        r_c_Pa=R_C if opts.joints == "brittle" else None, l_c_m=L_C if opts.joints == "brittle" else None,
        weight_N=weight, pier_reaction_over_weight=Rz / weight,
        loose_blocks=int(loose.sum()), loose_mass_kg=float(mass[loose].sum()),
        loose_weight_fraction=float(mass[loose].sum() / mass.sum()),
        loose_list=[[int(lay.blocks[i].course), int(lay.blocks[i].index)] for i in idx],
        moved_list=[[int(lay.blocks[i].course), int(lay.blocks[i].index), float(-uz[i])]
                    # fell more than half of what an unsupported block falls in the run (h^2 g per step): not the
                    # elastic settlement of the supported ones
                    for i in np.flatnonzero(-uz > 0.5 * cfg["steps"] * hstep * hstep * G)],
        loose_bed_blocks_not_on_piers=int(sum(1 for i in idx if lay.blocks[i].course == 0
                                              and lay.blocks[i].index not in pier_blocks)),
        max_fall_m=float(-uz.min()), broken_contacts=broken, run_time_s=run_time,
        max_edge_change=edge_change(blocks), max_rotation_rad=max(float(np.linalg.norm(b.rotation())) for b in blocks),
        nlgs_unconverged_steps=int(cst.n_unconverged), nlgs_last_residual=float(info.contact["residual"]),
        nlgs_max_residual=max_res, nlgs_tol=cst.opts.tol, nlgs_max_sweeps=cst.opts.max_sweeps,
        nlgs_order=cst.opts.order, nlgs_sweeps_total=int(sweeps_total),
        contact_timers_s={k: round(v, 3) for k, v in cst.timers.items()},  # detection (with Delassus), nlgs, ...
        outputs=dict(paraview="paraview/blocks.pvd", contacts="paraview/contacts.pvd", history="history.csv",
                     png="dome.png"))
    write_summary(os.path.join(out_dir, "summary.json"), summary)
    print(f"dome ({opts.joints} joints): {summary['loose_blocks']} loose blocks ({summary['loose_mass_kg']:.0f} kg) "
          f"{summary['loose_list']}, pier reaction / weight {Rz / weight:.4f}, {len(cst.cs.gap)} contacts, "
          f"{run_time:.1f} s")
    print(f"ParaView files: {os.path.join(os.path.abspath(pv), 'blocks.pvd')}")
    print(f"figure: {png}")
    return summary


if __name__ == "__main__":
    args = sys.argv[1:]
    quick = "--quick" in args
    args = [a for a in args if a != "--quick"]
    out = args.pop(0) if args and not args[0].startswith("--") else os.path.join("out", "demo-dome")
    main(out, quick, args)

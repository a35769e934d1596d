#!/usr/bin/env python3
"""Deliberate-bug (mutation) run: apply hand-written one-line bugs, one at a time, and check that the tests fail.

Each mutation is (id, where, file, old line, new line, test files). For each one the script copies the working
tree (tracked and untracked files, no .git, no __pycache__) to a temporary directory, replaces the one line
(the old text must occur exactly once: a stale mutation is an error, not a survivor), and runs the listed test
files there with

* PYTHONPATH = the copy (so the copy's fem_blocks is imported, not the installed one; checked before the run),
* a fresh, empty NUMBA_CACHE_DIR: numba's on-disk cache does not recompile a cached caller when a jitted callee in
  another module changes (e.g. `_proj_cone2`, inlined into solver/nlgs.py), so a stale cache can pass the tests
  against the old code. Every mutation therefore recompiles the kernels its tests use (~1-5 min).

Result per mutation: "killed" (pytest exit 1: at least one test failed; the failing tests are listed),
"survived" (exit 0), "error" (collection error, timeout, stale mutation). Mutations run one after the other,
never in parallel (the machine is shared and numba compiles on every core). Not part of CI (too slow); run it
before a release and after changing tests (docs/testing.md has the kill table measured last).

    python scripts/mutate.py                     # all mutations
    python scripts/mutate.py --only theta_term gyroscopic_sign
    python scripts/mutate.py --list
    python scripts/mutate.py --baseline          # the listed tests on the unmutated copy (fresh cache): must pass
    python scripts/mutate.py --json out.json --python /path/to/python

Exit status: 0 when every mutation run was killed, 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclass(frozen=True)
class Mutation:
    id: str
    title: str
    file: str
    old: str
    new: str
    tests: tuple


MUTATIONS = [
    # the ten bugs of issue 19's table that survived (or were caught only incidentally)
    Mutation("theta_term", "θ term h²θ(1−θ)K u → h²θ²K u (free velocity)", "fem_blocks/dynamics.py",
             "rhs -= h * h * th * (1 - th) * (bt.K @ U)", "rhs -= h * h * th * th * (bt.K @ U)",
             ("tests/test_theta_scheme.py",)),
    Mutation("rigid_force_weights", "rigid-body force weights (1−θ)F(t0) + θF(t1) swapped", "fem_blocks/dynamics.py",
             "b.Ftheta = (1 - th) * b.applied_force(t0, self.g) + th * b.applied_force(t1, self.g)",
             "b.Ftheta = th * b.applied_force(t0, self.g) + (1 - th) * b.applied_force(t1, self.g)",
             ("tests/test_theta_scheme.py",)),
    Mutation("fremond_exponent", "Frémond viscous exponent ^(1/p) → ^p", "fem_blocks/laws.py",
             "max(mid * Y - w, 0.0) ** (1.0 / p)", "max(mid * Y - w, 0.0) ** p",
             ("tests/test_law_closed_forms.py",)),
    Mutation("damage_friction", "damage friction μ = (1−β)μ_r → βμ_r", "fem_blocks/laws.py",
             "mu = (1.0 - x) * par[P_MUR]", "mu = x * par[P_MUR]",
             ("tests/test_law_closed_forms.py",)),
    Mutation("mm_mass_factor", "mm-N-MPa mass factor 1e3 → 1", "fem_blocks/case.py",
             "time=1.0, mass=1e3, moment=1e-3)", "time=1.0, mass=1, moment=1e-3)",
             ("tests/test_units_mm.py",)),
    Mutation("mixed_mode_ratio", "mixed-mode ratio b²/λ² → |b|/λ", "fem_blocks/laws.py",
             "m = (uT / dII) ** 2 / lam2  # mode ratio", "m = abs(uT / dII) / lam  # mode ratio",
             ("tests/test_law_closed_forms.py",)),
    Mutation("rayleigh_swap", "Rayleigh α and β swapped", "fem_blocks/bodies.py",
             "self.C = (m.alpha * self.M + m.beta * self.K).tocsr()",
             "self.C = (m.beta * self.M + m.alpha * self.K).tocsr()",
             ("tests/test_theta_scheme.py",)),
    Mutation("newton_direction", "Newton direction J⁻¹(−F) → J⁻¹F", "fem_blocks/solver/newton.py",
             "dr = blu.solve_checked(Jb, -F)", "dr = blu.solve_checked(Jb, F)",
             ("tests/test_newton_direction.py",)),
    Mutation("solve_dispatch", "solve(): the Coulomb Newton branch taken for solver = 'nlgs'",
             "fem_blocks/solver/driver.py",
             '    if o.solver == "newton":\n        return newton.solve_newton(',
             '    if o.solver == "nlgs":\n        return newton.solve_newton(',
             ("tests/test_solve_dispatch.py",)),
    Mutation("stop_after_peak", "stop-after-peak threshold (1 − drop)·peak → drop·peak", "fem_blocks/runner.py",
             "f < (1 - drop) * pk:", "f < drop * pk:",
             ("tests/test_stop_after_peak.py",)),
    Mutation("von_mises_2d", "2D von Mises 3σxy² → σxy²", "fem_blocks/fem_backend.py",
             "(szz - s[:, 0]) ** 2) + 3.0 * s[:, 2] ** 2)", "(szz - s[:, 0]) ** 2) + s[:, 2] ** 2)",
             ("tests/test_stress2d.py", "tests/test_fem_backend.py")),
    Mutation("rotated_clamp_component", "single-component clamp on a block rotated by ±90°: global x/y not swapped "
             "to the type frame", "fem_blocks/bodies.py",
             "                    comp = 1 - comp\n", "                    comp = comp\n",
             ("tests/test_clamps_split.py",)),
    Mutation("bed_head_split", "bed/head split on |n_y| → on |n_x|", "fem_blocks/contact/detection_2d.py",
             "use_head = (head >= 0) & (np.abs(n[:, 1]) < np.sqrt(0.5))",
             "use_head = (head >= 0) & (np.abs(n[:, 0]) < np.sqrt(0.5))",
             ("tests/test_clamps_split.py",)),
    # the six the suite already killed
    Mutation("cone_projection_sign", "2D Coulomb cone projection c = (x_N + μ|x_T|)/(1+μ²) → (x_N − μ|x_T|)/(1+μ²)",
             "fem_blocks/solver/local.py",
             "    c = (x0 + mu * ax1) / (1.0 + mu * mu)\n    return c, c * mu",
             "    c = (x0 - mu * ax1) / (1.0 + mu * mu)\n    return c, c * mu",
             ("tests/test_nlgs.py",)),
    Mutation("softening_cap_exponent", "softening cap exp(−f_c|u_p|/G_fc) → exp(−|u_p|/G_fc)", "fem_blocks/laws.py",
             "return fc * max(np.exp(-fc * k / par[P_GFC]), CAP_FLOOR)",
             "return fc * max(np.exp(-k / par[P_GFC]), CAP_FLOOR)",
             ("tests/test_cap.py",)),
    Mutation("checkpoint_law_state", "checkpointed law state not restored (zeros)", "fem_blocks/contact/step.py",
             'self.P, self.state = np.array(d["contact.P"]), np.array(d["contact.state"])',
             'self.P, self.state = np.array(d["contact.P"]), np.zeros_like(d["contact.state"])',
             ("tests/test_resume.py",)),
    Mutation("gap_sign_3d", "3D gap (x_c − x_a)·n → (x_a − x_c)·n", "fem_blocks/contact/detection_3d.py",
             "out[14] = (p0 - xx) * nx + (p1 - xy) * ny + (p2 - xz) * nz",
             "out[14] = (xx - p0) * nx + (xy - p1) * ny + (xz - p2) * nz",
             ("tests/test_detection3d.py", "tests/test_step3d.py")),
    Mutation("gyroscopic_sign", "3D gyroscopic moment −ω × Iω → +ω × Iω", "fem_blocks/dynamics.py",
             "F[3:] -= np.cross(w, b.inertia @ w)", "F[3:] += np.cross(w, b.inertia @ w)",
             ("tests/test_step3d.py",)),
    Mutation("gap_sign_2d", "2D gap (x_c − x_a)·n → (x_a − x_c)·n (detection)", "fem_blocks/contact/detection_2d.py",
             "g = (px - ax) * nax + (py - ay) * nay", "g = (ax - px) * nax + (ay - py) * nay",
             ("tests/test_detection_delassus.py", "tests/test_contact.py")),
    # co-rotational kinematics (issue 22)
    Mutation("corot_inertial_sign", "inertial term of the turning frame −h ω × (u − v̄) → +h ω × (u − v̄) (2D)",
             "fem_blocks/corotational.py",
             "            Ueff[2 * a, j] = U[2 * a, j] + h * om * uy\n"
             "            Ueff[2 * a + 1, j] = U[2 * a + 1, j] - h * om * ux",
             "            Ueff[2 * a, j] = U[2 * a, j] - h * om * uy\n"
             "            Ueff[2 * a + 1, j] = U[2 * a + 1, j] + h * om * ux",
             ("tests/test_corotational.py",)),
    Mutation("corot_translation_turns", "re-basing: v̄ kept in frame components instead of fixed in space (2D)",
             "fem_blocks/corotational.py",
             "        tx = cd * vx + sd * vy  # exp(-[Δφ]x) v̄_{i+1}\n        ty = -sd * vx + cd * vy",
             "        tx = vx  # exp(-[Δφ]x) v̄_{i+1}\n        ty = vy",
             ("tests/test_corotational.py",)),
    Mutation("corot_gravity_frame", "gravity of a framed group in the placement frame R0 instead of the current R",
             "fem_blocks/dynamics.py",
             'gr.Fg = gr.type.mass_properties.G @ np.einsum("kji,j->ik", gr.R, self.g)',
             'gr.Fg = gr.type.mass_properties.G @ np.einsum("kji,j->ik", gr.R0, self.g)',
             ("tests/test_corotational.py",)),
    Mutation("corot_frame_side_3d", "3D frame update R exp([Δφ]x) → exp([Δφ]x) R", "fem_blocks/corotational.py",
             "        Rn = R[j] @ Rd\n", "        Rn = Rd @ R[j]\n",
             ("tests/test_corotational.py",)),
    Mutation("corot_checkpoint_frame", "checkpoint exports the placement R0 instead of the frame R",
             "fem_blocks/dynamics.py",
             'd[key + "R"] = np.array(b.R)', 'd[key + "R"] = np.array(b.R0)',
             ("tests/test_corotational.py",)),
    # rotating blocks: output, small-rotation warning, acceptance tests (issue 22)
    Mutation("rotation_weights_sign", "best-fit small rotation Σ m r × q → Σ m q × r (2D rotation weights)",
             "fem_blocks/bodies.py",
             "A = (np.column_stack([-mp.m * r[:, 1], mp.m * r[:, 0]]).ravel() / mp.I0)[None, :]",
             "A = (np.column_stack([mp.m * r[:, 1], -mp.m * r[:, 0]]).ravel() / mp.I0)[None, :]",
             ("tests/test_rotation_output.py",)),
    Mutation("small_rotation_bound", "small-rotation warning past 2 x 0.01 rad instead of 0.01", "fem_blocks/runner.py",
             'if st["first"] is not None or st["max_rad"] <= self.bound:',
             'if st["first"] is not None or st["max_rad"] <= 2 * self.bound:',
             ("tests/test_rotation_output.py",)),
    Mutation("rotation_record_resume", "small-rotation record not checkpointed (run.json)", "fem_blocks/runner.py",
             '                                                 rotation=run.get("rotation"),\n', '',
             ("tests/test_rotation_output.py",)),
    Mutation("corotational_auto_off", "updated geometry no longer makes deformable blocks co-rotational",
             "fem_blocks/dynamics.py",
             'corotational = geometry == "updated"', "corotational = False",
             ("tests/test_rocking.py", "tests/test_tilting_table.py")),
    # issue 23 (the virtual laboratory) and the fixes found with it
    Mutation("triplet_two_joints", "triplet: the ram's force over A instead of the standard's 2A", "fem_blocks/lab/triplet.py",
             'total=np.abs(h["ram.Rx"][k:] - h["ram.Ix"][k:]) / (2 * A),',
             'total=np.abs(h["ram.Rx"][k:] - h["ram.Ix"][k:]) / A,',
             ("tests/test_lab_triplet.py",)),
    Mutation("lab_severity", "lab exit status: unconverged (3) ranked above a stopped run (1)", "fem_blocks/lab/__init__.py",
             "SEVERITY = {0: 0, 3: 1, 1: 2}", "SEVERITY = {0: 0, 3: 2, 1: 1}",
             ("tests/test_lab_triplet.py",)),
    Mutation("secant_fraction", "EN 1052-1 secant at half the peak instead of a third", "fem_blocks/lab/readout.py",
             "def secant_at_fraction(stress, strain, fraction: float = 1.0 / 3.0) -> dict:",
             "def secant_at_fraction(stress, strain, fraction: float = 1.0 / 2.0) -> dict:",
             ("tests/test_lab_compression.py",)),
    Mutation("gauge_weights", "gauge interpolation weights in reverse node order", "fem_blocks/output/gauges.py",
             "    return weights @ disp[nodes]", "    return weights[::-1] @ disp[nodes]",
             ("tests/test_gauges.py",)),
    Mutation("substep_pushout", "a sub-step clears a penetration at its own rate p/(h θ)", "fem_blocks/contact/step.py",
             "        gs = (gbar - pen) + pen * (h / hn)", "        gs = gbar",
             ("tests/test_substep_penetration.py",)),
    Mutation("tjunction_one_point", "overlap placement: one point per candidate node again (T-junctions)",
             "fem_blocks/contact/detection_2d.py",
             "    key = key * SLOTS - _body_slots(ovl_pl & (pk < 2), node_idx, bedge_body[ae], bedge_body[ce])",
             "    key = key * SLOTS",
             ("tests/test_placement.py",)),
    Mutation("colour_exchange_wrong", "distributed sweep: after each colour, the impulses of colour 0 are exchanged",
             "fem_blocks/distributed/colour.py",
             "                                          cases)\n                self._exchange(c)\n",
             "                                          cases)\n                self._exchange(0)\n",
             ("tests/test_dist_run.py",)),
    Mutation("groups_uncoupled", "colour groups: coupled groups may share a colour (the group graph without W)",
             "fem_blocks/distributed/colour.py",
             "    return colour_group_graph(ng, group[rows], group[cols])[group]",
             "    return colour_group_graph(ng, group[rows], group[rows])[group]",
             ("tests/test_colour.py", "tests/test_dist_run.py")),
    Mutation("signal_per_rank", "N ranks: each rank stops on its own signal, not on the ranks' common decision",
             "fem_blocks/runner.py",
             "                    received = _collective_signal(comm, sig.received)  # (N ranks: one decision for all)",
             "                    received = sig.received",
             ("tests/test_dist_run.py",)),
    Mutation("rank_contacts_no_antagonists", "N ranks: a rank's contacts L without those on its contacts' antagonists",
             "fem_blocks/contact/step.py", "        near[cs.ant_body[own]] = True\n", "",
             ("tests/test_dist_run.py",)),
    Mutation("impulse_every_contact", "N ranks: every rank adds the impulses of all its contacts L to the bodies",
             "fem_blocks/contact/step.py", "        imp[~self._local.dofs] = 0.0\n", "",
             ("tests/test_dist_run.py",)),
    Mutation("greedy_edges_not_symmetric", "N ranks: an edge known to one end's owner is not sent to the other's",
             "fem_blocks/distributed/greedy.py",
             "    extra, _ = exchange(comm, pairs, np.bincount(ob, minlength=size))\n",
             "    extra = exchange(comm, pairs, np.bincount(ob, minlength=size))[0][:0]\n", ("tests/test_dist_greedy.py",)),
    Mutation("greedy_ready_without_ghosts", "N ranks: a group is coloured without waiting for its lower ghost "
             "neighbours' colours", "fem_blocks/solver/parallel.py",
             "            if gid[j] < gid[i] and colour[j] < 0:\n                ready = False",
             "            if j < n_own and gid[j] < gid[i] and colour[j] < 0:\n                ready = False",
             ("tests/test_dist_greedy.py",)),
    Mutation("ck_state_not_per_contact", "checkpoint pieces: the law state left out of the per-contact entries "
             "(every rank holds all its rows)", "fem_blocks/contact/step.py",
             '    PER_CONTACT = ("contact.P", "contact.state", "contact.law",',
             '    PER_CONTACT = ("contact.P", "contact.law",', ("tests/test_checkpoint_pieces.py",)),
    Mutation("ck_owner_from_antagonist", "checkpoint pieces: a contact's rows go to the rank of its antagonist body",
             "fem_blocks/output/checkpoint.py", '        cand = np.asarray(arrays["contact.cs.cand_body"])',
             '        cand = np.asarray(arrays["contact.cs.ant_body"])', ("tests/test_checkpoint_pieces.py",)),
    Mutation("ck_set_by_largest_step", "checkpoint pieces: the newest set chosen by the largest step (an older run's "
             "pieces in .prev win)", "fem_blocks/output/checkpoint.py",
             "    for k, (p0, d0) in enumerate(valid.get(0, [])):",
             '    for k, (p0, d0) in enumerate(sorted(valid.get(0, []), key=lambda x: -int(x[1]["sim.step"]))):',
             ("tests/test_checkpoint_pieces.py",)),
    Mutation("sweep_order_returned", "colour solver: the impulses returned in sweep order, not in contact order",
             "fem_blocks/distributed/colour.py", "        out[self._back] = x\n",
             "        out[:] = x\n", ("tests/test_colour.py",)),
    Mutation("sweep_order_diagonal", "colour solver: the diagonal blocks' positions not moved with the rows",
             "fem_blocks/distributed/colour.py",
             "    diag = np.where(dpos >= 0, dpos - indptr[perm] + indptr_new[:-1], -1).astype(np.int64)",
             "    diag = np.where(dpos >= 0, dpos, -1).astype(np.int64)", ("tests/test_colour.py",)),
    Mutation("own_rows_ghost_warm_start", "N ranks, own rows: the ghosts' warm start left at zero, not exchanged",
             "fem_blocks/distributed/colour.py", "                self._exchange(c)\n        qo = ",
             "                pass\n        qo = ", ("tests/test_dist_own_rows.py",)),
    Mutation("own_rows_gathered_in_rank_order", "N ranks, own rows: the step's record left in rank order, not put "
             "back in contact order", "fem_blocks/distributed/sweep.py", "    out[order] = buf\n",
             "    out[:] = buf\n", ("tests/test_dist_own_rows.py",)),
    Mutation("own_rows_redetect_whole_index", "N ranks, own rows: a re-detected contact's impulse carried from its "
             "old place in the rank's contact set, not from the old own rows", "fem_blocks/contact/step.py",
             "            return olds, _lookup(ids, new_ids)\n",
             "            return olds, _lookup(old_local.ids, new_ids)\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("own_rows_L_not_scattered", "N ranks, own rows: the impulses of the contacts L owned elsewhere not "
             "scattered (zero in H P)", "fem_blocks/contact/step.py",
             "        out[other] = gvec.getArray().reshape(-1, d)\n", "        out[other] = 0.0\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("guard_first_rank_finding", "N ranks: the run check names the first rank's finding, not the worst of "
             "every rank's", "fem_blocks/distributed/root.py",
             "    return min(found, key=lambda x: (x[0], x[1])) if found else None\n",
             "    return found[0] if found else None\n", ("tests/test_dist_run.py", "tests/test_guards.py")),
    Mutation("contacts_pieces_whole", "N ranks: every rank writes the ParaView piece of every contact, not of its own",
             "fem_blocks/runner.py", "        pc.write(sim.time, sim.last_contact)\n",
             "        pc.write(sim.time, None if sim.last_contact is None else sim.last_contact.whole())\n",
             ("tests/test_dist_run.py",)),
    Mutation("body_sum_group_numpy", "sums over bodies: a group's kinetic energy summed by NumPy over its (ndof, k) array",
             "fem_blocks/dynamics.py", "                kin.append(0.5 * column_sums(U * (gr.type.M @ U)))\n",
             "                kin.append([0.5 * float(np.sum(U * (gr.type.M @ U)))])\n", ("tests/test_body_sums.py",)),
    Mutation("body_sum_every_body_per_rank", "N ranks: each rank adds every body's terms to the sums over bodies",
             "fem_blocks/dynamics.py",
             "        return [np.flatnonzero(mine[gr.members]) for gr in self.groups], mine, comm\n",
             "        return [slice(None)] * len(self.groups), np.ones(len(self.bodies), dtype=bool), comm\n",
             ("tests/test_body_sums.py", "tests/test_dist_run.py")),
    Mutation("body_sum_rigid_every_rank", "N ranks: the rigid bodies' energies added on every rank",
             "fem_blocks/dynamics.py", "            if mine[i]:\n                b = self.bodies[i]\n",
             "            if True:\n                b = self.bodies[i]\n", ("tests/test_body_sums.py",)),
    Mutation("own_bodies_max_velocity_all", "N ranks: the largest velocity taken over every body, not the own ones",
             "fem_blocks/dynamics.py", "            U = columns(gr.U, c)\n            if U.size:\n",
             "            U = gr.U\n            if U.size:\n", ("tests/test_dist_own_bodies.py",)),
    Mutation("own_bodies_guard_all", "N ranks: the body NaN check reading every body", "fem_blocks/runner.py",
             "        cols, mine, _ = sim.own_bodies()\n        found = {}\n",
             "        cols, mine = [None] * len(sim.groups), np.ones(len(sim.bodies), dtype=bool)\n        found = {}\n",
             ("tests/test_dist_own_bodies.py",)),
    Mutation("own_bodies_watch_all", "N ranks: the small-rotation watch reading every block", "fem_blocks/runner.py",
             "            Q = columns(gr.Q, c)\n",
             "            Q, members = gr.Q, gr.members\n", ("tests/test_dist_own_bodies.py",)),
    Mutation("own_bodies_dmax_all", "N ranks: the step's largest displacement increment taken over every body",
             "fem_blocks/dynamics.py", "            dmax = max(dmax, float(np.max(np.abs(dQc), initial=0.0)))\n",
             "            dmax = max(dmax, float(np.max(np.abs(dQ), initial=0.0)))\n",
             ("tests/test_dist_own_bodies.py",)),
    Mutation("factor_one_column_vector_solve", "one right-hand side solved by the vector solve, several by MatMatSolve",
             "fem_blocks/linalg.py", "        if k == 0:\n            return np.zeros((n, 0))\n",
             "        if k == 0:\n            return np.zeros((n, 0))\n        if k == 1:\n"
             "            return self.solve(b[:, 0])[:, None]\n", ("tests/test_linalg.py", "tests/test_body_sums.py")),
    # bodies stepped per rank (issue 24, phase B2)
    Mutation("stepped_every_body", "N ranks, frozen geometry: every rank steps every body", "fem_blocks/dynamics.py",
             "                out.append(None if gr.framed or not gr.op.factor.columnwise or s.size == len(gr.members) "
             "else s)\n", "                out.append(None)\n", ("tests/test_dist_own_bodies.py",)),
    Mutation("stepped_others_kept", "N ranks: the bodies a rank does not step keep their last values, not NaN",
             "fem_blocks/dynamics.py", "                A[:, off] = np.nan\n", "                pass\n",
             ("tests/test_dist_own_bodies.py",)),
    Mutation("stepped_shared_ignored", "N ranks: the shared bodies not added to a rank's stepped bodies",
             "fem_blocks/dynamics.py", "            mask[self.shared] = True\n", "            pass\n",
             ("tests/test_dist_own_bodies.py", "tests/test_dist_run.py")),
    Mutation("stepped_reset_every_column", "N ranks: the velocity reset zeroes every body's velocity, not the stepped "
             "ones'", "fem_blocks/dynamics.py", "                    gr.U[:, s] = 0.0\n",
             "                    gr.U[:] = 0.0\n", ("tests/test_dist_own_bodies.py",)),
    Mutation("read_bodies_not_shared", "N ranks: the bodies of the gauges and rotation columns not stepped on every "
             "rank", "fem_blocks/runner.py", "    sim.share_bodies(read_bodies(case, model, rot_ids, gauge_ids))",
             "    sim.share_bodies([])", ("tests/test_dist_run.py",)),
    Mutation("joints_points_every_contact", "N ranks: every rank computes the joints' points of every contact",
             "fem_blocks/runner.py", "    if rec.rows is None:\n        return rec, model.contact.contact_points\n",
             "    if True:\n        return rec.whole(), model.contact.contact_points\n", ("tests/test_dist_run.py",)),
    Mutation("figures_not_collected", "N ranks: rank 0 draws the figures without collecting the bodies' state",
             "fem_blocks/runner.py", "        sim.collect_bodies()", "        pass", ("tests/test_dist_run.py",)),
    Mutation("pieces_contiguous", "N ranks: blocks.pvd's pieces stay blocks of contiguous bodies, not the partition",
             "fem_blocks/output/paraview.py", "    if comm is not None and own is not None:\n",
             "    if False:\n", ("tests/test_dist_run.py",)),
    Mutation("stepped_traction_column", "N ranks: a traction added to the column of its body among all members, not "
             "among the stepped ones", "fem_blocks/dynamics.py",
             "            k = j if s is None else int(np.searchsorted(s, j))  # (its column in F)\n",
             "            k = j  # (its column in F)\n", ("tests/test_body_sums.py",)),
    Mutation("totals_numpy", "the contacts' totals (dissipated, frictional work) summed by NumPy, not exactly",
             "fem_blocks/contact/step.py",
             "        return exact_sums(terms, self.comm if self._local is not None else None)\n",
             "        return [float(np.sum(x)) for x in terms]\n", ("tests/test_dist_own_rows.py",)),
    Mutation("totals_not_reduced", "N ranks: each rank's totals of its own contacts only (no all-reduce)",
             "fem_blocks/contact/step.py",
             "        return exact_sums(terms, self.comm if self._local is not None else None)\n",
             "        return exact_sums(terms, None)\n", ("tests/test_dist_own_rows.py",)),
    Mutation("takeover_stale_blocks", "updated geometry: a colour solver taken over keeps the previous W's blocks",
             "fem_blocks/distributed/colour.py", "        self.rows = (ip, ix, lr.blocks, dp)\n",
             "        self.rows = previous.rows\n", ("tests/test_colour.py",)),
    Mutation("takeover_no_colours", "a colour solver taken over when only the colours differ (the same sweep order "
             "and count)", "fem_blocks/distributed/colour.py",
             "(previous._colour_local, colour_local),\n", "\n", ("tests/test_colour.py",)),
    Mutation("takeover_no_pattern", "a colour solver taken over when the rows' column numbers differ (same row "
             "lengths)", "fem_blocks/distributed/colour.py",
             "                (ip, lr.indptr), (dp, lr.diag_pos), (ix, lr.indices)))",
             "                (ip, lr.indptr), (dp, lr.diag_pos)))", ("tests/test_colour.py",)),
    Mutation("largest_allreduce_max", "N ranks: the largest of the ranks' values by an Allreduce MAX (a NaN on a rank "
             "other than the first is dropped)", "fem_blocks/distributed/exact.py",
             "    return float(np.max(every))\n",
             "    from mpi4py import MPI\n    return comm.allreduce(x, op=MPI.MAX)\n", ("tests/test_exact_sum.py",)),
    Mutation("rebalance_rows_unsorted", "updated geometry, a new partition: the rows received looked up in their "
             "arrival order, not sorted by id", "fem_blocks/contact/step.py",
             '        k = np.argsort(got, kind="stable")', "        k = np.arange(got.size)",
             ("tests/test_dist_own_rows.py",)),
    Mutation("rebalance_send_unsorted", "updated geometry, a new partition: the rows sent in the new contacts' order, "
             "not grouped by the rank they go to", "fem_blocks/contact/step.py",
             '        o = np.argsort(dest, kind="stable")\n', "        o = np.arange(dest.size)\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("rebalance_bound_inclusive", "a new partition also when the busiest rank owns exactly rebalance x the "
             "mean", "fem_blocks/contact/step.py",
             "        if not busiest * size > self.opts.rebalance * counts.sum():\n",
             "        if not busiest * size >= self.opts.rebalance * counts.sum():\n",
             ("tests/test_dist_partition.py",)),
    Mutation("rebalance_kept_if_worse", "a new partition kept even when its busiest rank owns as many contacts",
             "fem_blocks/contact/step.py",
             "        if self._rank_counts(new, rows).max(initial=0) >= busiest:\n",
             "        if False:\n", ("tests/test_dist_partition.py",)),
    Mutation("partition_unweighted", "the time stepper's partition: the vertex weights from the antagonists' "
             "counts", "fem_blocks/distributed/graph.py",
             "    comm.Reduce_scatter(np.bincount(cand, minlength=nb)",
             "    comm.Reduce_scatter(np.bincount(ant, minlength=nb)", ("tests/test_dist_partition.py",)),
    Mutation("pieces_current_partition", "N ranks: a snapshot's checkpoint split by the partition in use, not the "
             "snapshot's own (a failed step after a new partition)", "fem_blocks/runner.py",
             '    kept = None if arrays is None else arrays.get("contact.body_owner")\n', "    kept = None\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("vertex_weights_first_rows", "every rank gives PT-Scotch the first rows' vertex weights, not its own "
             "block's", "fem_blocks/distributed/graph.py", "np.asarray(vertex_weights)[start:start + n_loc]",
             "np.asarray(vertex_weights)[:n_loc]", ("tests/test_dist_partition.py",)),
    Mutation("rows_not_given", "a colour solver taken over leaves W its own index arrays (a second int64 per block "
             "beside the solver's)", "fem_blocks/distributed/colour.py",
             "        previous.dist = previous.rows = None  # (spent: its scatters and arrays are this solver's)\n"
             "        self._give_rows(self.W)\n",
             "        previous.dist = previous.rows = None  # (spent: its scatters and arrays are this solver's)\n",
             ("tests/test_colour.py",)),
    Mutation("couplings_held_bodies", "the colours read from the bodies couple groups through a held body too "
             "(W_b = 0)", "fem_blocks/distributed/colour.py", "    keep = moving[body]\n",
             "    keep = np.ones(body.size, dtype=bool)\n", ("tests/test_colour.py",)),
    Mutation("moving_bodies_length", "moving_bodies reads W_size[b] entries of a body's block, not W_size[b]²",
             "fem_blocks/distributed/colour.py",
             "np.searchsorted(nz, lo + np.asarray(W_size, dtype=np.int64) ** 2)",
             "np.searchsorted(nz, lo + np.asarray(W_size, dtype=np.int64))", ("tests/test_colour.py",)),
    Mutation("assemble_rows_in_computing_order", "Delassus rows asked in another order written in increasing "
             "contact order", "fem_blocks/delassus.py",
             "    for i in range(nr):\n        a = rows[i]\n        o = dest[i]\n        for kk in range(indptr[o]",
             "    for i in range(nr):\n        a = rows[i]\n        o = i\n        for kk in range(indptr[o]",
             ("tests/test_detection_delassus.py",)),
    Mutation("sweep_plan_unsorted", "the sweep plan's rows in contact order, not by colour",
             "fem_blocks/distributed/colour.py",
             '    rows = own[np.argsort(colour[own], kind="stable")]\n', "    rows = own\n",
             ("tests/test_colour.py", "tests/test_dist_run.py")),
    Mutation("detect_subset_own_grid", "a rank's detection runs its broad phase on the grid of its own edges, not "
             "the whole set's", "fem_blocks/contact/detection_2d.py",
             "cell, origin=lo.min(axis=0), top=hi.max(axis=0))]", "cell)]",
             ("tests/test_placement.py", "tests/test_detection_delassus.py")),
    Mutation("near_bodies_one_side", "a rank's detection misses the neighbours numbered below its bodies",
             "fem_blocks/contact/broadphase.py", "    near[pairs[mine[:, 1], 0]] = True\n", "",
             ("tests/test_placement.py",)),
    Mutation("detect_matches_not_filtered", "a rank's detection keeps the contacts of its neighbours' candidates",
             "fem_blocks/contact/detection_2d.py", "        m = bodies[bedge_body[ce]]\n",
             "        m = np.ones(ce.size, dtype=bool)\n", ("tests/test_placement.py",)),
    Mutation("gather_set_rank_order", "the ranks' own rows gathered in rank order, not in contact id order",
             "fem_blocks/distributed/sweep.py", "            order[o] = np.arange(every.size)\n",
             "            order = np.arange(every.size)\n", ("tests/test_dist_own_rows.py",)),
    Mutation("detect_error_not_shared", "a detection error found by one rank raised there only (the others wait in "
             "the gather)", "fem_blocks/contact/step.py",
             "            first = next((e for e in self.comm.allgather(err) if e is not None), None)\n",
             "            first = err\n", ("tests/test_colour.py",)),
    Mutation("replicas_no_positions", "updated geometry, detection split: the ranks' positions left out of the "
             "replica check", "fem_blocks/contact/step.py",
             "            mine += (zlib.crc32(np.ascontiguousarray(bx[::max(1, len(bx) // 4096)]).tobytes()),)\n", "",
             ("tests/test_colour.py",)),
    Mutation("detect3d_pairs_both_mine", "a rank's 3D detection keeps the body pairs with both bodies its own only",
             "fem_blocks/contact/detection_3d.py",
             "bpairs[bodies[bpairs[:, 0]] | bodies[bpairs[:, 1]]]", "bpairs[bodies[bpairs[:, 0]] & bodies[bpairs[:, 1]]]",
             ("tests/test_detection3d.py",)),
    Mutation("detect3d_matches_not_filtered", "a rank's 3D detection keeps the contacts of its neighbours' candidates",
             "fem_blocks/contact/detection_3d.py", "        m = bodies[bface_body[ri[:, 0]]]\n",
             "        m = np.ones(len(ri), dtype=bool)\n", ("tests/test_detection3d.py", "tests/test_dist_own_rows.py")),
    Mutation("vertex_weights_leak", "the vertex weights' PetscMalloc buffer not freed when PETSc does not take it",
             "fem_blocks/distributed/graph.py",
             '        lib.PetscFreeA(ctypes.c_int(1), ctypes.c_int(0), b"_set_vertex_weights", b"graph.py", ctypes.byref(ptr))\n',
             "", ("tests/test_dist_partition.py",)),
    Mutation("fail_alone", "a check of the ranks' agreement raised only on the rank that found it (the others wait)",
             "fem_blocks/contact/step.py", "        if self.comm.allreduce(int(bad), op=MPI.MAX):\n",
             "        if bad:\n", ("tests/test_colour.py",)),
    Mutation("partition_one_way", "the body graph from the ranks' contacts: each contact's edge one way only",
             "fem_blocks/distributed/graph.py", "    rows = np.concatenate([cand[two], ant[two]])\n"
             "    cols = np.concatenate([ant[two], cand[two]])\n",
             "    rows, cols = cand[two], ant[two]\n", ("tests/test_dist_partition.py",)),
    Mutation("partition_first_share", "a partition from a whole contact set (a resumed run): every rank gives the "
             "whole set to the graph",
             "fem_blocks/contact/step.py",
             "            self.body_owner = self._partition(np.arange(n * p // size, n * (p + 1) // size))",
             "            self.body_owner = self._partition(np.arange(n))", ("tests/test_dist_partition.py",)),
    Mutation("gather_overlap_unchecked", "the ranks' own contacts not checked for a contact held by two ranks",
             "fem_blocks/distributed/sweep.py", "            if np.any(every[o][1:] == every[o][:-1]):\n",
             "            if False:\n", ("tests/test_dist_own_rows.py",)),
    Mutation("rank_keeps_whole_set", "N ranks: a rank keeps the whole contact set, not its part L",
             "fem_blocks/contact/step.py", "                if L.size != len(self.cs.gap):\n",
             "                if False:\n", ("tests/test_dist_own_rows.py",)),
    Mutation("candidates_one_ring", "N ranks: a rank detects the candidates among its bodies' neighbours only, not "
             "their neighbours' (contacts of L missed)", "fem_blocks/contact/step.py",
             "        return near_bodies(pairs, near_bodies(pairs, self.body_owner == self.comm.Get_rank()))\n",
             "        return near_bodies(pairs, self.body_owner == self.comm.Get_rank())\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("numbers_no_offset", "N ranks: each rank's own contacts numbered from 0, not from the ranks before",
             "fem_blocks/contact/step.py", "        number[own_pos] = start + np.arange(own_pos.size)\n",
             "        number[own_pos] = np.arange(own_pos.size)\n", ("tests/test_dist_own_rows.py",)),
    Mutation("guard_number_id", "N ranks: a run check names the contact by its id, not its number in the whole set",
             "fem_blocks/runner.py",
             "        return int(self.comm.allreduce(int(np.count_nonzero(c.gather.ids < at)), op=MPI.SUM))\n",
             "        return at\n", ("tests/test_dist_run.py",)),
    Mutation("watch_not_agreed", "N ranks: the missed-contact watch takes each rank's deepest, not agreed",
             "fem_blocks/runner.py",
             "        found = least_found(self.comm if c.rows is not None else None, self._deepest(c))\n",
             "        found = self._deepest(c)\n",
             ("tests/test_guards.py",)),
    Mutation("pieces_by_position", "checkpoint pieces merged by their rows' place among each piece, not by id",
             "fem_blocks/output/checkpoint.py", "            ids = [np.searchsorted(every, i) for i in ids]\n",
             "            ids = list(np.split(np.arange(n), np.cumsum([len(i) for i in ids])[:-1]))\n",
             ("tests/test_checkpoint_pieces.py", "tests/test_dist_run.py")),
    Mutation("first_partition_all_held", "N ranks, the first partition: each rank gives the graph every contact it "
             "holds, not its own (contacts counted by several ranks)", "fem_blocks/contact/step.py",
             "        self.body_owner = self._partition(self._given())\n",
             "        self.body_owner = self._partition(np.arange(len(self.cs.gap)))\n", ("tests/test_dist_own_rows.py",)),
    Mutation("leave_colours_own_ids", "N ranks, a run leaving colour order: the old rows gathered whole but looked up "
             "among the rank's own ids", "fem_blocks/contact/step.py",
             "            return [old_local.gather(x) for x in olds], _lookup(every, new_ids)\n",
             "            return [old_local.gather(x) for x in olds], _lookup(ids, new_ids)\n",
             ("tests/test_dist_own_rows.py",)),
    Mutation("cohesive_flag_own_part", "N ranks: whether the contact set is cohesive read from the rank's own part "
             "only", "fem_blocks/contact/step.py",
             "            self.comm.Allreduce(used.astype(np.int64), every, op=MPI.MAX)\n",
             "            every[:] = used\n", ("tests/test_colour.py",)),
]

IGNORE = shutil.ignore_patterns(".git", "__pycache__", ".venv", "*.pyc", ".pytest_cache", "out", "*.egg-info")


def copy_tree(dst: str) -> str:
    """Copy the working tree to dst/repo; link dst/shared to the project's ../shared (FCLIB data, if any)."""
    repo = os.path.join(dst, "repo")
    shutil.copytree(ROOT, repo, ignore=IGNORE, symlinks=True)
    shared = os.path.join(os.path.dirname(ROOT), "shared")
    if os.path.isdir(shared):
        os.symlink(shared, os.path.join(dst, "shared"))
    return repo


def apply(repo: str, m: Mutation) -> None:
    path = os.path.join(repo, m.file)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    n = text.count(m.old)
    if n != 1:
        raise RuntimeError(f"{m.id}: the old text occurs {n} times in {m.file} (expected once): update the mutation")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text.replace(m.old, m.new))


def run_one(m: Mutation | None, tests, python: str, timeout: float, keep: bool) -> dict:
    tmp = tempfile.mkdtemp(prefix=f"fem_blocks_mut_{m.id if m else 'baseline'}_")
    t0 = time.perf_counter()
    out = dict(id=m.id if m else "baseline", title=m.title if m else "no mutation", file=m.file if m else "",
               tests=list(tests))
    try:
        repo = copy_tree(tmp)
        if m is not None:
            apply(repo, m)
        cache = os.path.join(tmp, "numba_cache")
        os.makedirs(cache)
        env = dict(os.environ, PYTHONPATH=repo, NUMBA_CACHE_DIR=cache, PYTHONDONTWRITEBYTECODE="1")
        where = subprocess.run([python, "-c", "import fem_blocks; print(fem_blocks.__file__)"], cwd=repo, env=env,
                               capture_output=True, text=True, timeout=120)
        if not where.stdout.strip().startswith(repo):
            raise RuntimeError(f"fem_blocks imported from {where.stdout.strip() or where.stderr.strip()!r}, "
                               f"not from the copy {repo}")
        p = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests], cwd=repo, env=env,
                           capture_output=True, text=True, timeout=timeout)
        failed = sorted(set(re.findall(r"^(?:FAILED|ERROR) (\S+)", p.stdout, flags=re.M)))
        summary = (p.stdout.strip().splitlines() or [""])[-1]
        out.update(returncode=p.returncode, failed=failed, summary=summary)
        out["result"] = {0: "survived", 1: "killed"}.get(p.returncode, "error")
        if out["result"] == "error":
            out["output_tail"] = (p.stdout + p.stderr)[-3000:]
    except subprocess.TimeoutExpired:
        out.update(result="error", summary=f"timeout after {timeout:g} s")
    except Exception as e:  # noqa: BLE001 - reported as an error row
        out.update(result="error", summary=str(e))
    finally:
        out["seconds"] = round(time.perf_counter() - t0, 1)
        if keep:
            out["directory"] = tmp
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="+", metavar="ID", help="run these mutations only")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--baseline", action="store_true", help="run the tests of the selected mutations unmutated")
    ap.add_argument("--python", default=sys.executable, help="interpreter with fem_blocks' dependencies")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per mutation (default 1800)")
    ap.add_argument("--json", help="write the results to this file (appended as they come)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copies")
    a = ap.parse_args(argv)
    sel = MUTATIONS
    if a.only:
        known = {m.id for m in MUTATIONS}
        bad = [x for x in a.only if x not in known]
        if bad:
            ap.error(f"unknown mutation {bad[0]!r}; expected one of {sorted(known)}")
        sel = [m for m in MUTATIONS if m.id in a.only]
    if a.list:
        for m in sel:
            print(f"{m.id:24s} {m.file:34s} {m.title}  [{' '.join(m.tests)}]")
        return 0
    results = []
    if a.baseline:
        tests = sorted({t for m in sel for t in m.tests})
        r = run_one(None, tests, a.python, a.timeout, a.keep)
        print(f"baseline: {'passed' if r.get('returncode') == 0 else 'FAILED'} ({r['summary']}, {r['seconds']} s)",
              flush=True)
        return 0 if r.get("returncode") == 0 else 1
    for m in sel:
        r = run_one(m, m.tests, a.python, a.timeout, a.keep)
        results.append(r)
        by = ", ".join(r.get("failed", [])[:4]) + (" ..." if len(r.get("failed", [])) > 4 else "")
        print(f"{r['result']:8s} {m.id:24s} {r['seconds']:7.1f} s  {r['summary']}  {by}", flush=True)
        if a.json:
            with open(a.json, "w") as f:
                json.dump(results, f, indent=1)
    print("\n| deliberate bug | where | result | killed by |\n|---|---|---|---|")
    for r in results:
        print(f"| {r['title']} | `{r['file']}` | {r['result']} | "
              f"{', '.join('`' + x.split('::')[-1] + '`' for x in r.get('failed', [])[:3])} |")
    return 0 if all(r["result"] == "killed" for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())

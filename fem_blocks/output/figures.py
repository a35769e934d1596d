"""Run figures: force–displacement curve (from history.csv) and crack pattern (deformed blocks, joints
coloured by damage, or by opening for dry joints)."""
from __future__ import annotations

import os

import numpy as np

from .plots import plot_crack_pattern, plot_curve


def _loop(edges: np.ndarray) -> np.ndarray:
    """Node sequence of the boundary loop containing edge 0 (edges oriented, body on the left)."""
    nxt = {int(a): int(b) for a, b in edges}
    start = int(edges[0, 0])
    seq = [start]
    k = nxt[start]
    while k != start and len(seq) <= len(edges):
        seq.append(k)
        k = nxt.get(k, start)
    return np.array(seq)


def body_outlines(sim, amplification: float):
    polys = []
    for b in sim.bodies:
        if b.kind == 0:
            loop = getattr(b.type, "_outline_loop", None)
            if loop is None:
                loop = b.type._outline_loop = _loop(b.type.mesh.boundary_edges)
            X = b.reference_points[loop]
            D = b.displacement_global()[loop]
            polys.append(X + amplification * D)
        else:
            ref = b.center0 + b.vertices_rel
            polys.append(ref + amplification * (b.current_vertices() - ref))
    return polys


def joint_segments(contact, sim, amplification: float):
    """Short segments along each joint at the contact points and their crack value in [0, 1]."""
    cs = getattr(contact, "cs", None)
    if cs is None or len(cs.gap) == 0:
        return np.zeros((0, 2, 2)), np.zeros(0), "damage"
    thick = contact.body_thickness[cs.cand_body]
    half = 0.5 * cs.area / thick
    # current point: reference point moved by the candidate displacement (amplified)
    s = contact.scene
    bx_ref = s.positions(reference=True)
    bx_cur = s.positions()
    b = cs.cand_body
    idx = s.bx_start[b][:, None] + s.bnode_index_flat[s.bnode_offset[b][:, None] + cs.cand_nodes]
    xr = cs.cand_w[:, :1] * bx_ref[idx[:, 0]] + cs.cand_w[:, 1:] * bx_ref[idx[:, 1]]
    xc = cs.cand_w[:, :1] * bx_cur[idx[:, 0]] + cs.cand_w[:, 1:] * bx_cur[idx[:, 1]]
    x = xr + amplification * (xc - xr)
    seg = np.stack([x - half[:, None] * cs.t, x + half[:, None] * cs.t], axis=1)
    law = getattr(contact, "law", np.zeros(len(cs.gap), int))
    if np.any(law >= 2):
        from ..laws import MIXED, S_BETA
        st = contact.state
        val = np.where(law == MIXED, st[:, S_BETA], np.where(law >= 2, 1.0 - st[:, S_BETA], 0.0))
        label = "joint damage"
    else:
        opening = np.maximum(np.asarray(contact.gt_end), 0.0)
        ref = max(float(np.percentile(opening, 99)) if opening.size else 0.0, 1e-12)
        val = np.clip(opening / ref, 0.0, 1.0)
        label = f"joint opening / {ref:.2g} m"
    return seg, val, label


def auto_amplification(sim) -> float:
    pts, disp = [], []
    for b in sim.bodies:
        if b.kind == 0:
            pts.append(b.reference_points)
            disp.append(b.displacement_global())
    if not pts:
        return 1.0
    P = np.concatenate(pts)
    dmax = float(np.abs(np.concatenate(disp)).max())
    size = float(np.ptp(P, axis=0).max())
    if dmax <= 0:
        return 1.0
    amp = 0.03 * size / dmax
    mag = 10 ** np.floor(np.log10(amp))
    return float(np.floor(amp / mag) * mag) if amp > 1 else 1.0


def write_crack_pattern(path, sim, contact, title=""):
    amp = auto_amplification(sim)
    polys = body_outlines(sim, amp)
    seg, val, label = joint_segments(contact, sim, amp) if contact is not None else (np.zeros((0, 2, 2)), [], "")
    return plot_crack_pattern(path, polys, seg, val, amp, title=title, value_label=label)


def curve_arrays(history: dict, body: str, force: str, displacement: str, scale_force=1e-3, scale_disp=1e3):
    f = np.asarray(history[f"{body}.{force}"], float) * scale_force
    d = np.asarray(history[f"{body}.{displacement}"], float) * scale_disp
    return d, f


def write_curve(path, history: dict, body: str, force: str, displacement: str, title=""):
    d, f = curve_arrays(history, body, force, displacement)
    return plot_curve(path, np.abs(d), np.abs(f), f"{body} displacement {displacement} [mm]",
                      f"{body} reaction {force} [kN]", title=title)

"""Joint resultants: per joint (all contact points of one pair of bodies) the resultant force, its normal and
tangential components and its point of application in the joint (the eccentricity), from the contact arrays of a
contact.result.ContactResult. Pure functions on plain arrays: nothing here reads or writes a simulation.

Conventions (docs/method.md §1): contact k has the frame (n_k, t_k[, s_k]), n_k the antagonist's outward normal, and
the reaction r_k (local components, N) is the force of the antagonist on the candidate; its global force is
f_k = r_N n_k + r_T t_k (+ r_S s_k in 3D). A joint is the unordered pair of bodies (a, b), a < b (body indices of
the contact set, model order). Every force of the joint is taken as the force of body a on body b:

    f_k^{a→b} = f_k  if cand_k = b,   -f_k  if cand_k = a          (action–reaction)

The joint frame: n_j = the tributary-area-weighted mean of the contact normals oriented from a to b (±n_k as
above), normalised; 2D t_j = (-n_y, n_x) (the contacts' convention); 3D t_j = the first contact's t projected on
the plane ⟂ n_j, s_j = n_j × t_j. The middle of the joint x_m = x̄, the tributary-area-weighted centroid of the
points, is the reference point. 2D: the joint's half-width is half its length, Σ_k l_k / 2 with l_k the tributary
length of point k (the caller's `lengths`: area / thickness): exact for a straight joint in full contact with every
placement ("overlap": points at the overlap ends, l = half the overlap each; "positions": cells tiling the edge;
"nodes": ∫N_k ds), and then x̄ is its middle. 3D (approximate): half-width along t_j = max_k(|ξ_k| + √a_k / 2),
ξ_k = (x_k − x̄)·t_j, likewise along s_j (exact for square tributary cells). Resultant and moment about x_m:

    F = Σ_k f_k^{a→b},   N = F·n_j (> 0 compression),   T = F·t_j  (3D: T_t, T_s = F·s_j),
    M = Σ_k (x_k − x_m) × f_k^{a→b}  (2D: scalar z)

The point of application x_m + e t_j (2D) is where the line of action of F crosses the joint's line:
M = e (t_j × F)_z = e N (t_j × n_j)_z = −e N, so e = −M / N. In 3D the point x_m + e_t t_j + e_s s_j:
M·t_j = e_s N, M·s_j = −e_t N (the torsion M·n_j is reported as is). e is NaN when N ≤ 0 (an open or pulled joint
has no point of application inside it). The joint is "inside" when |e| ≤ half_width (the line of thrust passes
through the joint; 3D: |e_t| ≤ half_width_t and |e_s| ≤ half_width_s).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class JointResultants:
    """Per joint j (nj rows, sorted by (a, b)); d = 2 or 3. Forces in N (2D: per the bodies' thickness, as r),
    lengths in m, moments in N·m."""
    bodies: np.ndarray      # (nj, 2) body indices a < b
    n_contacts: np.ndarray  # (nj,) contact points in the joint
    force: np.ndarray       # (nj, d) global resultant F, force of a on b
    N: np.ndarray           # (nj,) normal component F·n_j (> 0 compression)
    T: np.ndarray           # (nj,) 2D: F·t_j; 3D: |(F·t_j, F·s_j)|
    normal: np.ndarray      # (nj, d) n_j, from a to b
    tangent: np.ndarray     # (nj, d) t_j
    middle: np.ndarray      # (nj, d) x_m, the middle of the joint (reference point of M and e)
    moment: np.ndarray      # (nj,) 2D: M_z about x_m; (nj, 3) in 3D
    ecc: np.ndarray         # (nj,) 2D: e along t_j; (nj, 2) in 3D (e_t, e_s); NaN where N <= 0
    half_width: np.ndarray  # (nj,) 2D; (nj, 2) in 3D (along t_j, s_j)
    point: np.ndarray       # (nj, d) point of application x_m + e t_j (NaN where N <= 0)

    def __len__(self):
        return len(self.N)

    @property
    def inside(self) -> np.ndarray:
        """(nj,) True where the point of application lies inside the joint (False where N <= 0)."""
        e = np.abs(self.ecc).reshape(len(self.N), -1)
        hw = np.asarray(self.half_width).reshape(len(self.N), -1)
        with np.errstate(invalid="ignore"):
            return np.all(e <= hw * (1 + 1e-12), axis=1)

    def index(self, a: int, b: int) -> int:
        """Row of the joint between bodies a and b (either order); KeyError when they share no contact."""
        a, b = min(a, b), max(a, b)
        hit = np.flatnonzero((self.bodies[:, 0] == a) & (self.bodies[:, 1] == b))
        if not len(hit):
            raise KeyError(f"no joint between bodies {a} and {b}")
        return int(hit[0])


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def joint_resultants(cs, r, points=None, lengths=None) -> JointResultants:
    """JointResultants of contact set `cs` (detection_2d/detection_3d ContactSet: cand_body, ant_body, n, t[, s],
    area, point) under the local reactions `r` (nc, d) (ContactResult.r). `points` (nc, d): where the forces act
    (default cs.point; 2D runs: ContactStep.contact_points(cs), the current configuration); `lengths` (nc,): 2D
    tributary joint lengths (ContactStep.joint_lengths(cs); default cs.area)."""
    n_k = np.asarray(cs.n, float)
    nc, d = n_k.shape
    r = np.asarray(r, float).reshape(nc, d)
    x = np.asarray(cs.point if points is None else points, float).reshape(nc, d)
    area = np.asarray(cs.area, float)
    cand, ant = np.asarray(cs.cand_body, np.int64), np.asarray(cs.ant_body, np.int64)
    a, b = np.minimum(cand, ant), np.maximum(cand, ant)
    sign = np.where(cand == b, 1.0, -1.0)                       # f^{a→b} = sign f, normal a→b = sign n
    f = r[:, :1] * n_k + r[:, 1:2] * np.asarray(cs.t, float)
    if d == 3:
        f = f + r[:, 2:3] * np.asarray(cs.s, float)
    f *= sign[:, None]
    nab = n_k * sign[:, None]
    pairs, inv = np.unique(np.column_stack([a, b]), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    nj = len(pairs)
    counts = np.bincount(inv, minlength=nj)

    def jsum(v):  # per-joint sum of the rows of v (nc,) or (nc, k)
        v = np.asarray(v, float)
        if v.ndim == 1:
            return np.bincount(inv, weights=v, minlength=nj)
        return np.column_stack([np.bincount(inv, weights=v[:, c], minlength=nj) for c in range(v.shape[1])])

    wa = np.where(area > 0, area, 1.0)                          # weights (an empty area would drop a point)
    wsum = jsum(wa)
    nj_vec = jsum(nab * wa[:, None])
    nj_vec /= np.linalg.norm(nj_vec, axis=1)[:, None]
    xbar = jsum(x * wa[:, None]) / wsum[:, None]
    F = jsum(f)
    N = np.einsum("ij,ij->i", F, nj_vec)
    if d == 2:
        tj = np.column_stack([-nj_vec[:, 1], nj_vec[:, 0]])
        axes = [tj]
        ell = [np.asarray(area if lengths is None else lengths, float)]
    else:
        first = np.zeros(nj, np.int64)
        first[inv[::-1]] = np.arange(nc)[::-1]                  # first contact of each joint
        t0 = np.asarray(cs.t, float)[first]
        tj = t0 - np.einsum("ij,ij->i", t0, nj_vec)[:, None] * nj_vec
        tj /= np.linalg.norm(tj, axis=1)[:, None]
        sj = np.cross(nj_vec, tj)
        axes = [tj, sj]
        ell = [np.sqrt(area)] * 2                               # approximate tributary extent of a 3D point
    mid = xbar
    if d == 2:
        hws = [0.5 * jsum(ell[0])]                              # half the joint length Σ l_k / 2
    else:
        hws = []
        for ax, l in zip(axes, ell):
            hi = np.zeros(nj)
            np.maximum.at(hi, inv, np.abs(np.einsum("ij,ij->i", x - xbar[inv], ax[inv])) + 0.5 * l)
            hws.append(hi)
    arm = x - mid[inv]
    with np.errstate(invalid="ignore", divide="ignore"):
        if d == 2:
            M = jsum(_cross2(arm, f))
            T = np.einsum("ij,ij->i", F, tj)
            e = np.where(N > 0, -M / np.where(N > 0, N, 1.0), np.nan)
            point = mid + e[:, None] * tj
            hw = hws[0]
        else:
            M = jsum(np.cross(arm, f))
            T = np.hypot(np.einsum("ij,ij->i", F, tj), np.einsum("ij,ij->i", F, sj))
            Np = np.where(N > 0, N, 1.0)
            e = np.column_stack([-np.einsum("ij,ij->i", M, sj) / Np, np.einsum("ij,ij->i", M, tj) / Np])
            e[N <= 0] = np.nan
            point = mid + e[:, :1] * tj + e[:, 1:] * sj
            hw = np.column_stack(hws)
    return JointResultants(bodies=pairs, n_contacts=counts, force=F, N=N, T=T, normal=nj_vec, tangent=tj,
                           middle=mid, moment=M, ecc=e, half_width=hw, point=point)


def history_columns(names, joints_wanted) -> list[str]:
    """history.csv columns of the joints `joints_wanted` [(a, b), ...] (body indices) with body names `names`:
    'A|B.N', 'A|B.T' [N] and 'A|B.e' [m] (eccentricity; NaN while the joint is open), A and B in the given order
    (the values are those of the joint (min, max): force of the lower body index on the higher)."""
    cols = []
    for a, b in joints_wanted:
        tag = f"{names[a]}|{names[b]}"
        cols += [f"{tag}.N", f"{tag}.T", f"{tag}.e"]
    return cols


def history_values(res: JointResultants | None, joints_wanted, names) -> dict:
    """The values of history_columns for one step (0 force and NaN eccentricity for a joint without contact;
    3D: e = |(e_t, e_s)|)."""
    out = {}
    for a, b in joints_wanted:
        tag = f"{names[a]}|{names[b]}"
        try:
            j = res.index(a, b) if res is not None else None
        except KeyError:
            j = None
        if j is None:
            out.update({f"{tag}.N": 0.0, f"{tag}.T": 0.0, f"{tag}.e": float("nan")})
            continue
        e = res.ecc[j]
        out.update({f"{tag}.N": float(res.N[j]), f"{tag}.T": float(res.T[j]),
                    f"{tag}.e": float(e) if np.ndim(e) == 0 else float(np.hypot(*e))})
    return out


def record_joints(result, locate=None, lengths=None) -> JointResultants | None:
    """joint_resultants of a contact.result.ContactResult (None without contacts). `locate(cs)`, `lengths(cs)`: the
    contact step's contact_points / joint_lengths (2D); default cs.point, cs.area."""
    if result is None or not result.has_contacts():
        return None
    cs = result.cs
    return joint_resultants(cs, result.r, None if locate is None else locate(cs),
                            None if lengths is None else lengths(cs))


class JointsWriter:
    """The joints of a run as a vertex cloud per frame in `<directory>/joints.pvd`, written by
    output.contacts.ContactsWriter next to each contacts frame: one vertex per joint at its point of application
    (the joint's middle where N <= 0), point data force (global, force of body_a on body_b, N), N, T, e
    (2D: along tangent; 3D: (e_t, e_s)), half_width, inside (1/0), open (1 where N <= 0), body_a, body_b,
    n_contacts, normal, tangent."""

    def __init__(self, directory: str, dim: int, locate=None, lengths=None, append: bool = False,
                 keep_until_time: float | None = None):
        from .pvd import SeriesWriter
        self.dim, self.locate, self.lengths = dim, locate, lengths
        self.series = SeriesWriter(directory, "joints", append, keep_until_time)

    def arrays(self, result, locate=None):
        """(points, point data) of the joints of `result`; `locate`: instead of the writer's (runner.joints_record:
        the points gathered from the contacts' owners on N > 1 ranks)."""
        j = record_joints(result, locate or self.locate, self.lengths)
        if j is None:
            return np.zeros((0, self.dim)), {}
        opened = ~(j.N > 0)
        x = np.where(opened[:, None], j.middle, j.point)
        e = np.where(np.isnan(j.ecc), 0.0, j.ecc)
        data = dict(force=j.force, N=j.N, T=j.T, e=e, half_width=j.half_width,
                    inside=j.inside.astype(np.int64), open=opened.astype(np.int64),
                    body_a=j.bodies[:, 0].copy(), body_b=j.bodies[:, 1].copy(),
                    n_contacts=j.n_contacts.astype(np.int64), normal=j.normal, tangent=j.tangent)
        return x, data

    def write(self, time: float, result, locate=None) -> str:
        x, data = self.arrays(result, locate)
        return self.series.write_frame(time, x, [("vertex", np.arange(len(x)))], point_data=data)

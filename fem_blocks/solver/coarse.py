"""Two-level NLGS: a Galerkin coarse correction on the sticking contacts, per interface (2D, Signorini–Coulomb).

Gauss–Seidel is a smoother: it removes the local error of the reactions in a few sweeps but moves a long-wavelength
error (a whole wall settling, a force chain from the top to the floor) by about one contact per sweep. On the
contacts that are closed and sticking (r_N > 0, |r_T| < μ r_N) the contact problem is linear, u = W r + q = 0, so
the smooth part of the error is removed by a coarse correction (two-level method, as the rigid-body coarse space
of FETI or an aggregation multigrid):

    r_A <- r_A + P (Pᵀ W_AA P)⁻¹ Pᵀ (-(W r + q))_A,   then every corrected contact projected on its cone,

where A is the current sticking set and P maps 3 coarse unknowns per interface (the contacts between one pair of
bodies) to the contact impulses: a normal impulse linear along the interface (resultant and moment) and a
uniform tangential impulse,

    P_α = [[1, s_α, 0], [0, 0, c_α]],  s_α = ((x_α - x̄_g)·t_g) / ℓ_g,  c_α = t_α·t_g,

with x̄_g the mean position of the interface's sticking contacts, t_g the tangent of its first contact and ℓ_g the
RMS spread of the s (the moment column is dropped when the interface has fewer than two distinct sticking
points). W_c = Pᵀ W_AA P (3 × 3 blocks, one per pair of interfaces that share a body) is assembled in block-CSR
by a numba kernel from the Delassus block-CSR arrays and factored with SuperLU (MUMPS Cholesky from 3000 coarse
unknowns: 0.05 s against 0.15-0.2 s for the 10³-brick wall's 8 775).

The correction does not change the solution set: it is an extra move between sweeps, and the stopping test
(change or natural-map residual) is the plain NLGS one. The sticking set changes during a solve; the factor is
reused while the Delassus arrays are the same object and the sticking set differs from the factored one in at
most `refactor` (a fraction) of the contacts (the correction then acts on the contacts sticking in both), so
quasi-static steps near equilibrium reuse it. Safeguard: the correction is not
a descent step for the natural-map residual (it removes the smooth error and leaves local errors to the next
sweeps), so it is judged one chunk later: if ‖F‖ at the end of a chunk that started with a correction is larger
than before that correction, the corrections stop for the rest of that solve.

Measured (docs/benchmarks.md, "Two-level NLGS"): it carries a load down a long path at once (a column of 20 rigid
blocks: 20 sweeps instead of 116 280) and takes 2.6-3.1x fewer sweeps in the load transients of quasi-static
walls of 10³-10⁴ deformable bricks, but Gauss–Seidel's slow residual on deformable bricks with close contact
points is local (oscillating impulses along a joint, which 3 unknowns per joint cannot represent) and stays.
"""
from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from ..errors import InputError
from ..linalg import matvec_bcsr
from .nlgs import clip_to_cone_2d, natural_map_2d

M2 = 3  # coarse unknowns per interface in 2D
FACTOR_MUMPS = 3000  # coarse unknowns: from here on MUMPS Cholesky (linalg.Factor), below SuperLU


def interface_groups(body_a, body_b, nb: int | None = None):
    """Interface id per contact: one per unordered pair of bodies (ids 0..ng-1 in increasing order of the pair
    (min body, max body)). Returns (group (nc,) int64, ng)."""
    a = np.asarray(body_a, dtype=np.int64)
    b = np.asarray(body_b, dtype=np.int64)
    if a.shape != b.shape or a.ndim != 1:
        raise InputError(f"coarse: body_a and body_b must be two arrays of one body id per contact, got shapes "
                         f"{a.shape} and {b.shape}")
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    nb = int(hi.max()) + 1 if nb is None and hi.size else int(nb or 1)
    key = lo * nb + hi
    _, group = np.unique(key, return_inverse=True)
    group = group.astype(np.int64).ravel()
    return group, int(group.max()) + 1 if group.size else 0


class InterfaceCoarse:
    """Coarse space of the interfaces (2D): group id, position and tangent of each contact (see module docstring).

    `every`: a correction after every `every` sweeps. The factor of W_c is kept while the Delassus arrays are the
    same object and the sticking set differs from the factored one in at most `refactor` (a fraction) of the
    contacts. Counters: n_factor, n_correct, n_off (solves where the safeguard stopped the corrections)."""

    def __init__(self, group, point, t, every: int = 10, refactor: float = 0.02):
        group = np.ascontiguousarray(group, dtype=np.int64)
        point = np.asarray(point, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        nc = group.shape[0]
        if group.ndim != 1 or point.shape != (nc, 2) or t.shape != (nc, 2):
            raise InputError(f"coarse: expected group (nc,), point (nc, 2) and t (nc, 2), got {group.shape}, "
                             f"{point.shape}, {t.shape}")
        if nc and group.min() < 0:
            raise InputError("coarse: group ids must be >= 0")
        if int(every) != every or every < 1:
            raise InputError(f"coarse.every = {every!r}: expected an integer >= 1")
        if not (0.0 <= refactor <= 1.0):
            raise InputError(f"coarse.refactor = {refactor!r}: expected a fraction in [0, 1]")
        self.every = int(every)
        self.group = group
        self.ng = int(group.max()) + 1 if nc else 0
        first = np.full(self.ng, nc, dtype=np.int64)
        np.minimum.at(first, group, np.arange(nc))
        tg = t[first[group]] if nc else t
        self.s = np.einsum("ij,ij->i", point, tg)  # position along the interface's tangent
        self.c = np.einsum("ij,ij->i", t, tg)      # tangential direction relative to the interface's
        self.refactor = float(refactor)
        self._lu = None
        self._basis = None
        self._active_f = None
        self._W_f = None
        self._off = False
        self._last = None
        self.n_factor = 0   # factorisations of W_c
        self.n_correct = 0  # corrections applied
        self.n_off = 0      # solves where the safeguard stopped the corrections

    @classmethod
    def from_contacts(cls, cs, every: int = 10, refactor: float = 0.02):
        """From a 2D ContactSet (cand_body, ant_body, point, t)."""
        group, _ = interface_groups(cs.cand_body, cs.ant_body)
        return cls(group, cs.point, cs.t, every, refactor)

    # ------------------------------------------------------------------ coarse space on the sticking set
    def _basis_for(self, active):
        """P_α (nc, 2, 3) for the sticking set `active` (rows of other contacts zero)."""
        nc = self.group.shape[0]
        g = self.group[active]
        cnt = np.bincount(g, minlength=self.ng).astype(float)
        cnt1 = np.maximum(cnt, 1.0)
        mean = np.bincount(g, self.s[active], minlength=self.ng) / cnt1
        sc = self.s - mean[self.group]
        var = np.bincount(g, sc[active] ** 2, minlength=self.ng) / cnt1
        span = np.sqrt(var)
        ok = span > 1e-9 * (np.abs(mean) + 1.0)
        P = np.zeros((nc, 2, M2))
        P[active, 0, 0] = 1.0
        P[active, 0, 1] = np.where(ok[self.group], sc / np.where(ok, span, 1.0)[self.group], 0.0)[active]
        P[active, 1, 2] = self.c[active]
        return P

    def _factor(self, W, active):
        """Assemble and factor W_c = Pᵀ W_AA P for the sticking set `active`."""
        P = self._basis_for(active)
        order = np.argsort(self.group, kind="stable").astype(np.int64)
        gstart = np.zeros(self.ng + 1, dtype=np.int64)
        gstart[1:] = np.cumsum(np.bincount(self.group, minlength=self.ng))
        ip, ix, bl = _galerkin(W.indptr, W.indices, W.blocks, self.group, P, active, order, gstart, self.ng)
        Wc = sp.bsr_matrix((bl, ix, ip), shape=(M2 * self.ng, M2 * self.ng)).tocsr()
        d = Wc.diagonal()
        dead = ~(d > 0.0)  # interfaces without sticking contacts, moment of a single point: identity rows
        Wc = (Wc + sp.diags(np.where(dead, 1.0, 1e-12 * d))).tocsr()  # relative shift: W_c may be semi-definite
        self._release()
        if Wc.shape[0] >= FACTOR_MUMPS:
            from petsc4py import PETSc
            from ..linalg import Factor
            try:
                self._lu = Factor(Wc, "mumps")  # Cholesky (MUMPS): 0.05 s for 10³ bricks, SuperLU 0.15-0.2 s
            except PETSc.Error:
                self._lu = None
        if self._lu is None:
            self._lu = spla.splu(Wc.tocsc())
        self._basis = P
        self._active_f = active.copy()
        self._W_f = weakref.ref(W.blocks)  # the Delassus arrays factored (identity; not kept alive)
        self.n_factor += 1

    def _release(self):
        if self._lu is not None and hasattr(self._lu, "destroy"):
            self._lu.destroy()
        self._lu = None

    def start(self):
        """New solve: corrections enabled again (see `correct`)."""
        self._off = False
        self._last = None

    def correct(self, W, q, mu, r) -> bool:
        """One coarse correction of r (in place) on the current sticking set. The factor is reused while W is the
        same and the sticking set differs from the factored one in at most `refactor` of the contacts (then the
        correction acts on the contacts sticking in both). Safeguard: when the natural-map residual ‖F‖ at the end
        of a chunk of sweeps that started with a correction is larger than before that correction, corrections
        stop for the rest of the solve. Returns True if a correction was applied."""
        if self._off:
            return False
        active = _sticking(r, mu)
        u = np.empty_like(q)
        matvec_bcsr(W.indptr, W.indices, W.blocks, r, u)
        u += q
        f = natural_map_2d(r, u, mu)
        if self._last is not None and f > self._last:
            self._off = True
            self.n_off += 1
            return False
        if not active.any():
            return False
        if (self._lu is None or self._W_f() is not W.blocks
                or np.count_nonzero(active != self._active_f) > self.refactor * active.size):
            self._factor(W, active)
        act = active & self._active_f
        rc = _restrict(q, u, self.group, self._basis, act, self.ng)
        y = self._lu.solve(rc)
        _prolong(r, y, self.group, self._basis, act, mu)
        self._last = f
        self.n_correct += 1
        return True


# ----------------------------------------------------------------------------- compiled kernels
@njit(cache=True)
def _sticking(r, mu):
    """Closed and sticking contacts: r_N > 0 and |r_T| < μ r_N (strictly, relative margin 1e-9)."""
    n = mu.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for a in range(n):
        rn = r[2 * a]
        out[a] = rn > 0.0 and abs(r[2 * a + 1]) < mu[a] * rn * (1.0 - 1e-9)
    return out


@njit(cache=True)
def _galerkin(indptr, indices, blocks, group, P, active, order, gstart, ng):
    """W_c = Pᵀ W_AA P in block-CSR (M2 x M2 blocks): block (g, h) = Σ_{α∈g, β∈h, both sticking} P_αᵀ W_αβ P_β.
    Contacts listed per group by order[gstart[g]:gstart[g+1]]. Returns indptr, indices (sorted), blocks."""
    m = P.shape[2]
    d = blocks.shape[1]
    marker = -np.ones(ng, dtype=np.int64)
    counts = np.zeros(ng, dtype=np.int64)
    for g in range(ng):
        for e in range(gstart[g], gstart[g + 1]):
            a = order[e]
            if not active[a]:
                continue
            for k in range(indptr[a], indptr[a + 1]):
                b = indices[k]
                if active[b]:
                    h = group[b]
                    if marker[h] != g:
                        marker[h] = g
                        counts[g] += 1
    ip = np.zeros(ng + 1, dtype=np.int64)
    for g in range(ng):
        ip[g + 1] = ip[g] + counts[g]
    ix = np.empty(ip[ng], dtype=np.int64)
    bl = np.zeros((ip[ng], m, m))
    pos = -np.ones(ng, dtype=np.int64)
    marker[:] = -1
    WP = np.empty((d, m))
    for g in range(ng):
        nxt = ip[g]
        for e in range(gstart[g], gstart[g + 1]):
            a = order[e]
            if not active[a]:
                continue
            for k in range(indptr[a], indptr[a + 1]):
                b = indices[k]
                if not active[b]:
                    continue
                h = group[b]
                if marker[h] != g:
                    marker[h] = g
                    ix[nxt] = h
                    pos[h] = nxt
                    nxt += 1
                kk = pos[h]
                for i in range(d):
                    for j in range(m):
                        s = 0.0
                        for l in range(d):
                            s += blocks[k, i, l] * P[b, l, j]
                        WP[i, j] = s
                for i in range(m):
                    for j in range(m):
                        s = 0.0
                        for l in range(d):
                            s += P[a, l, i] * WP[l, j]
                        bl[kk, i, j] += s
        # sort the row's columns
        lo, hi = ip[g], ip[g + 1]
        perm = np.argsort(ix[lo:hi])
        ix[lo:hi] = ix[lo:hi][perm]
        bl[lo:hi] = bl[lo:hi][perm]
    return ip, ix, bl


@njit(cache=True)
def _restrict(q, u, group, P, active, ng):
    """Coarse right-hand side Pᵀ(-(u)_A) (ng * M2,) for u = W r + q."""
    m = P.shape[2]
    rc = np.zeros(ng * m)
    for a in range(group.shape[0]):
        if not active[a]:
            continue
        g = group[a]
        for i in range(m):
            rc[g * m + i] -= P[a, 0, i] * u[2 * a] + P[a, 1, i] * u[2 * a + 1]
    return rc


@njit(cache=True)
def _prolong(r, y, group, P, active, mu):
    """r_α += P_α y_g on the sticking set, then r_α projected on its cone: r_N >= 0, |r_T| <= μ r_N."""
    m = P.shape[2]
    for a in range(group.shape[0]):
        if not active[a]:
            continue
        g = group[a]
        d0 = 0.0
        d1 = 0.0
        for j in range(m):
            d0 += P[a, 0, j] * y[g * m + j]
            d1 += P[a, 1, j] * y[g * m + j]
        rn, rt = clip_to_cone_2d(r[2 * a] + d0, r[2 * a + 1] + d1, mu[a])
        r[2 * a] = rn
        r[2 * a + 1] = rt

"""Reader of FCLIB HDF5 frictional-contact problems (Acary, Brémond, Koziara, Pérignon 2014).

Local problems: u = W r + q. Global problems (M v = H r + f, u = Hᵀ v + w) are condensed:
W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w. Matrices are CSparse groups (nz >= 0 triplet, -1 CSC, -2 CSR).
Contact α occupies rows [d α, d α + d), normal first. `residual` is the README's natural-map residual.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from ..errors import InputError


@dataclass
class FrictionProblem:
    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    dim: int
    kind: str  # "local" or "global" (condensed)
    name: str
    guess_r: np.ndarray | None = None

    @property
    def n_contacts(self) -> int:
        return self.mu.size


def _matrix(g, path) -> sp.csr_matrix:
    try:
        m, n, nz = int(g["m"][0]), int(g["n"][0]), int(g["nz"][0])
        p = np.asarray(g["p"], dtype=np.int64)
        i = np.asarray(g["i"], dtype=np.int64)
        x = np.asarray(g["x"], dtype=np.float64)
    except KeyError as e:
        raise InputError(f"{path}: matrix {g.name}: missing dataset {e}") from None
    if nz >= 0:
        return sp.coo_matrix((x[:nz], (i[:nz], p[:nz])), shape=(m, n)).tocsr()
    if nz == -1:
        return sp.csc_matrix((x[:p[-1]], i[:p[-1]], p), shape=(m, n)).tocsr()
    if nz == -2:
        return sp.csr_matrix((x[:p[-1]], i[:p[-1]], p), shape=(m, n))
    raise InputError(f"{path}: matrix {g.name}: nz = {nz}: expected >= 0 (triplet), -1 (CSC) or -2 (CSR)")


@dataclass
class LocalProblem:
    """u = W r + q, Coulomb cone ‖r_T‖ <= mu r_N per contact (d = dim rows per contact, normal first)."""
    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    dim: int
    n_contacts: int
    name: str = ""
    guess_r: np.ndarray | None = None


@dataclass
class GlobalProblem:
    """M v = H r + f, u = Hᵀ v + w (FCLIB global problem)."""
    M: sp.csc_matrix
    H: sp.csc_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    dim: int
    name: str = ""
    guess_r: np.ndarray | None = None

    @property
    def n_contacts(self) -> int:
        return self.mu.size


def _open(path):
    import h5py
    if not os.path.isfile(path):
        raise InputError(f"{path}: FCLIB file not found")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        raise InputError(f"{path}: not an HDF5 file ({e})") from None


def _vec(g, key, path):
    if key not in g:
        raise InputError(f"{path}: missing dataset {g.name}/{key}")
    v = np.asarray(g[key], dtype=np.float64).ravel()
    if not np.all(np.isfinite(v)):
        raise InputError(f"{path}: {g.name}/{key}: expected finite values")
    return v


def _dim(g, path):
    if "spacedim" not in g:
        raise InputError(f"{path}: missing dataset {g.name}/spacedim")
    dim = int(np.asarray(g["spacedim"]).ravel()[0])
    if dim not in (2, 3):
        raise InputError(f"{path}: spacedim = {dim}: expected 2 or 3")
    return dim


def _guess(h, m):
    if "guesses/1/r" in h:
        g = np.asarray(h["guesses/1/r"], dtype=float).ravel()
        if g.size == m and np.all(np.isfinite(g)):
            return g
    return None


def _name(path):
    return os.path.splitext(os.path.basename(path))[0]


def read_local(path: str) -> LocalProblem:
    """The /fclib_local problem of an FCLIB file: W (CSR), q, mu, dim."""
    with _open(path) as h:
        if "fclib_local" not in h:
            raise InputError(f"{path}: expected a /fclib_local group (found {sorted(h.keys())})")
        g = h["fclib_local"]
        for key in ("W", "vectors"):
            if key not in g:
                raise InputError(f"{path}: missing group /fclib_local/{key}")
        dim = _dim(g, path)
        W = _matrix(g["W"], path)
        q = _vec(g["vectors"], "q", path)
        mu = _vec(g["vectors"], "mu", path)
        guess = _guess(h, q.size)
    if W.shape != (q.size, q.size) or q.size != dim * mu.size:
        raise InputError(f"{path}: inconsistent sizes W {W.shape}, q {q.size}, mu {mu.size} (dim {dim})")
    if np.any(mu < 0):
        raise InputError(f"{path}: vectors/mu: expected friction coefficients >= 0")
    return LocalProblem(W.tocsr(), q, mu, dim, mu.size, _name(path), guess)


def read_global(path: str) -> GlobalProblem:
    """The /fclib_global problem of an FCLIB file: M, H, f, w, mu, dim."""
    with _open(path) as h:
        if "fclib_global" not in h:
            raise InputError(f"{path}: expected a /fclib_global group (found {sorted(h.keys())})")
        g = h["fclib_global"]
        for key in ("M", "H", "vectors"):
            if key not in g:
                raise InputError(f"{path}: missing group /fclib_global/{key}")
        dim = _dim(g, path)
        M = _matrix(g["M"], path).tocsc()
        H = _matrix(g["H"], path).tocsc()
        f = _vec(g["vectors"], "f", path)
        w = _vec(g["vectors"], "w", path)
        mu = _vec(g["vectors"], "mu", path)
        guess = _guess(h, w.size)
    n, m = H.shape
    if M.shape != (n, n) or f.size != n or w.size != m or m != dim * mu.size:
        raise InputError(f"{path}: inconsistent sizes M {M.shape}, H {H.shape}, f {f.size}, w {w.size}, "
                         f"mu {mu.size} (dim {dim})")
    if np.any(mu < 0):
        raise InputError(f"{path}: vectors/mu: expected friction coefficients >= 0")
    return GlobalProblem(M, H, f, w, mu, dim, _name(path), guess)


def condense(g: GlobalProblem, dense_limit: int = 2000) -> LocalProblem:
    """Local problem of a global one: W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w (M v = H r + f, u = Hᵀ v + w).
    Dense solve for n <= dense_limit, sparse LU (SuperLU) otherwise, M⁻¹ H in column chunks."""
    n, m = g.H.shape
    if n <= dense_limit:
        Md = g.M.toarray()
        try:
            X = np.linalg.solve(Md, np.column_stack([g.H.toarray(), g.f]))
        except np.linalg.LinAlgError:
            raise InputError(f"{g.name}: M is singular: the global problem cannot be condensed") from None
        MiH = sp.csc_matrix(X[:, :m])
        Mif = X[:, m]
    else:
        try:
            lu = sla.splu(g.M.tocsc())
        except RuntimeError as e:
            raise InputError(f"{g.name}: M is singular: the global problem cannot be condensed ({e})") from None
        cols = []
        Hc = g.H.tocsc()
        for j0 in range(0, m, 256):
            X = lu.solve(Hc[:, j0:j0 + 256].toarray())
            X[np.abs(X) < 1e-300] = 0.0
            cols.append(sp.csc_matrix(X))
        MiH = sp.hstack(cols).tocsc() if cols else sp.csc_matrix((n, 0))
        Mif = lu.solve(g.f)
    W = sp.csr_matrix(g.H.T @ MiH)
    W.eliminate_zeros()
    q = g.H.T @ Mif + g.w
    return LocalProblem(W, np.asarray(q, dtype=float).ravel(), g.mu.copy(), g.dim, g.mu.size, g.name, g.guess_r)


@dataclass
class Residual:
    abs: float      # ‖F‖₂
    rel_q: float    # ‖F‖/‖q‖ (published comparisons, tolerance 1e-8)
    rel_max: float  # ‖F‖/max(‖q‖, ‖r‖, ‖u‖) (Siconos' convention)


def residual(W, q, mu, r, dim: int) -> Residual:
    """FCLIB natural-map residual (ρ = 1) per the data README:
    F_α = r_α - P_K(r_α - (u_α + [mu_α ‖u_T,α‖, 0(, 0)])), u = W r + q, K the cone ‖r_T‖ <= mu r_N.
    Vectorised numpy, independent of the solver's compiled version."""
    if dim not in (2, 3):
        raise InputError(f"dim = {dim!r}: expected 2 or 3")
    q = np.asarray(q, dtype=float).ravel()
    r = np.asarray(r, dtype=float).ravel()
    if r.size != q.size or q.size % dim:
        raise InputError(f"r: expected {q.size} entries (q has {q.size}, dim {dim}), got {r.size}")
    nc = q.size // dim
    mu = np.broadcast_to(np.asarray(mu, dtype=float).ravel(), (nc,))
    u = np.asarray(W @ r).ravel() + q
    R = r.reshape(nc, dim)
    U = u.reshape(nc, dim)
    ut = np.linalg.norm(U[:, 1:], axis=1)
    X = R - U
    X[:, 0] -= mu * ut
    xn = X[:, 0]
    xt = np.linalg.norm(X[:, 1:], axis=1)
    P = np.zeros_like(X)
    inside = xt <= mu * xn
    P[inside] = X[inside]
    side = ~inside & ~(mu * xt <= -xn)
    c = (xn[side] + mu[side] * xt[side]) / (1.0 + mu[side] ** 2)
    P[side, 0] = c
    P[side, 1:] = (mu[side] * c / xt[side])[:, None] * X[side, 1:]
    F = np.linalg.norm(R - P)
    nq = np.linalg.norm(q)
    den = max(nq, np.linalg.norm(r), np.linalg.norm(u))
    return Residual(float(F), float(F / nq) if nq > 0 else float(F), float(F / den) if den > 0 else float(F))


def read(path: str) -> FrictionProblem:
    """W, q, mu (and the warm-start guess if any) of a local or global FCLIB file (global ones condensed)."""
    with _open(path) as h:
        keys = sorted(h.keys())
    if "fclib_local" in keys:
        p, kind = read_local(path), "local"
    elif "fclib_global" in keys:
        p, kind = condense(read_global(path)), "global"
    else:
        raise InputError(f"{path}: expected a /fclib_local or /fclib_global group (found {keys})")
    return FrictionProblem(p.W, p.q, p.mu, p.dim, kind, p.name, p.guess_r)

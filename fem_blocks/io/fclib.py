"""Reader of FCLIB HDF5 frictional-contact problems (Acary, Brémond, Koziara, Pérignon 2014).

Local problems: u = W r + q. Global problems (M v = H r + f, u = Hᵀ v + w) are condensed:
W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w. Matrices are CSparse groups (nz >= 0 triplet, -1 CSC, -2 CSR).
Contact α occupies rows [d α, d α + d), normal first.
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


def read(path: str) -> FrictionProblem:
    """W, q, mu (and the warm-start guess if any) of a local or global FCLIB file."""
    import h5py
    if not os.path.isfile(path):
        raise InputError(f"{path}: FCLIB file not found")
    try:
        h = h5py.File(path, "r")
    except OSError as e:
        raise InputError(f"{path}: not an HDF5 file ({e})") from None
    name = os.path.splitext(os.path.basename(path))[0]
    with h:
        if "fclib_local" in h:
            g = h["fclib_local"]
            dim = int(g["spacedim"][0])
            W = _matrix(g["W"], path)
            q = np.asarray(g["vectors/q"], dtype=float)
            mu = np.asarray(g["vectors/mu"], dtype=float)
            kind = "local"
        elif "fclib_global" in h:
            g = h["fclib_global"]
            dim = int(g["spacedim"][0])
            M = _matrix(g["M"], path).tocsc()
            H = _matrix(g["H"], path).tocsc()
            f = np.asarray(g["vectors/f"], dtype=float)
            w = np.asarray(g["vectors/w"], dtype=float)
            mu = np.asarray(g["vectors/mu"], dtype=float)
            lu = sla.splu(M)
            MiH = lu.solve(H.toarray()) if H.shape[1] <= 20000 else None
            W = sp.csr_matrix(H.T @ MiH)
            W.data[np.abs(W.data) < 1e-300] = 0.0
            W.eliminate_zeros()
            q = H.T @ lu.solve(f) + w
            kind = "global"
        else:
            raise InputError(f"{path}: expected a /fclib_local or /fclib_global group "
                             f"(found {sorted(h.keys())})")
        guess = None
        if "guesses/1/r" in h:
            guess = np.asarray(h["guesses/1/r"], dtype=float)
    if dim not in (2, 3):
        raise InputError(f"{path}: spacedim = {dim}: expected 2 or 3")
    if W.shape != (q.size, q.size) or q.size != dim * mu.size:
        raise InputError(f"{path}: inconsistent sizes W {W.shape}, q {q.size}, mu {mu.size} (dim {dim})")
    return FrictionProblem(W.tocsr(), q, mu, dim, kind, name, guess if guess is not None and guess.size == q.size
                           else None)

"""Sparse LU for the global Newton solver: SuperLU vs MUMPS (linalg.lu_solve) on the Delassus pattern of the
thesis dome (demos/dome.py, full resolution: 8 112 contacts, 3×3 blocks, ~110 blocks per row).

The matrix is W + ε I (ε = 1e-6 mean diag, Newton's regularised stick Jacobian J = E (W + ε I) up to the row
scaling E) of the first time step, and its leading sub-blocks of n unknowns (n = 1 000 … all). Prints one markdown
row per size and method: factorisation + solve time [s] and the relative residual ‖J x − b‖/‖b‖.

Usage: .venv/bin/python bench/bench_lu.py [--quick]   (--quick: the quick dome, 664 contacts)
"""
import os
import sys
import time

import numpy as np
import scipy.sparse as sp

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "demos"))
import dome  # noqa: E402
from fem_blocks.linalg import lu_solve  # noqa: E402


def dome_delassus(quick: bool):
    cfg = dict(dome.CONFIG[quick])
    cfg["max_sweeps"] = 1  # only the operator is wanted: one sweep of the first step
    _lay, _blocks, _piers, sim, cst = dome.build("dry", cfg)
    sim.step()
    W = cst.Wdel
    n = W.n * W.dim
    A = sp.bsr_matrix((W.blocks, W.indices, W.indptr), shape=(n, n)).tocsr()
    d = A.diagonal()
    return (A + 1e-6 * float(np.mean(np.abs(d))) * sp.eye(n)).tocsr()


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    A = dome_delassus(quick)
    N = A.shape[0]
    print(f"dome{' (quick)' if quick else ''}: {N} unknowns, {A.nnz} nonzeros ({A.nnz / N:.0f} per row)\n")
    print("| unknowns | nonzeros | SuperLU [s] | MUMPS [s] | residual SuperLU | residual MUMPS |")
    print("|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    for n in [m for m in (1000, 2000, 4000, 8000, 16000) if m < N] + [N]:
        B = A[:n, :n].tocsr()
        b = rng.random(n)
        out = {}
        for method in ("superlu", "mumps"):
            t = time.perf_counter()
            x = lu_solve(B, b, method)
            out[method] = (time.perf_counter() - t, np.linalg.norm(B @ x - b) / np.linalg.norm(b))
        print(f"| {n} | {B.nnz} | {out['superlu'][0]:.2f} | {out['mumps'][0]:.2f} | {out['superlu'][1]:.1e} | "
              f"{out['mumps'][1]:.1e} |", flush=True)

"""The contact problem the solvers take and the result they return (data only; `solver.solve` in driver.py).

Problem (FCLIB / Siconos convention, contact α occupies entries [dα, dα+d) = (normal, tangent[, tangent 2])):

    u = W r + q,   r_N >= 0, u_N >= 0, r_N u_N = 0,   |r_T| <= μ r_N, r_T = -μ r_N u_T/|u_T| when sliding,

W a BlockCSR (linalg.py) of d x d blocks, d = 2 or 3. With interface laws (`laws`, laws.py) contact α carries an
adhesive impulse h A r_adh(u) of its jump u = u_eff + hθ v (v the velocity part of u), and the solvers work on the
transformed impulse P̃ = P + h A r_adh(u) (docs/laws.md); the law codes, parameters and committed states are data of
the problem, the trial internal variables part of the result.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..linalg import BlockCSR, to_block_csr


@dataclass
class InterfaceLaws:
    """Interface-law data of a contact problem (per contact α, nc contacts, d = dim)."""

    law: np.ndarray     # (nc,) law codes (laws.py; 0: Coulomb, with an optional crushing cap)
    par: np.ndarray     # (nc, NPAR) law parameters per unit area (laws.law_parameters)
    state: np.ndarray   # committed law states: (nc, NSTATE) in 2D, (nc, NSTATE3) in 3D (laws.initial_state)
    ueff: np.ndarray    # (nc, d) u_eff = u_i + h(1-θ) v_i - hθ s e_N: the jump is u = u_eff + hθ v
    area: np.ndarray    # (nc,) tributary area A_α [m² in 3D, m (per unit thickness) in 2D]
    h: float            # time step [s]
    theta: float        # θ of the θ-method, 0 < θ <= 1


@dataclass
class ContactProblem:
    """u = W r + q with Signorini–Coulomb (laws = None) or interface laws per contact.

    W: a BlockCSR, or a dense / scipy matrix of size dim * nc (converted by linalg.to_block_csr); q (dim * nc,);
    mu: a scalar or nc friction coefficients >= 0; dim: 2 or 3 (None: from W's blocks, else 2). own_rows: q, mu and
    the laws' arrays hold the rows of this rank's own contacts only, and so will the result (a problem shared by
    N > 1 MPI ranks in colour order, W the rows of those contacts: contact/step.py); else those of every contact."""

    W: BlockCSR
    q: np.ndarray
    mu: np.ndarray | float
    dim: int | None = None
    laws: InterfaceLaws | None = None
    own_rows: bool = False

    def __post_init__(self):
        if self.dim is not None and self.dim not in (2, 3):
            raise InputError(f"dim = {self.dim!r}: expected 2 or 3")
        if isinstance(self.W, BlockCSR):
            if self.dim is not None and self.W.dim != self.dim:
                raise InputError(f"dim = {self.dim}: W is a BlockCSR of {self.W.dim}x{self.W.dim} blocks")
        else:
            self.W = to_block_csr(self.W, self.dim or 2)
        self.dim = self.W.dim


@dataclass
class SolverResult:
    r: np.ndarray
    u: np.ndarray
    sweeps: int
    converged: bool
    change: float    # ‖Δr‖/‖r‖ over the last sweep
    residual: float  # FCLIB ‖F‖ / ‖q‖ recomputed from the returned r
    residual_abs: float  # ‖F‖
    message: str
    local_cases: np.ndarray | None = None  # 3D: counts of local cases (failed, open, stick, Newton, search, proj.)
    solver: str = "NLGS"  # what produced r: "NLGS", "Newton", "Newton + NLGS fallback", "NLGS + Newton fallback"
    trial: np.ndarray | None = None  # interface laws: trial internal variables (nc,) at r (to commit), else None

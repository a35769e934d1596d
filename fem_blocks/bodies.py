"""Bodies: deformable blocks (instances of shared block types) and 2D rigid bodies.

A `BlockType` is a prototype: one gmsh mesh, one material, its stiffness K, mass M and damping
C = a M + b K, assembled once. For a time step h and scheme parameter theta it provides (cached)
the iteration matrix (docs/method.md §2)

    Mhat = M + h theta C + h^2 theta^2 K,   W = Mhat^-1

factorized once with PETSc, and the dense boundary Delassus block W_bb = B W B^T over its boundary
dofs. Every `DeformableBody` placed by translation and rotation of a type shares these objects:
displacements and velocities of an instance are stored in the *type frame*; the global
displacement is R q, so Mhat_rot^-1 = R Mhat^-1 R^T never needs a new factorization.

A `RigidBody` (2D) has dofs (vx, vy, omega) about its centre of mass, mass diag(m, m, I); each dof
is free (applied force, constant or piecewise linear in time) or driven (prescribed velocity or
displacement history); the reaction on a driven dof is an output.

3D: `BlockType3D` (same prototype on a BlockMesh3D, dofs 3*node + c), `DeformableBody3D` (instance placed by a
3x3 rotation and a translation), `RigidBody3D` (dofs (v, omega), mass and inertia tensor from the geometry).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp

from .errors import InputError, check_range
from .geometry import rotation3d  # noqa: F401 (re-exported; rotation of body frames)
from .records import baseline_linear, record_velocity, record_velocity_knots  # noqa: F401 (re-exported)


# ----------------------------------------------------------------------------- load histories
class History:
    """Piecewise-linear function of time, constant beyond its ends: value(t)."""

    def __init__(self, times: Sequence[float], values: Sequence[float], name: str = "history"):
        t = np.asarray(times, dtype=float).ravel()
        v = np.asarray(values, dtype=float).ravel()
        if t.size == 0 or t.size != v.size:
            raise InputError(f"{name}: times and values must be non-empty lists of equal length "
                             f"(got {t.size} and {v.size})")
        if np.any(np.diff(t) <= 0):
            raise InputError(f"{name}.times: expected strictly increasing times")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise InputError(f"{name}: expected finite times and values")
        self.times, self.values, self.name = t, v, name

    @classmethod
    def constant(cls, value: float, name: str = "history") -> "History":
        return cls([0.0], [value], name)

    @classmethod
    def ramp(cls, t0: float, t1: float, v0: float, v1: float, name: str = "ramp") -> "History":
        return cls([t0, t1], [v0, v1], name)

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))


def as_history(value, name: str) -> History:
    """A History from a number, a {times, values} dict (case.py adds "file", the CSV file it came from, for the
    case fingerprint) or a History."""
    if isinstance(value, History):
        return value
    if isinstance(value, (int, float, np.floating, np.integer)):
        return History.constant(float(value), name)
    if isinstance(value, dict) and {"times", "values"} <= set(value) <= {"times", "values", "file"}:
        return History(value["times"], value["values"], name)
    raise InputError(f"{name}: expected a number or {{times = [...], values = [...]}}, got {value!r}")


# ----------------------------------------------------------------------------- material
@dataclass(frozen=True)
class Material:
    """Linear elastic isotropic material, small strain; Rayleigh damping C = alpha M + beta K."""

    E: float
    nu: float
    rho: float
    thickness: float = 1.0
    plane: str = "stress"
    alpha: float = 0.0
    beta: float = 0.0
    name: str = "material"

    def __post_init__(self):
        n = self.name
        check_range(f"{n}.E", self.E, 0.0, lo_open=True, expected="E > 0 [Pa]")
        check_range(f"{n}.nu", self.nu, -1.0, 0.5, lo_open=True, hi_open=True, expected="-1 < nu < 0.5")
        check_range(f"{n}.rho", self.rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
        check_range(f"{n}.thickness", self.thickness, 0.0, lo_open=True, expected="thickness > 0 [m]")
        check_range(f"{n}.alpha", self.alpha, 0.0, expected="Rayleigh alpha >= 0 [1/s]")
        check_range(f"{n}.beta", self.beta, 0.0, expected="Rayleigh beta >= 0 [s]")
        if self.plane not in ("stress", "strain"):
            raise InputError(f"{n}.plane = {self.plane!r}: expected 'stress' or 'strain'")


def check_step(h: float, theta: float):
    check_range("h", h, 0.0, lo_open=True, expected="time step h > 0 [s]")
    check_range("theta", theta, 0.5, 1.0, expected="0.5 <= theta <= 1")


def rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Inverse of rotation3d: the rotation vector w (|w| <= π) with exp([w]x) = R (R a 3x3 rotation)."""
    R = np.asarray(R, dtype=float)
    a = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # 2 sin(th) k
    c = np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0)
    s = 0.5 * np.linalg.norm(a)
    th = np.arctan2(s, c)
    if s > 1e-6:
        return th / (2.0 * s) * a
    if c > 0:  # th small: w = a/2 (1 + th²/6)
        return 0.5 * a * (1.0 + th * th / 6.0)
    # th near π: R + 1 = 2 k kᵀ + O(π - th); the largest column gives k
    B = 0.5 * (R + np.eye(3))
    j = int(np.argmax(np.diag(B)))
    k = B[:, j] / np.sqrt(max(B[j, j], 1e-300))
    if np.dot(k, a) < 0:
        k = -k
    return th * k / np.linalg.norm(k)


_EPS3 = np.zeros((3, 3, 3))  # Levi-Civita symbol
_EPS3[0, 1, 2] = _EPS3[1, 2, 0] = _EPS3[2, 0, 1] = 1.0
_EPS3[0, 2, 1] = _EPS3[2, 1, 0] = _EPS3[1, 0, 2] = -1.0


@dataclass(frozen=True)
class MassProperties:
    """Rigid-body quantities of a block type from its nodal masses m_a (diagonal of the lumped M, or row sums of
    the consistent M; M = M_s ⊗ I_d): total mass, centre X̄ = Σ m_a X_a / m, r0 = X - X̄ (n, d), the second moment
    I0 (2D Σ m_a |r0_a|², 3D Σ m_a (|r0_a|² 1 - r0_a r0_aᵀ) and its inverse), and the gravity columns G (ndof, d):
    the nodal load of a unit body acceleration e_c, G[:, c] = M (1 ⊗ e_c), so that gravity_load(g) = G g."""

    m: np.ndarray
    mass: float
    Xbar: np.ndarray
    r0: np.ndarray
    I0: object
    I0inv: object
    G: np.ndarray


# ----------------------------------------------------------------------------- block types
class StepOperator:
    """Factor of Mhat = M + h theta C + h^2 theta^2 K with clamped dofs eliminated.

    Clamped dofs (zero velocity) get an identity row and column, so `solve(b)` returns x with
    x_c = b_c and x_f = Mhat_ff^-1 b_f; callers set b_c = 0.
    static=True: Mhat = h^2 theta^2 K (no inertia, no damping; the static step, dynamics.py), which needs clamps
    that fix every rigid motion of the block (`BlockType.clamps_fix_rigid_modes`).
    """

    def __init__(self, block_type: "BlockType", h: float, theta: float, clamped: np.ndarray, static: bool = False):
        from .linalg import Factor
        self.h, self.theta, self.static = h, theta, bool(static)
        self.clamped = clamped  # bool (ndof,)
        bt = block_type
        Mhat = ((h * theta) ** 2 * bt.K).tocsr() if static else \
            (bt.M + (h * theta) * bt.C + (h * theta) ** 2 * bt.K).tocsr()
        keep = sp.diags((~clamped).astype(float))
        Mmod = (keep @ Mhat @ keep + sp.diags(clamped.astype(float))).tocsr()
        Mmod.eliminate_zeros()
        self.factor = Factor(Mmod)
        self.bdofs = bt.boundary_dofs
        self._W_bb = None

    def solve(self, B: np.ndarray) -> np.ndarray:
        return self.factor.solve(B)

    @property
    def W_bb(self) -> np.ndarray:
        """Dense boundary Delassus block B Mhat^-1 B^T (type frame), rows/cols = boundary dofs."""
        if self._W_bb is None:
            nd = self.clamped.size
            E = np.zeros((nd, self.bdofs.size))
            E[self.bdofs, np.arange(self.bdofs.size)] = 1.0
            E[self.clamped, :] = 0.0
            X = self.solve(E)
            X[self.clamped, :] = 0.0
            W = X[self.bdofs, :]
            self._W_bb = np.ascontiguousarray(0.5 * (W + W.T))
        return self._W_bb


class BlockType:
    """Prototype of identical deformable blocks: mesh + material -> K, M, C (assembled once)."""

    def __init__(self, mesh, material: Material, mass: str = "lumped", name: str = "block"):
        from . import fem_backend, meshing
        if mass not in ("lumped", "consistent"):
            raise InputError(f"{name}.mass = {mass!r}: expected 'lumped' or 'consistent'")
        meshing.validate(mesh, source=name)
        m = material
        self._setup(mesh, material, mass, name, fem_backend.assemble_operators(mesh, m.E, m.nu, m.rho, m.thickness,
                                                                               m.plane), 2)

    def _setup(self, mesh, material: Material, mass: str, name: str, ops, d: int):
        """Store K, M (lumped or consistent), C = alpha M + beta K from the FE operators `ops`, and the node and
        boundary numbering with d dofs per node (dof d*node + c)."""
        self.mesh, self.material, self.mass_kind, self.name = mesh, material, mass, name
        m = material
        self.K = ops.K.tocsr()
        self.M = (ops.M_lumped if mass == "lumped" else ops.M_consistent).tocsr()
        self.C = (m.alpha * self.M + m.beta * self.K).tocsr()
        self.n_nodes = mesh.points.shape[0]
        self.ndof = d * self.n_nodes
        self.boundary_nodes = np.asarray(mesh.boundary_nodes(), dtype=np.int64)
        self.bnode_index = -np.ones(self.n_nodes, dtype=np.int64)
        self.bnode_index[self.boundary_nodes] = np.arange(self.boundary_nodes.size)
        self.boundary_dofs = (d * self.boundary_nodes[:, None] + np.arange(d)[None, :]).ravel()
        self._ops: dict = {}
        self._stress = None

    def step_operator(self, h: float, theta: float, clamped: np.ndarray, static: bool = False) -> StepOperator:
        """Shared (cached) step operator for (h, theta, clamped dof set, static)."""
        key = (float(h), float(theta), clamped.tobytes()) + (("static",) if static else ())
        op = self._ops.get(key)
        if op is None:
            op = self._ops[key] = StepOperator(self, h, theta, clamped, static)
        return op

    def clamps_fix_rigid_modes(self, clamped: np.ndarray) -> bool:
        """True if no rigid motion of the block (2D: 2 translations, 1 rotation; 3D: 3 + 3) leaves every clamped
        dof at rest, i.e. K restricted to the free dofs is non-singular (the mesh is connected: `validate`)."""
        X = self.mesh.points - self.mesh.points.mean(axis=0)
        d = X.shape[1]
        n = X.shape[0]
        modes = []
        for c in range(d):
            m = np.zeros((n, d))
            m[:, c] = 1.0
            modes.append(m)
        axes = [np.array([0.0, 0.0, 1.0])] if d == 2 else list(np.eye(3))
        for a in axes:
            Xp = np.column_stack([X, np.zeros(n)]) if d == 2 else X
            modes.append(np.cross(a, Xp)[:, :d])
        P = np.column_stack([m.ravel() for m in modes])[clamped]  # dof d*i + c
        scale = max(1.0, float(np.abs(X).max()))
        return P.shape[0] >= P.shape[1] and np.linalg.matrix_rank(P / scale, tol=1e-10) == P.shape[1]

    def rotation_weights(self) -> np.ndarray:
        """A (k, ndof), θ_q = A q: the best-fit small rotation of q (_PlacedBlock._small_rotation, body frame) as one
        linear map, so that all instances of a type are done by one product A Q (runner._RotationWatch): 2D
        (k = 1) θ = Σ m_a r_a × q_a / Σ m_a |r_a|², 3D (k = 3) θ = I0⁻¹ Σ m_a r_a × q_a (mass_properties).
        Built once."""
        A = getattr(self, "_rot_weights", None)
        if A is None:
            mp = self.mass_properties
            r, d = mp.r0, mp.r0.shape[1]
            if d == 2:
                A = (np.column_stack([-mp.m * r[:, 1], mp.m * r[:, 0]]).ravel() / mp.I0)[None, :]
            else:  # (r × q)_i = ε_ijk r_j q_k: the block of node a maps q_a to m_a [r_a]x q_a
                cross = np.einsum("ijk,aj->aik", _EPS3, r)  # (n, 3, 3)
                A = mp.I0inv @ (mp.m[:, None, None] * cross).transpose(1, 0, 2).reshape(3, -1)
            self._rot_weights = A
        return A

    @property
    def mass_properties(self) -> MassProperties:
        """MassProperties of the type (computed once)."""
        mp = getattr(self, "_mass_props", None)
        if mp is None:
            X = self.mesh.points
            n, d = X.shape
            G = np.column_stack([self.M @ np.tile(np.eye(d)[c], n) for c in range(d)])
            m = G[0::d, 0].copy()  # row sums of the x rows = nodal masses
            mass = float(m.sum())
            Xbar = m @ X / mass
            r0 = X - Xbar
            if d == 2:
                I0 = float(np.dot(m, np.einsum("ni,ni->n", r0, r0)))
                I0inv = 1.0 / I0
            else:
                I0 = np.einsum("n,ni,ni->", m, r0, r0) * np.eye(3) - np.einsum("n,ni,nj->ij", m, r0, r0)
                I0inv = np.linalg.inv(I0)
            mp = self._mass_props = MassProperties(m, mass, Xbar, r0, I0, I0inv, G)
        return mp

    @property
    def stress_operator(self) -> sp.csr_matrix:
        """S: cell-centroid stresses σ = D B q in the type frame from q (built once), Voigt order: 2D (3 nc x 2n)
        (sxx, syy, sxy) in the material's plane stress or strain; 3D (6 nc x 3n) (sxx, syy, szz, syz, sxz, sxy)."""
        if self._stress is None:
            from . import fem_backend
            m = self.material
            S = (fem_backend.stress_operator(self.mesh, m.E, m.nu, m.plane) if self.mesh.points.shape[1] == 2
                 else fem_backend.stress_operator_3d(self.mesh, m.E, m.nu))
            self._stress = S.tocsr()
        return self._stress

    def gravity_load(self, g_type: np.ndarray) -> np.ndarray:
        """Nodal body force of gravity, F = M (1 ⊗ g): exact for consistent and row-sum lumped M."""
        return self.M @ np.tile(np.asarray(g_type, dtype=float), self.n_nodes)

    def traction_load(self, tag: str, traction: np.ndarray) -> np.ndarray:
        """Nodal forces of a uniform traction (type frame, N/m^2) on the edges tagged `tag`:
        F_i = sum over edges e of t |e| thickness / 2 at each end node (exact for linear edges)."""
        mesh = self.mesh
        if tag not in mesh.tag_names:
            raise InputError(f"{self.name}: boundary tag {tag!r} not found; "
                             f"expected one of {sorted(mesh.tag_names)}")
        edges = mesh.boundary_edges[mesh.edge_tags == mesh.tag_names[tag]]
        L = np.linalg.norm(mesh.points[edges[:, 1]] - mesh.points[edges[:, 0]], axis=1)
        f = np.zeros(self.ndof)
        w = 0.5 * L * self.material.thickness
        for k in range(2):
            np.add.at(f, 2 * edges[:, k], w * traction[0])
            np.add.at(f, 2 * edges[:, k] + 1, w * traction[1])
        return f


# ----------------------------------------------------------------------------- instances
@dataclass
class Clamp:
    """Zero-velocity condition on nodes selected by a global box (xmin, xmax, ymin, ymax) or a tag."""

    box: tuple | None = None
    tag: str | None = None
    components: str = "xy"


@dataclass
class Traction:
    """Uniform traction (global frame, Pa) on a tagged boundary part, scaled by a history."""

    tag: str
    value: tuple
    history: History | float = 1.0


class _PlacedBlock:
    """What DeformableBody and DeformableBody3D share: an instance of a block type (`type`, mesh points X in the
    type frame) placed by a rotation R then a translation c = `position` (x = R X + c), with displacements q
    and velocities u in the type frame (gdim dofs per node) and tractions on tagged boundaries."""

    gdim = 2

    def _init_tractions(self, tractions):
        self.tractions = list(tractions)
        for tr in self.tractions:
            tr.history = as_history(tr.history, f"{self.name}.traction.history")
            if tr.tag not in self.type.mesh.tag_names:
                raise InputError(f"{self.name}.traction.tag = {tr.tag!r}: expected one of "
                                 f"{sorted(self.type.mesh.tag_names)}")
            self._check_traction(tr)

    def _check_traction(self, tr):
        """Dimension-specific check of a traction's value (none in 2D)."""

    def _init_frame(self):
        """The placement (R0, position0) and the current frame (R, position): equal, and fixed, until a
        co-rotational Simulation attaches a frame (dynamics.Simulation: views into its group arrays)."""
        self.R0 = self.R.copy()
        self.position0 = self.position.copy()
        self.framed = False  # True: R, position follow the block (co-rotational kinematics, docs/method.md §7)
        self._phi = None     # 2D: (1,) view of the unwrapped frame angle since placement [rad]

    def attach_frame(self, R, position, phi=None):
        """Co-rotational kinematics: R (d, d) and position (d,) become views owned by the time stepper (and, 2D,
        phi (1,) the unwrapped angle of the frame since placement)."""
        self.R, self.position, self._phi, self.framed = R, position, phi, True

    def detach_frame(self):
        """Back to copies of the current frame (the time stepper rebuilds its arrays: Simulation.set_step)."""
        if self.framed:
            self.R, self.position = self.R.copy(), self.position.copy()
            self._phi = None if self._phi is None else self._phi.copy()

    @property
    def reference_points(self) -> np.ndarray:
        """Global node positions of the undeformed instance at its placement: x = R0 X + c0."""
        return self.type.mesh.points @ self.R0.T + self.position0

    def current_points(self) -> np.ndarray:
        """x = R (X + q) + position (current frame)."""
        return (self.type.mesh.points + self.q.reshape(-1, self.gdim)) @ self.R.T + self.position

    def displacement_global(self) -> np.ndarray:
        """Current - reference node positions (global); without a frame R q (R = R0)."""
        if self.framed:
            return self.current_points() - self.reference_points
        return self.q.reshape(-1, self.gdim) @ self.R.T

    def velocity_global(self) -> np.ndarray:
        """R u: u holds the absolute nodal velocities in frame components."""
        return self.u.reshape(-1, self.gdim) @ self.R.T

    def _small_rotation(self) -> np.ndarray:
        """Best-fit small rotation of q about the mass centre, in the body frame: 2D (1,) Σ m r × q / Σ m |r|²,
        3D I⁻¹ Σ m r × q (r = X - X̄, lumped nodal masses m_a: BlockType.mass_properties)."""
        mp = self.type.mass_properties
        Q = self.q.reshape(-1, self.gdim)
        if self.gdim == 2:
            r = mp.r0
            return np.array([np.dot(mp.m, r[:, 0] * Q[:, 1] - r[:, 1] * Q[:, 0]) / mp.I0])
        return mp.I0inv @ (mp.m @ np.cross(mp.r0, Q))

    def rotation(self):
        """Rotation of the block since its placement (global): 2D the angle [rad] (counter-clockwise, unwrapped:
        the frame angle + the best-fit small rotation of q); 3D the rotation vector (3,) of R exp([θ_q]x) R0ᵀ (θ_q
        the best-fit small rotation of q, body frame; |rotation| <= π), without a frame R0 θ_q."""
        th = self._small_rotation()
        if self.gdim == 2:
            return (0.0 if self._phi is None else float(self._phi[0])) + float(th[0])
        if not self.framed:
            return self.R0 @ th  # linear kinematics: the best-fit small rotation, global
        return rotation_vector(self.R @ rotation3d(th) @ self.R0.T)

    def external_load(self, t: float, g: np.ndarray) -> np.ndarray:
        """F(t) in the type frame: gravity + tractions."""
        f = self.type.gravity_load(self.R.T @ g) if np.any(g) else np.zeros(self.type.ndof)
        for tr in self.tractions:
            f = f + tr.history(t) * self.type.traction_load(tr.tag, self.R.T @ np.asarray(tr.value, float))
        return f


class DeformableBody(_PlacedBlock):
    """Instance of a BlockType placed by rotation `angle` about the type origin then translation."""

    kind = 0

    def __init__(self, block_type: BlockType, position=(0.0, 0.0), angle: float = 0.0,
                 clamps: Sequence[Clamp] = (), tractions: Sequence[Traction] = (), name: str = "block"):
        self.type, self.name = block_type, name
        self.position = np.asarray(position, dtype=float).reshape(2)
        self.angle = float(angle)
        self.R = rotation(self.angle)
        self._init_frame()
        self._init_tractions(tractions)
        self.clamped = self._clamped_dofs(clamps)
        # state (type frame); replaced by views into group arrays by the time stepper
        self.q = np.zeros(block_type.ndof)
        self.u = np.zeros(block_type.ndof)

    def _clamped_dofs(self, clamps) -> np.ndarray:
        nd = self.type.ndof
        mask = np.zeros(nd, dtype=bool)
        X = self.reference_points
        for c in clamps:
            if c.components not in ("x", "y", "xy"):
                raise InputError(f"{self.name}.clamp.components = {c.components!r}: expected 'x', 'y' or 'xy'")
            if (c.box is None) == (c.tag is None):
                raise InputError(f"{self.name}.clamp: give exactly one of box or tag")
            if c.box is not None:
                x0, x1, y0, y1 = map(float, c.box)
                scale = max(np.ptp(X[:, 0]), np.ptp(X[:, 1]))
                eps = 1e-9 * scale
                nodes = np.flatnonzero((X[:, 0] >= x0 - eps) & (X[:, 0] <= x1 + eps)
                                       & (X[:, 1] >= y0 - eps) & (X[:, 1] <= y1 + eps))
            else:
                m = self.type.mesh
                if c.tag not in m.tag_names:
                    raise InputError(f"{self.name}.clamp.tag = {c.tag!r}: expected one of {sorted(m.tag_names)}")
                nodes = np.unique(m.boundary_edges[m.edge_tags == m.tag_names[c.tag]])
            if nodes.size == 0:
                raise InputError(f"{self.name}.clamp: the box {c.box} selects no node")
            if c.components == "xy":
                mask[2 * nodes] = mask[2 * nodes + 1] = True
            else:
                # a single global component is a single type-frame component only for 90° rotations
                k = np.rint(self.angle / (np.pi / 2))
                if abs(self.angle - k * np.pi / 2) > 1e-12:
                    raise InputError(f"{self.name}.clamp.components = {c.components!r}: a single component can "
                                     f"be clamped only on blocks rotated by a multiple of 90 degrees")
                comp = {"x": 0, "y": 1}[c.components]
                if int(k) % 2:
                    comp = 1 - comp
                mask[2 * nodes + comp] = True
        return mask

DRIVER_KINDS = ("velocity", "displacement", "acceleration")


class Driver:
    """Prescribed motion of one rigid dof: kind 'velocity', 'displacement' or 'acceleration' (translation dofs: an
    acceleration record integrated exactly to the driver velocity, `record_velocity`), with a History. `pivot`
    (rotation dofs only): the body turns about the material point at `pivot` (global coordinates, taken where it is
    when the driver is attached); its translation dofs are then driven too (_DrivenDofs.drive)."""

    def __init__(self, kind: str, history, name: str = "driver", pivot=None):
        if kind not in DRIVER_KINDS:
            raise InputError(f"{name}.kind = {kind!r}: expected 'velocity', 'displacement' or 'acceleration'")
        self.kind, self.history, self.name = kind, as_history(history, f"{name}.history"), name
        self.pivot = None if pivot is None else np.asarray(pivot, dtype=float).ravel()
        if self.pivot is not None and not np.all(np.isfinite(self.pivot)):
            raise InputError(f"{name}.pivot: expected finite coordinates [m]")
        self._knots = None
        if kind == "acceleration" and self.history.times.size > 1:
            self._knots = record_velocity_knots(self.history.times, self.history.values)

    def step_velocity(self, t0: float, t1: float) -> float:
        """Velocity imposed over [t0, t1] and at t1 (displacement: (d(t1) - d(t0)) / h; acceleration: the exact
        integral of the record, v(t1) = v(t0) + ∫_{t0}^{t1} a dt)."""
        if self.kind == "velocity":
            return self.history(t1)
        if self.kind == "acceleration":
            return record_velocity(self.history.times, self.history.values, t1, self._knots)
        return (self.history(t1) - self.history(t0)) / (t1 - t0)


def polygon_properties(vertices: np.ndarray):
    """Area, centroid and polar second moment about the centroid of a simple polygon (CCW)."""
    x, y = vertices[:, 0], vertices[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    A = 0.5 * cr.sum()
    if A == 0.0:
        return 0.0, np.array([np.nan, np.nan]), np.nan
    cx = ((x + xn) * cr).sum() / (6 * A)
    cy = ((y + yn) * cr).sum() / (6 * A)
    Ixx = ((y * y + y * yn + yn * yn) * cr).sum() / 12.0
    Iyy = ((x * x + x * xn + xn * xn) * cr).sum() / 12.0
    J = Ixx + Iyy - A * (cx * cx + cy * cy)
    return A, np.array([cx, cy]), J


class _DrivenDofs:
    """Drivers and applied forces of a rigid body's dofs (shared by RigidBody and RigidBody3D). The class gives
    `dof_names` (one name per dof), `_dof(k)` (name or index -> index) and `_massless(i)`; `_init_loads` sets
    `drivers` {dof: Driver} and `forces` {dof: History}. A dof is driven (prescribed velocity) or free with the
    applied force Σ forces[i](t), never both.

    Pivot (docs/case-files.md "Rotation about a pivot"): a rotation driver with `pivot = p` also drives the
    translation dofs so that the body turns about the material point P at p. With r0 = Rot^T (c - p) taken when the
    driver is attached (Rot the body's rotation, c its centre of mass), the centre is c(Rot) = p + Rot r0. Over a
    step the rotation dofs get their drivers' velocity ω_{i+1}; the translation velocity at the step end is
    v_{i+1} = ω_{i+1} × (c_{i+1} - p), c_{i+1} = p + Rot_{i+1} r0 with Rot_{i+1} the end-of-step rotation the step
    will reach (2D: φ_{i+1} = d(t_{i+1}) for a displacement driver, φ_i + h((1-θ)ω_i + θω_{i+1}) for a velocity
    driver; 3D: exp([h((1-θ)ω_i + θω_{i+1})]x) Rot_i); after the step the centre is set to p + Rot_{i+1} r0
    (`hold_pivot`), so P stays at p to rounding whatever the rotation (as a displacement driver sets its dof to
    d(t_{i+1}))."""

    dof_names: tuple = ()
    pivot = None        # (d,) global pivot, or None
    pivot_arm = None    # r0 = Rot^T (c - p) at attachment

    @property
    def _nt(self) -> int:
        """Number of translation dofs (2 in 2D, 3 in 3D)."""
        return 2 if len(self.dof_names) == 3 else 3

    def _rot(self) -> np.ndarray:
        """The body's current rotation matrix."""
        return rotation(self.q[2]) if len(self.dof_names) == 3 else self.orientation

    def _init_loads(self, drivers, forces):
        name = self.name
        self.drivers: dict[int, Driver] = {}
        for k, d in (drivers or {}).items():
            i = self._dof(k)
            self.drivers[i] = d if isinstance(d, Driver) else Driver(*d, name=f"{name}.driver.{k}")
        self.forces: dict[int, History] = {}
        for k, f in (forces or {}).items():
            i = self._dof(k)
            if i in self.drivers:
                raise InputError(f"{name}.forces.{k}: dof {k!r} is driven; a driven dof cannot also carry a force")
            self.forces[i] = as_history(f, f"{name}.forces.{k}")
        self._check_drivers()

    def _check_drivers(self):
        """Driver kinds per dof (acceleration: translations only) and the pivot rules (rotation dofs only, one
        pivot point, no own driver or force on a translation dof, 3D: every rotation dof driven); attaches the
        pivot (pivot_arm) when there is one."""
        nt, name = self._nt, self.name
        pivots = []
        for i, d in self.drivers.items():
            if d.kind == "acceleration" and i >= nt:
                raise InputError(f"{name}.drivers.{self.dof_names[i]}.kind = 'acceleration': expected a translation "
                                 f"dof ({', '.join(self.dof_names[:nt])})")
            if d.pivot is not None:
                if i < nt:
                    raise InputError(f"{name}.drivers.{self.dof_names[i]}.pivot: expected on a rotation dof")
                if d.pivot.shape != (nt,):
                    raise InputError(f"{name}.drivers.{self.dof_names[i]}.pivot: expected {nt} coordinates [m]")
                pivots.append((i, d.pivot))
        if not pivots:
            self.pivot = self.pivot_arm = None
            return
        i0, p = pivots[0]
        for i, q in pivots[1:]:
            if not np.array_equal(p, q):
                raise InputError(f"{name}.drivers.{self.dof_names[i]}.pivot: expected the same pivot as "
                                 f"{self.dof_names[i0]} ({list(p)}): a body turns about one point")
        for i in range(nt):
            if i in self.drivers or i in self.forces:
                what = "driver" if i in self.drivers else "force"
                raise InputError(f"{name}.drivers.{self.dof_names[i0]}.pivot: the body's dof {self.dof_names[i]!r} "
                                 f"has its own {what}; expected no driver or force on {', '.join(self.dof_names[:nt])}"
                                 f" with a pivot (the pivot drives them)")
        missing = [self.dof_names[i] for i in range(nt, len(self.dof_names)) if i not in self.drivers]
        if missing:
            raise InputError(f"{name}.drivers.{self.dof_names[i0]}.pivot: expected every rotation dof driven with a "
                             f"pivot (free: {', '.join(missing)})")
        self.pivot = p.copy()
        self.pivot_arm = self._rot().T @ (self.center - p)

    def set_driver(self, dof, driver: "Driver | None"):
        """Drive a dof (removing any applied force on it) or free it (driver None) — e.g. between load stages.
        Freeing a rotation dof whose driver has a pivot frees the translation dofs it drove."""
        i = self._dof(dof)
        had_pivot = self.pivot is not None
        if driver is None:
            self.drivers.pop(i, None)
            freed = [i] + (list(range(self._nt)) if had_pivot and i >= self._nt else [])
            for j in freed:
                if self._massless(j):
                    raise InputError(f"{self.name}: dof {self.dof_names[j]!r} cannot be freed: the body has no mass "
                                     f"(give rho or mass)")
        else:
            if driver.pivot is not None:  # the pivot takes the translation dofs over
                for j in range(self._nt):
                    self.drivers.pop(j, None)
                    self.forces.pop(j, None)
            self.drivers[i] = driver
            self.forces.pop(i, None)
        self._check_drivers()

    def set_force(self, dof, history):
        """Apply a force history on a free dof (a driven dof is freed first)."""
        i = self._dof(dof)
        if self.pivot is not None and i < self._nt:
            raise InputError(f"{self.name}.forces.{self.dof_names[i]}: the dof is driven by a pivot; expected no "
                             f"force on it")
        if i in self.drivers:
            self.set_driver(dof, None)
        self.forces[i] = as_history(history, f"{self.name}.forces.{self.dof_names[i]}")

    @property
    def driven(self) -> np.ndarray:
        """(ndof,) bool, True on the driven dofs (with a pivot: the translation dofs too)."""
        m = np.zeros(len(self.dof_names), dtype=bool)
        m[list(self.drivers)] = True
        if self.pivot is not None:
            m[:self._nt] = True
        return m

    def drive(self, uf: np.ndarray, t0: float, t1: float, h: float, theta: float) -> None:
        """Set the driven entries of the end-of-step velocity `uf` (in place): each driver's step velocity, then,
        with a pivot, the translation velocity ω_{i+1} × (c_{i+1} - p) (class docstring)."""
        for k, drv in self.drivers.items():
            uf[k] = drv.step_velocity(t0, t1)
        if self.pivot is None:
            return
        nt = self._nt
        w = uf[nt:]
        if nt == 2:
            drv = self.drivers[2]
            phi1 = drv.history(t1) if drv.kind == "displacement" else \
                self.q[2] + h * ((1 - theta) * self.u[2] + theta * w[0])
            arm = rotation(phi1) @ self.pivot_arm
            uf[:2] = w[0] * np.array([-arm[1], arm[0]])
        else:
            arm = rotation3d(h * ((1 - theta) * self.u[3:] + theta * w)) @ self.orientation @ self.pivot_arm
            uf[:3] = np.cross(w, arm)

    def hold_pivot(self) -> None:
        """After a step's move: the centre of mass at p + Rot r0, so the pivot's material point is at p (no-op
        without a pivot)."""
        if self.pivot is not None:
            self.q[:self._nt] = self.pivot + self._rot() @ self.pivot_arm - self.center0

    def n_driven(self, drivers) -> int:
        """How many dofs `drivers` (dof -> Driver or (kind, history[, ...])) drive, the translations of a pivot
        included."""
        piv = any(isinstance(d, Driver) and d.pivot is not None for d in (drivers or {}).values())
        dofs = {self._dof(k) for k in (drivers or {})}
        return len(dofs | (set(range(self._nt)) if piv else set()))


DOF_NAMES = ("x", "y", "rz")


class RigidBody(_DrivenDofs):
    """2D rigid polygon with dofs (vx, vy, omega) at its centre of mass."""

    kind = 1
    dof_names = DOF_NAMES

    def __init__(self, vertices, rho: float = None, thickness: float = 1.0, mass: float = None,
                 inertia: float = None, drivers: dict | None = None, forces: dict | None = None,
                 name: str = "rigid"):
        V = np.asarray(vertices, dtype=float)
        if V.ndim != 2 or V.shape[1] != 2 or V.shape[0] < 3:
            raise InputError(f"{name}.vertices: expected at least 3 (x, y) points")
        A, c, J = polygon_properties(V)
        if abs(A) < 1e-14 * max(1.0, np.ptp(V) ** 2):
            raise InputError(f"{name}.vertices: polygon has zero area")
        if A < 0:
            V = V[::-1].copy()
            A, c, J = polygon_properties(V)
        self.name = name
        check_range(f"{name}.thickness", thickness, 0.0, lo_open=True, expected="thickness > 0 [m]")
        n_driven = self.n_driven(drivers)
        if mass is None and rho is None and n_driven == 3:
            mass, inertia = 0.0, 0.0  # fully driven: its motion is prescribed, its inertia plays no role
        elif mass is None:
            if rho is None:
                raise InputError(f"{name}: give rho (density) or mass")
            check_range(f"{name}.rho", rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
            mass, inertia = rho * A * thickness, rho * J * thickness
        elif mass == 0.0 and n_driven == 3:
            inertia = 0.0
        else:
            check_range(f"{name}.mass", mass, 0.0, lo_open=True, expected="mass > 0 [kg]")
            inertia = mass * J / A if inertia is None else inertia
            check_range(f"{name}.inertia", inertia, 0.0, lo_open=True, expected="inertia > 0 [kg m^2]")
        self.mass = np.array([mass, mass, inertia], dtype=float)
        self.center0 = c
        self.vertices_rel = V - c  # reference vertices relative to the centre of mass
        self.thickness = thickness
        self.q = np.zeros(3)  # (dx, dy, phi) of the centre of mass
        self.u = np.zeros(3)
        self._init_loads(drivers, forces)
        self.reaction = np.zeros(3)  # force/moment applied by the drivers, last step
        self.reaction_inertia = np.zeros(3)  # inertial part of the reaction, last step (dynamics.py module docstring)

    def _dof(self, k) -> int:
        if k in DOF_NAMES:
            return DOF_NAMES.index(k)
        if k in (0, 1, 2):
            return int(k)
        raise InputError(f"{self.name}: dof {k!r}: expected one of {DOF_NAMES}")

    def _massless(self, i: int) -> bool:
        return self.mass[i] == 0.0

    @property
    def center(self) -> np.ndarray:
        return self.center0 + self.q[:2]

    def current_vertices(self) -> np.ndarray:
        return self.center + self.vertices_rel @ rotation(self.q[2]).T

    def applied_force(self, t: float, g: np.ndarray) -> np.ndarray:
        f = np.array([self.mass[0] * g[0], self.mass[1] * g[1], 0.0])
        for i, hist in self.forces.items():
            f[i] += hist(t)
        return f

    @property
    def W(self) -> np.ndarray:
        """Inverse mass with driven dofs removed: diag(1/m, 1/m, 1/I), zero on driven dofs."""
        w = np.divide(1.0, self.mass, out=np.zeros(3), where=~self.driven)
        return np.diag(w)


# ============================================================================= 3D
def check_rotation3d(R, name: str = "rotation") -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1e-10) \
            or np.linalg.det(R) <= 0:
        raise InputError(f"{name}: expected a 3x3 rotation matrix (orthogonal, det = +1)")
    return R


def solid_properties(mesh):
    """Volume V, centroid c and second moment S = ∫ (x - c)(x - c)^T dV of a BlockMesh3D, exact for its
    geometry: tetrahedra in closed form, ∫_tet x x^T = V_e/20 (sum_a x_a x_a^T + (sum_a x_a)(sum_a x_a)^T);
    trilinear hexahedra by 3x3x3 Gauss (x x^T det J is of degree 4 per reference direction)."""
    from .meshing import cell_jacobians_3d, gauss_hex, hex_shape_functions
    P = mesh.points[mesh.cells]
    if mesh.cell_type == "tetrahedron":
        Ve = cell_jacobians_3d(mesh.points, mesh.cells, "tetrahedron") / 6.0
        V = Ve.sum()
        c = np.einsum("c,cai->i", Ve, P) / (4.0 * V)
        Y = P - c
        s = Y.sum(axis=1)
        S = np.einsum("c,cai,caj->ij", Ve, Y, Y) / 20.0 + np.einsum("c,ci,cj->ij", Ve, s, s) / 20.0
        return float(V), c, S
    X, W = gauss_hex(3)
    dJ = cell_jacobians_3d(mesh.points, mesh.cells, "hexahedron", X)  # (nc, k)
    x = np.einsum("ka,cai->cki", hex_shape_functions(X), P)  # (nc, k, 3)
    w = dJ * W[None, :]
    V = w.sum()
    c = np.einsum("ck,cki->i", w, x) / V
    y = x - c
    S = np.einsum("ck,cki,ckj->ij", w, y, y)
    return float(V), c, S


def inertia_from_second_moment(rho_or_scale: float, S: np.ndarray) -> np.ndarray:
    """Inertia tensor about the centroid, I = rho (tr(S) 1 - S)."""
    return rho_or_scale * (np.trace(S) * np.eye(3) - S)


def box_inertia(mass: float, lx: float, ly: float, lz: float) -> np.ndarray:
    """Closed form for a homogeneous box: diag(m (ly² + lz²), m (lx² + lz²), m (lx² + ly²)) / 12."""
    return mass / 12.0 * np.diag([ly * ly + lz * lz, lx * lx + lz * lz, lx * lx + ly * ly])


class BlockType3D(BlockType):
    """Prototype of identical 3D deformable blocks: BlockMesh3D + material -> K, M, C (assembled once) and the
    cached StepOperator (factor of Mhat = M + h theta C + h^2 theta^2 K and W_bb over the boundary dofs
    3*node + c). `material.thickness` and `material.plane` play no role in 3D."""

    gdim = 3

    def __init__(self, mesh, material: Material, mass: str = "lumped", name: str = "block"):
        from . import fem_backend, meshing
        if mass not in ("lumped", "consistent"):
            raise InputError(f"{name}.mass = {mass!r}: expected 'lumped' or 'consistent'")
        if not isinstance(mesh, meshing.BlockMesh3D):
            raise InputError(f"{name}: expected a 3D mesh (BlockMesh3D), got {type(mesh).__name__}")
        meshing.validate3d(mesh, source=name)
        self._setup(mesh, material, mass, name, fem_backend.assemble_operators_3d(mesh, material.E, material.nu,
                                                                                  material.rho), 3)

    def traction_load(self, tag: str, traction: np.ndarray) -> np.ndarray:
        """Nodal forces of a uniform traction (type frame, N/m^2) on the faces tagged `tag`:
        F_a = t ∫_faces N_a dA (exact: 3-point rule on triangles, 2x2 Gauss on bilinear quadrangles)."""
        from .meshing import face_quadrature
        mesh = self.mesh
        if tag not in mesh.tag_names:
            raise InputError(f"{self.name}: boundary tag {tag!r} not found; expected one of {sorted(mesh.tag_names)}")
        faces = mesh.boundary_faces[mesh.face_tags == mesh.tag_names[tag]]
        N, w = face_quadrature(mesh.points, faces)
        wa = np.einsum("fka,fk->fa", N, w)  # ∫ N_a dA per face corner
        nodal = np.bincount(faces.ravel(), weights=wa.ravel(), minlength=self.n_nodes)
        return (nodal[:, None] * np.asarray(traction, dtype=float).reshape(1, 3)).ravel()


@dataclass
class Clamp3D:
    """Zero-velocity condition on nodes selected by a global box (xmin, xmax, ymin, ymax, zmin, zmax) or a face
    tag; `components` a non-empty subset of "xyz" (global components)."""

    box: tuple | None = None
    tag: str | None = None
    components: str = "xyz"


class DeformableBody3D(_PlacedBlock):
    """Instance of a BlockType3D placed by a rotation R (3x3, default identity) about the type origin, then a
    translation: x = R X + c. Displacements and velocities q, u are stored in the type frame (3*node + c), so
    the type's K, M, factor and W_bb are shared; global displacement = R q per node, and the boundary Delassus
    block in the global frame is diag(R) W_bb diag(R)^T."""

    kind = 0
    gdim = 3

    def __init__(self, block_type: BlockType3D, position=(0.0, 0.0, 0.0), R=None,
                 clamps: Sequence[Clamp3D] = (), tractions: Sequence[Traction] = (), name: str = "block"):
        self.type, self.name = block_type, name
        self.position = np.asarray(position, dtype=float).reshape(3)
        self.R = np.eye(3) if R is None else check_rotation3d(R, f"{name}.rotation")
        self._init_frame()
        self._init_tractions(tractions)
        self.clamped = self._clamped_dofs(clamps)
        self.q = np.zeros(block_type.ndof)
        self.u = np.zeros(block_type.ndof)

    def _check_traction(self, tr):
        if np.asarray(tr.value, dtype=float).shape != (3,):
            raise InputError(f"{self.name}.traction.value: expected 3 components (tx, ty, tz) [Pa]")

    def _clamped_dofs(self, clamps) -> np.ndarray:
        mask = np.zeros(self.type.ndof, dtype=bool)
        X = self.reference_points
        for c in clamps:
            comps = c.components
            if not comps or any(k not in "xyz" for k in comps) or len(set(comps)) != len(comps):
                raise InputError(f"{self.name}.clamp.components = {comps!r}: expected a non-empty subset of 'xyz'")
            if (c.box is None) == (c.tag is None):
                raise InputError(f"{self.name}.clamp: give exactly one of box or tag")
            if c.box is not None:
                b = np.asarray(c.box, dtype=float).ravel()
                if b.shape != (6,):
                    raise InputError(f"{self.name}.clamp.box: expected (xmin, xmax, ymin, ymax, zmin, zmax)")
                eps = 1e-9 * np.ptp(X, axis=0).max()
                nodes = np.flatnonzero(np.all((X >= b[0::2] - eps) & (X <= b[1::2] + eps), axis=1))
                if nodes.size == 0:
                    raise InputError(f"{self.name}.clamp: the box {tuple(b)} selects no node")
            else:
                m = self.type.mesh
                if c.tag not in m.tag_names:
                    raise InputError(f"{self.name}.clamp.tag = {c.tag!r}: expected one of {sorted(m.tag_names)}")
                nodes = np.unique(m.boundary_faces[m.face_tags == m.tag_names[c.tag]])
                if nodes.size == 0:
                    raise InputError(f"{self.name}.clamp.tag = {c.tag!r}: no face carries this tag")
            if len(comps) == 3:
                type_comps = [0, 1, 2]
            else:
                # global component i is one type-frame component only if R is a signed permutation
                A = np.abs(self.R)
                if not np.allclose(A, np.rint(A), atol=1e-12):
                    raise InputError(f"{self.name}.clamp.components = {comps!r}: single components can be clamped "
                                     f"only on blocks whose rotation maps axes to axes")
                type_comps = [int(np.argmax(A["xyz".index(k)])) for k in comps]
            for j in type_comps:
                mask[3 * nodes + j] = True
        return mask

DOF_NAMES_3D = ("x", "y", "z", "rx", "ry", "rz")


class RigidBody3D(_DrivenDofs):
    """3D rigid body with dofs (vx, vy, vz, wx, wy, wz): velocity of its centre of mass and angular velocity
    (global frame). Mass matrix diag(m, m, m) ⊕ I with I = Rot I0 Rot^T the inertia tensor about the centre of
    mass in the current orientation Rot. Geometry: a BlockMesh3D, or the 8 corners of a hexahedral block (gmsh
    order), or `RigidBody3D.box(...)`. Each dof is free (optional applied force/moment history) or driven
    (Driver: prescribed velocity or displacement history), as the 2D RigidBody."""

    kind = 1
    gdim = 3
    dof_names = DOF_NAMES_3D

    def __init__(self, geometry, rho: float | None = None, mass: float | None = None, inertia=None,
                 drivers: dict | None = None, forces: dict | None = None, name: str = "rigid"):
        from .meshing import BlockMesh3D, HEX_FACES, check_hex_corners, validate3d
        self.name = name
        if isinstance(geometry, BlockMesh3D):
            validate3d(geometry, name)
            mesh = geometry
            faces = geometry.boundary_faces
        else:
            C = check_hex_corners(geometry, name)
            mesh = BlockMesh3D(C, np.arange(8, dtype=np.int64)[None, :], "hexahedron", HEX_FACES.copy(),
                               np.arange(6, dtype=np.int64), {}, name)
            faces = HEX_FACES.copy()
        V, c, S = solid_properties(mesh)
        n_driven = self.n_driven(drivers)
        if mass is None and rho is None and n_driven == 6:
            mass, I0 = 0.0, np.zeros((3, 3))  # fully driven: its inertia plays no role
        elif mass is None:
            if rho is None:
                raise InputError(f"{name}: give rho (density) or mass")
            check_range(f"{name}.rho", rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
            mass = rho * V
            I0 = inertia_from_second_moment(rho, S) if inertia is None else self._inertia(inertia)
        elif mass == 0.0 and n_driven == 6:
            I0 = np.zeros((3, 3))
        else:
            check_range(f"{name}.mass", mass, 0.0, lo_open=True, expected="mass > 0 [kg]")
            I0 = inertia_from_second_moment(mass / V, S) if inertia is None else self._inertia(inertia)
        self.mass = float(mass)
        self.inertia0 = I0  # about the centre of mass, reference orientation
        self.volume = V
        self.center0 = c
        self.points_rel = mesh.points - c  # surface/vertex points relative to the centre of mass
        self.boundary_faces = np.asarray(faces, dtype=np.int64)
        self.orientation = np.eye(3)
        self.q = np.zeros(6)  # displacement of the centre of mass, accumulated rotation vector increments
        self.u = np.zeros(6)
        self._init_loads(drivers, forces)
        self.reaction = np.zeros(6)
        self.reaction_inertia = np.zeros(6)  # inertial part of the reaction, last step (dynamics.py module docstring)

    @classmethod
    def box(cls, lx: float, ly: float, lz: float, origin=(0.0, 0.0, 0.0), rho: float | None = None,
            mass: float | None = None, **kw) -> "RigidBody3D":
        """Box [0,lx]x[0,ly]x[0,lz] + origin with the closed-form inertia m (b² + c²)/12 (box_inertia) unless
        `inertia` is given."""
        from .meshing import box_corners
        name = kw.get("name", "rigid")
        for k, v in (("lx", lx), ("ly", ly), ("lz", lz)):
            check_range(f"{name}.{k}", v, 0.0, lo_open=True, expected=f"{k} > 0 [m]")
        if mass is None and rho is not None:
            check_range(f"{name}.rho", rho, 0.0, lo_open=True, expected="rho > 0 [kg/m^3]")
            mass = rho * lx * ly * lz
        inertia = kw.pop("inertia", None)
        if inertia is None and mass is not None and mass != 0.0:
            inertia = box_inertia(mass, lx, ly, lz)
        return cls(box_corners(lx, ly, lz, origin), mass=mass, inertia=inertia, **kw)

    def _inertia(self, inertia) -> np.ndarray:
        I = np.asarray(inertia, dtype=float)
        if I.shape == (3,):
            I = np.diag(I)
        if I.shape != (3, 3) or not np.all(np.isfinite(I)) or not np.allclose(I, I.T, rtol=1e-12,
                                                                               atol=1e-300):
            raise InputError(f"{self.name}.inertia: expected a symmetric 3x3 tensor or 3 principal values [kg m^2]")
        ev = np.linalg.eigvalsh(I)
        if ev.min() <= 0 or ev[0] + ev[1] < ev[2] * (1 - 1e-12):
            raise InputError(f"{self.name}.inertia: expected a positive definite tensor whose principal values "
                             f"satisfy the triangle inequality I1 + I2 >= I3")
        return I

    def _dof(self, k) -> int:
        if k in DOF_NAMES_3D:
            return DOF_NAMES_3D.index(k)
        if isinstance(k, (int, np.integer)) and 0 <= k < 6:
            return int(k)
        raise InputError(f"{self.name}: dof {k!r}: expected one of {DOF_NAMES_3D}")

    def _massless(self, i: int) -> bool:
        return self.mass == 0.0

    @property
    def center(self) -> np.ndarray:
        return self.center0 + self.q[:3]

    @property
    def inertia(self) -> np.ndarray:
        """Inertia tensor about the centre of mass in the current orientation: Rot I0 Rot^T."""
        return self.orientation @ self.inertia0 @ self.orientation.T

    @property
    def mass_matrix(self) -> np.ndarray:
        Mm = np.zeros((6, 6))
        Mm[:3, :3] = self.mass * np.eye(3)
        Mm[3:, 3:] = self.inertia
        return Mm

    def rotate(self, dphi):
        """Compose the orientation with an incremental rotation vector dphi (global frame):
        Rot <- exp([dphi]x) Rot; q[3:] accumulates dphi."""
        dphi = np.asarray(dphi, dtype=float).reshape(3)
        self.orientation = rotation3d(dphi) @ self.orientation
        self.q[3:] += dphi

    def current_points(self) -> np.ndarray:
        return self.center + self.points_rel @ self.orientation.T

    def applied_force(self, t: float, g: np.ndarray) -> np.ndarray:
        f = np.zeros(6)
        f[:3] = self.mass * np.asarray(g, dtype=float).reshape(3)
        for i, hist in self.forces.items():
            f[i] += hist(t)
        return f

    @property
    def W(self) -> np.ndarray:
        """Inverse of the mass matrix restricted to the free dofs (zero rows/columns on driven dofs)."""
        free = ~self.driven
        W = np.zeros((6, 6))
        if free.any():
            W[np.ix_(free, free)] = np.linalg.inv(self.mass_matrix[np.ix_(free, free)])
        return W

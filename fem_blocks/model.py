"""From a validated Case to bodies: expand its generated geometry (expand.py), mesh each block type once, build
its operators once, place instances."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .bodies import (BlockType, BlockType3D, Clamp, Clamp3D, DeformableBody, DeformableBody3D, Driver, Material,
                     RigidBody, RigidBody3D, Traction)
from .case import Case, BlockTypeSpec, dofs_of, rigid_specs
from .errors import InputError
from .expand import expand


@dataclass
class Model:
    bodies: list
    block_types: dict
    names: list
    gravity: np.ndarray
    groups: list = field(default_factory=list)
    contact: object = None  # contact.step.ContactStep or None
    dimension: int = 2

    @property
    def dofs(self) -> tuple:
        """Rigid-body dof names: x, y, rz (2D); x, y, z, rx, ry, rz (3D)."""
        return dofs_of(self.dimension)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"body {name!r} not found; expected one of {self.names}") from None


def mesh_block_type(spec: BlockTypeSpec, dimension: int = 2):
    """gmsh mesh of a block type: rectangle, polygon or user .geo/.msh file (2D); box, hexahedron (8 corners,
    structured: mesh_size or divisions) or a 3D .geo/.msh file (3D)."""
    from . import meshing
    if dimension == 3:
        if spec.geometry == "box":
            return meshing.mesh_box(spec.lx, spec.ly, spec.lz, size=spec.mesh_size, divisions=spec.divisions,
                                    cell=spec.cell)
        if spec.geometry == "hexahedron":
            return meshing.mesh_hexahedron(np.asarray(spec.corners), size=spec.mesh_size, divisions=spec.divisions,
                                           cell=spec.cell)
        if spec.file.endswith(".geo"):
            return meshing.load_geo3d(spec.file, size=spec.mesh_size, cell=spec.cell)
        mesh = meshing.load_msh3d(spec.file)
        if spec.cell is not None and mesh.cell_type != spec.cell:
            raise InputError(f"cell = {spec.cell!r}: the file {spec.file} holds {mesh.cell_type} elements")
        return mesh
    if spec.geometry == "rectangle":
        return meshing.mesh_rectangle(spec.lx, spec.ly, spec.mesh_size, cell=spec.cell)
    if spec.geometry == "polygon":
        return meshing.mesh_polygon(np.asarray(spec.vertices), spec.mesh_size, cell=spec.cell)
    if spec.file.endswith(".geo"):
        return meshing.load_geo(spec.file, size=spec.mesh_size, cell=spec.cell)
    return meshing.load_msh(spec.file)


def mass_centre(body) -> np.ndarray:
    """Mass centre of a placed deformable block, c = Σ_a m_a x_a / Σ_a m_a with m_a = Σ_b M_ab (the row sums of one
    displacement component of its mass matrix, lumped or consistent: exact for both), x_a the placed nodes."""
    d = body.gdim
    ex = np.zeros(body.type.ndof)
    ex[0::d] = 1.0
    w = (body.type.M @ ex)[0::d]
    return w @ body.reference_points / w.sum()


def set_initial_motion(body, velocity=None, spin=None) -> None:
    """The initial velocity of a body (docs/case-files.md "Initial velocity and spin"): the rigid field
    u_a = v + ω × (x_a - c) at the nodes x_a of a deformable block (c its mass centre, `mass_centre`; 2D
    ω × r = ω (-r_y, r_x)), stored in the type frame (R^T u_a); on a rigid body its dofs (v, ω) at the centre of
    mass. None: at rest. (The case checks that the body can move: no clamps, no driver on those dofs.)"""
    if velocity is None and spin is None:
        return
    d = 2 if body.kind == 1 and len(body.dof_names) == 3 else (3 if body.kind == 1 else body.gdim)
    v = np.zeros(d) if velocity is None else np.asarray(velocity, dtype=float).reshape(d)
    w = np.zeros(1 if d == 2 else 3) if spin is None else np.atleast_1d(np.asarray(spin, dtype=float))
    if body.kind == 1:
        body.u[:d] = v
        body.u[d:] = w
        return
    r = body.reference_points - mass_centre(body)
    u = v + (w[0] * np.column_stack([-r[:, 1], r[:, 0]]) if d == 2 else np.cross(w, r))
    body.u[:] = (u @ body.R).ravel()  # type frame: R^T u per node


def build_model(case: Case) -> Model:
    """Bodies of dimension case.dimension (2: BlockType/DeformableBody/RigidBody; 3: the *3D classes) and the
    ContactStep of the interfaces (the same for both dimensions). A case not yet expanded is expanded first."""
    case = expand(case)
    D = case.dimension
    Type, Body, ClampCls = ((BlockType, DeformableBody, Clamp) if D == 2 else
                            (BlockType3D, DeformableBody3D, Clamp3D))
    block_types = {}
    used_types = {b.type for b in case.blocks}
    for name, spec in case.block_types.items():
        if name not in used_types:
            continue
        ms = case.materials[spec.material]
        mat = Material(ms.E, ms.nu, ms.rho, ms.thickness, ms.plane, ms.alpha, ms.beta,
                       name=f"materials.{ms.name}")
        try:
            mesh = mesh_block_type(spec, D)
        except InputError as e:
            raise InputError(f"{case.source}: block_types.{name}: {e}") from None
        block_types[name] = Type(mesh, mat, mass=spec.mass, name=f"block_types.{name}")
    bodies, names, groups = [], [], []
    for i, b in enumerate(case.blocks):
        bt = block_types[b.type]
        label = f"{case.source}: blocks[{i}]"
        try:
            body = Body(bt, b.position, b.angle if D == 2 else b.R,
                        clamps=[ClampCls(c.box, c.tag, c.components) for c in b.clamps],
                        tractions=[Traction(t.tag, t.value, t.history) for t in b.tractions],
                        name=label)
        except InputError as e:
            raise InputError(str(e)) from None
        set_initial_motion(body, b.initial_velocity, b.initial_spin)
        bodies.append(body)
        names.append(b.name)
        groups.append(b.group)
    for i, r in enumerate(case.rigid_bodies):
        label = f"{case.source}: body {r.name!r}"
        drivers = {dof: Driver(spec[0], spec[1], name=f"{label}.drivers.{dof}", pivot=getattr(spec, "pivot", None))
                   for dof, spec in r.drivers.items()}
        if D == 2:
            body = RigidBody(r.vertices, rho=r.rho, thickness=r.thickness, mass=r.mass, inertia=r.inertia,
                             drivers=drivers, forces=r.forces, name=label)
        else:
            try:
                body = RigidBody3D(np.asarray(r.vertices, dtype=float), rho=r.rho, mass=r.mass, inertia=r.inertia,
                                   drivers=drivers, forces=r.forces, name=label)
            except InputError as e:
                raise InputError(str(e)) from None
        set_initial_motion(body, r.initial_velocity, r.initial_spin)
        bodies.append(body)
        names.append(r.name)
        groups.append(r.group)
    contact = None
    if case.interfaces:
        from .contact.step import ContactStep
        parent = [-1] * len(names)
        index = {n: k for k, n in enumerate(names)}
        for b in case.blocks:
            parent[index[b.name]] = b.parent
        contact = ContactStep(case.interfaces, groups, case.contact, body_names=names, body_parent=parent)
    return Model(bodies, block_types, names, np.asarray(case.gravity, dtype=float), groups, contact, D)


def groups_without_interface(case: Case, model: Model, sim) -> list[str]:
    """Warnings (one line each) for every pair of body groups whose bodies touch at the start (boundaries within
    the search distance of the contact detection: the largest g0 + alert of the interfaces, at least 1 mm) with no
    [[interfaces]] between them and not listed in `allow_no_interface`: such bodies pass through each other.

    Runs the contact detection once on the reference configuration with one probe interface on exactly those
    group pairs (candidate points at the FE nodes / rigid vertices). Pairs of massless (always fully driven)
    rigid bodies, e.g. the parts of a split foundation, are skipped."""
    from .contact.scene import ContactScene
    if len(model.bodies) < 2:
        return []
    have = {tuple(sorted(i.groups)) for i in case.interfaces} | set(case.allow_no_interface)
    groups = sorted(set(model.groups))
    gid = {g: k for k, g in enumerate(groups)}
    massless = {r.name for r in rigid_specs(case) if r.rho is None and r.mass is None}
    fixed = np.array([n in massless for n in model.names])  # massless rigid bodies: fully driven, never pushed
    body_group = np.array([gid[g] for g in model.groups], dtype=np.int64)
    all_fixed = np.array([fixed[body_group == k].all() for k in range(len(groups))])
    pair = -np.ones((len(groups), len(groups)), dtype=np.int64)
    for a in range(len(groups)):
        for b in range(a, len(groups)):
            if (groups[a], groups[b]) not in have and not (all_fixed[a] and all_fixed[b]):
                pair[a, b] = pair[b, a] = 0
    if np.all(pair < 0):
        return []
    search = max([i.g0 + i.alert for i in case.interfaces] + [1e-3])
    scene = ContactScene(sim)
    bx = scene.positions(reference=True)
    if scene.dim == 2:
        from .contact import detection_2d as det
        table = det.InterfaceTable(pair_iface=pair, g0=np.zeros(1), alert=np.array([search]),
                                   placement=np.ones(1, dtype=np.int64), positions=-np.ones((1, 1)),
                                   cand_group=-np.ones(1, dtype=np.int64), thickness=np.ones(1),
                                   cos_max_angle=np.cos(np.deg2rad([60.0])), split_head=-np.ones(1, dtype=np.int64))
        cs = det.detect(bx, scene.bnode_body, scene.bnode_local, scene.bedges, scene.bedge_body, scene.kind,
                        body_group, table)
    else:
        from .contact import detection_3d as det3
        table = det3.simple_table(g0=0.0, alert=search, placement="nodes", max_angle=60.0)
        table.pair_iface = pair
        cs = det3.detect(bx, scene.bnode_body, scene.bnode_local, scene.bfaces, scene.bface_body, scene.kind,
                         body_group, table)
    cs = cs.subset(np.flatnonzero(~(fixed[cs.cand_body] & fixed[cs.ant_body])))
    if len(cs.gap) == 0:
        return []
    gname = np.array(model.groups, dtype=object)
    ga, gb = gname[cs.cand_body], gname[cs.ant_body]
    out = []
    for a, b in sorted({tuple(sorted(p)) for p in zip(ga, gb)}):
        sel = np.flatnonzero(((ga == a) & (gb == b)) | ((ga == b) & (gb == a)))
        pairs = {tuple(sorted((int(cs.cand_body[k]), int(cs.ant_body[k])))) for k in sel}
        k = sel[np.argmin(cs.gap[sel])]
        i, j = sorted((int(cs.cand_body[k]), int(cs.ant_body[k])))
        out.append(f"{case.source}: groups {a!r} and {b!r}: {len(pairs)} pair(s) of bodies in contact at the start "
                   f"(e.g. {model.names[i]} / {model.names[j]}, gap {cs.gap[k]:.3g} m) but no [[interfaces]] between "
                   f"them, so they pass through each other; add an interface, or allow_no_interface = "
                   f"[[\"{a}\", \"{b}\"]] if this is intended")
    return out

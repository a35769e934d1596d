"""Expand a parsed case: generated geometry becomes block types, blocks and rigid bodies.

Input flows one way: parse (case.py: the file, validated, in SI) → expand (this module) → build (model.py: meshes,
bodies, contact step) → run. `expand(case)` returns a new Case whose `block_types`, `blocks` and `rigid_bodies` hold
the file's own entries followed by those of its generators, in file order [wall], [arch], [wall3d], [dome]:

- [wall] (builders.running_bond / courses / stack_prism, optionally builders.split_bricks): one rectangle block
  type per brick size ("wall_K"), bricks "brickK" at (x, y) + position, a rigid foundation (fixed; cut at `split`
  into parts "foundationK", one possibly settling) `depth` under the lowest course and a rigid beam `depth` high
  on the top course, both spanning the wall ± `overhang`, a joint away unless the bricks are expanded;
- [arch] (builders.semicircular_arch): one polygon block type "arch_voussoir" centred on the springing line's
  midpoint c, voussoir k its instance at c rotated by -k π/n; fixed rectangular piers "pier0", "pier1";
- [wall3d] (builders3d.running_bond_wall) and [dome] (builders3d.dome): one hexahedron block type per prototype
  ("brick_K", "voussoir_K"), blocks x = R X + position; wall3d slabs as in 2D in the wall frame, dome piers.

Errors are InputErrors "SOURCE: KEY: ...", KEY the generator's key path (`GeneratorSpec.key`); openings give one
note each (what was built) and a warning when the opening built differs from the one asked (`_opening_report`).
Then, on all bodies, the checks that need the geometry: a 'crack' interface needs split bricks, and in 3D bodies must
not overlap at the start (separating axes on hexahedra; blocks meshed from a file are not checked).
Pure geometry: no meshing, no dolfinx.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from . import builders, builders3d
from .case import (UNIT_SYSTEMS, ArchSpec, BlockSpec, BlockTypeSpec, Case, DomeSpec, GeneratorSpec, Wall3DSpec,
                   WallSpec, type_corners)
from .errors import InputError
from .geometry import box_corners

OPENING_TOL = 1e-3  # [m]: a built opening that differs from the asked one by more than this is reported


class _Out:
    """What expand builds: the lists of the case extended in place, the names taken, warnings and notes."""

    def __init__(self, case: Case):
        self.source = case.source
        self.units = case.units
        self.block_types = dict(case.block_types)
        self.blocks = list(case.blocks)
        self.rigid = list(case.rigid_bodies)
        self.names = {b.name for b in self.blocks} | {r.name for r in self.rigid}
        self.warnings: list = []
        self.notes: list = []

    def error(self, g: GeneratorSpec, k: str, msg: str) -> InputError:
        return InputError(f"{self.source}: {g.key}.{k}: {msg}")


def expand(case: Case) -> Case:
    """The case with its generators' block types, blocks and rigid bodies added (a new Case; `case` is not
    changed), their notes and warnings appended, and the geometric checks done. An expanded case is returned
    as it is."""
    if case.expanded:
        return case
    out = _Out(case)
    for g in case.generators:
        _EXPAND[type(g)](g, out)
    _check_cracks(case, out.blocks)
    if case.dimension == 3:
        _check_overlaps_3d(case.source, out.block_types, out.blocks, out.rigid)
    return replace(case, block_types=out.block_types, blocks=out.blocks, rigid_bodies=out.rigid, generators=[],
                   expanded=True, warnings=list(case.warnings) + out.warnings, notes=list(case.notes) + out.notes)


# ----------------------------------------------------------------------------- dimension 2
def _wall(g: WallSpec, out: _Out):
    name = f"{out.source}: {g.key}"
    L, H, joint, expanded = g.brick_length, g.brick_height, g.joint, g.expanded
    x0, y0 = g.position
    if g.kind == "running_bond":
        lay = builders.running_bond(g.courses, g.bricks_per_course, L, H, joint, expanded, g.half_bricks,
                                    openings=g.openings, name=name)
        for i, op in enumerate(g.openings):
            _opening_report(out, g, i, op, builders.opening_extent(lay, op, joint, expanded))
    elif g.kind == "courses":
        lay = builders.courses(g.rows, L, H, joint, expanded, name=f"{name}.rows")
        for i, op in enumerate(g.openings):
            lay = builders.cut_opening(lay, op, L, joint, expanded, f"{name}.openings[{i}]")
        for i, op in enumerate(g.openings):
            _opening_report(out, g, i, op, builders.opening_extent(lay, op, joint, expanded))
    else:
        lay = builders.stack_prism(g.bricks, L, H, joint, expanded, name=name)
    if g.split_bricks:
        lay = builders.split_bricks(lay, L)
    builders.Layout(lay).check_no_overlap(name)
    sizes = {}
    for k, b in enumerate(lay):
        if b.size_key not in sizes:
            tname = f"wall_{len(sizes)}"
            sizes[b.size_key] = tname
            out.block_types[tname] = BlockTypeSpec(name=tname, geometry="rectangle", material=g.material,
                                                   mesh_size=g.mesh_size, cell=g.cell, mass=g.mass, lx=b.length,
                                                   ly=b.height)
        bname = f"brick{k}"
        if bname in out.names:
            raise out.error(g, "group", f"body name {bname!r} already used")
        out.names.add(bname)
        out.blocks.append(BlockSpec(name=bname, type=sizes[b.size_key], position=(b.x + x0, b.y + y0), angle=0.0,
                                    group=g.group, parent=b.parent))
    xs0 = min(b.x for b in lay) + x0
    xs1 = max(b.x + b.length for b in lay) + x0
    ybot = min(b.y for b in lay) + y0
    ytop = max(b.y + b.height for b in lay) + y0
    gap = 0.0 if expanded else joint
    f = g.foundation
    if f is not None:
        over, depth = f.overhang, f.depth
        for c in f.cuts:
            if not (xs0 - over < c < xs1 + over):
                raise out.error(g, "foundation.split", f"cut at x = {c:g} m outside the foundation "
                                                       f"[{xs0 - over:g}, {xs1 + over:g}]")
        edges = [xs0 - over] + f.cuts + [xs1 + over]
        top = ybot - gap
        for k, r in enumerate(f.bodies):
            verts = [(edges[k], top - depth), (edges[k + 1], top - depth), (edges[k + 1], top), (edges[k], top)]
            out.names.add(r.name)
            out.rigid.append(replace(r, vertices=verts))
    if g.beam is not None:
        over, depth = g.beam.overhang, g.beam.depth
        bot = ytop + gap
        verts = [(xs0 - over, bot), (xs1 + over, bot), (xs1 + over, bot + depth), (xs0 - over, bot + depth)]
        out.names.add("beam")
        out.rigid.append(replace(g.beam.bodies[0], vertices=verts))


def _arch(g: ArchSpec, out: _Out):
    n = g.voussoirs
    polys, piers = builders.semicircular_arch(g.span, g.ring_depth, n, g.pier_height, g.pier_width, g.joint,
                                              name=f"{out.source}: {g.key}")
    c = np.array([0.5 * g.span, g.pier_height])
    tname = "arch_voussoir"
    out.block_types[tname] = BlockTypeSpec(name=tname, geometry="polygon", material=g.material,
                                           mesh_size=g.mesh_size, cell=g.cell, mass=g.mass,
                                           vertices=[tuple(p) for p in (polys[0] - c)])
    dth = math.pi / n
    for k in range(n):
        bname = f"voussoir{k}"
        out.names.add(bname)
        out.blocks.append(BlockSpec(name=bname, type=tname, position=(float(c[0]), float(c[1])), angle=-k * dth,
                                    group=g.group))
    for r, P in zip(g.piers, piers):
        out.names.add(r.name)
        out.rigid.append(replace(r, vertices=[tuple(p) for p in P]))


def _opening_report(out: _Out, g, i: int, op, ext: dict):
    """One line saying what opening i of generator g became (builders.opening_extent), in the file's length unit:
    a note always (`fem-blocks check`), a warning too when the clear opening differs from the asked one by more
    than OPENING_TOL or its jambs are toothed."""
    f = UNIT_SYSTEMS[out.units]["length"]
    unit = "m" if out.units == "SI" else "mm"
    aw, ah = ext["asked"]
    cx0, cy0, cx1, cy1 = ext["clear"]
    toothed = ext["width_max"] - ext["width_min"] > OPENING_TOL
    c0, c1 = ext["courses"]
    text = (f"{out.source}: {g.key}.openings[{i}] = {[round(v / f, 9) for v in op]}: asked {aw / f:.4g} x "
            f"{ah / f:.4g} {unit}, built {(cx1 - cx0) / f:.4g} x {ext['height'] / f:.4g} {unit} (clear opening "
            f"[{cx0 / f:.4g}, {cy0 / f:.4g}, {cx1 / f:.4g}, {cy1 / f:.4g}] between brick faces; courses {c0} to {c1} "
            "cut" + (f"; toothed jambs: course widths {ext['width_min'] / f:.4g} to {ext['width_max'] / f:.4g} {unit}"
                     if toothed else "") + ")")
    out.notes.append(text)
    g2 = 2 * ext["gap"]  # bricks are cut a joint away from the asked sides: clear = asked + 2 joints when it fits
    if toothed or abs(cx1 - cx0 - aw - g2) > OPENING_TOL or abs(ext["height"] - ah - g2) > OPENING_TOL:
        out.warnings.append(text + "; openings snap to whole courses and bricks (pieces < brick_length/4 dropped): "
                                   "give its sides on brick faces to build it as asked")


def _check_cracks(case: Case, blocks: list):
    """An interface of orientation 'crack' joins the halves of split bricks: some block must be such a half."""
    if any(b.parent >= 0 for b in blocks):
        return
    pairs = {}
    for itf in case.interfaces:
        pairs.setdefault(tuple(sorted(itf.groups)), []).append(itf)
    for lst in pairs.values():
        cracks = [x.name for x in lst if x.orientation == "crack"]
        if cracks:
            raise InputError(f"{case.source}: interfaces {cracks}: orientation 'crack' needs split bricks ([wall] "
                             "split_bricks = true)")


# ----------------------------------------------------------------------------- dimension 3
def _res(g: GeneratorSpec) -> dict:
    return dict(mesh_size=g.mesh_size, divisions=g.divisions, cell=g.cell, mass=g.mass)


def _add_layout_blocks(out: _Out, g: GeneratorSpec, lay, prefix: str):
    """Block types (one per prototype, 'hexahedron' from its corners) and blocks of a builders3d.Layout3D."""
    types = {}
    for key, C in lay.prototypes.items():
        tname = f"{prefix}_{len(types)}"
        types[key] = tname
        out.block_types[tname] = BlockTypeSpec(name=tname, geometry="hexahedron", material=g.material,
                                               corners=[tuple(float(x) for x in c) for c in C], **_res(g))
    for b in lay.blocks:
        bname = f"{prefix}_c{b.course}_{b.index}" + (f"_l{b.leaf}" if b.leaf else "")
        if bname in out.names:
            raise out.error(g, "group", f"body name {bname!r} already used")
        out.names.add(bname)
        out.blocks.append(BlockSpec(name=bname, type=types[b.key], position=tuple(float(x) for x in b.position),
                                    angle=0.0, group=g.group, R=np.array(b.R)))


def _wall3d(g: Wall3DSpec, out: _Out):
    name = f"{out.source}: {g.key}"
    L, H, W, joint, ops = g.brick_length, g.brick_height, g.brick_width, g.joint, g.openings
    lay = builders3d.running_bond_wall(g.courses, g.bricks_per_course, L, H, W, joint, half_bricks=g.half_bricks,
                                       openings=ops, leaves=g.leaves, stagger_leaves=g.stagger_leaves,
                                       origin=g.position, angle=g.angle, name=name)
    if ops:  # openings as built, in the wall frame (x, z) of the first leaf
        lay2 = builders.running_bond(g.courses, g.bricks_per_course, L, H, joint, False, g.half_bricks, openings=ops,
                                     name=name)
        for i, op in enumerate(ops):
            _opening_report(out, g, i, op, builders.opening_extent(lay2, op, joint))
    lay.check_no_overlap(name)
    _add_layout_blocks(out, g, lay, "brick")
    R = builders3d.rot_z(g.angle)
    o = np.asarray(g.position)
    local = (lay.corners() - o) @ R  # wall frame
    x0, x1 = local[..., 0].min(), local[..., 0].max()
    y0, y1 = local[..., 1].min(), local[..., 1].max()
    z0, z1 = local[..., 2].min(), local[..., 2].max()

    def slab(over, zb, depth):
        C = box_corners(x1 - x0 + 2 * over, y1 - y0 + 2 * over, depth, (x0 - over, y0 - over, zb))
        return [tuple(float(v) for v in c) for c in C @ R.T + o]
    for s, zb in ((g.foundation, lambda d: z0 - joint - d), (g.beam, lambda d: z1 + joint)):
        if s is not None:
            r = s.bodies[0]
            out.names.add(r.name)
            out.rigid.append(replace(r, vertices=slab(s.overhang, zb(s.depth), s.depth)))


def _dome(g: DomeSpec, out: _Out):
    lay = builders3d.dome(span=g.span, thickness=g.thickness, n_courses=g.courses,
                          blocks_per_course=g.blocks_per_course, joint=g.joint, top_elevation=g.top_elevation,
                          running_bond=g.running_bond, piers=g.piers, pier_blocks=g.pier_blocks,
                          pier_height=g.pier_height, name=f"{out.source}: {g.key}")
    _add_layout_blocks(out, g, lay, "voussoir")
    for r, p in zip(g.pier_bodies, lay.rigid):
        out.names.add(r.name)
        out.rigid.append(replace(r, vertices=[tuple(float(v) for v in c) for c in p.corners]))


def _check_overlaps_3d(source: str, block_types: dict, blocks: list, rigid: list):
    """Hexahedral blocks and rigid bodies must not overlap at the start (separating-axis test,
    builders3d.overlapping_pairs; touching is fine). Blocks meshed from a file are not checked here."""
    C, who = [], []
    for b in blocks:
        P = type_corners(block_types[b.type])
        if P is not None:
            C.append(P @ b.R.T + np.asarray(b.position))
            who.append(b.name)
    for r in rigid:
        C.append(np.asarray(r.vertices, dtype=float))
        who.append(r.name)
    if len(C) < 2:
        return
    bad = builders3d.overlapping_pairs(np.array(C))
    if len(bad):
        i, j = bad[0]
        raise InputError(f"{source}: blocks: bodies {who[i]!r} and {who[j]!r} overlap at the start "
                         f"({len(bad)} overlapping pair(s)); expected blocks that at most touch")


_EXPAND = {WallSpec: _wall, ArchSpec: _arch, Wall3DSpec: _wall3d, DomeSpec: _dome}

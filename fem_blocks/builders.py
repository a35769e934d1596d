"""Geometry builders for masonry specimens: plain geometry, no meshing.

A builder returns a `Layout`: rectangular blocks (length, height, lower-left corner, course,
group) and rigid polygons (foundation, top beam), plus the joint geometry actually used:

* thick joints: blocks are the bricks, separated by gaps of the joint thickness t_j; the
  interfaces get g0 = t_j (impenetrability on g - g0, docs/method.md §1);
* expanded bricks: each block is a brick enlarged by t_j (half a joint on each side), so blocks
  touch (g0 = 0) and the joint's flexibility is carried by the interface law or the block material.

Identical block sizes share one block type (meshed once): `Layout.block_sizes()` gives them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError, check_range

ROUND = 12  # decimals used to identify equal block sizes


@dataclass
class Block:
    length: float
    height: float
    x: float  # lower-left corner
    y: float
    course: int
    group: str = "bricks"
    parent: int = -1  # index of the brick this block is a half of (split_bricks), -1: a whole block

    @property
    def size_key(self):
        return (round(self.length, ROUND), round(self.height, ROUND))


@dataclass
class RigidPart:
    name: str
    vertices: np.ndarray  # (k, 2) CCW
    group: str


@dataclass
class Layout:
    blocks: list
    rigid: list = field(default_factory=list)
    g0: float = 0.0  # joint gap between neighbouring blocks (thick joints) or 0 (expanded bricks)
    thickness: float = 1.0

    def block_sizes(self) -> list:
        """Distinct (length, height) block sizes, in first-appearance order."""
        seen = {}
        for b in self.blocks:
            seen.setdefault(b.size_key, None)
        return list(seen)

    def bbox(self):
        x0 = min(b.x for b in self.blocks)
        x1 = max(b.x + b.length for b in self.blocks)
        y0 = min(b.y for b in self.blocks)
        y1 = max(b.y + b.height for b in self.blocks)
        return x0, x1, y0, y1

    def check_no_overlap(self, source: str = "layout"):
        """Raise InputError if two blocks overlap (area > 0, tolerance 1e-9 of the block size): the pairs whose boxes
        meet (the contact detection's grid broad phase, contact/broadphase.grid_pairs: linear in the number of
        blocks), then overlaps ox = min(x1) - max(x0) > tol and oy > tol; the first such pair (i < j, smallest i, then
        j) is named."""
        if not self.blocks:
            raise InputError(f"{source}: the layout has no block")
        from .contact.broadphase import grid_pairs
        B = np.array([[b.x, b.y, b.x + b.length, b.y + b.height] for b in self.blocks])
        size = B[:, 2:] - B[:, :2]
        tol = 1e-9 * max(1.0, float(np.max(size)))
        P = grid_pairs(B[:, :2], B[:, 2:], np.arange(len(B)), max(float(np.median(size.max(axis=1))), 1e-12))
        if not len(P):
            return
        i, j = P[:, 0], P[:, 1]
        ox = np.minimum(B[i, 2], B[j, 2]) - np.maximum(B[i, 0], B[j, 0])
        oy = np.minimum(B[i, 3], B[j, 3]) - np.maximum(B[i, 1], B[j, 1])
        bad = P[(ox > tol) & (oy > tol)]
        if len(bad):
            i, j = bad[np.lexsort((bad[:, 1], bad[:, 0]))[0]]
            raise InputError(f"{source}: blocks {i} and {j} overlap")


def split_bricks(blocks: list, brick_length: float) -> list:
    """Potential brick cracks (Lourenço's micro-model): every block at least 3/4 of a full brick long is
    replaced by its two halves, which share `parent` = the block's index in `blocks`; shorter blocks (half
    bricks, pieces cut by openings) stay whole. The halves are joined by an interface of orientation "crack"."""
    out = []
    for k, b in enumerate(blocks):
        if b.length >= 0.75 * brick_length:
            half = 0.5 * b.length
            out.append(Block(half, b.height, b.x, b.y, b.course, b.group, parent=k))
            out.append(Block(half, b.height, b.x + half, b.y, b.course, b.group, parent=k))
        else:
            out.append(b)
    return out


def _rect(x0, y0, x1, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def courses(rows, brick_length: float, brick_height: float, joint: float = 0.0, expanded: bool = False,
            x0: float = 0.0, y0: float = 0.0, name: str = "courses") -> list:
    """Blocks from explicit courses, bottom first. Each course is a list of items: a positive number is
    a block of that many brick lengths (1 = full brick, 0.5 = half brick, 3 = lintel of three bricks...);
    a dict {"gap": w} is an empty space of width w [m] (an opening). Block k of a course spans the item's
    nominal length n*L + (n-1)*t_j (thick joints, followed by a joint t_j), or n*(L + t_j) when expanded.
    """
    check_range(f"{name}.brick_length", brick_length, 0, lo_open=True, expected="brick_length > 0 [m]")
    check_range(f"{name}.brick_height", brick_height, 0, lo_open=True, expected="brick_height > 0 [m]")
    check_range(f"{name}.joint", joint, 0, expected="joint >= 0 [m]")
    if not rows:
        raise InputError(f"{name}: expected at least one course")
    L, H, t = brick_length, brick_height, joint
    blocks = []
    for c, row in enumerate(rows):
        if not isinstance(row, (list, tuple)) or not row:
            raise InputError(f"{name}[{c}]: expected a non-empty list of block lengths or {{gap = w}}")
        x = x0
        y = y0 + c * (H + t)
        for k, item in enumerate(row):
            if isinstance(item, dict):
                if set(item) != {"gap"}:
                    raise InputError(f"{name}[{c}][{k}]: expected {{gap = width}}")
                w = check_range(f"{name}[{c}][{k}].gap", item["gap"], 0, lo_open=True, expected="gap > 0 [m]")
                x += w + (0.0 if expanded else t)
                continue
            n = check_range(f"{name}[{c}][{k}]", item, 0, lo_open=True,
                            expected="a block length in brick lengths > 0, or {gap = width}")
            # thick joints: n bricks and the n-1 joints between them; a half brick is (L - t)/2 so that
            # two halves and a joint make one brick. Expanded bricks carry their own joint.
            length = n * (L + t) if expanded else n * (L + t) - t
            if length <= 0:
                raise InputError(f"{name}[{c}][{k}] = {n}: block length {length:g} m <= 0 with joint {t:g} m")
            blocks.append(Block(length, H + t if expanded else H, x, y, c))
            x += length + (0.0 if expanded else t)
    return blocks


def running_bond(n_courses: int, bricks_per_course: int, brick_length: float, brick_height: float,
                 joint: float = 0.0, expanded: bool = False, half_bricks: bool = True,
                 openings=(), name: str = "wall") -> list:
    """Running-bond wall: odd courses (1st, 3rd, ... from the bottom counted from 0 as even) are
    `bricks_per_course` full bricks; the others are offset by half a brick, with half bricks at both
    ends when `half_bricks` (else the offset course has one brick less and the wall is toothed).

    Openings (x0, y0, x1, y1) [m, wall coordinates]: a block whose interior intersects an opening is cut
    to the part on each side of the opening; pieces shorter than a quarter brick are dropped.
    """
    n_courses = int(check_range(f"{name}.courses", n_courses, 1, expected="courses >= 1"))
    bricks_per_course = int(check_range(f"{name}.bricks_per_course", bricks_per_course, 1,
                                        expected="bricks_per_course >= 1"))
    rows = []
    for c in range(n_courses):
        if c % 2 == 0:
            rows.append([1.0] * bricks_per_course)
        elif half_bricks:
            rows.append([0.5] + [1.0] * (bricks_per_course - 1) + [0.5])
        else:
            rows.append([{"gap": 0.5 * brick_length + (0.0 if expanded else -0.5 * joint)}]
                        + [1.0] * max(bricks_per_course - 1, 1))
    blocks = courses(rows, brick_length, brick_height, joint, expanded, name=name)
    for i, op in enumerate(openings):
        blocks = cut_opening(blocks, op, brick_length, joint, expanded, f"{name}.openings[{i}]")
    return blocks


def cut_opening(blocks, opening, brick_length, joint, expanded, name):
    if len(opening) != 4:
        raise InputError(f"{name}: expected [x0, y0, x1, y1]")
    ox0, oy0, ox1, oy1 = map(float, opening)
    if ox1 <= ox0 or oy1 <= oy0:
        raise InputError(f"{name} = {list(opening)}: expected x0 < x1 and y0 < y1")
    wx0 = min(b.x for b in blocks)
    wx1 = max(b.x + b.length for b in blocks)
    wy0 = min(b.y for b in blocks)
    wy1 = max(b.y + b.height for b in blocks)
    if ox0 < wx0 - 1e-12 or ox1 > wx1 + 1e-12 or oy0 < wy0 - 1e-12 or oy1 > wy1 + 1e-12:
        raise InputError(f"{name} = {list(opening)}: opening outside the wall [{wx0:g}, {wx1:g}] x [{wy0:g}, {wy1:g}]")
    gap = 0.0 if expanded else joint
    min_piece = 0.25 * brick_length
    tol = 1e-9 * brick_length  # a piece of exactly a quarter brick is kept on both sides (rounding of x0 - b.x)
    out = []
    eps = 1e-9 * max(1.0, wx1 - wx0, wy1 - wy0)  # as opening_extent: a block touching the opening is not in it
    for b in blocks:                               # (11 x 0.062 m = 0.68199... must not cut the course at 0.682 m)
        if b.y >= oy1 - eps or b.y + b.height <= oy0 + eps or b.x >= ox1 - eps or b.x + b.length <= ox0 + eps:
            out.append(b)
            continue
        left = ox0 - b.x - (gap if b.x < ox0 else 0.0)
        right = b.x + b.length - ox1 - (gap if b.x + b.length > ox1 else 0.0)
        if b.x < ox0 and left >= min_piece - tol:
            out.append(Block(left, b.height, b.x, b.y, b.course, b.group))
        if b.x + b.length > ox1 and right >= min_piece - tol:
            out.append(Block(right, b.height, b.x + b.length - right, b.y, b.course, b.group))
    if len(out) == 0:
        raise InputError(f"{name}: the opening removes every block")
    return out


def opening_extent(blocks, opening, joint: float = 0.0, expanded: bool = False) -> dict:
    """What an opening (x0, y0, x1, y1) [m] asked of `running_bond` became in the built wall `blocks`: the clear
    space between the faces of the remaining blocks. Openings remove whole courses (every course whose height
    range meets the opening) and cut bricks a joint away from the asked sides, dropping pieces shorter than a
    quarter brick, so the built opening is usually larger than the asked one and its jambs may be toothed.

    Returns dict(asked=(width, height), clear=(x0, y0, x1, y1) the largest rectangle of the clear space that
    contains the asked opening (width = the narrowest course), height, width_min, width_max (course widths,
    differing for toothed jambs), courses=(first, last) removed course indices, gap = the joint left between the
    asked sides and the cut bricks: the joint, 0 for expanded bricks). An opening that fits the bond is built with
    a clear opening of the asked size plus a joint on each side."""
    ox0, oy0, ox1, oy1 = map(float, opening)
    gap = 0.0 if expanded else joint
    wx0 = min(b.x for b in blocks)
    wx1 = max(b.x + b.length for b in blocks)
    B = np.array([[b.x, b.y, b.x + b.length, b.y + b.height, b.course] for b in blocks], dtype=float)
    eps = 1e-9 * max(1.0, float(np.ptp(B[:, :4])))
    hit = (B[:, 1] < oy1 - eps) & (B[:, 3] > oy0 + eps)  # blocks of the courses the opening meets
    courses = np.unique(B[hit, 4]).astype(int)
    if courses.size == 0:
        return dict(asked=(ox1 - ox0, oy1 - oy0), clear=(ox0, oy0, ox1, oy1), height=oy1 - oy0,
                    width_min=ox1 - ox0, width_max=ox1 - ox0, courses=(-1, -1), gap=gap)
    lefts, rights = [], []
    for c in courses:
        row = B[B[:, 4] == c]
        left = row[row[:, 2] <= ox0 + eps, 2]
        right = row[row[:, 0] >= ox1 - eps, 0]
        lefts.append(left.max() if left.size else wx0)
        rights.append(right.min() if right.size else wx1)
    lefts, rights = np.array(lefts), np.array(rights)
    rows = B[np.isin(B[:, 4], courses)]
    y0 = float(rows[:, 1].min()) - gap
    y1 = float(rows[:, 3].max()) + gap
    clear = (float(lefts.max()), y0, float(rights.min()), y1)
    widths = rights - lefts
    return dict(asked=(ox1 - ox0, oy1 - oy0), clear=clear, height=y1 - y0, width_min=float(widths.min()),
                width_max=float(widths.max()), courses=(int(courses.min()), int(courses.max())), gap=gap)


def stack_prism(n_bricks: int, brick_length: float, brick_height: float, joint: float = 0.0,
                expanded: bool = False, name: str = "prism") -> list:
    """Stack-bonded prism (or couplet n=2, triplet n=3): one brick per course.

    A stack-bonded prism has bed joints only (no head joints), so expanded bricks are enlarged in height
    only: blocks L x (H + t_j) at y = k (H + t_j); with thick joints, blocks L x H with a gap t_j."""
    n = int(check_range(f"{name}.bricks", n_bricks, 1, expected="bricks >= 1"))
    blocks = courses([[1.0]] * n, brick_length, brick_height, joint, expanded, name=name)
    if expanded:  # courses() enlarges a block by t_j in length too (it carries half a head joint at each end)
        blocks = [Block(brick_length, b.height, b.x, b.y, b.course, b.group) for b in blocks]
    return blocks


def foundation(layout_blocks, depth: float, overhang: float, joint: float = 0.0, name="foundation") -> RigidPart:
    """Rigid slab under the wall, top face at y = min(block y) - joint (the bed joint below course 0)."""
    x0 = min(b.x for b in layout_blocks) - overhang
    x1 = max(b.x + b.length for b in layout_blocks) + overhang
    ytop = min(b.y for b in layout_blocks) - joint
    return RigidPart(name, _rect(x0, ytop - depth, x1, ytop), "foundation")


def top_beam(layout_blocks, depth: float, overhang: float, joint: float = 0.0, name="beam") -> RigidPart:
    x0 = min(b.x for b in layout_blocks) - overhang
    x1 = max(b.x + b.length for b in layout_blocks) + overhang
    ybot = max(b.y + b.height for b in layout_blocks) + joint
    return RigidPart(name, _rect(x0, ybot, x1, ybot + depth), "beam")


def semicircular_arch(span: float, ring_depth: float, n_voussoirs: int, pier_height: float, pier_width: float,
                      joint: float = 0.0, name: str = "arch"):
    """Semicircular arch of `n_voussoirs` trapezoidal voussoirs (intrados radius span/2) on two rectangular
    piers. Returns (voussoir polygons list, pier rectangles list); joints radial, of thickness `joint`
    (the voussoirs are shrunk by joint/2 on each radial face)."""
    check_range(f"{name}.span", span, 0, lo_open=True, expected="span > 0 [m]")
    check_range(f"{name}.ring_depth", ring_depth, 0, lo_open=True, expected="ring_depth > 0 [m]")
    n = int(check_range(f"{name}.voussoirs", n_voussoirs, 3, expected="voussoirs >= 3"))
    check_range(f"{name}.pier_height", pier_height, 0, expected="pier_height >= 0 [m]")
    check_range(f"{name}.pier_width", pier_width, 0, lo_open=True, expected="pier_width > 0 [m]")
    check_range(f"{name}.joint", joint, 0, expected="joint >= 0 [m]")
    ri, re = 0.5 * span, 0.5 * span + ring_depth
    cx, cy = 0.5 * span, pier_height
    if pier_height > 0 and pier_width < ring_depth:
        raise InputError(f"{name}.pier_width = {pier_width:g}: expected >= ring_depth = {ring_depth:g} m")
    dth = math.pi / n
    if joint / 2 >= ri * dth / 2:
        raise InputError(f"{name}.joint = {joint:g}: joints wider than the voussoirs at the intrados")
    polys = []
    for k in range(n):
        a0, a1 = math.pi - k * dth, math.pi - (k + 1) * dth  # voussoir between angles a1 < a0
        e0 = np.array([-math.sin(a0), math.cos(a0)])  # direction of increasing angle
        e1 = np.array([-math.sin(a1), math.cos(a1)])
        # each radial face moved by half a joint into the voussoir
        P = np.array([
            [cx + ri * math.cos(a0), cy + ri * math.sin(a0)] - 0.5 * joint * e0,
            [cx + ri * math.cos(a1), cy + ri * math.sin(a1)] + 0.5 * joint * e1,
            [cx + re * math.cos(a1), cy + re * math.sin(a1)] + 0.5 * joint * e1,
            [cx + re * math.cos(a0), cy + re * math.sin(a0)] - 0.5 * joint * e0,
        ])
        A = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
        polys.append(P if A > 0 else P[::-1].copy())
    piers = []
    if pier_height > 0:
        top = pier_height - 0.5 * joint  # a full joint below the springing voussoirs
        piers.append(_rect(-pier_width, 0.0, 0.0, top))
        piers.append(_rect(span, 0.0, span + pier_width, top))
    return polys, piers

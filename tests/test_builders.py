"""Geometry builders: exact dimensions, joints, openings, arches; bad geometry rejected."""
import math

import numpy as np
import pytest

from fem_blocks import builders as B
from fem_blocks.errors import InputError


def test_running_bond_thick_joints_exact_geometry():
    L, H, t = 0.25, 0.06, 0.01
    blocks = B.running_bond(4, 3, L, H, t)
    lay = B.Layout(blocks, g0=t)
    lay.check_no_overlap()
    assert len(blocks) == 3 + 4 + 3 + 4
    x0, x1, y0, y1 = lay.bbox()
    assert x1 - x0 == pytest.approx(3 * L + 2 * t, rel=1e-14)
    assert y1 - y0 == pytest.approx(4 * H + 3 * t, rel=1e-14)
    halves = [b for b in blocks if b.length < L]
    assert len(halves) == 4 and all(b.length == pytest.approx((L - t) / 2, rel=1e-14) for b in halves)
    # every course spans the same width, head joints are exactly t
    for c in range(4):
        row = sorted((b for b in blocks if b.course == c), key=lambda b: b.x)
        gaps = [q.x - (p.x + p.length) for p, q in zip(row, row[1:])]
        assert np.allclose(gaps, t, rtol=1e-12)
        assert row[-1].x + row[-1].length - row[0].x == pytest.approx(3 * L + 2 * t, rel=1e-14)
    assert set(lay.block_sizes()) == {(L, H), (round((L - t) / 2, 12), H)}


def test_expanded_bricks_touch():
    L, H, t = 0.25, 0.06, 0.01
    blocks = B.running_bond(2, 2, L, H, t, expanded=True)
    assert all(b.height == pytest.approx(H + t) for b in blocks)
    row = sorted((b for b in blocks if b.course == 1), key=lambda b: b.x)
    assert [b.length for b in row] == pytest.approx([(L + t) / 2, L + t, (L + t) / 2])
    assert all(q.x == pytest.approx(p.x + p.length, abs=1e-15) for p, q in zip(row, row[1:]))


def test_opening_cuts_blocks_and_keeps_area():
    L, H, t = 0.2, 0.05, 0.0
    blocks = B.running_bond(8, 6, L, H, t, openings=[(0.4, 0.1, 0.8, 0.3)])
    B.Layout(blocks).check_no_overlap()
    area = sum(b.length * b.height for b in blocks)
    assert area == pytest.approx(6 * L * 8 * H - 0.4 * 0.2, rel=1e-12)
    for b in blocks:  # no block inside the opening
        assert b.x + b.length <= 0.4 + 1e-12 or b.x >= 0.8 - 1e-12 or b.y + b.height <= 0.1 + 1e-12 or b.y >= 0.3 - 1e-12


def test_opening_side_on_an_inexact_course_face_cuts_no_extra_course():
    """Bug caught: cut_opening compared the course faces exactly while opening_extent (the report) used a tolerance:
    with 62 mm courses the face of course 11 is 11 x 0.062 = 0.68199... m in floating point, so an opening asked up
    to 0.682 m removed a brick of course 11 that the report said was untouched. Expected by hand: the opening
    [0.33, 0.31, 0.66, 0.682] of a 4.5-brick wall (220 x 62 mm expanded bricks) meets courses 5 to 10 only and
    removes one block per course (one brick inside, one cut to a half)."""
    rows = [[1, 1, 1, 1, 0.5], [0.5, 1, 1, 1, 1]] * 8
    lay = B.courses(rows, 0.21, 0.052, 0.01, expanded=True)
    cut = B.cut_opening(lay, (0.33, 0.31, 0.66, 0.682), 0.21, 0.01, True, "wall.openings[0]")
    per_course = lambda bl, c: sorted((round(b.x, 9), round(b.length, 9)) for b in bl if b.course == c)
    for c in range(16):
        if 5 <= c <= 10:
            assert len(per_course(cut, c)) == len(per_course(lay, c)) - 1, c
        else:
            assert per_course(cut, c) == per_course(lay, c), c


def test_lmgc90_window_wall_courses():
    """The benchmark wall of bench/ (LMGC90's deformable-brick example): explicit courses with gaps."""
    g = {"gap": 0.2}
    rows = [[0.5, 1, 1, 1, 1, 0.5], [1] * 5, [0.5, 1, 1, 1, 1, 0.5], [1] * 5,
            [0.5, 1, g, 1, 0.5], [1, 0.5, g, 0.5, 1], [0.5, 1, g, 1, 0.5], [1, 3, 1], [0.5, 1, 1, 1, 1, 0.5]]
    blocks = B.courses(rows, 0.1, 0.05)
    B.Layout(blocks).check_no_overlap()
    assert len(blocks) == 6 + 5 + 6 + 5 + 4 + 4 + 4 + 3 + 6
    assert {b.size_key for b in blocks} == {(0.1, 0.05), (0.05, 0.05), (0.3, 0.05)}
    for c in range(9):
        row = [b for b in blocks if b.course == c]
        assert max(b.x + b.length for b in row) == pytest.approx(0.5, abs=1e-12)


def test_prism_and_rigid_parts():
    blocks = B.stack_prism(5, 0.2, 0.05, 0.01)
    assert [b.y for b in blocks] == pytest.approx([0, 0.06, 0.12, 0.18, 0.24])
    f = B.foundation(blocks, 0.1, 0.05, joint=0.01)
    beam = B.top_beam(blocks, 0.1, 0.05, joint=0.01)
    assert f.vertices[:, 1].max() == pytest.approx(-0.01) and beam.vertices[:, 1].min() == pytest.approx(0.30)
    # expanded: bed joints only (stack bond), so the blocks are L x (H + t_j), not (L + t_j) wide
    ex = B.stack_prism(3, 0.2, 0.05, 0.01, expanded=True)
    got = np.array([(b.x, b.y, b.length, b.height) for b in ex])
    assert np.allclose(got, [(0, 0, 0.2, 0.06), (0, 0.06, 0.2, 0.06), (0, 0.12, 0.2, 0.06)], rtol=0, atol=1e-15)


def test_arch_voussoirs():
    span, d, n, t = 2.0, 0.3, 9, 0.01
    vous, piers = B.semicircular_arch(span, d, n, 1.0, 0.4, joint=t)
    assert len(vous) == n and len(piers) == 2
    for P in vous:
        A = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
        assert A > 0
    # joint between consecutive voussoirs: faces parallel at distance t
    a = math.pi - math.pi / n
    e = np.array([-math.sin(a), math.cos(a)])
    d1 = np.dot(vous[0][1] - np.array([1.0, 1.0]), e)  # face of voussoir 0 at angle a (moved +t/2)
    d2 = np.dot(vous[1][0] - np.array([1.0, 1.0]), e)
    assert d1 - d2 == pytest.approx(t, rel=1e-12)
    assert vous[0][:, 1].min() - piers[0][:, 1].max() == pytest.approx(t, rel=1e-12)


@pytest.mark.parametrize("call, match", [
    (lambda: B.running_bond(0, 3, 0.2, 0.05), "wall.courses"),
    (lambda: B.running_bond(2, 3, -0.2, 0.05), "brick_length"),
    (lambda: B.running_bond(2, 3, 0.2, 0.05, joint=-0.01), "joint"),
    (lambda: B.running_bond(2, 3, 0.2, 0.05, openings=[(0.1, 0.0, 5.0, 0.05)]), "opening outside the wall"),
    (lambda: B.running_bond(2, 3, 0.2, 0.05, openings=[(0.3, 0.0, 0.1, 0.05)]), "x0 < x1"),
    (lambda: B.courses([[1, {"gap": -1}]], 0.2, 0.05), r"gap"),
    (lambda: B.semicircular_arch(2, 0.3, 9, 1.0, 0.2), "pier_width"),
    (lambda: B.semicircular_arch(2, 0.3, 2, 1.0, 0.4), "voussoirs"),
])
def test_bad_geometry(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_overlap_detected():
    blocks = [B.Block(0.2, 0.05, 0, 0, 0), B.Block(0.2, 0.05, 0.1, 0.01, 0)]
    with pytest.raises(InputError, match="overlap"):
        B.Layout(blocks).check_no_overlap()


def test_overlap_check_names_the_first_overlapping_pair_and_accepts_touching_blocks():
    """Layout.check_no_overlap on a running-bond wall (blocks touching along every joint: no error) and the same wall
    with one block of the second course moved up by a quarter of its height onto its upper neighbours.
    Catches: touching counted as overlap (the tolerance dropped), a pair missed by the broad phase, the wrong pair
    named."""
    blocks = B.running_bond(3, 6, 0.2, 0.05, 0.0)
    B.Layout(blocks).check_no_overlap()
    moved = list(blocks)
    k = next(i for i, b in enumerate(blocks) if b.course == 1 and b.x > 0.05)
    b = blocks[k]
    moved[k] = B.Block(b.length, b.height, b.x, b.y + 0.25 * b.height, b.course, b.group)
    over = sorted(j for j, c in enumerate(blocks) if j != k and c.course == 2 and c.x < b.x + b.length - 1e-12
                  and c.x + c.length > b.x + 1e-12)
    with pytest.raises(InputError, match=rf"blocks {min(k, over[0])} and {max(k, over[0])} overlap"):
        B.Layout(moved).check_no_overlap("wall")

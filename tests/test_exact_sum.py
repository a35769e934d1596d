"""Exact, order-independent sums (fem_blocks/distributed/exact.py).

Expectation (independent of the code under test): math.fsum, Python's correctly rounded sum (Shewchuk's partials,
round-half-even), on the same terms, bitwise; and hand-computed roundings (ties to even, subnormal results, the
largest double). The sum must not depend on the order of the terms, on how they are split into accumulators, or
on the number of MPI ranks holding them (mpirun -n 3, one rank empty; in-process: one rank).
"""
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
from numba import njit

from fem_blocks.distributed import exact

from _mpi import ENV  # noqa: E402
from _paths import ROOT  # noqa: E402

MAX = sys.float_info.max
TINY = 5e-324  # 2^-1074, the smallest subnormal


def bits(v):
    return int(np.float64(v).view(np.int64))


def same(a, b):
    """Bitwise equality of two doubles (so 0.0 != -0.0 and nan == nan of the same bits)."""
    return bits(a) == bits(b)


def wide(rng, n):
    """n terms of both signs, magnitudes 1e-300..1e300."""
    return rng.choice([-1.0, 1.0], n) * rng.uniform(1, 10, n) * 10.0 ** rng.integers(-300, 300, n)


@pytest.mark.parametrize("seed", range(5))
def test_mixed_signs_and_exponents_equal_fsum(seed):
    """Random terms of both signs over 600 decades, plus cancelling pairs and subnormals: the exact sum rounded
    once is math.fsum bitwise (catches a lost sign, e.g. the sign mask s = b >> 63 replaced by 0, or a term's
    pieces put one limb off)."""
    rng = np.random.default_rng(seed)
    x = wide(rng, 5000)
    x = np.concatenate([x, -x[:1000], rng.integers(1, 1 << 52, 200) * TINY, [1e16, 1.0, -1e16]])
    rng.shuffle(x)
    assert same(exact.exact_sum(x), math.fsum(x))
    # magnitudes within a few decades, where the rounding of the total matters
    y = rng.normal(size=5000) * 10.0 ** rng.uniform(-3, 3, 5000)
    assert same(exact.exact_sum(y), math.fsum(y))


CASES = [  # terms, the correctly rounded sum computed by hand
    ([1e16, 1.0, -1e16], 1.0),                                # cancellation
    ([1.0, 2.0 ** -53], 1.0),                                 # tie, to even (down)
    ([1.0 + 2.0 ** -52, 2.0 ** -53], 1.0 + 2.0 ** -51),       # tie, to even (up)
    ([1.0, 2.0 ** -53, TINY], 1.0 + 2.0 ** -52),              # just above the tie, by 2^-1074
    ([1.0, -(2.0 ** -54), -TINY], 1.0 - 2.0 ** -53),          # below the tie 1 - 2^-54 (ulp 2^-53 below 1): down
    ([TINY, TINY], 2 * TINY),                                 # subnormal
    ([2.0 ** -1022, -TINY], 2.0 ** -1022 - TINY),             # the largest subnormal
    ([3 * TINY, -TINY, 2.0 ** -1030], 2.0 ** -1030 + 2 * TINY),
    ([MAX, -MAX], 0.0),
    ([MAX, 2.0 ** 969], MAX),                                 # below half an ulp of MAX (2^970): MAX
    ([-0.0], 0.0), ([-0.0, -0.0], 0.0), ([], 0.0),             # an exact zero is +0.0 (as fsum on Python 3.11)
]


@pytest.mark.parametrize("terms, expected", CASES)
def test_hand_rounded_cases(terms, expected):
    """Sums whose correct rounding is known by hand, and equal to math.fsum (catches a double rounding in value,
    e.g. math.ldexp(float(total), -1074): float(total) rounds to 53 bits before the scaling rounds again, wrong at
    ties and in the subnormal range, and overflows for totals above 2^1024)."""
    x = np.array(terms, dtype=np.float64)
    assert same(exact.exact_sum(x), expected)
    assert same(exact.exact_sum(x), math.fsum(terms))


def test_beyond_the_double_range_and_non_finite():
    """Totals past the largest double round to ±inf (the tie MAX + 2^970 goes to the even 2^1024), totals back in
    range after huge partial sums are exact (math.fsum raises there); inf and nan propagate as in IEEE arithmetic
    (catches the special bins ignored: inf would be taken as a huge finite term)."""
    s = exact.exact_sum
    assert s(np.array([MAX, 2.0 ** 970])) == math.inf and s(np.array([-MAX, -MAX])) == -math.inf
    assert same(s(np.array([MAX, MAX, -MAX])), MAX)
    assert same(s(np.array([MAX] * 1000 + [-MAX] * 999 + [1.0])), MAX)
    assert s(np.array([1.0, math.inf])) == math.inf and s(np.array([-math.inf, 1.0])) == -math.inf
    assert math.isnan(s(np.array([math.inf, -math.inf]))) and math.isnan(s(np.array([1.0, math.nan])))


def test_huge_and_subnormal_terms_together_equal_fsum():
    """Cancelling huge pairs near the top of the range, subnormals and the smallest normals, one array: fsum
    bitwise (catches the subnormal exponent taken as E - 1 = -1 instead of 0, or the implicit bit set for E = 0)."""
    rng = np.random.default_rng(3)
    big = rng.uniform(1e306, 1e308, 300)
    pairs = np.ravel(np.column_stack([big, -big * (1 + rng.uniform(-1e-10, 1e-10, 300))]))
    sub = rng.choice([-1, 1], 400) * rng.integers(1, 1 << 52, 400) * TINY
    small = rng.choice([-1, 1], 200) * rng.uniform(1, 2, 200) * 2.0 ** -1022
    for x in (pairs, sub, small, np.concatenate([pairs[:2], sub, small]), np.concatenate([sub, small])):
        assert same(exact.exact_sum(x), math.fsum(x))
    sub = rng.choice([-1, 1], 400) * rng.integers(1, 1 << 44, 400) * TINY
    assert same(exact.exact_sum(sub), math.fsum(sub)) and 0 < abs(math.fsum(sub)) < 2.0 ** -1022  # subnormal total


def test_one_million_terms_and_cost():
    """10^6 terms: fsum bitwise; the accumulation costs a few ns per term (bound 100 ns, loose for a loaded
    machine: catches accumulate running as Python, e.g. its njit removed). Prints the cost measured."""
    rng = np.random.default_rng(11)
    x = rng.normal(size=10 ** 6) * 10.0 ** rng.uniform(-20, 20, 10 ** 6)
    acc = exact.new()
    exact.accumulate(x[:10], acc)  # compiled
    best = math.inf
    for _ in range(3):
        acc = exact.new()
        t0 = time.perf_counter()
        exact.accumulate(x, acc)
        best = min(best, time.perf_counter() - t0)
    assert same(exact.value(acc), math.fsum(x))
    print(f"accumulate: {best * 1e6:.0f} us for 1e6 terms ({best * 1e3:.2f} ns per term), "
          f"message {exact.NBINS * 8} bytes")
    assert best < 0.1


def test_any_order_and_any_split_give_the_same_bits():
    """Permutations of the terms, and splits into 1..17 parts (empty parts included) accumulated separately whose
    bins are then added as integers (what the Allreduce does): always fsum of the whole, bitwise (catches value
    assuming normalised limbs, e.g. each limb but the top one masked to 32 bits: exact_sum normalises before value,
    a sum of raw accumulators does not)."""
    rng = np.random.default_rng(2)
    x = np.concatenate([wide(rng, 3000), rng.normal(size=3000), rng.integers(1, 1 << 52, 100) * TINY])
    ref = math.fsum(x)
    for trial in range(20):
        p = rng.permutation(x)
        assert same(exact.exact_sum(p), ref)
        k = int(rng.integers(1, 18))
        cuts = np.sort(rng.integers(0, p.size + 1, k - 1))
        total = exact.new()
        for part in np.split(p, cuts):
            acc = exact.new()
            exact.accumulate(part, acc)
            if trial % 2:
                exact.normalise(acc)
            total += acc
        assert same(exact.value(total), ref)


@njit
def _add_loop(x, acc):
    for i in range(x.shape[0]):
        exact.add(acc, x[i])


def test_normalise_and_the_renormalisation_bound():
    """normalise keeps the value and brings limbs 0..NLIMB-2 into [0, 2^32); add and accumulate normalise by
    themselves when PENDING reaches RENORM = 2^30 terms, so int64 limbs never overflow (2^30 terms of < 2^32 per
    limb over a normalised state stay below 2^63) (catches a missing renormalisation, e.g. the PENDING count not
    incremented, which would overflow after 2^31 terms, too many to run here)."""
    rng = np.random.default_rng(4)
    x = wide(rng, 2000)
    acc = exact.new()
    exact.accumulate(-np.abs(x), acc)
    exact.accumulate(x[:100], acc)
    assert np.any(acc[:exact.NLIMB] < 0)
    before = exact.value(acc)
    norm = acc.copy()
    exact.normalise(norm)
    lim = norm[:exact.NLIMB - 1]
    assert np.all((lim >= 0) & (lim < 2 ** 32)) and norm[exact.PENDING] == 0
    assert same(exact.value(norm), before) and same(before, math.fsum(np.concatenate([-np.abs(x), x[:100]])))
    # the count reaching RENORM triggers the normalisation, from add (per term) and from accumulate (per call)
    for fn in (_add_loop, exact.accumulate):
        acc = exact.new()
        acc[exact.PENDING] = exact.RENORM - 5
        if fn is _add_loop:
            _add_loop(-np.abs(x[:4]), acc)
            assert acc[exact.PENDING] == exact.RENORM - 1
            _add_loop(-np.abs(x[4:10]), acc)
        else:
            exact.accumulate(-np.abs(x[:10]), acc)
        assert acc[exact.PENDING] < 10 and np.all(acc[:exact.NLIMB - 1] >= 0)
        assert same(exact.value(acc), math.fsum(-np.abs(x[:10])))


def test_add_in_a_numba_loop_equals_accumulate_and_exact_sums():
    """exact.add inside a compiled loop (the sweep's use) = accumulate = exact_sums' entries = fsum, bitwise; a
    strided view is read correctly (catches add diverging from accumulate, e.g. its bits taken from abs(x))."""
    rng = np.random.default_rng(6)
    x = wide(rng, 4001)
    a1, a2 = exact.new(), exact.new()
    _add_loop(x, a1)
    exact.accumulate(x, a2)
    assert np.array_equal(a1[:exact.NLIMB], a2[:exact.NLIMB]) and same(exact.value(a1), math.fsum(x))
    s = exact.exact_sums([x, x[::3], x[:0], np.sqrt(np.abs(x))], comm=None)
    assert [bits(v) for v in s] == [bits(math.fsum(v)) for v in (x, x[::3], x[:0], np.sqrt(np.abs(x)))]
    from mpi4py import MPI
    assert same(exact.exact_sum(x[1::2], MPI.COMM_SELF), math.fsum(x[1::2]))  # size 1: no reduction


def _mpirun(n, out):
    p = subprocess.run(["mpirun", "-n", str(n), sys.executable, os.path.join(ROOT, "tests", "_exact_mpi.py"),
                        str(out)], capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    return np.load(out)


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
@pytest.mark.parametrize("n", [3])
def test_mpirun_split_across_ranks_same_bits_on_every_rank(tmp_path, n):
    """A global array split unevenly across N = 3 ranks (rank 0 empty for N > 1): exact_sum (mpi4py
    communicator) and exact_sums of three arrays in one Allreduce (petsc4py communicator) give on every rank the
    same bits, math.fsum of the global array (catches the Allreduce skipped: each rank would return its own
    part's sum, 0.0 on the empty rank)."""
    out = _mpirun(n, tmp_path / "out.npz")
    got, x, y = out["got"], out["x"], out["y"]
    assert got.shape == (n, 5)
    assert got[:, 4].sum() == x.size and (n == 1 or got[0, 4] == 0)
    expected = np.array([math.fsum(x), math.fsum(x), math.fsum(y), math.fsum(y)])
    assert np.array_equal(got[:, :4].view(np.int64), np.tile(expected, (n, 1)).view(np.int64))
    # exact.largest (the history's largest velocity, dynamics.Simulation.max_velocity): the largest rank number
    # n - 1 on every rank; NaN on every rank whichever rank holds the NaN (an Allreduce MAX of Python floats kept
    # it only when it came first: max(v, nan) is v)
    big = out["largest"]
    assert big.shape == (n, n + 1) and np.all(big[:, 0] == n - 1)
    assert np.isnan(big[:, 1:]).all(), big

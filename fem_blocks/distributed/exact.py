"""Exact, order-independent sums of doubles: the same result, bitwise, for any order of the terms and any split of
them across ranks.

Every finite double is an integer multiple of 2^-1074: x = (-1)^s M 2^(E-1075) with M = 2^52 + F for a biased
exponent E >= 1 and x = (-1)^s F 2^-1074 for E = 0 (subnormals), F the 52 stored fraction bits. So

    x 2^1074 = (-1)^s M 2^k,   k = max(E, 1) - 1 in [0, 2045],  M < 2^53,

an integer below 2^2099 in magnitude. The accumulator holds Σ x_i 2^1074 exactly, as a fixed-point integer in
limbs of 32 bits: acc[j] counts units of 2^(32 j - 1074), j = 0 .. NLIMB-1, each an int64 that may carry any sign
and more than 32 bits, the value being Σ_j acc[j] 2^(32 j) 2^-1074. A term M 2^k, k = 32 j + o (0 <= o < 32),
adds its three 32-bit pieces (M 2^o) mod 2^32, (M 2^o >> 32) mod 2^32 and M 2^o >> 64 (< 2^21) to limbs j, j+1,
j+2 with the term's sign: integer additions, so exact and associative. A limb grows by < 2^32 per term: after at
most 2^30 terms since the last normalisation (`normalise`: carries propagated so that limbs 0..NLIMB-2 lie in
[0, 2^32) and the top one holds the signed rest) it stays below 2^62 + 2^32 < 2^63; `add`/`accumulate`
normalise by themselves when that count (bin PENDING) reaches 2^30, so no number of terms overflows.
Accumulators add as integer vectors (bins summed), which is what one MPI Allreduce (SUM, int64) does: every bin
of the sum is a sum of the parts' bins, counters included, and each part is normalised before, so the reduced
bins stay below P 2^32 for P ranks.

Non-finite terms are counted (bins POSINF, NEGINF, NAN): the sum is NaN if any term is NaN or both infinities
occur, ±inf if one infinity occurs (math.fsum raises ValueError for inf + -inf).

`value` rounds the exact sum S = (Σ_j acc[j] 2^(32 j)) 2^-1074 once to the nearest double, ties to even: the
integer numerator is built with Python ints and divided by 2^1074 with int / int, which CPython rounds correctly
(subnormal results included). An exact zero gives +0.0 (math.fsum on Python 3.11 likewise, even for -0.0 terms).
A sum beyond the largest double gives ±inf (IEEE rounding; math.fsum raises OverflowError, also whenever a
partial sum overflows although the total would not). Otherwise the result is math.fsum's, bitwise.

Message of a reduction: NBINS int64 = 560 bytes per summed quantity (`exact_sums` reduces several in one
Allreduce of len(xs) NBINS int64).

A maximum is exact under any order and split by itself: `largest` is the ranks' largest of one double (one
Allreduce MAX), beside the sums for the same readers (the sweeps' stopping tests, the largest velocity and
displacement increment of a step).
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

NLIMB = 66        # limbs of 32 bits: a term touches limbs j..j+2, j = k >> 5 <= 63; the top limb holds the rest
PENDING = NLIMB   # terms added since the last normalisation (an upper bound: parts' counts add)
POSINF = NLIMB + 1
NEGINF = NLIMB + 2
NAN = NLIMB + 3
NBINS = NLIMB + 4
RENORM = 1 << 30  # normalise when PENDING reaches this: limbs stay below 2^62 + 2^32
_SCALE = 1 << 1074


@intrinsic
def _bits(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (a bit cast)."""
    if not isinstance(x, types.Float) or x.bitwidth != 64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


def new() -> np.ndarray:
    """An empty accumulator: int64 zeros (NBINS,)."""
    return np.zeros(NBINS, dtype=np.int64)


@njit(cache=True)
def normalise(acc):
    """Propagate the carries of the limbs (value unchanged): limbs 0..NLIMB-2 in [0, 2^32), the top one signed;
    PENDING reset to 0. acc may also be (m, NBINS): every row."""
    a = acc.reshape(-1, acc.shape[-1])
    for i in range(a.shape[0]):
        c = 0
        for j in range(NLIMB - 1):
            v = a[i, j] + c
            c = v >> 32              # floor division by 2^32 (arithmetic shift)
            a[i, j] = v - (c << 32)  # in [0, 2^32)
        a[i, NLIMB - 1] += c
        a[i, PENDING] = 0


@njit(cache=True, inline="always")
def _add_bits(acc, b):
    """acc += the double whose bits are b, exactly (no PENDING count)."""
    e = (b >> 52) & 0x7FF
    if e == 0x7FF:  # inf or nan
        if b & 0xFFFFFFFFFFFFF:
            acc[NAN] += 1
        elif b < 0:
            acc[NEGINF] += 1
        else:
            acc[POSINF] += 1
        return
    m = b & 0xFFFFFFFFFFFFF
    if e != 0:
        m |= 0x10000000000000
        e -= 1
    j = e >> 5
    o = e & 31
    lo = (m & (0xFFFFFFFF >> o)) << o  # (M 2^o) mod 2^32, without overflowing
    hi = m >> (32 - o)     # M 2^o >> 32 < 2^52
    mid = hi & 0xFFFFFFFF
    top = hi >> 32
    s = b >> 63            # 0 or -1: (v ^ s) - s is v or -v
    acc[j] += (lo ^ s) - s
    acc[j + 1] += (mid ^ s) - s
    acc[j + 2] += (top ^ s) - s


@njit(cache=True, inline="always")
def add(acc, x):
    """acc += x exactly (one float64; for use inside numba loops)."""
    _add_bits(acc, _bits(x))
    acc[PENDING] += 1
    if acc[PENDING] >= RENORM:
        normalise(acc)


@njit(cache=True)
def accumulate(x, acc):
    """acc += Σ_i x[i] exactly (x float64 1-D of any sign, any stride; acc an accumulator, changed in place)."""
    n = x.shape[0]
    i = 0
    while i < n:
        stop = min(n, i + (RENORM >> 1))
        for k in range(i, stop):
            _add_bits(acc, _bits(x[k]))
        acc[PENDING] += stop - i
        if acc[PENDING] >= RENORM:
            normalise(acc)
        i = stop


def value(acc) -> float:
    """The exact sum held by acc, rounded once to the nearest double (ties to even): math.fsum of the same terms,
    bitwise (see the module docstring for zeros, infinities and overflow)."""
    acc = np.asarray(acc)
    if acc[NAN] > 0 or (acc[POSINF] > 0 and acc[NEGINF] > 0):
        return math.nan
    if acc[POSINF] > 0:
        return math.inf
    if acc[NEGINF] > 0:
        return -math.inf
    total = 0
    for j in range(NLIMB - 1, -1, -1):
        total = (total << 32) + int(acc[j])
    if total == 0:
        return 0.0
    try:
        return total / _SCALE  # int / int: correctly rounded in CPython
    except OverflowError:
        return math.inf if total > 0 else -math.inf


def _mpi_comm(comm):
    """An mpi4py communicator from an mpi4py or petsc4py one (None: serial)."""
    if comm is None:
        return None
    if hasattr(comm, "tompi4py"):
        comm = comm.tompi4py()
    return comm if comm.Get_size() > 1 else None


def allreduce(acc, comm=None):
    """Normalise acc ((NBINS,) or (m, NBINS)) and replace it by the sum of every rank's, in place, with one
    Allreduce (SUM, int64); collective. comm: mpi4py or petsc4py communicator; None or size 1: normalise only."""
    normalise(acc)
    comm = _mpi_comm(comm)
    if comm is not None:
        from mpi4py import MPI
        comm.Allreduce(MPI.IN_PLACE, [acc, MPI.INT64_T], op=MPI.SUM)
    return acc


def exact_sums(xs, comm=None) -> list[float]:
    """[Σ x for x in xs] over the local arrays and, when comm has several ranks, every rank's (one Allreduce of
    len(xs) NBINS int64 for them all; collective, every rank passes as many arrays): each sum exact then rounded
    once, the same double on every rank whatever the split of the terms."""
    accs = np.zeros((len(xs), NBINS), dtype=np.int64)
    for i, x in enumerate(xs):
        accumulate(np.asarray(x, dtype=np.float64).ravel(), accs[i])
    allreduce(accs, comm)
    return [value(a) for a in accs]


def largest(x: float, comm=None) -> float:
    """The largest of every rank's x, NaN if any rank's x is NaN (one Allgather of a double per rank; collective):
    np.max of the gathered values, so a NaN on any rank reaches every rank (a reduction by max applies it pairwise,
    and max(v, nan) is v: whether a NaN survived would depend on its rank). comm: mpi4py or petsc4py
    communicator; None or size 1: x."""
    comm = _mpi_comm(comm)
    if comm is None:
        return x
    every = np.empty(comm.Get_size())
    comm.Allgather(np.array([x], dtype=np.float64), every)
    return float(np.max(every))


def exact_sum(x, comm=None) -> float:
    """Σ x over the local array and, when comm has several ranks, every rank's (one Allreduce of NBINS int64,
    560 bytes; collective): exact then rounded once, math.fsum of all the terms bitwise, the same on every rank."""
    return exact_sums([x], comm)[0]

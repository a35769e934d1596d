"""The greedy colouring of a graph spread over MPI ranks (fem_blocks/distributed/greedy.py): the colours of the
sequential greedy (solver/parallel.pair_colouring) on the union of every rank's edges, on any number of ranks, without
any rank holding the graph.

Expectation: the definition of the greedy colouring, c(v) = min{k ≥ 0 : k ≠ c(w) for every neighbour w < v},
applied vertex by vertex in plain Python to the whole graph in this process; solver/parallel.pair_colouring (the
serial colouring of every run in colour order, whose pass the ranks share) must give the same colours. One mpirun launch per rank count
(tests/_greedy_mpi.py, four graphs each: random with duplicates and self-pairs, random plus a path through every
vertex, one vertex alone, vertices without edges); on 2 ranks both own vertices, on 3 the last owns none; each edge is
given only to the owner of its first end. Catches: an edge not made symmetric (a rank colouring a vertex before a
lower neighbour it does not know of), a colour other than the smallest free one, a vertex coloured before its lower ghost neighbours' colours arrived, the
colour of a ghost read from the wrong rank or position, a rank leaving the rounds early (hang: the launch times out).
"""
import numpy as np
import pytest

from fem_blocks.solver.parallel import pair_colouring

import _greedy_mpi  # noqa: E402 (tests/ is on sys.path: tests/conftest.py)
from _mpi import run_helper  # noqa: E402


def greedy_by_definition(n, a, b):
    """c(v) = the smallest k ≥ 0 that no neighbour w < v has, for v = 0, 1, ..., n - 1 (edges either way)."""
    lower = [set() for _ in range(n)]
    for x, y in zip(a.tolist(), b.tolist()):
        if x != y:
            lower[max(x, y)].add(min(x, y))
    c = []
    for v in range(n):
        taken = {c[w] for w in lower[v]}
        c.append(next(k for k in range(n + 1) if k not in taken))
    return np.array(c, dtype=np.int64)


@pytest.mark.parametrize("size", [1, 2, 3])
def test_distributed_greedy_colours_are_the_serial_greedy(tmp_path, size):
    run_helper(size, "_greedy_mpi.py", tmp_path)
    got = [np.load(tmp_path / f"rank{r}.npz") for r in range(size)]
    for k in range(4):
        n, a, b, owner = _greedy_mpi.graph(k, size)
        ref = greedy_by_definition(n, a, b)
        assert np.array_equal(pair_colouring(n, a, b), ref)
        if k == 1:
            assert ref.max() >= 3  # a graph that needs several colours
            if size > 1:  # the path's dependencies cross ranks: several rounds, the same count on every rank
                assert len({int(g["rounds_1"]) for g in got}) == 1 and int(got[0]["rounds_1"]) > 2
        for r in range(size):
            ids, col = got[r][f"ids_{k}"], got[r][f"colour_{k}"]
            mine = np.flatnonzero(owner == r)
            assert np.all(np.isin(mine, ids))  # its vertices, and the neighbours it saw
            assert np.array_equal(col, ref[ids]), (k, r)
        assert len(np.unique(owner)) == min(size, 2) or n == 1  # vertices on 2 ranks (on 3: the last has none)
        if size > 2:
            assert not np.any(owner == size - 1)

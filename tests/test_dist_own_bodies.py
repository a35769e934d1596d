"""What the step and the runner's per-step checks read of the bodies on N > 1 ranks: only the rank's bodies B_p
(those it owns, those of its own contacts, the rigid bodies), the prerequisite for each rank to step only those
(docs/scaling.md "Bodies").

Expectation (from outside the distributed code): the same steps on ONE process in colour order. On 2 and 3 ranks
the state of every deformable body outside B_p is set to NaN after each step (tests/_own_bodies_mpi.py); the next
steps must still give, on every rank and bit for bit, the serial history's sums over bodies (energies, external,
driver and inertia work, largest velocity), the rigid bodies' reactions and their inertia parts, the record of
every contact, the state of each body of B_p, no NaN found by the body check, and the small-rotation watch's record
(largest rotation, its block, the blocks beyond a bound). Case: a wall of 6 x 6 bricks with mixed-mode cohesive
joints under a rigid beam pushed sideways (its reaction has an inertia part), in frozen geometry (the contact set
and G fixed: detection reads every body, so updated geometry waits for the per-rank detection).

One-line bugs these catch (checked): the largest velocity taken over every body; the body check or the rotation
watch reading every body. (The step's largest displacement increment taken over every body is not caught: it only
sets the threshold below which a driven dof counts as standing still, docs/testing.md row 60.)
"""
import pytest

import dist_cases
from _mpi import rank_results, run_alone, run_helper

HELPER = "_own_bodies_mpi.py"
BEAM = """[wall.beam]
depth = 0.1
overhang = 0.0
rho = 2000.0
[wall.beam.drivers]
x = {kind = "velocity", history = 0.01}
rz = {kind = "velocity", history = 0.0}
[[interfaces]]
name = "b"
between = ["bricks", "beam"]
mu = 0.7
"""
CASE = dist_cases.wall("own_bodies", courses=6, per=6, joint=dist_cases.MIXED).replace("[[interfaces]]\n",
                                                                                      BEAM + "[[interfaces]]\n", 1)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    d = tmp_path_factory.mktemp("own_bodies")
    path = d / "own_bodies.toml"
    path.write_text(CASE)
    run_alone(HELPER, path, d / "serial")
    return path, rank_results(d / "serial", 1)[0]


@pytest.mark.parametrize("n", [2, 3])
def test_the_step_and_checks_read_only_the_ranks_bodies(serial, n, tmp_path):
    path, one = serial
    run_helper(n, HELPER, path, tmp_path / "out", timeout=300)
    ranks = rank_results(tmp_path / "out", n)
    assert all(min(r["poisoned"]) > 0 for r in ranks)  # every rank had bodies it does not step
    for r in ranks:
        for mine, ref in zip(r["steps"], one["steps"]):
            assert mine["sums"] == ref["sums"]
            for key in ("reactions", "record", "guard", "watch"):
                assert mine[key] == ref[key], key
            assert mine["bodies"] and all(ref["bodies"][i] == v for i, v in mine["bodies"].items())
    first = one["steps"][0]
    assert first["guard"] is None and first["watch"]["blocks_beyond"] and first["sums"][6] > 0
    assert all(s["sums"][5] != 0.0 for s in one["steps"])  # inertia work, shared among the beam's moving dofs
    assert len(set(s["record"] for s in one["steps"])) == 3  # the steps differ

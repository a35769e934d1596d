"""Each rank steps only its bodies on N > 1 ranks (frozen geometry, colour order): B_p (those it owns, those of its
own contacts, the rigid bodies) and the bodies shared with every rank (Simulation.share_bodies), and what the step
and the runner's per-step checks read of the bodies is only those (docs/scaling.md "Bodies stepped per rank").

Expectation (from outside the distributed code): the same steps on ONE process in colour order. On 2 and 3 ranks
(tests/_own_bodies_mpi.py) every rank must give, bit for bit, the serial history's sums over bodies (energies,
external, driver and inertia work, largest velocity), the rigid bodies' reactions and their inertia parts, the record
of every contact, the state of each body of B_p and of the shared bodies, no NaN found by the body check, and the
small-rotation watch's record (largest rotation, its block, the blocks beyond a bound); every other deformable body
must be NaN on that rank, and from the second step (the partition is made during the first) every solve by a step
operator (free velocities, corrections) must have the columns of the group's bodies in B_p and the shared ones.
Case: a wall of 6 x 6 bricks with mixed-mode cohesive joints under a rigid beam pushed sideways (its reaction has an
inertia part), in frozen geometry (the contact set and G fixed: detection reads every body, so updated geometry
steps every body until the per-rank detection).

One-line bugs these catch (checked): the largest velocity taken over every body; the body check or the rotation
watch reading every body; every body stepped (the solves' columns; the other bodies not NaN); the shared bodies not
added to the stepped set (NaN on a rank whose B_p does not hold them); the bodies not stepped left with their last
values rather than NaN. (The step's largest displacement increment taken over every body is not caught: it only
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
def test_each_rank_steps_only_its_bodies_with_the_serial_bits(serial, n, tmp_path):
    path, one = serial
    run_helper(n, HELPER, path, tmp_path / "out", timeout=300)
    ranks = rank_results(tmp_path / "out", n)
    for r in ranks:
        for k, (mine, ref) in enumerate(zip(r["steps"], one["steps"])):
            assert mine["sums"] == ref["sums"]
            for key in ("reactions", "record", "guard", "watch"):
                assert mine[key] == ref[key], key
            # the stepped bodies hold the serial state; every other deformable body is NaN (not stepped)
            assert mine["bodies"] and all(ref["bodies"][i] == v for i, v in mine["bodies"].items())
            others = sorted(set(one["steps"][0]["stepped"]) - set(mine["stepped"]))
            assert others and mine["nan"] == others, k  # every rank has bodies it does not step
            if k:  # (step 1: the partition is made during the step, so its free velocities are every body's)
                assert mine["solves"] and all(c == mine["expected"][g] for g, c in mine["solves"]), mine["solves"]
    # a shared body outside a rank's B_p is stepped by that rank too (its state above)
    assert any(r["steps"][-1]["outside_shared"] for r in ranks)
    first = one["steps"][0]
    assert first["guard"] is None and first["watch"]["blocks_beyond"] and first["sums"][6] > 0
    assert all(s["sums"][5] != 0.0 for s in one["steps"])  # inertia work, shared among the beam's moving dofs
    assert len(set(s["record"] for s in one["steps"])) == 3  # the steps differ
    assert not one["steps"][-1]["nan"]  # one process steps every body

"""Run under mpirun by tests/test_dist_sweep.py, one launch per rank count: the file driver of the distributed
sweep (`python -m fem_blocks.distributed.colour`, its `main`) once per run listed in RUNS.json, in sequence in the
same processes (each run writes its OUT.npz on rank 0).

Usage: mpirun -n N python tests/_dist_sweep_mpi.py RUNS.json   (RUNS.json: a list of argument lists of main)
"""
import json
import sys

from fem_blocks.distributed import colour


def main(path):
    with open(path) as f:
        runs = json.load(f)
    for argv in runs:
        if colour.main(argv) != 0:
            raise SystemExit(f"colour.main({argv}) failed")


if __name__ == "__main__":
    main(sys.argv[1])

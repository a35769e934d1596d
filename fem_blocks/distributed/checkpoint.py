"""Checkpoints on N > 1 ranks: each rank writes its piece, together (`write_pieces`).

A round of writes (one checkpoint of the run): rank 0 draws a token and broadcasts it; every rank writes
`checkpoint.rank<p>.npz` (output/checkpoint.py `split`: the entries of its bodies, the rows of its contacts and
every other entry, with the token and the partition), keeping its previous piece as `.prev`; the ranks then agree
that every piece is on disk (one all-gather of the failures). Only then does rank 0 remove the files of another
layout (a one-process checkpoint.npz, the pieces of ranks >= N of an earlier run on more ranks).

The ranks write a round together, so no rank starts round k + 1 before every rank has finished round k: a run
killed during a round leaves each rank's newest piece of round k or k - 1, and the set of round k - 1 complete in
the newest and previous pieces (output/checkpoint.py `latest_checkpoint_files` takes the newest complete set).

A resumed run reads the whole set on every rank (`load_checkpoint`): the state is still held whole by every rank
(docs/scaling.md "Phase B1"); the pieces already hold what each rank will own when the bodies are distributed.
"""
from __future__ import annotations

import uuid

from ..output.checkpoint import piece_names, remove_other_layout, split, write_checkpoint


def write_pieces(comm, directory: str, arrays: dict, body_owner, body_of, contact_keys, before=None) -> None:
    """COLLECTIVE: every rank of `comm` writes its piece of the checkpoint `arrays` (the same on every rank) in
    `directory` (module docstring); `before()` runs on rank 0 before its piece is written (the history flushed).
    A rank that fails raises its exception and every other rank a RuntimeError naming it, after the round (no rank
    is left waiting)."""
    rank, size = comm.Get_rank(), comm.Get_size()
    token = comm.bcast(uuid.uuid4().hex if rank == 0 else None, root=0)
    failure = None
    try:
        if before is not None and rank == 0:
            before()
        write_checkpoint(directory, split(arrays, rank, size, token, body_owner, body_of, contact_keys),
                         piece_names(rank))
    except Exception as e:  # noqa: BLE001 - reported to every rank below
        failure = e
    every = comm.allgather(None if failure is None else f"{type(failure).__name__}: {failure}")
    if failure is not None:
        raise failure
    bad = [(p, msg) for p, msg in enumerate(every) if msg is not None]
    if bad:
        raise RuntimeError(f"checkpoint: rank {bad[0][0]} could not write its piece in {directory}: {bad[0][1]}")
    if rank == 0:
        remove_other_layout(directory, size)

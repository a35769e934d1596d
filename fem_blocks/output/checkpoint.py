"""Checkpoints: the full state of a run in one .npz, written atomically (temporary file, fsync, rename).

`DIR/checkpoint.npz` is the newest checkpoint and `DIR/checkpoint.prev.npz` the one before: a new checkpoint is
written to a temporary file and synced; then the newest becomes `.prev` (through a hard link, so `checkpoint.npz`
never disappears) and the temporary file is renamed over `checkpoint.npz`. At any instant both names hold a
complete checkpoint (where hard links are not available, the newest is renamed to `.prev` instead, leaving only
`.prev` between the two renames). Every checkpoint carries a SHA-256 digest of its arrays (`_digest`) and the case file's
fingerprint (`case_hash`); `latest_checkpoint` returns the newest one that opens and whose digest matches
(a file truncated or corrupted after the fact is reported and skipped).

Contents (see `runner.run_case`): `run.*` counters of the runner (stage, step in stage, peak force, statistics),
`sim.*` the Simulation state (time, step count, work, displacements and velocities of every body, driver
reactions) and `contact.*` the contact layer (contact set, G blocks, reference gaps, impulses for the warm
start, every law's internal variables: β / damage, jumps u_N, u_T, dissipated energy).
"""
from __future__ import annotations

import hashlib
import io
import os
import sys
import zipfile

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes, fsync_dir

NAME = "checkpoint.npz"
PREV = "checkpoint.prev.npz"


def digest(arrays: dict) -> str:
    """SHA-256 over the sorted keys, dtypes, shapes and bytes of the arrays (the `_digest` entry excluded)."""
    h = hashlib.sha256()
    for k in sorted(arrays):
        if k == "_digest":
            continue
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def write_checkpoint(directory: str, arrays: dict) -> str:
    """Write `arrays` (name -> numpy array or scalar) as DIR/checkpoint.npz, keeping the previous one."""
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    arrays["_digest"] = np.array(digest(arrays))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path = os.path.join(directory, NAME)
    prev = os.path.join(directory, PREV)

    def keep_previous():  # called once the new checkpoint is complete on disk, before it replaces the newest
        if not os.path.exists(path):
            return
        link = prev + ".link"
        try:
            if os.path.lexists(link):
                os.unlink(link)
            os.link(path, link)
            os.replace(link, prev)
        except OSError:  # no hard links here: rename (for an instant only .prev exists)
            os.replace(path, prev)
        fsync_dir(directory)
    atomic_write_bytes(path, buf.getvalue(), before_replace=keep_previous)
    return path


def read_checkpoint(path: str) -> dict:
    """The arrays of one checkpoint file; InputError if it cannot be read or its digest does not match."""
    path = os.fspath(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise InputError(f"{path}: checkpoint not found") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        raise InputError(f"{path}: unreadable checkpoint (truncated or corrupted: {e})") from None
    if "_digest" not in d:
        raise InputError(f"{path}: checkpoint has no digest (incomplete or not written by fem-blocks)")
    if str(d["_digest"]) != digest(d):
        raise InputError(f"{path}: checkpoint digest mismatch (corrupted)")
    return d


def latest_checkpoint(directory: str, warn=None) -> tuple[str, dict]:
    """(path, arrays) of the newest valid checkpoint in `directory`; skipped files are reported via `warn`."""
    warn = warn or (lambda msg: print(f"fem-blocks: warning: {msg}", file=sys.stderr))
    errors = []
    for name in (NAME, PREV):
        p = os.path.join(directory, name)
        if not os.path.exists(p):
            continue
        try:
            return p, read_checkpoint(p)
        except InputError as e:
            errors.append(str(e))
            warn(f"{e}; trying the previous checkpoint")
    why = "; ".join(errors) if errors else "no checkpoint.npz (set [output] checkpoint_every = N to write them)"
    raise InputError(f"{directory}: cannot resume: {why}")

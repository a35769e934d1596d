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

On N > 1 MPI ranks each rank p writes its piece, `DIR/checkpoint.rank<p>.npz` (and `.rank<p>.prev.npz`, kept the
same way): the rows of the bodies and contacts it owns and every other entry (`split`); the pieces of one round of
writes share a token (`part.token`). The newest complete set is the one of rank 0's newest piece when every rank
holds a valid piece with its token, else the one of rank 0's previous piece: the ranks write each round together
(distributed/checkpoint.py), so a run killed while they write leaves the set before complete. `merge` puts a set
back together (any number of processes can read it); a run that writes a checkpoint removes the other layout's files
once its own are complete, so a directory holds one run's checkpoints.
"""
from __future__ import annotations

import hashlib
import io
import os
import re
import sys
import zipfile

import numpy as np

from ..errors import InputError
from .atomic import atomic_write_bytes, fsync_dir

NAME = "checkpoint.npz"
PREV = "checkpoint.prev.npz"
_PIECE = re.compile(r"^checkpoint\.rank(\d+)\.(prev\.)?npz$")


def piece_names(rank: int) -> tuple[str, str]:
    """(newest, previous) file names of rank `rank`'s checkpoint piece."""
    return f"checkpoint.rank{rank}.npz", f"checkpoint.rank{rank}.prev.npz"


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


def write_checkpoint(directory: str, arrays: dict, names: tuple[str, str] = (NAME, PREV)) -> str:
    """Write `arrays` (name -> numpy array or scalar) as DIR/checkpoint.npz (names: (newest, previous); a rank's
    piece: `piece_names`), keeping the previous one. One process (names = the default): the pieces of an earlier run
    on N ranks are removed once the new file is complete."""
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    arrays["_digest"] = np.array(digest(arrays))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path = os.path.join(directory, names[0])
    prev = os.path.join(directory, names[1])

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
    if names[0] == NAME:
        remove_other_layout(directory, None)
    return path


def remove_other_layout(directory: str, size: int | None) -> None:
    """After a complete checkpoint of one process (size None): remove every rank's piece; after a complete set of
    pieces of `size` ranks: remove the one-process files and the pieces of ranks >= size (an earlier run on more
    ranks), so that no older checkpoint can be taken for the newest."""
    pieces = [(m[0], int(m[1])) for m in map(_PIECE.match, os.listdir(directory)) if m]
    names = [f for f, _ in pieces] if size is None else [NAME, PREV] + [f for f, r in pieces if r >= size]
    for f in names:
        try:
            os.unlink(os.path.join(directory, f))
        except FileNotFoundError:
            pass


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


def split(arrays: dict, rank: int, size: int, token: str, body_owner, body_of, contact_keys) -> dict:
    """Rank `rank`'s piece (of `size`) of the checkpoint `arrays`: the entries of the bodies it owns
    (body_owner[body_of(key)] == rank; body_of(key) is None for an entry of no body), the rows of its contacts (those
    whose candidate body it owns, "contact.cs.cand_body") of the per-contact entries `contact_keys`, and every other
    entry; plus `part.*`: rank, size, token, the body partition, the contacts' ids (contact/matching.contact_ids,
    increasing: their order in the whole set) and the whole set's count ("contact.n_contacts" when the arrays give
    it: a rank's contact set may be its part of the whole), the per-contact entries' names. A per-contact entry holds
    the rows of every contact of the arrays' set, or already those of this rank's contacts only (the contact step's
    and its record's on N ranks; when the rank owns every contact the two are the same)."""
    owner = np.asarray(body_owner, dtype=np.int64)
    keys = sorted(k for k in contact_keys if k in arrays)
    out = {"part.rank": np.int64(rank), "part.size": np.int64(size), "part.token": np.array(str(token)),
           "part.body_owner": owner}
    ids = None
    if keys:
        from ..contact.matching import contact_ids
        cand = np.asarray(arrays["contact.cs.cand_body"])
        ids = np.flatnonzero(owner[cand] == rank)
        out.update({"part.contact_ids": contact_ids(np.asarray(arrays["contact.cs.key"])[ids],
                                                    np.asarray(arrays["contact.cs.ant_body"])[ids], len(owner)),
                    "part.n_contacts": np.int64(arrays.get("contact.n_contacts", len(cand))),
                    "part.contact_keys": np.array(keys)})
    for k, v in arrays.items():
        if ids is not None and k in keys:
            v = np.asarray(v)
            if len(v) not in (len(cand), len(ids)):
                raise RuntimeError(f"checkpoint: {k} has {len(v)} rows, neither the {len(cand)} contacts nor the "
                                   f"{len(ids)} of rank {rank}")
            out[k] = v if len(v) == len(ids) else v[ids]  # (already its rows: the contact step's on N ranks)
        else:
            b = body_of(k)
            if b is None or owner[b] == rank:
                out[k] = v
    return out


def merge(pieces: list, label: str = "checkpoint") -> dict:
    """The whole checkpoint from the pieces of one set (`split` on every rank), in any order; InputError naming
    `label` if they are not one complete set (a rank missing or twice, another token, contacts missing or twice)."""
    pieces = sorted(pieces, key=lambda d: int(d["part.rank"]))
    size, token = int(pieces[0]["part.size"]), str(pieces[0]["part.token"])
    if [int(d["part.rank"]) for d in pieces] != list(range(size)) or \
            any(int(d["part.size"]) != size or str(d["part.token"]) != token for d in pieces):
        raise InputError(f"{label}: not one complete set of checkpoint pieces (expected ranks 0..{size - 1} of one "
                         "write)")
    out = {}
    for d in pieces:
        for k, v in d.items():
            if not k.startswith("part.") and k != "_digest":
                out.setdefault(k, v)  # a body's entries are in one piece; the others are the same in every piece
    if "part.contact_keys" in pieces[0]:
        n = int(pieces[0]["part.n_contacts"])
        if all("part.contact_ids" in d for d in pieces):  # each piece's rows placed by their contact ids
            ids = [np.asarray(d["part.contact_ids"], dtype=np.int64) for d in pieces]
            every = np.sort(np.concatenate(ids))
            if every.size != n or np.any(every[1:] == every[:-1]):
                raise InputError(f"{label}: the pieces do not hold each of the {n} contacts once")
            ids = [np.searchsorted(every, i) for i in ids]
        else:  # (pieces written before the contact ids: the contacts' numbers in the whole set)
            ids = [np.asarray(d["part.contacts"], dtype=np.int64) for d in pieces]
            if not np.array_equal(np.sort(np.concatenate(ids)), np.arange(n)):
                raise InputError(f"{label}: the pieces do not hold each of the {n} contacts once")
        for k in pieces[0]["part.contact_keys"]:
            k = str(k)
            first = np.asarray(pieces[0][k])
            a = np.empty((n,) + first.shape[1:], dtype=first.dtype)
            for d, i in zip(pieces, ids):
                a[i] = d[k]
            out[k] = a
    return out


def has_checkpoint(directory: str) -> bool:
    """True when `directory` holds a checkpoint file of one process or a rank's piece (valid or not)."""
    return os.path.isdir(directory) and any(f in (NAME, PREV) or _PIECE.match(f) for f in os.listdir(directory))


def _valid(paths, warn, errors, check=None):
    """(path, arrays) of each of `paths` that exists and reads as a checkpoint (read_checkpoint) and passes
    `check(path, arrays)` (which raises InputError otherwise), in order and as they are read; the others are reported
    through `warn` and listed in `errors`."""
    for p in paths:
        if not os.path.exists(p):
            continue
        try:
            d = read_checkpoint(p)
            if check is not None:
                check(p, d)
            yield p, d
        except InputError as e:
            errors.append(str(e))
            warn(f"{e}; trying the previous checkpoint")


def _latest_set(directory: str, warn, errors):
    """(paths, pieces) of the newest complete set of rank pieces (module docstring), or None."""
    ranks = sorted({int(m[1]) for m in map(_PIECE.match, os.listdir(directory)) if m})

    def piece_of(r):
        def check(p, d):
            if not {"part.rank", "part.size", "part.token"} <= set(d) or int(d["part.rank"]) != r:
                raise InputError(f"{p}: not rank {r}'s piece of a checkpoint")
        return check
    valid = {r: list(_valid([os.path.join(directory, f) for f in piece_names(r)], warn, errors, piece_of(r)))
             for r in ranks}
    for k, (p0, d0) in enumerate(valid.get(0, [])):
        token, size = str(d0["part.token"]), int(d0["part.size"])
        chosen = []
        for r in range(size):
            match = [(p, d) for p, d in valid.get(r, []) if str(d["part.token"]) == token]
            if not match:
                msg = f"{p0}: rank {r}'s piece of this checkpoint is missing or invalid (the run stopped while the " \
                      "ranks wrote it)"
                errors.append(msg)
                if k == 0:
                    warn(f"{msg}; trying the previous checkpoint")
                break
            chosen.append(match[0])
        else:
            return [p for p, _ in chosen], [d for _, d in chosen]
    return None


def latest_checkpoint_files(directory: str, warn=None) -> tuple[str, list, dict]:
    """(label, paths, arrays) of the newest valid checkpoint in `directory`: checkpoint.npz (or .prev) of one process,
    or the newest complete set of rank pieces (merged), whichever was written last; skipped files are reported via
    `warn`. `load_checkpoint(paths)` reads the same checkpoint again (another process)."""
    warn = warn or (lambda msg: print(f"fem-blocks: warning: {msg}", file=sys.stderr))
    errors = []
    one = next(_valid([os.path.join(directory, n) for n in (NAME, PREV)], warn, errors), None) \
        if os.path.isdir(directory) else None
    many = _latest_set(directory, warn, errors) if os.path.isdir(directory) else None
    if many is not None and (one is None or os.path.getmtime(many[0][0]) > os.path.getmtime(one[0])):
        paths, pieces = many
        label = os.path.join(directory, f"checkpoint.rank*.npz ({len(paths)} pieces)")
        return label, paths, merge(pieces, label)
    if one is not None:
        return one[0], [one[0]], one[1]
    why = "; ".join(errors) if errors else \
        "no checkpoint.npz (set [output] checkpoint_every = N to write them) and no checkpoint.rank<p>.npz pieces"
    raise InputError(f"{directory}: cannot resume: {why}")


def load_checkpoint(paths: list) -> dict:
    """The checkpoint in the files `paths` (latest_checkpoint_files): one file, or the pieces of one set merged."""
    if len(paths) == 1:
        return read_checkpoint(paths[0])
    return merge([read_checkpoint(p) for p in paths], os.path.dirname(paths[0]))


def latest_checkpoint(directory: str, warn=None) -> tuple[str, dict]:
    """(label, arrays) of the newest valid checkpoint in `directory` (latest_checkpoint_files)."""
    label, _, arrays = latest_checkpoint_files(directory, warn)
    return label, arrays

"""Atomic file writes: temporary file in the same directory, write, flush, os.fsync, os.replace, fsync the
directory.
`atomic_write_with(path, write_to)` does the same for a writer that wants a file name (meshio).

A crash (or an exception while writing) leaves either the complete old file or the complete new one, never a
truncated file, and no temporary file is left behind by an exception. The new file gets the permissions of
the file it replaces, or 0o666 minus the umask for a new file (not mkstemp's 0o600)."""
from __future__ import annotations

import os
import stat
import tempfile


def _umask() -> int:
    old = os.umask(0o022)
    os.umask(old)
    return old


def atomic_write_bytes(path, data: bytes, before_replace=None) -> None:
    """Replace `path` by `data` atomically (same-directory temporary + fsync + os.replace + directory fsync).
    `before_replace()`, if given, runs once the temporary file is complete and synced, just before the rename."""
    def write_to(tmp):
        with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_TRUNC), "wb") as f:
            f.write(data)
    atomic_write_with(path, write_to, before_replace)


def atomic_write_with(path, write_to, before_replace=None) -> None:
    """Replace `path` atomically by the file that `write_to(tmp_path)` writes (also for writers that want a file
    name, e.g. meshio): temporary file in the same directory, fsync, the old file's permissions (else the umask's),
    `before_replace()` if given, os.replace, fsync of the directory; the temporary file is removed on any error."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except FileNotFoundError:
        mode = 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=".tmp-" + os.path.basename(path) + "-", dir=d)
    os.close(fd)
    try:
        write_to(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.chmod(tmp, mode)
        if before_replace is not None:
            before_replace()
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    fsync_dir(d)


def atomic_write_text(path, text: str) -> None:
    """atomic_write_bytes of `text` encoded as UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))


def fsync_dir(d) -> None:
    """fsync a directory so a rename in it survives a power loss (no-op where directories cannot be opened)."""
    try:
        fd = os.open(os.fspath(d), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)

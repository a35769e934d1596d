"""fem_blocks: deformable-block masonry with Non-Smooth Contact Dynamics on FEniCSx.

Importing the package first points numba's on-disk cache at a directory named by a hash of the package's
numba modules (`_numba_cache_dir`; docs/stack-facts.md §4). numba keys a cached kernel on its own file only: a
kernel that inlines a function of another module (nlgs.py calling laws.cap_stress, ...) would otherwise be loaded
stale after that other module changed (e.g. after a `git pull`), and compute with the old law — silently. With the
hash, any change to any numba module recompiles every kernel once (the warm-up, `python -m fem_blocks.warmup`,
about 2 min).
"""
import hashlib as _hashlib
import os as _os

__version__ = "0.1.0"


def _numba_cache_dir() -> str:
    """`$FEM_BLOCKS_NUMBA_CACHE` (default: fem_blocks/__pycache__/numba) / sha1 of every module of the package
    that imports numba (relative path + bytes), 16 hex digits. Sibling directories of other versions are removed
    when a new one is made."""
    root = _os.path.dirname(_os.path.abspath(__file__))
    h = _hashlib.sha1()
    for dirpath, dirs, files in _os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for f in sorted(files):
            if f.endswith(".py"):
                p = _os.path.join(dirpath, f)
                with open(p, "rb") as fh:
                    src = fh.read()
                if b"numba" in src:
                    h.update(_os.path.relpath(p, root).encode() + b"\0" + src + b"\0")
    base = _os.environ.get("FEM_BLOCKS_NUMBA_CACHE") or _os.path.join(root, "__pycache__", "numba")
    path = _os.path.join(base, h.hexdigest()[:16])
    if not _os.path.isdir(path):
        try:
            _os.makedirs(path, exist_ok=True)
            for old in _os.listdir(base):
                q = _os.path.join(base, old)
                if q != path and len(old) == 16 and _os.path.isdir(q):
                    import shutil
                    shutil.rmtree(q, ignore_errors=True)
        except OSError:
            pass  # read-only install: numba falls back to its own locations and warns
    return path


def _point_numba_cache():
    try:
        from numba.core import config
    except ImportError:  # numba missing: the kernels' import will say so
        return
    config.CACHE_DIR = _numba_cache_dir()


_point_numba_cache()

"""numba's cache is keyed per file: a kernel inlining a function of another module would be loaded stale after
that module changed. fem_blocks/__init__.py points the cache at a directory named by a hash of every numba module.
Bug caught: a hash that misses a numba module (laws.py edited, nlgs.py's cached kernels reused with the old law),
or that changes with modules without kernels (needless recompiles), or a cache dir not applied."""
import os
import shutil
import subprocess
import sys

from tests._paths import ROOT

CODE = "import fem_blocks, numba.core.config as c; print(c.CACHE_DIR)"


def _cache_dir(pkg_parent, env=None):
    e = {k: v for k, v in os.environ.items() if k != "FEM_BLOCKS_NUMBA_CACHE"}
    e.update(PYTHONPATH=str(pkg_parent), **(env or {}))
    out = subprocess.run([sys.executable, "-c", CODE], cwd=str(pkg_parent), env=e, capture_output=True, text=True,
                         check=True)
    return out.stdout.strip()


def test_cache_dir_follows_the_numba_modules(tmp_path):
    shutil.copytree(os.path.join(ROOT, "fem_blocks"), tmp_path / "fem_blocks",
                    ignore=shutil.ignore_patterns("__pycache__"))
    d0 = _cache_dir(tmp_path)
    assert d0.startswith(str(tmp_path / "fem_blocks" / "__pycache__" / "numba")) and os.path.isdir(d0)
    with open(tmp_path / "fem_blocks" / "case.py", "a") as f:   # no kernel in case.py: same cache
        f.write("\n# edited\n")
    assert _cache_dir(tmp_path) == d0
    with open(tmp_path / "fem_blocks" / "laws.py", "a") as f:   # a law changed: every kernel recompiled
        f.write("\n# edited\n")
    d1 = _cache_dir(tmp_path)
    assert d1 != d0 and os.path.isdir(d1) and not os.path.exists(d0)   # the stale version is removed
    with open(tmp_path / "fem_blocks" / "solver" / "nlgs.py", "a") as f:
        f.write("\n# edited\n")
    assert _cache_dir(tmp_path) != d1
    other = tmp_path / "elsewhere"
    d2 = _cache_dir(tmp_path, {"FEM_BLOCKS_NUMBA_CACHE": str(other)})
    assert os.path.dirname(d2) == str(other)

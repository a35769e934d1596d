#!/usr/bin/env bash
# Idempotent set-up on Debian bookworm: system packages, venv, editable install.
# Called by `make demo` / `make test` / `make bench` when the stamp file is missing or stale.
set -euo pipefail
cd "$(dirname "$0")/.."
PKGS="python3-dolfinx-real python3-gmsh python3-meshio python3-scipy python3-numba python3-h5py \
python3-matplotlib python3-pytest libopenblas0-pthread python3-venv python3-pip python3-setuptools python3-vtk9"
missing=""
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "[setup] installing Debian packages:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv (with system site packages)"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
# Pin numpy to the Debian version: numpy 2 from PyPI breaks dolfinx.
/usr/bin/python3 -c "import numpy; print('numpy==' + numpy.__version__)" > constraints.txt
.venv/bin/python -m pip install -q --no-build-isolation --no-deps -c constraints.txt -e .
.venv/bin/python -c "import dolfinx, gmsh, numba, fem_blocks; print('[setup] ok: fem_blocks', fem_blocks.__version__, 'dolfinx', dolfinx.__version__)"
# Compile numba's kernels once now (about 2 min on 2 cores), not in the user's first run (fem_blocks/warmup.py).
.venv/bin/python -m fem_blocks.warmup

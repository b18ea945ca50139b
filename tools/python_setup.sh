#!/usr/bin/env bash
# Build and install the Python package `camsim` (python/, PyO3 + maturin) into the project's
# git-ignored virtual environment .venv-py, with pinned maturin, numpy and pytest from PyPI.
# Idempotent: the venv and its tools are made once; the package is rebuilt every run (cargo
# reuses the workspace's target/ and release profile, so an unchanged tree rebuilds in
# seconds).
#
#   tools/python_setup.sh            # → <repo>/.venv-py/bin/python -c "import camsim"
#   CAMSIM_PY_VENV=/path tools/python_setup.sh
#   .venv-py/bin/python -m pytest python/tests
set -euo pipefail
MATURIN_VERSION="1.16.0"
NUMPY_VERSION="2.4.6"
PYTEST_VERSION="9.2.0"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${CAMSIM_PY_VENV:-$repo/.venv-py}"
py="$venv/bin/python"
# shellcheck source=tools/venv_lock.sh
. "$repo/tools/venv_lock.sh"
venv_lock "$venv"
pip=("$py" -m pip --disable-pip-version-check)
if ! [ -x "$py" ] || ! "$py" - <<PYEOF 2>/dev/null
import sys, importlib.metadata as m
want = {"maturin": "$MATURIN_VERSION", "numpy": "$NUMPY_VERSION", "pytest": "$PYTEST_VERSION"}
sys.exit(any(m.version(k) != v for k, v in want.items()))
PYEOF
then
    venv_fresh "$venv"
    "${pip[@]}" install --quiet --upgrade pip
    "${pip[@]}" install --quiet "maturin==$MATURIN_VERSION" "numpy==$NUMPY_VERSION" "pytest==$PYTEST_VERSION"
fi
export PATH="$venv/bin:$PATH"
# The same build `pip install ./python` does, with the venv's pinned maturin (no isolated
# build environment to download each time). Cargo output goes to <repo>/target.
"${pip[@]}" install --quiet --no-build-isolation --force-reinstall --no-deps "$repo/python"
"$py" -c "import camsim; print('python_setup: camsim', camsim.__version__, 'installed in $venv')"

#!/usr/bin/env bash
# Install LibRaw's Python binding rawpy and the DNG writer pidng (PyPI) into the project's
# git-ignored virtual environment .venv-libraw, for the DNG-development check against LibRaw
# (tests/develop_libraw.rs, tools/libraw_develop.py). Idempotent: a venv that already has the
# pinned versions is left as it is.
#
#   tools/libraw_setup.sh            # → <repo>/.venv-libraw/bin/python
#   CAMSIM_LIBRAW_VENV=/path tools/libraw_setup.sh
set -euo pipefail
RAWPY_VERSION="0.28.0"
PIDNG_VERSION="4.0.9"
NUMPY_VERSION="2.2.6"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${CAMSIM_LIBRAW_VENV:-$repo/.venv-libraw}"
py="$venv/bin/python"
# shellcheck source=tools/venv_lock.sh
. "$repo/tools/venv_lock.sh"
venv_lock "$venv"
check="import rawpy, pidng, importlib.metadata as m, sys; sys.exit(not (m.version('rawpy') == '$RAWPY_VERSION' and m.version('pidng') == '$PIDNG_VERSION'))"
if [ -x "$py" ] && "$py" -c "$check" 2>/dev/null; then
    echo "libraw_setup: rawpy $RAWPY_VERSION and pidng $PIDNG_VERSION already in $venv"
    exit 0
fi
venv_fresh "$venv"
"$py" -m pip install --quiet --disable-pip-version-check --upgrade pip
"$py" -m pip install --quiet --disable-pip-version-check "numpy==$NUMPY_VERSION" "rawpy==$RAWPY_VERSION" "pidng==$PIDNG_VERSION"
"$py" -c "import rawpy, pidng; print('libraw_setup: rawpy', rawpy.__version__, '(LibRaw', rawpy.libraw_version, ') and pidng installed in $venv')"

#!/usr/bin/env bash
# Install the EMVA 1288 reference implementation `emva1288` (PyPI) into the project's git-ignored
# virtual environment .venv-emva1288, for the EMVA 1288 cross-check test and bench/emva1288.sh
# (tools/emva1288_ref.py). Idempotent: a venv that already has the pinned version is left as it is.
#
#   tools/emva1288_setup.sh            # → <repo>/.venv-emva1288/bin/python
#   CAMSIM_EMVA1288_VENV=/path tools/emva1288_setup.sh
set -euo pipefail
EMVA_VERSION="1.0.2"
# emva1288 1.0.2 calls numpy.asfarray (removed in NumPy 2.0): pin a NumPy 1.x stack it runs on.
DEPS="numpy==1.26.4 scipy==1.13.1 matplotlib==3.8.4 pillow==10.4.0 lxml==5.3.0 jinja2==3.1.4"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${CAMSIM_EMVA1288_VENV:-$repo/.venv-emva1288}"
py="$venv/bin/python"
# shellcheck source=tools/venv_lock.sh
. "$repo/tools/venv_lock.sh"
venv_lock "$venv"
check="import importlib.metadata as m, sys; sys.exit(m.version('emva1288') != '$EMVA_VERSION' or m.version('numpy') != '1.26.4')"
if [ -x "$py" ] && "$py" -c "$check" 2>/dev/null; then
    echo "emva1288_setup: emva1288 $EMVA_VERSION already in $venv"
    exit 0
fi
venv_fresh "$venv"
"$py" -m pip install --quiet --disable-pip-version-check --upgrade pip
# shellcheck disable=SC2086
"$py" -m pip install --quiet --disable-pip-version-check $DEPS "emva1288==$EMVA_VERSION"
"$py" -c "import importlib.metadata as m; print('emva1288_setup: emva1288', m.version('emva1288'), 'installed in $venv')"

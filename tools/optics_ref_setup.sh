#!/usr/bin/env bash
# Install the lens reference packages (PyPI) into the project's git-ignored virtual environment
# .venv-optics, for tools/optics_ref_run.sh (which calls this script) and
# ../shared/tools/optics_ref/ref_lens.py. Idempotent: a venv that already has the pinned
# versions is left as it is. The versions are the ones the stored lens/tests/data/optics_ref/
# *.ref.json files were made with (each records them).
#
#   tools/optics_ref_setup.sh            # → <repo>/.venv-optics/bin/python
# Env: PYTHON (interpreter used to create the venv, default python3)
set -euo pipefail
OPTILAND_VERSION="0.6.3"
RAYOPTICS_VERSION="0.9.8"
OPTICALGLASS_VERSION="1.1.1"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$repo/.venv-optics"
py="$venv/bin/python"
# shellcheck source=tools/venv_lock.sh
. "$repo/tools/venv_lock.sh"
venv_lock "$venv"
check="
from importlib.metadata import version
import sys
sys.exit(not (version('optiland') == '$OPTILAND_VERSION' and version('rayoptics') == '$RAYOPTICS_VERSION'
              and version('opticalglass') == '$OPTICALGLASS_VERSION'))
"
if [ -x "$py" ] && "$py" -c "$check" 2>/dev/null; then
    echo "optics_ref_setup: optiland $OPTILAND_VERSION, rayoptics $RAYOPTICS_VERSION already in $venv"
    exit 0
fi
venv_fresh "$venv"
"$py" -m pip install --quiet --disable-pip-version-check --upgrade pip
"$py" -m pip install --quiet --disable-pip-version-check "optiland==$OPTILAND_VERSION" \
    "rayoptics==$RAYOPTICS_VERSION" "opticalglass==$OPTICALGLASS_VERSION"
"$py" -c "$check"
echo "optics_ref_setup: optiland $OPTILAND_VERSION, rayoptics $RAYOPTICS_VERSION installed in $venv"

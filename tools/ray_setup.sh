#!/usr/bin/env bash
# Install Ray (PyPI) into the project's git-ignored virtual environment .venv-ray, for
# `camsim study SPEC --engine ray` (tools/ray_study.py). Idempotent: a venv that already has
# the pinned Ray is left as it is, so the first run downloads and later runs return at once.
#
#   tools/ray_setup.sh            # → <repo>/.venv-ray/bin/python
#   CAMSIM_RAY_VENV=/path tools/ray_setup.sh
set -euo pipefail
RAY_VERSION="2.60.0"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${CAMSIM_RAY_VENV:-$repo/.venv-ray}"
py="$venv/bin/python"
# shellcheck source=tools/venv_lock.sh
. "$repo/tools/venv_lock.sh"
venv_lock "$venv"
if [ -x "$py" ] && "$py" -c "import ray, sys; sys.exit(ray.__version__ != '$RAY_VERSION')" 2>/dev/null; then
    echo "ray_setup: Ray $RAY_VERSION already in $venv"
    exit 0
fi
venv_fresh "$venv"
"$py" -m pip install --quiet --disable-pip-version-check --upgrade pip
"$py" -m pip install --quiet --disable-pip-version-check "ray[default]==$RAY_VERSION"
"$py" -c "import ray; print('ray_setup: Ray', ray.__version__, 'installed in $venv')"

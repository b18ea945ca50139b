#!/usr/bin/env bash
# Install Mitsuba 3 (the render crate's reference renderer) into a git-ignored venv,
# .venv-mitsuba, in the repository root, and check the glTF camera convention with the
# shared harness (<shared>/tools/mitsuba_ref/gltf_to_mitsuba.py --verify-camera).
#
# The llvm_ad_* variants need libLLVM >= 16 (with Debian 12's libLLVM-15 Dr.Jit aborts in
# codegen; see the harness README). This script installs libllvm19 with apt when no
# libLLVM-16..19 is present and apt is usable; otherwise it falls back to scalar_spectral.
# It prints the variant to use on its last line: "MITSUBA_VARIANT=<variant>".
#
# Usage: tools/mitsuba_setup.sh [--no-apt] [--no-verify]
# Env:   PYTHON           interpreter used to create the venv (default python3)
#        MITSUBA_VERSION  pip version spec for mitsuba (default 3.9.1, the harness's tested one)
#        CAMSIM_SHARED    the shared folder (default: <repo>/../shared)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARED="${CAMSIM_SHARED:-$ROOT/../shared}"
HARNESS="$SHARED/tools/mitsuba_ref"
VENV="$ROOT/.venv-mitsuba"
MITSUBA_VERSION="${MITSUBA_VERSION:-3.9.1}"
USE_APT=1
VERIFY=1
for arg in "$@"; do
    case "$arg" in
        --no-apt) USE_APT=0 ;;
        --no-verify) VERIFY=0 ;;
        *) echo "mitsuba_setup.sh: unknown argument '$arg' (expected --no-apt or --no-verify)" >&2; exit 2 ;;
    esac
done

if [[ ! -f "$HARNESS/gltf_to_mitsuba.py" ]]; then
    echo "mitsuba_setup.sh: harness not found at $HARNESS (set CAMSIM_SHARED to the shared folder)" >&2
    exit 1
fi

# 1. Python packages (one install at a time; a half-installed venv is rebuilt from empty).
# shellcheck source=tools/venv_lock.sh
. "$ROOT/tools/venv_lock.sh"
venv_lock "$VENV"
if ! { [[ -x "$VENV/bin/python" ]] && "$VENV/bin/python" -c "import mitsuba, numpy" 2>/dev/null; }; then
    venv_fresh "$VENV"
    "$VENV/bin/pip" install --quiet --upgrade pip
    "$VENV/bin/pip" install --quiet "mitsuba==$MITSUBA_VERSION" numpy
fi

# 2. libLLVM >= 16 for the JIT (llvm_ad_*) variants.
find_llvm() {
    local v f
    for v in 19 18 17 16; do
        for f in /usr/lib/x86_64-linux-gnu/libLLVM-$v.so /usr/lib/x86_64-linux-gnu/libLLVM-$v.so.1 \
                 /usr/lib/llvm-$v/lib/libLLVM-$v.so /usr/lib/llvm-$v/lib/libLLVM.so.1; do
            if [[ -e "$f" ]]; then echo "$f"; return 0; fi
        done
    done
    return 1
}
LLVM_LIB="$(find_llvm || true)"
if [[ -z "$LLVM_LIB" && "$USE_APT" == 1 ]] && command -v apt-get >/dev/null; then
    SUDO=""
    [[ "$(id -u)" != 0 ]] && SUDO="sudo"
    if $SUDO apt-get update -qq && $SUDO apt-get install -y -qq libllvm19 >/dev/null; then
        LLVM_LIB="$(find_llvm || true)"
    else
        echo "mitsuba_setup.sh: apt-get install libllvm19 failed; using scalar_spectral" >&2
    fi
fi

VARIANT=scalar_spectral
if [[ -n "$LLVM_LIB" ]]; then
    export DRJIT_LIBLLVM_PATH="$LLVM_LIB"
    if "$VENV/bin/python" -c "import mitsuba as mi; mi.set_variant('llvm_ad_spectral')" 2>/dev/null; then
        VARIANT=llvm_ad_spectral
    else
        echo "mitsuba_setup.sh: llvm_ad_spectral does not load with $LLVM_LIB; using scalar_spectral" >&2
    fi
fi
"$VENV/bin/python" - <<'PY'
from importlib.metadata import version
print("mitsuba", version("mitsuba"), "| drjit", version("drjit"), "| numpy", version("numpy"))
PY
[[ -n "$LLVM_LIB" ]] && echo "libLLVM: $LLVM_LIB"

# 3. Camera convention check (markers within 0.5 px of the plain OpenGL projection).
if [[ "$VERIFY" == 1 ]]; then
    (cd "$HARNESS" && "$VENV/bin/python" gltf_to_mitsuba.py camera_test.gltf --verify-camera --variant "$VARIANT")
fi
echo "MITSUBA_VARIANT=$VARIANT"

#!/usr/bin/env bash
# Large-mesh renderer benchmark (issue 18, acceptance 5): a scene of ≥ 10⁶ triangles rendered
# by camsim and by Mitsuba 3 (llvm_ad_spectral) at equal spp in the same run. The scene is the
# shared Cornell box with its two boxes replaced by a bumpy sphere of TRIANGLES triangles
# (bench/make_mesh_scene.py); the comparison itself is bench/render_mitsuba.sh (render time,
# load time = parse + BVH build, noise at equal spp, agreement of the two renders).
# Writes docs/benchmarks/render_mesh.md.
#
# Usage: bench/render_mesh.sh     Env: TRIANGLES (1000000), SPP (16), WIDTH (256), and those
#                                 of bench/render_mitsuba.sh
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARED="${CAMSIM_SHARED:-$ROOT/../shared}"
TRIANGLES="${TRIANGLES:-1000000}"
if [[ -z "${VARIANT:-}" ]]; then
    VARIANT="$("$ROOT/tools/mitsuba_setup.sh" --no-verify | sed -n 's/^MITSUBA_VARIANT=//p')"
fi
export VARIANT
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
"$ROOT/.venv-mitsuba/bin/python" "$ROOT/bench/make_mesh_scene.py" \
    "$SHARED/tools/mitsuba_ref/cornell.gltf" "$WORK/mesh.gltf" --triangles "$TRIANGLES"
SCENE="$WORK/mesh.gltf" \
SCENE_DESC="the shared Cornell box with its boxes replaced by a bumpy sphere (\`bench/make_mesh_scene.py --triangles $TRIANGLES\`)" \
TARGET="target of issue 18, acceptance 5: ≥ 2× at equal spp" \
OUT_MD="$ROOT/docs/benchmarks/render_mesh.md" \
SPP="${SPP:-16}" \
    "$ROOT/bench/render_mitsuba.sh"

#!/usr/bin/env bash
# Regenerate the Mitsuba 3 references that render/tests/mitsuba.rs compares camsim with.
#
# For each scene (cornell = <shared>/tools/mitsuba_ref/cornell.gltf, used in place; thinlens,
# metal, glass = scenes/mitsuba/*.gltf, rewritten first by scenes/mitsuba/make_scenes.py; envmap =
# scenes/mitsuba/envmap.gltf from `cargo run --release -p camsim-render --example make_blender_scenes`,
# rendered by scenes/mitsuba/envmap_ref.py, the harness plus the scene's environment map) this
# renders SEEDS independent Mitsuba images with the shared harness (gltf_to_mitsuba.py, called
# in place) and packs them into scenes/mitsuba/refs/<scene>.exr: per band the mean and the
# variance of the mean over the seeds, plus depth (see scenes/mitsuba/pack_refs.py), with a
# JSON sidecar recording variant, versions, spp, seeds and timings.
#
# Usage: tools/mitsuba_refs.sh [scene ...]        (default: cornell thinlens metal glass envmap)
# Env:   SEEDS (8), SPP per seed (1024), WIDTH (64, square images), BANDS (400:700:20),
#        VARIANT (default: what tools/mitsuba_setup.sh finds, llvm_ad_spectral if it can),
#        CAMSIM_SHARED (default <repo>/../shared). CI never runs this.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARED="${CAMSIM_SHARED:-$ROOT/../shared}"
HARNESS="$SHARED/tools/mitsuba_ref"
VENV="$ROOT/.venv-mitsuba"
OUT="$ROOT/scenes/mitsuba/refs"
SEEDS="${SEEDS:-8}"
SPP="${SPP:-1024}"
WIDTH="${WIDTH:-64}"
BANDS="${BANDS:-400:700:20}"
SCENES=("$@")
[[ ${#SCENES[@]} -eq 0 ]] && SCENES=(cornell thinlens metal glass envmap)

if [[ -z "${VARIANT:-}" ]]; then
    VARIANT="$("$ROOT/tools/mitsuba_setup.sh" --no-verify | sed -n 's/^MITSUBA_VARIANT=//p')"
fi
for f in /usr/lib/x86_64-linux-gnu/libLLVM-{19,18,17,16}.so; do
    if [[ -e "$f" ]]; then export DRJIT_LIBLLVM_PATH="${DRJIT_LIBLLVM_PATH:-$f}"; break; fi
done
PY="$VENV/bin/python"
"$PY" "$ROOT/scenes/mitsuba/make_scenes.py" --shared "$SHARED" >/dev/null
mkdir -p "$OUT"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
VERSIONS="$("$PY" -c 'from importlib.metadata import version as v; print(v("mitsuba"), v("drjit"))')"

for scene in "${SCENES[@]}"; do
    case "$scene" in
        cornell) gltf="$HARNESS/cornell.gltf" ;;
        thinlens|metal|glass|envmap) gltf="$ROOT/scenes/mitsuba/$scene.gltf" ;;
        *) echo "mitsuba_refs.sh: unknown scene '$scene' (expected cornell, thinlens, metal, glass or envmap)" >&2; exit 2 ;;
    esac
    # envmap: the harness plus the scene's environment map (scenes/mitsuba/envmap_ref.py)
    render_cmd=("$HARNESS/gltf_to_mitsuba.py")
    [[ $scene == envmap ]] && render_cmd=("$ROOT/scenes/mitsuba/envmap_ref.py" --harness "$HARNESS")
    files=()
    t0=$(date +%s.%N)
    for ((s = 0; s < SEEDS; s++)); do
        extra=()
        [[ $s == 0 ]] && extra=(--preview "$OUT/${scene}_preview.png")
        "$PY" "${render_cmd[@]}" "$gltf" -o "$TMP/${scene}_s$s.exr" --variant "$VARIANT" \
            --spp "$SPP" --seed "$s" --width "$WIDTH" --height "$WIDTH" --bands "$BANDS" "${extra[@]}" \
            >"$TMP/${scene}_s$s.json"
        files+=("$TMP/${scene}_s$s.exr")
    done
    t1=$(date +%s.%N)
    render_s=$(
        "$PY" -c 'import json,sys; print(sum(json.load(open(f))["render_s"] for f in sys.argv[1:]))' \
            "$TMP/${scene}"_s*.json
    )
    meta=$(printf '{"scene": "%s", "gltf": "%s", "variant": "%s", "mitsuba_drjit": "%s", "spp_per_seed": %d, "bands": "%s", "render_s_total": %s, "wall_s": %.1f}' \
        "$scene" "$(basename "$gltf")" "$VARIANT" "$VERSIONS" "$SPP" "$BANDS" "$render_s" "$(echo "$t1 - $t0" | bc)")
    "$PY" "$ROOT/scenes/mitsuba/pack_refs.py" "$OUT/$scene.exr" "${files[@]}" --meta "$OUT/$scene.json" --meta-json "$meta"
done

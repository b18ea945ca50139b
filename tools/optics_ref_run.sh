#!/usr/bin/env bash
# Regenerate the Optiland / rayoptics reference numbers for the lens crate's tests.
#
# For each input prescription lens/tests/data/optics_ref/<name>.json this runs the shared
# reference harness (../shared/tools/optics_ref/ref_lens.py, called in place, not copied)
# and writes <name>.ref.json beside it. The Python packages live in a git-ignored venv,
# .venv-optics, in the repository root, made by tools/optics_ref_setup.sh (pinned versions).
#
# An input may carry a key "ref_lens_runs" (ignored by ref_lens.py): an object mapping a tag to
# ref_lens.py arguments; tag "" writes <name>.ref.json, any other tag <name>.<tag>.ref.json.
# E.g. {"": "--backends optiland", "paraxial_aiming": "--backends optiland --optiland-aiming paraxial"}
# for a lens with a glass that rayoptics' catalogue lacks. Without the key: one run, default args.
#
# An input may also carry "extra_runs": an object mapping a tool of tools/optics_ref_extra.py
# (field_curvature, finite) to extra arguments; each writes <name>.<tool>.ref.json. An input
# with "ref_lens_runs": {} runs only its extra tools (e.g. a finite-conjugate lens, which
# ref_lens.py cannot express).
#
# An input with "ref_lens_runner": "asphere" (surfaces with "conic" / "aspheric_coeffs") runs its
# ref_lens runs through tools/optics_ref_extra.py asphere: ref_lens.py with those surfaces built
# as optiland even aspheres (optiland only). "ref_lens_runner": "patched" runs both backends
# through tools/optics_ref_extra.py patched: aspheres in both, and the glasses listed in
# "rayoptics_glass_from_optiland" given to rayoptics as optiland's material (opticalglass 1.1.1
# lacks e.g. Schott N-SK15 and rayoptics then silently builds air).
#
# Usage: tools/optics_ref_run.sh [name ...]     (default: every *.json that is not *.ref.json)
# Env:   PYTHON (interpreter used to create the venv, default python3)
#        REF_LENS_ARGS (extra arguments appended to every ref_lens.py run, e.g. "--no-psf")
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
REF_LENS="$ROOT/../shared/tools/optics_ref/ref_lens.py"
EXTRA="$ROOT/tools/optics_ref_extra.py"
DATA="$ROOT/lens/tests/data/optics_ref"
VENV="$ROOT/.venv-optics"

if [[ ! -f "$REF_LENS" ]]; then
    echo "ref_lens.py not found at $REF_LENS" >&2
    exit 1
fi

# The pinned optiland / rayoptics / opticalglass (idempotent).
"$ROOT/tools/optics_ref_setup.sh"
"$VENV/bin/python" - <<'PY'
from importlib.metadata import version
print("optiland", version("optiland"), "| rayoptics", version("rayoptics"),
      "| opticalglass", version("opticalglass"))
PY

if [[ $# -gt 0 ]]; then
    inputs=()
    for n in "$@"; do inputs+=("$DATA/${n%.json}.json"); done
else
    inputs=()
    for f in "$DATA"/*.json; do
        [[ "$f" == *.ref.json ]] && continue
        inputs+=("$f")
    done
fi

failed=0
for f in "${inputs[@]}"; do
    # one "kind|tag|args" line per run
    runs="$("$VENV/bin/python" -c '
import json, sys
j = json.load(open(sys.argv[1]))
kind = {"asphere": "asphere", "patched": "patched"}.get(j.get("ref_lens_runner"), "ref_lens")
for tag, args in j.get("ref_lens_runs", {"": ""}).items():
    print(kind + "|" + tag + "|" + args)
for tool, args in j.get("extra_runs", {}).items():
    print("extra|" + tool + "|" + args)
' "$f")"
    while IFS='|' read -r kind tag args; do
        [[ -z "$kind" ]] && continue
        if [[ -z "$tag" ]]; then out="${f%.json}.ref.json"; else out="${f%.json}.$tag.ref.json"; fi
        echo "== $(basename "$f") ${kind} ${args:+[$args] }-> $(basename "$out")"
        start=$SECONDS
        if [[ "$kind" == extra ]]; then
            cmd=("$VENV/bin/python" "$EXTRA" "$tag" "$f" -o "$out")
            common=""
        elif [[ "$kind" == asphere || "$kind" == patched ]]; then
            cmd=("$VENV/bin/python" "$EXTRA" "$kind" "$f" -o "$out")
            common="${REF_LENS_ARGS:-}"
        else
            cmd=("$VENV/bin/python" "$REF_LENS" "$f" -o "$out")
            common="${REF_LENS_ARGS:-}"
        fi
        # shellcheck disable=SC2086
        if "${cmd[@]}" $args $common > /dev/null; then
            echo "   done in $((SECONDS - start)) s"
        else
            echo "   FAILED (see the traceback above); $(basename "$out") not updated" >&2
            failed=$((failed + 1))
        fi
    done <<< "$runs"
done
if [[ $failed -gt 0 ]]; then
    echo "$failed run(s) failed" >&2
    exit 1
fi

#!/usr/bin/env bash
# Out-of-sample check of `camsim diagnose` (issue 6): every effect id of effects.md at the test
# matrix's magnitude and concealment (tests/diagnose.rs), generated with another SEED than the
# tests use, on the same 32×48 sensor; prints one line per effect (findings, undecided groups,
# χ²/dof after, seconds). Usage: bench/diagnose_seeds.sh [SEED] (default 7).
set -euo pipefail
cd "$(dirname "$0")/.."
SEED=${1:-7}
cargo build --release -q --bin camsim
BIN=${CARGO_TARGET_DIR:-target}/release/camsim
OUT=${OUT:-target/diagnose-seeds}
run() {
  local d="$OUT/$1-$2-$SEED"
  rm -rf "$d"
  "$BIN" demo diagnose --effect "$1" --conceal "$2" --rows 32 --cols 48 --seed "$SEED" --out "$d/set" >/dev/null 2>&1
  local s e
  s=$(date +%s)
  "$BIN" --threads 2 diagnose "$d/set/captures.json" --out "$d/out" >/dev/null 2>&1
  e=$(date +%s)
  python3 - "$d/out/report.json" "$1 $2 seed $SEED" "$((e - s))" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
f = [(x["effect"], round(x["magnitude"], 5)) for x in r["findings"]]
u = [x["effects"] for x in r.get("undecided", [])]
print(f"{sys.argv[2]}: findings {f} undecided {u} chi2/dof {r['fit_after']['chi2_per_dof']:.3f} ({sys.argv[3]} s)")
PY
}
run exposure_scale=1.08 none
run conversion_gain=0.9 mimicked
run black_level=6.5 mimicked
run dark_current=0.02 mimicked
run read_noise=0.002 mimicked
run dsnu=0.002 mimicked
run prnu=2.0 mimicked
run column_fpn=0.001 below-noise
run hot_pixels=0.004 under-scene
run nonlinearity=0.06 under-scene
run full_well=7000 under-scene
run relative_illumination=0.25 none
run veiling_glare=0.03 under-scene
run defocus=1.5 under-scene
run crosstalk=0.05 mimicked
run ir_leakage=0.03 mimicked
run qe_shift=-6 mimicked
run distortion=-0.04 under-scene
run lateral_color=2.5 under-scene

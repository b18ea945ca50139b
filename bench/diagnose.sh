#!/usr/bin/env bash
# diagnose benchmark (issue 6, acceptance 4): a generated capture set of ~50 frames of a
# 1 MP sensor (default 1024×1024) with two concealed effects, diagnosed with every candidate;
# prints the wall time of the generator and of `camsim diagnose` (CAMSIM_PROFILE=1 prints the
# time of every stage). No peer exists for this; docs/benchmarks/diagnose.md holds results.
# Env: ROWS, COLS (default 1024), THREADS (default 2), OUT (default target/bench-diagnose),
#      CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROWS=${ROWS:-1024}
COLS=${COLS:-1024}
THREADS=${THREADS:-2}
OUT=${OUT:-target/bench-diagnose}
cargo build --release -q --bin camsim
BIN=${CARGO_TARGET_DIR:-target}/release/camsim
rm -rf "$OUT/set" "$OUT/out"
mkdir -p "$OUT"
# conversion_gain (mimicked: photon-transfer flats ×4, darks ×2) + prnu (mimicked: flats at
# 10/40/80/95 % ×4, darks ×4): 52 frames.
t0=$(date +%s.%N)
"$BIN" demo diagnose --effect conversion_gain=0.9 --effect prnu=2.0 --conceal mimicked \
    --rows "$ROWS" --cols "$COLS" --seed 1 --out "$OUT/set" >/dev/null
t1=$(date +%s.%N)
frames=$(find "$OUT/set/raw" -type f | wc -l)
RAYON_NUM_THREADS=$THREADS CAMSIM_PROFILE=${CAMSIM_PROFILE:-} \
    "$BIN" --threads "$THREADS" diagnose "$OUT/set/captures.json" --out "$OUT/out" 2>"$OUT/diagnose.log" \
    || { cat "$OUT/diagnose.log"; exit 1; }
t2=$(date +%s.%N)
python3 - "$OUT" "$ROWS" "$COLS" "$frames" "$t0" "$t1" "$t2" "$THREADS" <<'PY'
import json, sys
out, rows, cols, frames, t0, t1, t2, th = sys.argv[1:]
r = json.load(open(f"{out}/out/report.json"))
f = [(x["effect"], round(x["magnitude"], 5)) for x in r["findings"]]
print(f"sensor {rows}x{cols}, {frames} frames, {th} threads")
print(f"generate: {float(t1)-float(t0):.1f} s   diagnose: {float(t2)-float(t1):.1f} s")
print(f"findings {f}; chi2/dof {r['fit_before']['chi2_per_dof']:.3f} -> {r['fit_after']['chi2_per_dof']:.3f}; fit pixels {r['settings']['fit_pixels']}")
PY

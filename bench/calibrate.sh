#!/usr/bin/env bash
# calibrate speed benchmark (library level): 60 frames of 1024×1024 (3 darks × 4 frames, 8 flats
# × 6 frames) calibrated by camsim_diagnose::calibrate, timed by the #[ignore]d harness
# diagnose/tests/spectral_and_sets.rs::sixty_megapixel_frames_calibrate_timing. The target is
# ≤ BUDGET_S seconds (default 20, the former timed test's bound); exit status 1 when it is
# exceeded. The whole-process comparison with numpy (CLI incl. PNG reading) is bench/run.sh.
# Env: BUDGET_S (default 20), CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
BUDGET_S=${BUDGET_S:-20}
# --workspace: the same feature set as .ci/run, so the build cache is shared.
out=$(cargo test --release -q --workspace --test tests \
    sixty_megapixel_frames_calibrate_timing -- --ignored --nocapture 2>&1) \
    || { echo "$out"; exit 1; }
line=$(grep -o -m1 'calibrate 60 × [0-9]*×[0-9]*: [0-9.]* s' <<<"$out") \
    || { echo "$out"; echo "no timing line"; exit 1; }
dt=$(sed -E 's/.*: ([0-9.]+) s$/\1/' <<<"$line")
echo "$line (budget ${BUDGET_S} s; $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg))"
python3 - "$dt" "$BUDGET_S" <<'PY'
import sys
dt, budget = map(float, sys.argv[1:])
sys.exit(0 if dt <= budget else f"over budget: {dt:.2f} s > {budget:.0f} s")
PY

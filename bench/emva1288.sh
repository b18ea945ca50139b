#!/usr/bin/env bash
# EMVA 1288 benchmark (issue 22, acceptance 4): the full analysis of a 1 MP series (default
# 1024×1024, 50 steps to saturation + 10 beyond, dark pairs, L = 100 spatial stacks: 440
# frames) by camsim (`camsim calibrate --emva1288`: read the PNGs + analyse) and by the
# reference implementation emva1288 1.0.2 (tools/emva1288_ref.py analyse: parse + load +
# Data1288 + Results1288), timed in the same run on the same images. The series is written
# once by `camsim emva1288` (Table 1 camera). Result rows go to docs/benchmarks.md.
# Env: ROWS, COLS (default 1024), L (default 100), THREADS (default 2), BIN (a prebuilt camsim),
#      OUT (default target/bench-emva1288), CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROWS=${ROWS:-1024}
COLS=${COLS:-1024}
L=${L:-100}
THREADS=${THREADS:-2}
OUT=${OUT:-target/bench-emva1288}
if [ -z "${BIN:-}" ]; then
    cargo build --release -q --bin camsim
    BIN=${CARGO_TARGET_DIR:-target}/release/camsim
fi
tools/emva1288_setup.sh >/dev/null
PY=${CAMSIM_EMVA1288_VENV:-.venv-emva1288}/bin/python
rm -rf "$OUT"
mkdir -p "$OUT"
t0=$(date +%s.%N)
"$BIN" --threads "$THREADS" emva1288 examples/table1/camera.json --rows "$ROWS" --cols "$COLS" \
    --spatial-frames "$L" --out "$OUT/series" 2>"$OUT/simulate.log" || { cat "$OUT/simulate.log"; exit 1; }
t1=$(date +%s.%N)
# CPU time (user + sys) of each analysis too: on a shared machine the wall ratio depends on
# the load, the CPU-time ratio much less.
echo "load before the analyses: $(uptime | sed 's/.*load average/load average/')"
RAYON_NUM_THREADS=$THREADS /usr/bin/time -f "%U %S" -o "$OUT/camsim.cpu" \
    "$BIN" --threads "$THREADS" calibrate --emva1288 \
    "$OUT/series/EMVA1288descriptor.txt" --out "$OUT/camsim" 2>"$OUT/camsim.log" \
    || { cat "$OUT/camsim.log"; exit 1; }
t2=$(date +%s.%N)
/usr/bin/time -f "%U %S" -o "$OUT/reference.cpu" \
    "$PY" tools/emva1288_ref.py analyse "$OUT/series/EMVA1288descriptor.txt" >"$OUT/reference.json"
t3=$(date +%s.%N)
echo "load after the analyses: $(uptime | sed 's/.*load average/load average/')"
python3 - "$OUT" "$ROWS" "$COLS" "$L" "$THREADS" "$t0" "$t1" "$t2" "$t3" <<'PY'
import json, sys
out, rows, cols, L, th, t0, t1, t2, t3 = sys.argv[1:]
t0, t1, t2, t3 = map(float, (t0, t1, t2, t3))
cpu = {k: [float(x) for x in open(f"{out}/{k}.cpu").read().split()[-2:]]
       for k in ("camsim", "reference")}
frames = sum(1 for l in open(f"{out}/series/EMVA1288descriptor.txt") if l.startswith("i "))
ref = json.load(open(f"{out}/reference.json"))
cam = json.load(open(f"{out}/camsim/datasheet.json"))["values"]
std = ref["values_standard_saturation"]
worst = max(abs(cam[k]["value"] - v) / abs(v) for k, v in std.items()
            if k in cam and v not in (None, 0.0) and cam[k]["value"] == cam[k]["value"])
print(f"sensor {rows}x{cols}, {frames} frames (L = {L}), {th} threads")
print(f"camsim emva1288 (simulate + write + analyse): {t1-t0:.1f} s")
print(f"analysis: camsim {t2-t1:.2f} s, emva1288 {t3-t2:.2f} s (its own timer {ref['seconds']:.2f} s)"
      f" -> {(t3-t2)/(t2-t1):.1f}x")
(cu, cs), (ru, rs) = cpu["camsim"], cpu["reference"]
print(f"CPU time (user + sys): camsim {cu:.2f} + {cs:.2f} s, emva1288 {ru:.2f} + {rs:.2f} s"
      f" -> {(ru + rs) / (cu + cs):.1f}x")
print(f"largest relative difference of a datasheet number: {worst:.2e}")
PY

#!/usr/bin/env bash
# diagnose at scale (issue 23, acceptance "a 12 MP set with three chart shots and a dark/flat
# series takes at most 120 s"): a generated capture set on a ROWS x COLS sensor (default
# 3000 x 4000 = 12 MP) with the dark and photon-transfer flat series and three chart shots
# (`camsim demo diagnose --conceal charts`, 24 frames) hiding one effect, diagnosed with every
# candidate. Prints the generator's wall/user CPU time and peak memory (GNU time), then
# diagnose's wall, user CPU, peak memory, findings, full-resolution chi2/dof, what the fits
# subsampled and the time per stage (DIR/out-*/timing.json); the progress log (time per
# candidate) is DIR/diagnose-*.log. A generator or diagnose that refuses the size (memory
# limit, docs/limits.md) prints its one error line and the script stops (exit status 1).
# A/B: BASE=/path/to/an/older/camsim runs the same set with that binary first.
# Env: ROWS (default 3000), COLS (default 4000), EFFECT (default veiling_glare=0.03),
#      THREADS (default 2), MAX_MEMORY (passed as --max-memory to both, e.g. 12G; default: the
#      tools' own limit), OUT (default target/bench-diagnose-12mp), SET (reuse this existing
#      set folder instead of generating one), BASE, BIN (the binary to test; default: build
#      this tree's), CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
ROWS=${ROWS:-3000}
COLS=${COLS:-4000}
EFFECT=${EFFECT:-veiling_glare=0.03}
THREADS=${THREADS:-2}
OUT=${OUT:-target/bench-diagnose-12mp}
MEM=()
if [ -n "${MAX_MEMORY:-}" ]; then MEM=(--max-memory "$MAX_MEMORY"); fi
if [ -z "${BIN:-}" ]; then
  cargo build --release -q --bin camsim
  BIN=${CARGO_TARGET_DIR:-target}/release/camsim
fi
mkdir -p "$OUT"
echo "machine: $(nproc) cores, $(free -g | awk '/Mem:/ {print $2}') GB; load before: $(uptime | sed 's/.*load average: //')"
if [ -n "${SET:-}" ]; then
  CAPS=$SET/captures.json
  echo "set: $SET (reused)"
else
  rm -rf "$OUT/set"
  if ! RAYON_NUM_THREADS=$THREADS /usr/bin/time -f "%e %U %M" -o "$OUT/time-generate.txt" \
      "$BIN" --threads "$THREADS" demo diagnose "${MEM[@]}" --effect "$EFFECT" --conceal charts \
      --rows "$ROWS" --cols "$COLS" --seed 1 --out "$OUT/set" >"$OUT/generate.log" 2>&1; then
    echo "generate ${ROWS}x${COLS} failed:"; grep -v "^Command exited" "$OUT/generate.log" | head -3
    exit 1
  fi
  read -r gw gu gm < <(tail -1 "$OUT/time-generate.txt")
  frames=$(find "$OUT/set/raw" -type f | wc -l)
  echo "sensor ${ROWS}x${COLS}, $frames frames, effect $EFFECT, $THREADS threads; generate: $gw s wall, $gu s user CPU, $((gm / 1024)) MB peak"
  CAPS=$OUT/set/captures.json
fi
one() {
  local bin=$1 name=$2
  echo "load before $name: $(uptime | sed 's/.*load average: //')"
  rm -rf "$OUT/out-$name"
  if ! CAMSIM_PROFILE=1 RAYON_NUM_THREADS=$THREADS /usr/bin/time -f "%e %U %M" -o "$OUT/time-$name.txt" \
      "$bin" --threads "$THREADS" diagnose "${MEM[@]}" "$CAPS" \
      --out "$OUT/out-$name" 2>"$OUT/diagnose-$name.log"; then
    echo "$name: diagnose failed:"; grep -v "^camsim: *[0-9.]* s " "$OUT/diagnose-$name.log" | head -3
    return 1
  fi
  python3 - "$OUT/out-$name" "$name" "$OUT/time-$name.txt" <<'PY'
import json, os, sys
out, name, tf = sys.argv[1:]
r = json.load(open(f"{out}/report.json"))
f = [(x["effect"], round(x["magnitude"], 5)) for x in r["findings"]]
u = [x["effects"] for x in r.get("undecided", [])]
wall, user, rss = open(tf).read().split()[-3:]
def c(x):
    return "null" if x is None else f"{x:.3f}"
print(f"{name}: diagnose {float(wall):.1f} s wall, {user} s user CPU, {int(rss)//1024} MB peak; findings {f}; undecided {u}; "
      f"chi2/dof (every pixel) {c(r['fit_before']['chi2_per_dof'])} -> {c(r['fit_after']['chi2_per_dof'])}")
print(f"  subsampled: {json.dumps(r.get('subsampled'))}")
t = f"{out}/timing.json"
if os.path.exists(t):
    for x in json.load(open(t))["stages"]:
        c = f" / {x['calls']} calls" if "calls" in x else ""
        print(f"  {x['stage']}: {x['seconds']:.2f} s{c}")
PY
}
if [ -n "${BASE:-}" ]; then one "$BASE" base || true; fi
one "$BIN" new

#!/usr/bin/env bash
# diagnose on captures with scene content (issue 23): a generated capture set with darks,
# photon-transfer flats, two colour charts, a slanted edge and a point grid (the demo
# generator's default set, `camsim demo diagnose --conceal none`, 25 frames) hiding one
# effect, diagnosed with every candidate. Prints the generator's and diagnose's wall times,
# the findings, and diagnose's wall and user CPU time (GNU time) and time per stage
# (DIR/out/timing.json).
# A/B: BASE=/path/to/an/older/camsim runs the same set with that binary first (same run, same
# machine load).
# Env: ROWS (default 160), COLS (default 240), EFFECT (default veiling_glare=0.03),
#      THREADS (default 2), OUT (default target/bench-diagnose-scene), BASE, CARGO_TARGET_DIR,
#      SET (an existing capture-set directory holding captures.json: used as it is, nothing is
#      generated and ROWS/COLS/EFFECT are ignored), BIN (the camsim to measure; default: this
#      checkout's release binary, built first).
set -euo pipefail
cd "$(dirname "$0")/.."
ROWS=${ROWS:-160}
COLS=${COLS:-240}
EFFECT=${EFFECT:-veiling_glare=0.03}
THREADS=${THREADS:-2}
OUT=${OUT:-target/bench-diagnose-scene}
if [ -z "${BIN:-}" ]; then
  cargo build --release -q --bin camsim
  BIN=${CARGO_TARGET_DIR:-target}/release/camsim
fi
if [ -n "${SET:-}" ]; then
  # OUT is wiped below: it must not hold the set
  case "$(realpath -m "$SET")/" in
    "$(realpath -m "$OUT")"/*) echo "SET=$SET lies inside OUT=$OUT, which is wiped: choose another OUT" >&2; exit 2 ;;
  esac
fi
rm -rf "$OUT"
mkdir -p "$OUT"
if [ -n "${SET:-}" ]; then
  # an existing set: never regenerated, never written to
  [ -f "$SET/captures.json" ] || { echo "SET=$SET: no captures.json there" >&2; exit 2; }
  SETDIR=$SET
  echo "set $SET (as it is), $THREADS threads"
else
  SETDIR=$OUT/set
  t0=$(date +%s.%N)
  "$BIN" demo diagnose --effect "$EFFECT" --conceal none \
      --rows "$ROWS" --cols "$COLS" --seed 1 --out "$SETDIR" >/dev/null 2>&1
  t1=$(date +%s.%N)
  frames=$(find "$SETDIR/raw" -type f | wc -l)
  echo "sensor ${ROWS}x${COLS}, $frames frames, effect $EFFECT, $THREADS threads; generate: $(python3 -c "print(f'{$t1-$t0:.1f}')") s"
fi
one() {
  local bin=$1 name=$2
  local s e
  s=$(date +%s.%N)
  echo "load before $name: $(uptime | sed 's/.*load average: //')"
  CAMSIM_PROFILE=1 RAYON_NUM_THREADS=$THREADS /usr/bin/time -f "%U %S" -o "$OUT/time-$name.txt" \
      "$bin" --threads "$THREADS" diagnose "$SETDIR/captures.json" \
      --out "$OUT/out-$name" 2>"$OUT/diagnose-$name.log" || { cat "$OUT/diagnose-$name.log"; exit 1; }
  e=$(date +%s.%N)
  python3 - "$OUT/out-$name" "$name" "$s" "$e" "$OUT/time-$name.txt" <<'PY'
import json, os, sys
out, name, s, e, tf = sys.argv[1:]
r = json.load(open(f"{out}/report.json"))
f = [(x["effect"], round(x["magnitude"], 5)) for x in r["findings"]]
u = [x["effects"] for x in r.get("undecided", [])]
user_s, sys_s = open(tf).read().split()[-2:]
print(f"{name}: diagnose {float(e)-float(s):.1f} s wall, {user_s} s user CPU; findings {f}; undecided {u}; chi2/dof {r['fit_before']['chi2_per_dof']:.3f} -> {r['fit_after']['chi2_per_dof']:.3f}")
t = f"{out}/timing.json"
if os.path.exists(t):
    for x in json.load(open(t))["stages"]:
        c = f" / {x['calls']} calls" if "calls" in x else ""
        print(f"  {x['stage']}: {x['seconds']:.2f} s{c}")
PY
}
if [ -n "${BASE:-}" ]; then one "$BASE" base; fi
one "$BIN" new

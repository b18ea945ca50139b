#!/usr/bin/env bash
# Lens benchmarks: camsim-lens (trace rate, field-model build) against Optiland in the same run.
# Builds lens/examples/lens_bench.rs in release, makes sure the Optiland venv (.venv-optics, the
# one tools/optics_ref_run.sh uses) exists, runs bench/lens_bench.py and writes
# docs/benchmarks/lens.md.
# Env: BENCH_REPEATS (default 5), LENS_BENCH_RAYS (default 4000000), CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=.venv-optics
if [[ ! -x "$VENV/bin/python" ]]; then
    "${PYTHON:-python3}" -m venv "$VENV"
fi
if ! "$VENV/bin/python" -c "import optiland, rayoptics" 2>/dev/null; then
    "$VENV/bin/pip" install --quiet --upgrade pip
    "$VENV/bin/pip" install --quiet optiland rayoptics
fi
cargo build --release -q -p camsim-lens --example lens_bench
"$VENV/bin/python" bench/lens_bench.py

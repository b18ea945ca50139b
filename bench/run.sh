#!/usr/bin/env bash
# Benchmark harness: installs numpy into .venv-bench, builds camsim in release, runs bench.py.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv-bench/bin/python ] || python3 -m venv .venv-bench
.venv-bench/bin/pip install -q numpy
cargo build --release -q
.venv-bench/bin/python bench/bench.py

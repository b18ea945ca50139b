#!/usr/bin/env bash
# Python package overhead benchmark: builds the CLI (release) and installs the package into
# .venv-py (tools/python_setup.sh), then runs bench/python_bench.py (writes
# docs/benchmarks/python.md).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q --bin camsim
tools/python_setup.sh
.venv-py/bin/python bench/python_bench.py

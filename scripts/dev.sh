#!/usr/bin/env bash
# Developer rebuild: compiles the extension in release mode into .venv in place (editable), so
# python/ edits take effect without rebuilding. A lock serialises concurrent rebuilds.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || bash scripts/setup.sh
.venv/bin/python -m pip show maturin >/dev/null 2>&1 || .venv/bin/python -m pip install -q maturin
exec flock .venv/.build.lock .venv/bin/maturin develop --release -q

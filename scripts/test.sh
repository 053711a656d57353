#!/usr/bin/env bash
# All the tests, from a fresh machine: setup (with the training extras' torch), Rust, Python.
set -euo pipefail
cd "$(dirname "$0")/.."
AFFCORR_WITH_TORCH=1 bash scripts/setup.sh
echo "== cargo test"
# The default members: everything but the extension module, which pytest covers.
cargo test --locked
echo "== pytest"
.venv/bin/python -m pytest -q

#!/usr/bin/env bash
# What to run before a commit: formatting, clippy with warnings as errors, rustdoc, ruff, and
# the typed stub of the extension checked against the built module (mypy's stubtest; rebuild
# with scripts/dev.sh first).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked --quiet
[ -x .venv/bin/ruff ] || .venv/bin/python -m pip install -q ruff
.venv/bin/ruff check python tests benches
.venv/bin/ruff format --check python tests benches
.venv/bin/python -c "import mypy" 2>/dev/null || .venv/bin/python -m pip install -q "mypy>=1.10"
.venv/bin/python -m mypy.stubtest affcorr._native --allowlist scripts/stubtest_allowlist.txt

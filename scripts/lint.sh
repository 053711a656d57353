#!/usr/bin/env bash
# What to run before a commit: formatting, clippy with warnings as errors, ruff.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked --quiet
[ -x .venv/bin/ruff ] || .venv/bin/python -m pip install -q ruff
.venv/bin/ruff check python tests benches
.venv/bin/ruff format --check python tests benches

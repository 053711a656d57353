#!/usr/bin/env bash
# The main job on bundled real data, from a fresh machine: setup, then the demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/affcorr demo --out "${1:-affcorr_demo.png}"

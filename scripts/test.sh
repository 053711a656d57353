#!/usr/bin/env bash
# All the tests, from a fresh machine: setup (with the training extras' torch), Rust, Python.
set -euo pipefail
cd "$(dirname "$0")/.."
AFFCORR_WITH_TORCH=1 bash scripts/setup.sh
# The evaluation suite's peers (OpenCV, pyhesaff, LightGlue; benches/eval/setup.sh), so that its
# smoke tests run rather than skip; a peer that cannot be installed is listed, not fatal. It also
# exports the models that are made at setup time (DISK + LightGlue and ALIKED + LightGlue,
# docs/matchers.md), which the
# Rust and Python tests below then require (AFFCORR_REQUIRE_EXPORTED_MODELS: a missing one fails
# instead of skipping).
bash benches/eval/setup.sh
export AFFCORR_REQUIRE_EXPORTED_MODELS=1
echo "== cargo test"
# The runner's tests load ONNX Runtime at run time: the library of the onnxruntime wheel.
if [ -z "${ORT_DYLIB_PATH:-}" ]; then
    ORT_DYLIB_PATH=$(.venv/bin/python -c 'import affcorr.shape as s; print(s.find_ort_library())')
    export ORT_DYLIB_PATH
fi
echo "ORT_DYLIB_PATH=$ORT_DYLIB_PATH"
# The default members: everything but the extension module, which pytest covers.
cargo test --locked
echo "== pytest"
.venv/bin/python -m pytest -q

#!/usr/bin/env bash
# The API reference: HTML built by pdoc from the runtime docstrings (the native functions' text
# comes from python/affcorr/_native.pyi through affcorr._docs), and the Rust crates' rustdoc.
#   bash scripts/docs.sh [OUT]        # default: target/api-docs; open OUT/python/index.html
# AFFCORR_DOCS_RUST=0 builds the Python part only. Checked in CI by tests/test_ecosystem_docs.py.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/api-docs}
py=.venv/bin/python
"$py" -c "import pdoc" 2>/dev/null || "$py" -m pip install -q --disable-pip-version-check "pdoc>=14"
# The public API (affcorr.solvers and affcorr.opencv come with affcorr, in its __all__);
# training, export and the torch losses need torch and are left out.
"$py" -m pdoc --docformat restructuredtext --no-show-source -o "$out/python" \
    affcorr affcorr.estimation affcorr.pipeline affcorr.shape affcorr.metrics affcorr.data \
    affcorr.plot affcorr.cli
if [ "${AFFCORR_DOCS_RUST:-1}" = 1 ]; then
    RUSTDOCFLAGS="-D warnings" cargo doc --locked --no-deps -p affcorr -p affcorr-geom \
        -p affcorr-solvers -p affcorr-ransac -p affcorr-image -p affcorr-runner -p affcorr-pipeline
    rm -rf "$out/rust" && cp -r target/doc "$out/rust"
    echo "docs: $out/rust/affcorr/index.html"
fi
echo "docs: $out/python/index.html"

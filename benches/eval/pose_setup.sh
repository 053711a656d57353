#!/usr/bin/env bash
# Experiment 3 (python -m affcorr_bench.eval.pose) on a fresh Debian machine: its matchers, its
# estimators' venvs, and its data, all into caches outside the repository (AFFCORR_CACHE, ~/.cache/affcorr):
#   - the matchers of the registry (benches/eval/setup.sh, which also runs scripts/setup.sh);
#   - PoseLib + OpenCV 5 (.venv-peers) and pygcransac (.venv-gcransac): benches/peers/setup.sh;
#   - Debian's opencv-doc (apt-get download + dpkg-deb -x, affcorr.train.sources), undistorted
#     and calibrated once by affcorr_bench.eval.pose_calib in .venv-peers;
#   - the synthetic pairs, rendered once (about 1 s each).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash benches/eval/setup.sh
bash benches/peers/setup.sh
PYTHONPATH=benches .venv/bin/python - <<'PY'
from affcorr_bench.eval import pose_data

print("chessboard:", len(pose_data.chessboard_pairs()), "pairs;",
      "motorcycle:", pose_data.motorcycle_pair().K1[0, 0], "px focal")
PY
PYTHONPATH=benches nice -n 10 .venv/bin/python -m affcorr_bench.eval.pose_data "${POSE_SYNTHETIC:-500}"
echo "pose_setup: done"

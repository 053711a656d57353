"""Ground truth of the opencv-doc chessboard set, with OpenCV (runs in benches/peers/.venv-peers).

    PYTHONPATH=benches benches/peers/.venv-peers/bin/python -m affcorr_bench.eval.pose_calib \
        DATA_DIR OUT_DIR

(pose_data.chessboard_calibration runs it so, on first use; cv2 is imported by the functions
that use it, so that the module imports in .venv as well).

DATA_DIR is opencv-doc's examples/data (left01..14.jpg, right01..14.jpg, left_intrinsics.yml,
stereo_calib.xml). Writes to OUT_DIR:

- ``left01.png`` ... ``right14.png``: the images undistorted to the pinhole camera of their
  intrinsics (``cv2.undistort`` with the same K), so that every matcher sees pinhole views;
- ``calib.json``: ``K_left``, ``K_right``; ``board_from_yml``: per left image ``R``, ``t`` of
  the board (X_cam = R X_board + t) from left_intrinsics.yml's ``extrinsic_parameters``;
  ``pnp_check_deg``/``pnp_check_m``: how far solvePnP on the detected corners is from them (a
  check of the image order); ``stereo``: ``R``, ``t`` (X_right = R X_left + t, metres) from
  ``cv2.stereoCalibrate`` on the pairs of stereo_calib.xml, with its RMS reprojection error.

Only left_intrinsics.yml comes with calibrated intrinsics; the right camera is calibrated here
(``cv2.calibrateCamera`` on its detected corners), then the rig with both intrinsics fixed.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np

PATTERN = (9, 6)


def yml_matrix(text: str, name: str) -> np.ndarray:
    """An ``!!opencv-matrix`` entry of an OpenCV YAML file."""
    m = re.search(
        name + r":\s*!!opencv-matrix\s*rows:\s*(\d+)\s*cols:\s*(\d+).*?data:\s*\[(.*?)\]",
        text,
        re.S,
    )
    if m is None:
        raise ValueError(f"{name} not found")
    rows, cols = int(m.group(1)), int(m.group(2))
    return np.array([float(v) for v in m.group(3).replace("\n", " ").split(",")]).reshape(
        rows, cols
    )


def corners(path: Path) -> np.ndarray | None:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    found, c = cv2.findChessboardCorners(img, PATTERN)
    if not found:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    return cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit).reshape(-1, 2)


def main(data: Path, out: Path) -> int:
    import cv2

    out.mkdir(parents=True, exist_ok=True)
    text = (data / "left_intrinsics.yml").read_text()
    K_l = yml_matrix(text, "camera_matrix")
    D_l = yml_matrix(text, "distortion_coefficients").reshape(-1)
    ext = yml_matrix(text, "extrinsic_parameters")
    square = float(re.search(r"square_size:\s*([0-9.eE+-]+)", text).group(1))
    names = re.findall(r'"([^"]+\.jpg)"', (data / "stereo_calib.xml").read_text())
    lefts, rights = names[0::2], names[1::2]
    if len(lefts) != len(ext):
        raise ValueError(f"{len(lefts)} left images but {len(ext)} extrinsics")
    grid = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    grid[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * square
    cl = [corners(data / n) for n in lefts]
    cr = [corners(data / n) for n in rights]

    board, checks_deg, checks_m = {}, [], []
    for name, row, c in zip(lefts, ext, cl):
        R, _ = cv2.Rodrigues(row[:3])
        board[name] = dict(R=R.tolist(), t=row[3:].tolist())
        if c is not None:
            _, rv, tv = cv2.solvePnP(grid, c, K_l, D_l)
            Rp, _ = cv2.Rodrigues(rv)
            dR = np.degrees(np.arccos(np.clip((np.trace(Rp @ R.T) - 1) / 2, -1, 1)))
            checks_deg.append(float(dR))
            checks_m.append(float(np.linalg.norm(tv.reshape(3) - row[3:])))

    size = cv2.imread(str(data / rights[0]), cv2.IMREAD_GRAYSCALE).shape[::-1]
    ok_r = [i for i, c in enumerate(cr) if c is not None]
    rms_r, K_r, D_r, _, _ = cv2.calibrateCamera(
        [grid] * len(ok_r), [cr[i].astype(np.float32) for i in ok_r], size, None, None
    )
    D_r = D_r.reshape(-1)
    both = [i for i in range(len(lefts)) if cl[i] is not None and cr[i] is not None]
    rms_s, *_, R_s, t_s, _, _ = cv2.stereoCalibrate(
        [grid] * len(both),
        [cl[i].astype(np.float32) for i in both],
        [cr[i].astype(np.float32) for i in both],
        K_l,
        D_l,
        K_r,
        D_r,
        size,
        flags=cv2.CALIB_FIX_INTRINSIC,
    )

    for names_, K, D in ((lefts, K_l, D_l), (rights, K_r, D_r)):
        for n in names_:
            img = cv2.imread(str(data / n), cv2.IMREAD_GRAYSCALE)
            cv2.imwrite(str(out / (Path(n).stem + ".png")), cv2.undistort(img, K, D, None, K))

    calib = dict(
        K_left=K_l.tolist(),
        K_right=K_r.tolist(),
        right_calibration_rms_px=float(rms_r),
        lefts=[Path(n).stem for n in lefts],
        rights=[Path(n).stem for n in rights],
        board_from_yml={Path(k).stem: v for k, v in board.items()},
        pnp_check_deg=max(checks_deg),
        pnp_check_m=max(checks_m),
        stereo=dict(
            R=R_s.tolist(), t=t_s.reshape(3).tolist(), rms_px=float(rms_s), pairs=len(both)
        ),
        square_size_m=square,
        opencv=cv2.__version__,
    )
    (out / "calib.json").write_text(json.dumps(calib, indent=1))
    print(
        json.dumps(
            {k: calib[k] for k in ("right_calibration_rms_px", "pnp_check_deg", "pnp_check_m")}
        ),
        calib["stereo"]["rms_px"],
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))

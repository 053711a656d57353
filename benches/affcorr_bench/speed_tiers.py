"""Speed tiers: affcorr's pipeline configurations against SIFT + PoseLib and SIFT + OpenCV on
the same real and rendered pairs, in one run: time per pair (images in memory → model) and
success (issue 21's second target: "time per pair below SIFT + PoseLib's at equal or better
success").

    cd benches && ../.venv/bin/python -m affcorr_bench.speed_tiers            # ~10 min
    ../.venv/bin/python -m affcorr_bench.speed_tiers --planar-images 1 --synthetic 4   # quick

Pairs:
- *planar*: graffiti 1→3 and held-out photographs under random homographies and illumination
  changes (experiment 1's generator, ``eval.data.hpatches_pairs``) at up to 1024 px; a pair is
  solved when the estimated H maps a 10 × 10 grid of image 1 (the part seen in image 2) within
  5 px of the truth on average; threshold 2 px for every estimator.
- *extreme*: experiment 4's planes seen at 50–80° tilt (``eval.data.extreme_pairs``, 640×480),
  scored as the planar pairs.
- *pose*: the 13 chessboard stereo pairs, the motorcycle pair, every 6th chessboard board pair
  and ``--synthetic`` rendered multi-plane scenes (``eval.pose_data``); error max(rotation,
  translation direction), solved below 10°, AUC@5/10/20; threshold 1 px.

SIFT is what a user runs: OpenCV's SIFT (all keypoints) with Lowe's ratio test (0.8) on a
brute-force kNN, 2 OpenCV threads; PoseLib and OpenCV's USAC_MAGSAC estimate in the peers' venv
(``peers.worker``, one thread, the fastest of ``PEERS_REPEAT`` calls). affcorr runs with 2
threads; its time is ``match_pair``'s wall time plus the estimator's. Needs
benches/eval/setup.sh and benches/peers/setup.sh.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from . import common
from .eval import data as planar_data
from .eval import pose as pose_eval
from .eval import pose_data

#: affcorr configurations (Pipeline keyword arguments), the default first (the result file of
#: 2026-12-04 03:03 predates the default of 1024 keypoints: its "default" row is 2048).
CONFIGS: dict[str, dict] = {
    "affcorr default (xfeat-lighterglue, 1024 kp)": {},
    "affcorr xfeat-lighterglue, 2048 kp": {"max_keypoints": 2048},
    "affcorr xfeat (MNN), 2048 kp": {"matcher": "xfeat", "max_keypoints": 2048},
    "affcorr xfeat (MNN), 4096 kp": {"matcher": "xfeat", "max_keypoints": 4096},
}
PEERS = {"SIFT + PoseLib": "poselib", "SIFT + OpenCV USAC_MAGSAC": "opencv-USAC_MAGSAC"}
H_THRESHOLD, POSE_THRESHOLD = 2.0, 1.0
H_SOLVED_PX, POSE_SOLVED_DEG = 5.0, 10.0
THREADS = 2


def sift_matches(img1: np.ndarray, img2: np.ndarray) -> tuple[np.ndarray, float]:
    """(N, 4) SIFT matches by the ratio test, and the seconds they took."""
    import cv2

    cv2.setNumThreads(THREADS)
    t0 = time.perf_counter()
    sift = cv2.SIFT_create()
    k1, d1 = sift.detectAndCompute(img1, None)
    k2, d2 = sift.detectAndCompute(img2, None)
    rows = []
    if d1 is not None and d2 is not None and len(d1) >= 2 and len(d2) >= 2:
        for m in cv2.BFMatcher(cv2.NORM_L2).knnMatch(d1, d2, k=2):
            if len(m) == 2 and m[0].distance < 0.8 * m[1].distance:
                rows.append([*k1[m[0].queryIdx].pt, *k2[m[0].trainIdx].pt])
    return np.array(rows, np.float64).reshape(-1, 4), time.perf_counter() - t0


def grid_error(H: np.ndarray | None, H_gt: np.ndarray, shape1, shape2) -> float:
    """Mean distance (px) between H and H_gt on a 10 × 10 grid of image 1 that H_gt maps into
    image 2 (inf without an H)."""
    if H is None or not np.all(np.isfinite(H)):
        return np.inf
    h, w = shape1
    xs, ys = np.meshgrid(np.linspace(0, w - 1, 10), np.linspace(0, h - 1, 10))
    p = np.c_[xs.ravel(), ys.ravel(), np.ones(100)]

    def apply(M):
        q = p @ M.T
        return q[:, :2] / q[:, 2:]

    gt = apply(H_gt)
    seen = (gt[:, 0] >= 0) & (gt[:, 0] < shape2[1]) & (gt[:, 1] >= 0) & (gt[:, 1] < shape2[0])
    if not seen.any():
        return np.inf
    return float(np.linalg.norm(apply(H)[seen] - gt[seen], axis=1).mean())


def pose_error(R, t, pair) -> float:
    if R is None:
        return np.inf
    return max(
        pose_eval.rotation_error(R, pair.R), pose_eval.translation_error(np.ravel(t), pair.t)
    )


def run_affcorr(pipe, kind: str, img1, img2, pair) -> tuple[float, float, int]:
    """(error, seconds, matches) of one pipeline on one pair."""
    import affcorr

    t0 = time.perf_counter()
    res = pipe.match_pair(img1, img2)
    corrs = res.corrs
    if len(corrs) < pose_eval.MIN_MATCHES:
        return np.inf, time.perf_counter() - t0, len(corrs)
    if kind != "pose":
        H, info = affcorr.estimate_homography(corrs, threshold=H_THRESHOLD)
        err = grid_error(H if info.num_inliers else None, pair.H, img1.shape, img2.shape)
    else:
        corrs = corrs[pair.keep(corrs[:, :2], corrs[:, 2:4])]
        if len(corrs) < pose_eval.MIN_MATCHES:
            return np.inf, time.perf_counter() - t0, len(corrs)
        pz, info = affcorr.estimate_relative_pose(corrs, pair.K1, pair.K2, threshold=POSE_THRESHOLD)
        err = pose_error(pz.R, pz.t, pair) if info.num_inliers else np.inf
    return err, time.perf_counter() - t0, len(corrs)


def run_peers(kind: str, jobs: list[dict], tmp: Path, notes: list[str]) -> dict:
    """{(peer label, job index): (error, estimator seconds)} from the peers' worker."""
    out = {}
    ok = [i for i, j in enumerate(jobs) if len(j["corrs"]) >= pose_eval.MIN_MATCHES]
    scenes = [
        dict(
            corrs=jobs[i]["corrs"],
            K1=jobs[i].get("K1", np.eye(3)),
            K2=jobs[i].get("K2", np.eye(3)),
        )
        for i in ok
    ]
    problem, thr = ("homography", H_THRESHOLD) if kind != "pose" else ("relpose", POSE_THRESHOLD)
    raw = (
        pose_eval.run_worker("peers", scenes, list(PEERS.values()), tmp, problem, thr)
        if scenes
        else {}
    )
    if "group_error" in raw:
        notes.append(f"peers: {raw['group_error']}")
    for label, method in PEERS.items():
        for k, i in enumerate(ok):
            key = f"{method}/{k}/"
            job, err = jobs[i], np.inf
            if key + "ok" in raw and bool(raw[key + "ok"]):
                if kind != "pose":
                    err = grid_error(raw[key + "H"], job["pair"].H, *job["shapes"])
                else:
                    err = pose_error(raw[key + "R"], raw[key + "t"], job["pair"])
            out[label, i] = (err, float(raw.get(key + "time", np.nan)))
    return out


def pairs(args) -> dict[str, list]:
    planar = planar_data.hpatches_pairs(max_side=1024, images=args.planar_images)
    extreme = planar_data.extreme_pairs()
    board = pose_data.chessboard_pairs()
    pose = [p for p in board if "stereo" in p.dataset]
    pose += [p for p in board if "stereo" not in p.dataset][:: args.board_every]
    pose.append(pose_data.motorcycle_pair())
    pose += pose_data.synthetic_pairs(args.synthetic)
    return {"planar": planar, "extreme": extreme, "pose": pose}


def summarize(kind: str, errors: list[float], seconds: list[float]) -> dict:
    e = np.asarray(errors, float)
    solved_at = H_SOLVED_PX if kind != "pose" else POSE_SOLVED_DEG
    row = {
        "pairs": len(e),
        "solved": int((e < solved_at).sum()),
        "median error": float(np.median(e)) if len(e) else np.nan,
        "median s/pair": float(np.median(seconds)) if seconds else np.nan,
        "mean s/pair": float(np.mean(seconds)) if seconds else np.nan,
    }
    if kind == "pose":
        for thr, auc in zip(pose_eval.AUC_DEG, pose_eval.pose_auc(e)):
            row[f"AUC@{thr}"] = 100.0 * auc
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--planar-images", type=int, default=None, help="held-out images per kind")
    ap.add_argument("--synthetic", type=int, default=12, help="rendered pose pairs")
    ap.add_argument("--board-every", type=int, default=6, help="every k-th chessboard pair")
    ap.add_argument("-o", "--out", type=Path, default=common.RESULTS / "speed_tiers.md")
    args = ap.parse_args(argv)

    import affcorr

    start, load0 = time.time(), common.load_average()
    pipes = {k: affcorr.Pipeline(threads=THREADS, **v) for k, v in CONFIGS.items()}
    data, notes, rows = pairs(args), [], []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, items in data.items():
            errors: dict[str, list] = {k: [] for k in [*CONFIGS, *PEERS]}
            seconds: dict[str, list] = {k: [] for k in errors}
            jobs = []
            for n, pair in enumerate(items):
                if kind != "pose":
                    img1, img2 = pair.img1, pair.img2
                else:
                    img1, img2 = pair.load()
                # Alternate the order of the sides pair by pair, so that drift in the
                # machine's load is shared.
                sides = list(pipes.items())
                for label, pipe in sides if n % 2 == 0 else sides[::-1]:
                    err, sec, _ = run_affcorr(pipe, kind, img1, img2, pair)
                    errors[label].append(err)
                    seconds[label].append(sec)
                corrs, sec = sift_matches(img1, img2)
                if kind == "pose":
                    corrs = corrs[pair.keep(corrs[:, :2], corrs[:, 2:4])]
                jobs.append(
                    dict(
                        pair=pair,
                        corrs=corrs,
                        seconds=sec,
                        shapes=(img1.shape, img2.shape),
                        **({"K1": pair.K1, "K2": pair.K2} if kind == "pose" else {}),
                    )
                )
                label = getattr(pair, "name", None) or pair.id
                print(f"{kind} {n + 1}/{len(items)} {label}", flush=True)
            peer = run_peers(kind, jobs, Path(tmp), notes)
            for label in PEERS:
                for i, job in enumerate(jobs):
                    err, est = peer.get((label, i), (np.inf, 0.0))
                    errors[label].append(err)
                    seconds[label].append(job["seconds"] + (0.0 if np.isnan(est) else est))
            for label in errors:
                rows.append(
                    {"set": kind, "method": label, **summarize(kind, errors[label], seconds[label])}
                )
    write(args, rows, notes, start, load0)
    return 0


def write(args, rows, notes, start, load0) -> None:
    import affcorr

    lines = [
        "# Speed tiers: affcorr's configurations against SIFT + PoseLib / OpenCV (same run)",
        "",
        f"Command: `{common.command('affcorr_bench.speed_tiers', prefix='cd benches && ../')}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; affcorr "
        f"{affcorr.__version__}; {time.time() - start:.0f} s; load average "
        f"{load0[0]:.1f} before, {common.load_average()[0]:.1f} after, on 2 cores "
        "(above 1, other jobs shared the machine: compare rows, not absolute times).",
        "",
        (__doc__ or "").split("\n\n", 2)[2].strip(),
        "",
    ]
    for kind in ("planar", "extreme", "pose"):
        sel = [r for r in rows if r["set"] == kind]
        if not sel:
            continue
        cols = ["method", "pairs", "solved", "median error", "median s/pair", "mean s/pair"]
        if kind == "pose":
            cols += [f"AUC@{t}" for t in pose_eval.AUC_DEG]
        ref = next(r for r in sel if r["method"] == "SIFT + PoseLib")
        unit = "px" if kind != "pose" else "°"
        lines += [
            f"## {kind} pairs (error in {unit}; time ratio to SIFT + PoseLib)",
            "",
            *common.md_table(
                [*cols, "time / SIFT + PoseLib"],
                [
                    [
                        *(r[c] if isinstance(r[c], str) else round(r[c], 3) for c in cols),
                        round(r["median s/pair"] / ref["median s/pair"], 2),
                    ]
                    for r in sel
                ],
            ),
            "",
        ]
    if notes:
        lines += ["Notes:", "", *(f"- {n}" for n in notes), ""]
    common.write_report(args.out, lines)
    common.write_csv(rows, args.out.with_suffix(".csv"), fieldnames=list(rows[-1]))


if __name__ == "__main__":
    raise SystemExit(main())

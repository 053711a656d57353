"""The `affcorr` command line.

    affcorr match A B -o acs.npz            images -> ACs (N, 8) with certainty
    affcorr match --pairs list.txt -o DIR   many pairs (one "A B" per line), with a progress bar
    affcorr homography A B [--gt H.txt]     H, inliers, and the corner error against a ground truth
                       [-o h.json|h.npz]    ... saved at full precision (.npz: with the ACs)
    affcorr pose A B --K1 ... --K2 ...      relative pose (R, t) from calibrated images [-o ...]
    affcorr show acs.npz -o matches.png     picture: matches (coloured by correctness with --gt)
                                            and affine frames as ellipses
    affcorr demo                            the whole pipeline on graffiti 1->3 (ground-truth H)

Intrinsics are given as "fx,fy,cx,cy", as nine numbers "k11,...,k33", or as a text/.npy file
holding a 3x3 matrix. A ground-truth homography is a text file of 3x3 numbers or an OpenCV XML
file (like graffiti's H1to3p.xml).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .metrics import corner_error
from .pipeline import MATCHERS, PIPELINE_DEFAULTS


def read_matrix(text: str, what: str) -> np.ndarray:
    """A 3x3 matrix from "fx,fy,cx,cy", nine comma-separated numbers, or a file."""
    path = Path(text)
    if path.exists():
        try:
            if path.suffix == ".npy":
                m = np.load(path)
            elif path.suffix in (".xml", ".yml", ".yaml"):
                from .data import read_opencv_matrix

                m = read_opencv_matrix(path)
            else:
                m = np.loadtxt(path)
        except Exception as e:  # any parse failure of a user file is a bad argument
            raise ValueError(f"{what}: cannot read a 3x3 matrix from {text!r}: {e}") from None
    else:
        try:
            v = [float(x) for x in text.replace(" ", "").split(",") if x]
        except ValueError:
            raise ValueError(
                f"{what}: neither a file nor comma-separated numbers: {text!r}"
            ) from None
        if len(v) == 4:
            m = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
        elif len(v) == 9:
            m = np.array(v).reshape(3, 3)
        else:
            raise ValueError(f"{what}: expected 4 (fx,fy,cx,cy) or 9 numbers, got {len(v)}")
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (3, 3):
        raise ValueError(f"{what}: expected a 3x3 matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{what}: the matrix contains NaN or infinity")
    return m


def _pipeline(args):
    import affcorr

    return affcorr.Pipeline(
        matcher=args.matcher,
        max_keypoints=args.max_keypoints,
        max_side=args.max_side,
        threads=args.threads,
        dense_model=args.dense_model,
        shape_model=args.shape_model,
        refine_affine=args.refine_affine,
    )


def _add_pipeline_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--matcher",
        choices=MATCHERS,
        default=None,
        help=f"default: dense with --dense-model, else {PIPELINE_DEFAULTS['matcher']}",
    )
    p.add_argument(
        "--dense-model",
        default=None,
        help="a dense-warp-v1 ONNX matcher (DKM/RoMa export, docs/matchers.md)",
    )
    p.add_argument(
        "--shape-model", default=None, help="a shape-v1 ONNX network (default: the bundled one)"
    )
    p.add_argument(
        "--max-keypoints",
        type=int,
        default=PIPELINE_DEFAULTS["max_keypoints"],
        help="keypoints per image (default: %(default)s)",
    )
    p.add_argument(
        "--max-side",
        type=int,
        default=None,
        help="resize so that the longer side is at most this (px)",
    )
    p.add_argument("--threads", type=int, default=None, help="default: all cores")
    p.add_argument(
        "--refine-affine",
        action=argparse.BooleanOptionalAction,
        default=PIPELINE_DEFAULTS["refine_affine"],
        help="refine the ACs against the images by affine Lucas-Kanade (affcorr.refine_affine; "
        "default: %(default)s)",
    )


def _print_timings(timings: dict) -> None:
    for k, v in timings.items():
        print(f"  {k:<12} {1e3 * v:8.1f} ms")


def _output_file(path: str | Path, flag: str) -> Path:
    """Checks that `path` can be written before the work that produces it."""
    path = Path(path)
    if not path.parent.is_dir():
        raise ValueError(f"{flag}: the directory of {str(path)!r} does not exist")
    return path


def cmd_match(args) -> int:
    if args.pairs is not None:
        lines = [ln.split() for ln in Path(args.pairs).read_text().splitlines() if ln.strip()]
        bad = [i + 1 for i, ln in enumerate(lines) if len(ln) != 2]
        if bad:
            raise ValueError(f"--pairs: lines {bad[:5]} do not hold two image paths")
        pipe = _pipeline(args)
        out = Path(args.output)
        out.mkdir(parents=True, exist_ok=True)
        from ._progress import progress

        for k, (a, b) in enumerate(progress(lines, desc="matching pairs", unit="pair")):
            res = pipe.match_pair(a, b)
            np.savez(
                out / f"pair_{k:05d}.npz",
                corrs=res.corrs,
                certainty=res.certainty,
                image_a=a,
                image_b=b,
            )
        print(f"wrote {len(lines)} files to {out}")
        return 0
    if args.image_b is None:
        raise ValueError("give two images, or --pairs FILE")
    _output_file(args.output, "-o")
    pipe = _pipeline(args)
    res = pipe.match_pair(args.image_a, args.image_b)
    np.savez(
        args.output,
        corrs=res.corrs,
        certainty=res.certainty,
        image_a=args.image_a,
        image_b=args.image_b,
    )
    print(f"{len(res.corrs)} ACs -> {args.output}")
    _print_timings(res.timings)
    return 0


def _estimate_output(path: str | None) -> Path | None:
    """``-o`` of an estimating command: a .json or .npz path, checked before any work."""
    if path is None:
        return None
    out = _output_file(path, "-o")
    if out.suffix not in (".json", ".npz"):
        raise ValueError(f"-o: {path!r} must end in .json or .npz")
    return out


def _save_estimate(out: Path | None, args, models: dict, info, res) -> None:
    """The model at full precision with the estimation's info: JSON (inlier indices), or .npz
    (with the ACs, their certainty and the inlier mask too)."""
    if out is None:
        return
    summary = {
        "image_a": str(args.image_a),
        "image_b": str(args.image_b),
        "matcher": args.matcher or PIPELINE_DEFAULTS["matcher"],
        "threshold": args.threshold,
        "num_acs": len(res.corrs),
        "num_inliers": int(info.num_inliers),
        "num_iterations": int(info.num_iterations),
        "score": float(info.score),
    }
    if out.suffix == ".json":
        import json

        payload = {
            **summary,
            **{k: np.asarray(v).tolist() for k, v in models.items()},
            "inliers": np.flatnonzero(info.inliers).tolist(),
        }
        out.write_text(json.dumps(payload, indent=1) + "\n")
    else:
        np.savez(
            out,
            corrs=res.corrs,
            certainty=res.certainty,
            inliers=info.inliers,
            **models,
            **summary,
        )
    print(f"-> {out}")


def cmd_homography(args) -> int:
    # A bad --gt or -o fails before the matching, not after it.
    H_gt = read_matrix(args.gt, "--gt") if args.gt is not None else None
    out = _estimate_output(args.output)
    pipe = _pipeline(args)
    H, info, res = pipe.homography(
        args.image_a, args.image_b, threshold=args.threshold, return_matches=True
    )
    _save_estimate(out, args, {"H": H}, info, res)
    n = len(info.inliers)
    print(f"inliers: {int(info.inliers.sum())} / {n}")
    with np.printoptions(precision=6, suppress=True):
        print(f"H =\n{H}")
    if H_gt is not None:
        from . import read_gray_image

        h, w = read_gray_image(args.image_a).shape
        print(f"mean corner error vs ground truth: {corner_error(H, H_gt, w, h):.2f} px")
    return 0


def cmd_pose(args) -> int:
    K1, K2 = read_matrix(args.K1, "--K1"), read_matrix(args.K2, "--K2")
    out = _estimate_output(args.output)
    pipe = _pipeline(args)
    pose, info, res = pipe.relative_pose(
        args.image_a, args.image_b, K1, K2, threshold=args.threshold, return_matches=True
    )
    models = {"R": pose.R, "t": pose.t, "E": pose.E, "F": pose.F}
    _save_estimate(out, args, models, info, res)
    print(f"inliers: {int(info.inliers.sum())} / {len(info.inliers)}")
    with np.printoptions(precision=6, suppress=True):
        print(f"R =\n{pose.R}\nt = {pose.t}")
    return 0


def cmd_show(args) -> int:
    from .plot import draw_matches

    H = read_matrix(args.gt, "--gt") if args.gt is not None else None
    _output_file(args.output, "-o")
    try:
        data = np.load(args.acs)
    except (OSError, ValueError, EOFError) as e:
        # np.load says "pickled data" for any non-.npz bytes; name the file and the fix.
        raise ValueError(f"{args.acs}: not an .npz file written by `affcorr match` ({e})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"{args.acs}: a single .npy array, not an .npz of `affcorr match`")
    missing = [k for k in ("corrs", "image_a", "image_b") if k not in data]
    if missing:
        raise ValueError(f"{args.acs}: missing arrays {missing} (write it with `affcorr match`)")
    from . import read_gray_image

    a, b = read_gray_image(str(data["image_a"])), read_gray_image(str(data["image_b"]))
    certainty = data["certainty"] if "certainty" in data else None
    draw_matches(
        a, b, data["corrs"], args.output, H=H, certainty=certainty, threshold=args.threshold
    )
    print(f"picture: {args.output}")
    return 0


def cmd_demo(args) -> int:
    _output_file(args.out, "-o")
    if args.geometry:
        from affcorr import demo as demo_module

        demo_module.run(out=args.out, step=args.step)
        return 0
    from affcorr import pipeline_demo

    pipeline_demo.run(out=args.out, matcher=args.matcher, max_keypoints=args.max_keypoints)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="affcorr", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("match", help="images -> ACs (.npz)")
    p.add_argument("image_a", nargs="?")
    p.add_argument("image_b", nargs="?")
    p.add_argument("--pairs", help="text file, one 'A B' pair per line (output is a folder)")
    p.add_argument("-o", "--output", required=True)
    _add_pipeline_args(p)
    p.set_defaults(run=cmd_match)

    p = sub.add_parser("homography", help="estimate H between two images")
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument(
        "--threshold",
        type=float,
        default=PIPELINE_DEFAULTS["homography_threshold"],
        help="inlier threshold (px, default: %(default)s)",
    )
    p.add_argument("--gt", help="ground-truth H (text or OpenCV XML) to report the error")
    p.add_argument(
        "-o", "--output", help="save H (full precision) and the inliers: .json, or .npz with ACs"
    )
    _add_pipeline_args(p)
    p.set_defaults(run=cmd_homography)

    p = sub.add_parser("pose", help="estimate the relative pose of two calibrated images")
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument("--K1", required=True, help="fx,fy,cx,cy | 9 numbers | file")
    p.add_argument("--K2", required=True, help="fx,fy,cx,cy | 9 numbers | file")
    p.add_argument(
        "-o", "--output", help="save R, t, E, F and the inliers: .json, or .npz with ACs"
    )
    p.add_argument(
        "--threshold",
        type=float,
        default=PIPELINE_DEFAULTS["pose_threshold"],
        help="inlier threshold (px, default: %(default)s)",
    )
    _add_pipeline_args(p)
    p.set_defaults(run=cmd_pose)

    p = sub.add_parser("show", help="draw the ACs of an .npz written by `affcorr match`")
    p.add_argument("acs")
    p.add_argument("-o", "--output", default="matches.png")
    p.add_argument("--gt", help="ground-truth H: colour matches by correctness")
    p.add_argument("--threshold", type=float, default=3.0, help="correct within (px)")
    p.set_defaults(run=cmd_show)

    p = sub.add_parser("demo", help="the pipeline on graffiti 1->3 with its ground-truth H")
    p.add_argument("-o", "--out", type=Path, default=Path("affcorr_demo.png"))
    p.add_argument(
        "--geometry",
        action="store_true",
        help="the geometry-only demo (ACs from the ground-truth H)",
    )
    p.add_argument("--step", type=int, default=40, help="--geometry: grid step in pixels")
    p.add_argument("--matcher", choices=MATCHERS, default=PIPELINE_DEFAULTS["matcher"])
    p.add_argument("--max-keypoints", type=int, default=PIPELINE_DEFAULTS["max_keypoints"])
    p.set_defaults(run=cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (ValueError, OSError, RuntimeError) as e:
        # Bad arguments, unreadable or unwritable files, models, ONNX Runtime: one line, no
        # traceback (OSError covers FileNotFoundError, IsADirectoryError, PermissionError).
        print(f"affcorr {args.command}: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"affcorr {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())

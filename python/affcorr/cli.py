"""The `affcorr` command line.

    affcorr match A B -o acs.npz            images -> ACs (N, 8) with certainty
    affcorr match --pairs list.txt -o DIR   many pairs (one "A B" per line, # comments), with a
                                            progress bar; DIR/<A>__<B>.npz and DIR/summary.json
    affcorr homography A B [--gt H.txt]     H, inliers, and the corner error against a ground truth
                       [-o h.json|h.npz]    ... saved at full precision (.npz: with the ACs)
    affcorr pose A B --K1 ... --K2 ...      relative pose (R, t) from calibrated images [-o ...]
    affcorr show acs.npz -o matches.png     picture: matches (coloured by correctness with --gt,
                                            by the estimated model's inliers with --inliers)
                                            and affine frames as ellipse pairs
    affcorr demo                            the whole pipeline on graffiti 1->3 (ground-truth H)

Models print at full precision (every digit of the float64, as saved by -o). -o writes exactly
the path given; it is checked writable before any work. -v / -q: more or less logging (stderr).

Intrinsics are given as "fx,fy,cx,cy", as nine numbers "k11,...,k33", or as a text/.npy file
holding a 3x3 matrix. A ground-truth homography is a text file of 3x3 numbers or an OpenCV XML
file (like graffiti's H1to3p.xml).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
from pathlib import Path

import numpy as np

from ._logging import configure_cli, logger
from .batch import BATCH_VIEW_RELATIVE_BUDGET
from .metrics import corner_error
from .pipeline import MATCHERS, PIPELINE_DEFAULTS


class MissingExtra(RuntimeError):
    """A command needs an optional dependency: the message names the extra to install."""


def require(module: str, extra: str) -> None:
    """Raises :class:`MissingExtra` (one line: what to install) unless ``module`` imports."""
    from .data import importable

    if not importable(module):
        raise MissingExtra(f"this command needs {module}: pip install 'affcorr[{extra}]'")


def format_matrix(name: str, m) -> str:
    """``name = [[...], ...]`` with every float64 digit (numpy's shortest round-trip repr), so
    that the printed numbers are the model itself."""
    text = np.array2string(
        np.asarray(m, dtype=np.float64),
        floatmode="unique",
        separator=", ",
        max_line_width=160,
        threshold=1000,
    )
    return f"{name} = {text}"


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
        detection_threshold=args.detection_threshold,
        max_side=args.max_side,
        threads=args.threads,
        dense_model=args.dense_model,
        shape_model=args.shape_model,
        refine_affine=args.refine_affine,
        drop_unreliable=args.drop_unreliable,
        exif_orientation=args.exif_orientation,
        guided_matching=args.guided_matching,
        views=args.views,
        view_budget=args.view_budget,
        view_relative_budget=args.view_relative_budget,
    )


def _budget(value: str) -> float | None:
    """A relative view budget on the command line: a number, or 'none' (no limit)."""
    if value.lower() == "none":
        return None
    try:
        return float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{value!r} is not a number of plain passes or 'none'"
        ) from None


def _add_detection_threshold(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--detection-threshold",
        type=float,
        default=None,
        help="the score a keypoint needs in the detector's map (sparse matchers; default: the "
        f"model's, and {PIPELINE_DEFAULTS['aliked_detection_threshold']} for ALIKED: its top "
        "keypoints)",
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
    _add_detection_threshold(p)
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
    p.add_argument(
        "--exif-orientation",
        action=argparse.BooleanOptionalAction,
        default=PIPELINE_DEFAULTS["exif_orientation"],
        help="match image files as their EXIF orientation shows them; coordinates stay in the "
        "files' stored pixels (default: %(default)s)",
    )
    p.add_argument(
        "--drop-unreliable",
        action="store_true",
        help="keep only the ACs whose A is flagged reliable (calibrated affine_confidence; "
        "docs/shape_network.md, 'Confidence')",
    )
    p.add_argument(
        "--guided-matching",
        action=argparse.BooleanOptionalAction,
        default=PIPELINE_DEFAULTS["guided_matching"],
        help="add matches around the verified ones, predicted by their ACs and fitted to the "
        "images (default: %(default)s; the view cascade does it anyway for a pass it keeps "
        "with few inliers)",
    )
    p.add_argument(
        "--views",
        choices=["auto", "full", "off"],
        default=PIPELINE_DEFAULTS["views"],
        help="synthetic views (rotations, zooms, tilts) for pairs the plain matcher cannot "
        "solve: auto tries them only when the plain pair fails verification (default: "
        "%(default)s)",
    )
    p.add_argument(
        "--view-budget",
        type=float,
        default=None,
        help="seconds after which the view cascade starts no new view (default: no limit)",
    )
    p.add_argument(
        "--view-relative-budget",
        type=_budget,
        default=PIPELINE_DEFAULTS["view_relative_budget"],
        help="the view cascade starts no new view once it has done this many times the plain "
        "pass's work, counted, not timed ('none': no limit; default: %(default)s)",
    )


def _print_views(res) -> None:
    """The view cascade's one line (``MatchResult.view_summary``), when it ran."""
    if line := res.view_summary():
        print(line)


def _print_timings(timings: dict) -> None:
    logger.info("timings:")
    for k, v in timings.items():
        logger.info(f"  {k:<12} {1e3 * v:8.1f} ms")


def _output_file(path: str | Path, flag: str) -> Path:
    """Checks, before the work that produces it, that exactly ``path`` can be written: not a
    directory, its directory exists and is writable (and so is the file, if it exists)."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{flag}: {str(path)!r} is a directory; give a file name")
    parent = path.parent
    if not parent.is_dir():
        raise ValueError(f"{flag}: the directory of {str(path)!r} does not exist")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ValueError(f"{flag}: {str(path)!r} is not writable")
    return path


def _output_dir(path: str | Path, flag: str) -> Path:
    """An output folder, created if missing (its parent must exist), checked writable."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{flag}: {str(path)!r} exists and is not a directory")
    if not path.exists():
        if not path.parent.is_dir():
            raise ValueError(f"{flag}: the directory of {str(path)!r} does not exist")
        path.mkdir()
    if not os.access(path, os.W_OK):
        raise ValueError(f"{flag}: {str(path)!r} is not writable")
    return path


def save_npz(path: str | Path, **arrays) -> None:
    """``np.savez`` to exactly ``path`` (numpy would append ``.npz`` to a name without it)."""
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def read_pairs(path: str | Path) -> tuple[list[tuple[int, str, str]], list[tuple[int, str]]]:
    """The pairs of a ``--pairs`` file: ``([(line, A, B)], [(line, why)])``. Blank lines and
    ``#`` comments are skipped; paths with spaces can be quoted; a line that does not hold
    exactly two paths is returned as bad, by its number."""
    pairs, bad = [], []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        try:
            fields = shlex.split(line, comments=True)
        except ValueError as e:  # an unclosed quote
            bad.append((n, f"cannot be parsed ({e})"))
            continue
        if not fields:
            continue
        if len(fields) != 2:
            bad.append((n, f"holds {len(fields)} fields, not two image paths"))
            continue
        pairs.append((n, fields[0], fields[1]))
    return pairs, bad


def _pair_file_name(a: str, b: str, line: int, taken: set[str]) -> str:
    """``<stem A>__<stem B>.npz``, with ``__line<N>`` where two pairs would share a name."""
    name = f"{Path(a).stem}__{Path(b).stem}.npz"
    if name in taken:
        name = f"{Path(a).stem}__{Path(b).stem}__line{line}.npz"
    taken.add(name)
    return name


def _match_pairs(args) -> int:
    """``--pairs``: every pair is tried; a bad line or a failing pair is named by its line
    number and the batch goes on; summary.json lists each line's outcome; the exit status is 2
    when any line failed (the last stderr line says which)."""
    pairs, bad = read_pairs(args.pairs)
    out = _output_dir(args.output, "-o")
    pipe = _pipeline(args) if pairs else None
    from ._progress import progress

    failed = [(n, why) for n, why in bad]
    for n, why in bad:
        logger.warning(f"--pairs line {n}: {why}")
    summary = [{"line": n, "status": "bad line", "error": why} for n, why in bad]
    taken: set[str] = set()
    items = pairs if logger.getEffectiveLevel() > 20 else progress(pairs, "matching pairs", "pair")
    for n, a, b in items:
        entry = {"line": n, "image_a": a, "image_b": b}
        try:
            res = pipe.match_pair(a, b)
        except (ValueError, OSError, RuntimeError) as e:
            logger.warning(f"--pairs line {n} ({a} {b}): {e}")
            failed.append((n, str(e)))
            summary.append({**entry, "status": "failed", "error": str(e)})
            continue
        name = _pair_file_name(a, b, n, taken)
        save_npz(
            out / name,
            corrs=res.corrs,
            certainty=res.certainty,
            affine_confidence=res.affine_confidence,
            reliable=res.reliable,
            image_a=a,
            image_b=b,
        )
        # Few or no matches is an outcome of matching, not a failure.
        summary.append({**entry, "status": "ok", "file": name, "num_acs": len(res.corrs)})
    summary.sort(key=lambda e: e["line"])
    ok = sum(e["status"] == "ok" for e in summary)
    (out / "summary.json").write_text(
        json.dumps(
            {"pairs_file": str(args.pairs), "ok": ok, "failed": len(failed), "pairs": summary},
            indent=1,
        )
        + "\n"
    )
    print(f"{ok} of {len(summary)} pairs matched -> {out} (summary.json)")
    if failed:
        failed.sort()
        lines = [n for n, _ in failed]
        first_line, first_why = failed[0]
        raise ValueError(
            f"--pairs: {len(failed)} of {len(summary)} lines failed (lines {lines[:20]}); "
            f"line {first_line}: {first_why}"
        )
    return 0


def cmd_match(args) -> int:
    if args.pairs is not None:
        if args.image_a is not None:
            raise ValueError("give two images or --pairs FILE, not both")
        return _match_pairs(args)
    if args.image_b is None:
        raise ValueError("give two images, or --pairs FILE")
    out = _output_file(args.output, "-o")
    pipe = _pipeline(args)
    res = pipe.match_pair(args.image_a, args.image_b)
    save_npz(
        out,
        corrs=res.corrs,
        certainty=res.certainty,
        affine_confidence=res.affine_confidence,
        reliable=res.reliable,
        image_a=args.image_a,
        image_b=args.image_b,
    )
    print(f"{len(res.corrs)} ACs -> {out}")
    _print_views(res)
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


def _info_fields(info) -> dict:
    """The estimation's counters (everything of RansacInfo but the mask)."""
    return {
        "num_inliers": int(info.num_inliers),
        "num_iterations": int(info.num_iterations),
        "score": float(info.score),
        "lo_runs": int(info.lo_runs),
        "refinements": int(info.refinements),
        "residual_evaluations": int(info.residual_evaluations),
        "sprt_rejections": int(info.sprt_rejections),
    }


def _save_estimate(out: Path | None, args, models: dict, info, res) -> None:
    """The model at full precision with the estimation's info: JSON (inlier indices), or .npz
    (with the ACs, their certainty and the inlier mask too)."""
    if out is None:
        return
    summary = {
        "affcorr_version": _version(),
        "image_a": str(args.image_a),
        "image_b": str(args.image_b),
        "matcher": args.matcher or PIPELINE_DEFAULTS["matcher"],
        "threshold": args.threshold,
        "num_acs": len(res.corrs),
        **_info_fields(info),
    }
    if out.suffix == ".json":
        payload = {
            **summary,
            **{k: np.asarray(v).tolist() for k, v in models.items()},
            "inliers": np.flatnonzero(info.inliers).tolist(),
        }
        out.write_text(json.dumps(payload, indent=1) + "\n")
    else:
        save_npz(
            out,
            corrs=res.corrs,
            certainty=res.certainty,
            inliers=info.inliers,
            **models,
            **summary,
        )
    logger.info(f"-> {out}")


def cmd_homography(args) -> int:
    # A bad --gt or -o fails before the matching, not after it.
    H_gt = read_matrix(args.gt, "--gt") if args.gt is not None else None
    out = _estimate_output(args.output)
    pipe = _pipeline(args)
    H, info, res = pipe.homography(
        args.image_a, args.image_b, threshold=args.threshold, return_matches=True
    )
    _save_estimate(out, args, {"H": H}, info, res)
    _print_views(res)
    n = len(info.inliers)
    print(f"inliers: {int(info.inliers.sum())} / {n}")
    print(format_matrix("H", H))
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
    _print_views(res)
    print(f"inliers: {int(info.inliers.sum())} / {len(info.inliers)}")
    print(format_matrix("R", pose.R))
    print(format_matrix("t", pose.t))
    return 0


def _version() -> str:
    from ._native import __version__

    return __version__


def model_residuals(data, threshold: float) -> tuple[str, np.ndarray, np.ndarray]:
    """For ``affcorr show --inliers``: (what, residuals (N,) px, inliers (N,) bool) of the model
    saved in ``data`` (an .npz of ``affcorr homography -o``: H and its transfer errors; of
    ``affcorr pose -o``: F and its Sampson distances), or of a homography estimated here from the
    ACs (``affcorr match``'s .npz) at ``threshold``."""
    from . import estimate_homography, sampson_point
    from .metrics import transfer

    corrs = np.asarray(data["corrs"], dtype=np.float64)
    saved = data["inliers"].astype(bool) if "inliers" in data else None
    if "F" in data and "H" not in data:
        # sampson_point is the squared distance (px²); the residual is its root (px).
        r = np.sqrt(np.abs(sampson_point(data["F"], corrs))) if len(corrs) else np.zeros(0)
        what = "the saved F (Sampson distance)"
    else:
        if "H" in data:
            H, what = np.asarray(data["H"], dtype=np.float64), "the saved H (transfer error)"
        else:
            H, info = estimate_homography(corrs, threshold=threshold)
            saved = info.inliers
            what = f"H estimated at {threshold:g} px (transfer error)"
        r = np.linalg.norm(transfer(H, corrs[:, :2]) - corrs[:, 2:4], axis=1)
    inliers = saved if saved is not None else r < threshold
    return what, r, inliers


def cmd_show(args) -> int:
    require("matplotlib", "plot")
    from .plot import draw_matches

    H = read_matrix(args.gt, "--gt") if args.gt is not None else None
    out = _output_file(args.output, "-o")
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
    model = None
    if args.inliers:
        threshold = (
            args.threshold
            if args.threshold is not None
            else PIPELINE_DEFAULTS["homography_threshold"]
        )
        what, residuals, inliers = model_residuals(data, threshold)
        model = {"what": what, "residuals": residuals, "inliers": inliers}
        print(f"inliers of {what}: {int(inliers.sum())} / {len(inliers)}")
    draw_matches(
        a,
        b,
        data["corrs"],
        out,
        H=H,
        certainty=certainty,
        threshold=args.threshold if args.threshold is not None else 3.0,
        model=model,
    )
    print(f"picture: {out}")
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


def cmd_batch(args) -> int:
    from affcorr import batch

    geometry = [g for g in args.geometry.split(",") if g] if args.geometry else []
    summary = batch.run(
        args.pairs,
        args.images,
        args.output,
        matcher=args.matcher,
        max_keypoints=args.max_keypoints,
        detection_threshold=args.detection_threshold,
        max_side=args.max_side,
        views=args.views,
        view_relative_budget=args.view_relative_budget,
        refine_affine=args.refine_affine,
        shape_model=args.shape_model,
        geometry=geometry,
        cameras=args.cameras,
        colmap=args.colmap,
        workers=args.workers,
        threads_per_worker=args.threads_per_worker,
        ray_address=args.ray,
        ship_images=args.ship_images,
        chunk_size=args.chunk_size,
        cache=args.cache,
        resume=args.resume,
        overwrite=args.overwrite,
        retries=args.retries,
        progress=not args.no_progress,
    )
    for a, b, e in summary.failures[:20]:
        print(f"  failed: {a} {b}: {e}", file=sys.stderr)
    if len(summary.failures) > 20:
        print(f"  ... and {len(summary.failures) - 20} more (failures.jsonl)", file=sys.stderr)
    return 0 if summary.failed == 0 else 3


def _add_verbosity(p: argparse.ArgumentParser, top: bool) -> None:
    # On the top parser and on each command, so that `affcorr -v match ...` and
    # `affcorr match ... -v` both work (a command's flags must not reset the top's).
    d = 0 if top else argparse.SUPPRESS
    p.add_argument(
        "-v", "--verbose", action="count", default=d, help="more logging (stderr): -v debug"
    )
    p.add_argument(
        "-q", "--quiet", action="count", default=d, help="less: warnings and errors only"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="affcorr", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"affcorr {_version()}")
    _add_verbosity(parser, top=True)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("match", help="images -> ACs (.npz)")
    p.add_argument("image_a", nargs="?")
    p.add_argument("image_b", nargs="?")
    p.add_argument(
        "--pairs",
        help="text file, one 'A B' pair per line, '#' comments (output: a folder with "
        "<A>__<B>.npz per pair and summary.json)",
    )
    p.add_argument("-o", "--output", required=True, help="the .npz to write (exactly this path)")
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
    p.add_argument("-o", "--output", default="matches.png", help="picture (.png, .pdf, .svg)")
    p.add_argument("--gt", help="ground-truth H: colour matches by correctness")
    p.add_argument(
        "--inliers",
        action="store_true",
        help="colour by the inliers of the estimated model (the H or F saved by "
        "`affcorr homography/pose -o x.npz`, else H estimated from the ACs) and plot residuals",
    )
    p.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="correct within (px, default 3) for --gt; inlier threshold for --inliers "
        f"(default {PIPELINE_DEFAULTS['homography_threshold']})",
    )
    p.set_defaults(run=cmd_show)

    p = sub.add_parser(
        "batch",
        help="many pairs -> hloc HDF5 (features.h5, matches.h5) and a COLMAP database, "
        "locally or on Ray, resumable",
    )
    p.add_argument("pairs", help="pairs file: one 'name0 name1' per line (hloc's format)")
    p.add_argument("images", help="the image folder the names are relative to")
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument(
        "--geometry",
        default="fundamental",
        help="comma-separated: homography, fundamental, relative_pose ('' for none; "
        "default: %(default)s)",
    )
    p.add_argument(
        "--cameras",
        help="camera file: 'name MODEL width height params...' per image (COLMAP models); "
        "default: SIMPLE_PINHOLE, f = 1.2 max(W, H)",
    )
    p.add_argument("--colmap", action="store_true", help="also write database.db (pycolmap)")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: cores)")
    p.add_argument(
        "--threads-per-worker", type=int, default=1, help="threads per worker (default: 1)"
    )
    p.add_argument(
        "--ray",
        metavar="ADDRESS",
        default=None,
        help="run on the Ray cluster at ADDRESS ('auto', host:port, ray://host:port)",
    )
    p.add_argument(
        "--ship-images",
        action="store_true",
        help="with --ray: send the images' bytes through Ray's object store (workers without "
        "the image folder, e.g. no shared file system)",
    )
    p.add_argument("--chunk-size", type=int, default=4, help="pairs per task (default: 4)")
    p.add_argument(
        "--cache",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="keep each image's features on disk (<output>/cache; default: on)",
    )
    p.add_argument("--resume", action="store_true", help="skip the pairs already written")
    p.add_argument("--overwrite", action="store_true", help="replace earlier outputs")
    p.add_argument("--retries", type=int, default=2, help="resubmissions of a dead worker's pairs")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--matcher",
        choices=MATCHERS,
        default=None,
        help=f"default: {PIPELINE_DEFAULTS['matcher']}",
    )
    p.add_argument("--shape-model", default=None, help="a shape-v1 ONNX network")
    p.add_argument(
        "--max-keypoints",
        type=int,
        default=PIPELINE_DEFAULTS["max_keypoints"],
        help="keypoints per image (default: %(default)s)",
    )
    _add_detection_threshold(p)
    p.add_argument("--max-side", type=int, default=None, help="working resolution (px)")
    p.add_argument("--views", choices=["auto", "full", "off"], default=PIPELINE_DEFAULTS["views"])
    p.add_argument(
        "--view-relative-budget",
        type=_budget,
        default=BATCH_VIEW_RELATIVE_BUDGET,
        help="the view cascade starts no new view once a pair has done this many times the "
        "plain pass's work; a pair that does not overlap spends all of it ('none': no limit; "
        "default: %(default)s, lower than a single pair's "
        f"{PIPELINE_DEFAULTS['view_relative_budget']:g}: see docs/scale.md)",
    )
    p.add_argument(
        "--refine-affine",
        action=argparse.BooleanOptionalAction,
        default=PIPELINE_DEFAULTS["refine_affine"],
    )
    p.set_defaults(run=cmd_batch)

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
    for p in sub.choices.values():
        _add_verbosity(p, top=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    configure_cli(args.verbose - args.quiet)
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

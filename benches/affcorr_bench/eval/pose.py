"""Experiment 3 (paper Tables 3, 5, 6): relative pose from each matcher's matches, estimated by
point RANSAC and by AC-based RANSAC on the SAME matches.

    bash benches/eval/pose_setup.sh                            # once: opencv-doc, peer venvs
    nice -n 10 .venv/bin/python -m affcorr_bench.eval.pose           # full run (see PAIRS below)
    .venv/bin/python -m affcorr_bench.eval.pose --quick              # a few pairs per dataset

Data (pose_data.py): the opencv-doc chessboard set (78 left/left pairs with board poses from
left_intrinsics.yml, 13 left/right pairs of the calibrated rig), scikit-image's motorcycle
stereo pair, and rendered MegaDepth-like multi-plane scenes with held-out real textures.

Matchers: every usable one of the registry (matchers.py); matches are cached per matcher and
pair (``cache_dir()/eval/pose/matches``), so a re-run only estimates. The ACs (N, 8) carry the
matcher's own A when it has one ("own A": SIFT/ASIFT similarities, Hessian-Affine, affcorr's
shape network) and affcorr's shape network's A at the same points otherwise ("affcorr A",
matchers.with_affcorr_shapes); matchers with an own A other than affcorr get both.

Estimators, all on the same matches, with the same threshold THRESHOLD px (on each library's own
residual, as in affcorr_bench.peers.methods), confidence 0.9999, at most 10000 iterations,
single-threaded, each in its own venv through the peer harness's worker
(affcorr_bench.peers.worker):
- points: OpenCV findEssentialMat(USAC_MAGSAC) + recoverPose, PoseLib estimate_relative_pose,
  GC-RANSAC (5-point), affcorr (5-point);
- ACs: affcorr estimate_relative_pose (2-AC samples, MAGSAC++), GC-RANSAC's affine solver.

Metrics (SuperGlue/LoFTR protocol): rotation error, translation-direction error
``min(e, 180 - e)``, pose error ``max`` of the two; AUC of the pose error's recall curve up to
5/10/20 degrees (a failure counts as an infinite error); medians of both errors.

Writes benches/results/eval/pose.md, pose.csv (one row per pair x matcher x estimator),
pose_summary.csv, pose_curves.png.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from .. import common
from ..peers import run as peer_run  # the peer venvs and the worker's environment
from ..peers import scenes as scene_io
from . import matchers, pose_data, suite  # suite: OpenBLAS for Debian's torch

THRESHOLD = 1.0  # px; the paper uses 0.5 px at MegaDepth's 1200 px, these images are <= 741 px
MAX_KEYPOINTS = 2048
MATCHES_VERSION = 1  # of the cached matches (see _registry_tag)
MIN_MATCHES = 8  # fewer: counted as a failure without calling any estimator
AUC_DEG = (5, 10, 20)
# Matchers that take many seconds per 640x480 pair on one shared core (upstream XFeat+LighterGlue
# on Debian's torch 1.13: ~40 s): they run on every `slow_every`-th pair, and every table says
# how many pairs each row has. affcorr's own matcher is XFeat+LighterGlue (ONNX, in Rust), so
# its point-RANSAC rows are XFeat+LighterGlue's on every pair.
SLOW = {"asift", "disk-lightglue", "aliked-lightglue", "hesaff", "xfeat", "xfeat-lighterglue"}
PAIRS = {  # full run / --quick: synthetic pairs (slow matchers: every `slow_every`-th),
    # chessboard pairs (None: all 91; slow matchers: every `slow_every`-th)
    "full": dict(synthetic=500, slow_every=25, chessboard=None, chess_slow_every=13),
    "quick": dict(synthetic=6, slow_every=2, chessboard=6, chess_slow_every=2),
}
#: (group, method name in affcorr_bench.peers.methods, uses ACs) in table order.
ESTIMATORS = [
    ("peers", "opencv-USAC_MAGSAC", False),
    ("peers", "poselib", False),
    ("affcorr", "affcorr-points", False),
    ("gcransac", "gcransac-AC", True),
    ("affcorr", "affcorr-AC", True),
    ("local", "affcorr-AC-min200", True),
]
#: Variants of affcorr's estimator run in this process (.venv): options beyond the defaults.
#: At least 200 samples: the adaptive stopping rule alone ends 2-AC RANSAC after ~10-30 samples
#: when a wrong model has many inliers (seen on multi-plane scenes).
LOCAL = {"affcorr-AC-min200": dict(min_iterations=200)}
#: Counts changes of affcorr's own estimator (affcorr-ransac) that alter its results: its cached
#: estimates carry it, so bumping it re-runs affcorr's rows and keeps the peers' (the cache holds
#: no build hash; an installed wheel has none to give).
# 2: λ of the affine terms from at most 512 inliers; 3: scoring at the measured λ̂; 4: only
# after the fallback check at the default weight; 5: the measured λ̂ polishes the first
# model instead of sampling again.
AFFCORR_ESTIMATOR_REVISION = 5
LABELS = {
    "opencv-USAC_MAGSAC": "OpenCV USAC_MAGSAC (5pt)",
    "poselib": "PoseLib (5pt)",
    "gcransac-points": "GC-RANSAC (5pt)",
    "affcorr-points": "affcorr (5pt)",
    "gcransac-AC": "GC-RANSAC (2AC)",
    "affcorr-AC": "affcorr (2AC)",
    "affcorr-AC-min200": "affcorr (2AC, >= 200 samples)",
}
DATASETS = [
    "synthetic",
    "synthetic-common",
    "chessboard",
    "chessboard-common",
    "chessboard-stereo",
    "motorcycle",
]
COMMON = ("synthetic", "chessboard")  # datasets whose slow matchers ran on a subset


# --- metrics ------------------------------------------------------------------------------------


def rotation_error(R: np.ndarray, R_gt: np.ndarray) -> float:
    c = (np.trace(R @ R_gt.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def translation_error(t: np.ndarray, t_gt: np.ndarray) -> float:
    """Angle between the directions, folded to [0, 90]: E fixes t only up to sign (LoFTR)."""
    n = np.linalg.norm(t) * np.linalg.norm(t_gt)
    if not np.isfinite(n) or n == 0:
        return float("inf")
    e = float(np.degrees(np.arccos(np.clip(float(t @ t_gt) / n, -1.0, 1.0))))
    return min(e, 180.0 - e)


def pair_pose_error(pair, corrs: np.ndarray, threshold: float) -> tuple[float, int]:
    """The pose error of ``corrs`` ((N, 8) ACs or (N, 4) points) on a calibrated ``pair`` of
    ``pose_data``: the rows ``pair.keep`` keeps (a board pair's matches on the board), then
    affcorr.estimate_relative_pose at ``threshold`` and max(rotation, translation direction
    error) in degrees, inf with fewer than 5 rows or no pose; and how many rows were kept."""
    import affcorr

    corrs = corrs[pair.keep(corrs[:, :2], corrs[:, 2:4])]
    if len(corrs) < 5:
        return float("inf"), len(corrs)
    try:
        pose, _ = affcorr.estimate_relative_pose(corrs, pair.K1, pair.K2, threshold=threshold)
    except (RuntimeError, ValueError):
        return float("inf"), len(corrs)
    return max(rotation_error(pose.R, pair.R), translation_error(pose.t, pair.t)), len(corrs)


def pose_auc(errors, thresholds=AUC_DEG) -> list[float]:
    """Area under the recall-vs-error curve up to each threshold, normalised to [0, 1]
    (SuperGlue's definition; infinite errors never count as recalled)."""
    e = np.sort(np.asarray(errors, float))
    if len(e) == 0:
        return [float("nan")] * len(thresholds)
    recall = np.arange(1, len(e) + 1) / len(e)
    e, recall = np.r_[0.0, e], np.r_[0.0, recall]
    out = []
    for th in thresholds:
        k = np.searchsorted(e, th)
        x = np.r_[e[:k], th]
        y = np.r_[recall[:k], recall[k - 1]]
        out.append(float(np.sum(np.diff(x) * (y[1:] + y[:-1]) / 2) / th))  # trapezoids
    return out


# --- matches (cached) --------------------------------------------------------------------------


def _registry_tag() -> str:
    """The cache's key: bump MATCHES_VERSION (or delete the cache) when a matcher of the
    registry changes, or its old matches are reused."""
    return f"v{MATCHES_VERSION}-k{MAX_KEYPOINTS}"


def match_path(name: str, pair: pose_data.PosePair) -> Path:
    return (
        pose_data.pose_cache()
        / "matches"
        / _registry_tag()
        / name
        / pair.dataset
        / (pair.name + ".npz")
    )


def get_matches(name: str, pair: pose_data.PosePair, cached_only: bool = False) -> dict | None:
    """x1, x2 (N, 2), A_own (N, 2, 2) or absent, A_affcorr, score, seconds (matching),
    seconds_shape (affcorr's shape network, when it ran). None if ``cached_only`` and not
    cached (for affcorr: not cached for the current shape model and pipeline)."""
    path = match_path(name, pair)
    tag = matchers.shape_model_tag()
    if name == "affcorr":
        # affcorr's matches depend on its pipeline's code too (the view cascade), as the
        # suite's cache keys say (suite._key)
        tag += suite.pipeline_tag()
    out = dict(np.load(path)) if path.exists() else None
    if out is not None and str(out.get("shape_tag", "")) == tag:
        return out
    # affcorr's matches are its ACs: a stale one means matching again, as a missing one does
    rematch = out is None or name == "affcorr"
    if cached_only and rematch:
        return None
    img1, img2 = pair.load()
    if rematch:
        m = matchers.run(name, img1, img2, max_keypoints=MAX_KEYPOINTS)
        out = dict(x1=m.x1, x2=m.x2, score=m.score, seconds=np.float64(m.seconds))
        if m.A is not None:
            out["A_own"] = m.A
    else:  # another matcher's points, cached by an older shape network: new A only
        m = matchers.Matches(out["x1"], out["x2"], None, out["score"], float(out["seconds"]))
    if name == "affcorr":
        out["A_affcorr"] = m.A
    else:
        s = matchers.with_affcorr_shapes(m, img1, img2)
        out["A_affcorr"] = s.A
        out["seconds_shape"] = np.float64(s.seconds - m.seconds)
    out["shape_tag"] = np.str_(tag)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **out)
    tmp.replace(path)  # atomic: a concurrent reader never sees half a file
    return out


def a_sources(name: str, m: dict) -> list[str]:
    if name == "affcorr":
        return ["affcorr"]
    return (["own"] if "A_own" in m else []) + ["affcorr"]


# --- estimation through the peer harness's worker -----------------------------------------------


def run_worker(
    group: str,
    scene_list: list[dict],
    methods: list[str],
    tmp: Path,
    problem: str = "relpose",
    threshold: float = THRESHOLD,
) -> dict:
    """The peer worker in the group's venv on ``scene_list`` (dicts with corrs, K1, K2):
    ``problem`` "relpose", "homography" or "fundamental" at ``threshold`` px."""
    py = peer_run.GROUP_PYTHON[group]
    if not py.exists():
        return {"group_error": f"{py} missing: run benches/eval/pose_setup.sh"}
    src, dst = tmp / f"{group}_in.npz", tmp / f"{group}_out.npz"
    scene_io.save(src, scene_list)
    if dst.exists():
        dst.unlink()
    cmd = common.module_cmd(py, peer_run.WORKER, group, problem, threshold, src, dst, *methods)
    p = subprocess.run(cmd, env=peer_run.worker_env(), capture_output=True, text=True)
    if p.returncode != 0 or not dst.exists():
        return {"group_error": f"worker failed ({p.returncode}): {p.stderr[-600:]}"}
    z = np.load(dst)
    return {k: z[k] for k in z.files}


def estimates_cache() -> Path:
    return pose_data.pose_cache() / f"estimates-{_registry_tag()}-thr{THRESHOLD}.jsonl"


def _key(r: dict) -> tuple:
    return (
        r["dataset"],
        r["pair"],
        r["matcher"],
        r["estimator"],
        r["A_source"],
        r.get("shape_tag", ""),
        r.get("estimator_rev", ""),
    )


def estimate(jobs: list[dict], tmp: Path, notes: list[str], versions: set) -> list[dict]:
    """One row per job and estimator, reusing the rows cached by earlier runs (estimates_cache:
    one JSON row per line, appended as they are computed)."""
    cache = estimates_cache()
    done = {}
    if cache.exists():
        for line in cache.read_text().splitlines():
            r = json.loads(line)
            done[_key(r)] = r
    wanted = {}
    for j in jobs:
        for _, method, uses_ac in ESTIMATORS:
            if uses_ac or j["first"]:
                wanted[_job_key(j, method, uses_ac)] = j
    todo = {k: j for k, j in wanted.items() if k not in done}
    rows = [done[k] for k in wanted if k in done]
    todo_jobs = list({id(j): j for j in todo.values()}.values())
    new = _estimate(todo_jobs, tmp, notes, versions, set(todo))
    new = [r for r in new if _key(r) in todo]
    with open(cache, "a") as f:
        for r in new:
            f.write(json.dumps(r) + "\n")
    return rows + new


def _job_key(j: dict, method: str, uses_ac: bool) -> tuple:
    """An estimate's cache key; ACs with affcorr's A also carry the shape network's tag, and
    affcorr's estimators their revision (``AFFCORR_ESTIMATOR_REVISION``)."""
    p = j["pair"]
    source = j["A_source"] if uses_ac else "-"
    uses_shape = uses_ac and (source == "affcorr" or j["matcher"] == "affcorr")
    tag = matchers.shape_model_tag() if uses_shape else ""
    rev = f"est{AFFCORR_ESTIMATOR_REVISION}" if method.startswith("affcorr") else ""
    return (p.dataset, p.name, j["matcher"], method, source, tag, rev)


def _estimate(
    jobs: list[dict], tmp: Path, notes: list[str], versions: set, need: set | None = None
) -> list[dict]:
    """One row per job and estimator (only the (job, estimator) keys in ``need`` if given).
    A job: matcher, A source, pair, corrs (N, 8)."""
    rows = []
    ok_jobs = [j for j in jobs if len(j["corrs"]) >= MIN_MATCHES]

    def needed(j, methods, uses_ac):
        return need is None or any(_job_key(j, m, uses_ac) in need for m in methods)

    for group in ("peers", "gcransac", "affcorr"):
        for uses_ac in (False, True):
            methods = [m for g, m, ac in ESTIMATORS if g == group and ac == uses_ac]
            if not methods:
                continue
            # point methods run once per (matcher, pair): on the first A source's job
            sel = [j for j in ok_jobs if (uses_ac or j["first"]) and needed(j, methods, uses_ac)]
            if not sel:
                continue
            scene_list = [dict(corrs=j["corrs"], K1=j["pair"].K1, K2=j["pair"].K2) for j in sel]
            raw = run_worker(group, scene_list, methods, tmp)
            if "group_error" in raw:
                notes.append(f"{group}: {raw['group_error']}")
            if "versions" in raw:
                versions.add(str(raw["versions"]))
            for method in methods:
                for i, j in enumerate(sel):
                    key = f"{method}/{i}/"
                    r = None
                    if key + "ok" in raw and bool(raw[key + "ok"]):
                        r = (raw[key + "R"], raw[key + "t"].reshape(3), raw[key + "inliers"])
                    if key + "error" in raw and len(notes) < 40:
                        err = str(raw[key + "error"]).strip().splitlines()[-1][-160:]
                        notes.append(f"{method} on {j['matcher']}/{j['pair'].name}: {err}")
                    rows.append(row(j, method, uses_ac, r, float(raw.get(key + "time", np.nan))))
    for method, opts in LOCAL.items():
        import affcorr

        for j in ok_jobs:
            if not needed(j, [method], True):
                continue
            t0 = time.perf_counter()
            pz, info = affcorr.estimate_relative_pose(
                j["corrs"], j["pair"].K1, j["pair"].K2, threshold=THRESHOLD, **opts
            )
            dt = time.perf_counter() - t0
            r = (pz.R, pz.t, info.inliers) if info.num_inliers > 0 else None
            rows.append(row(j, method, True, r, dt))
    # jobs with too few matches: a failure for every estimator
    for j in jobs:
        if len(j["corrs"]) < MIN_MATCHES:
            for _, method, uses_ac in ESTIMATORS:
                if uses_ac or j["first"]:
                    rows.append(row(j, method, uses_ac, None, np.nan))
    return rows


def row(job: dict, method: str, uses_ac: bool, r, seconds: float) -> dict:
    key = _job_key(job, method, uses_ac)
    p = job["pair"]
    e_R = e_t = float("inf")
    inliers = 0
    if r is not None and np.all(np.isfinite(r[0])) and np.all(np.isfinite(r[1])):
        e_R, e_t = rotation_error(r[0], p.R), translation_error(r[1], p.t)
        inliers = int(np.sum(r[2]))
    return dict(
        dataset=p.dataset,
        pair=p.name,
        matcher=job["matcher"],
        estimator=method,
        A_source=job["A_source"] if uses_ac else "-",
        matches=len(job["corrs"]),
        inliers=inliers,
        rot_err=e_R,
        t_err=e_t,
        pose_err=max(e_R, e_t),
        est_ms=1e3 * seconds,
        match_s=job["seconds"],
        shape_tag=key[-2],
        estimator_rev=key[-1],
    )


# --- the run ------------------------------------------------------------------------------------


def pairs_for(grid: dict) -> dict[str, list[pose_data.PosePair]]:
    chess = pose_data.chessboard_pairs()
    if grid["chessboard"] is not None:
        k = grid["chessboard"]
        chess = [p for p in chess if p.dataset == "chessboard"][: k - 2] + [
            p for p in chess if p.dataset == "chessboard-stereo"
        ][:2]
    return {
        "synthetic": pose_data.synthetic_pairs(grid["synthetic"]),
        "chessboard": chess,
        "motorcycle": [pose_data.motorcycle_pair()],
    }


def schedule(names, data, grid) -> list[tuple[str, pose_data.PosePair]]:
    """(matcher, pair) in the order the matches are computed: the motorcycle and the stereo
    pairs, then the synthetic pairs one by one (every matcher on pair i before pair i + 1) with
    a chessboard pair of left views after every CHESS_STRIDE synthetic ones, so that a run cut
    short still has every matcher on the same first pairs of each dataset. Slow matchers take
    every ``slow_every``-th synthetic pair and every ``chess_slow_every``-th chessboard pair."""

    def take(name, key, i):
        every = grid["chess_slow_every" if key.startswith("chessboard") else "slow_every"]
        return name not in SLOW or key == "motorcycle" or i % every == 0

    chess = [p for p in data["chessboard"] if p.dataset == "chessboard"]
    stereo = [p for p in data["chessboard"] if p.dataset == "chessboard-stereo"]
    order = [("motorcycle", i, p) for i, p in enumerate(data["motorcycle"])]
    order += [("chessboard-stereo", i, p) for i, p in enumerate(stereo)]
    for i, p in enumerate(data["synthetic"]):
        order.append(("synthetic", i, p))
        if i % CHESS_STRIDE == CHESS_STRIDE - 1 and chess:
            k = i // CHESS_STRIDE
            if k < len(chess):
                order.append(("chessboard", k, chess[k]))
    k0 = len(data["synthetic"]) // CHESS_STRIDE
    order += [("chessboard", k, p) for k, p in enumerate(chess) if k >= k0]
    return [(n, p) for key, i, p in order for n in names if take(n, key, i)]


CHESS_STRIDE = 5


def collect_jobs(names, data, grid, log, cached_only=False) -> list[dict]:
    """Every (matcher, A source, pair) to estimate on. With ``cached_only`` a match that is not
    cached (for the current shape model, and for affcorr its pipeline) is a SystemExit naming
    how many per matcher: estimating on part of the pairs would overwrite the results with a
    partial table."""
    jobs = []
    per_matcher = defaultdict(float)
    missing: dict[str, int] = defaultdict(int)
    t0 = time.time()
    todo = schedule(names, data, grid)
    for step, (name, p) in enumerate(todo):
        if not cached_only and step % 50 == 0:
            log(f"matches: {step}/{len(todo)} ({p.dataset} {p.name})")
        m = get_matches(name, p, cached_only)
        if m is None:
            missing[name] += 1
            continue
        per_matcher[name] += float(m["seconds"])
        keep = p.keep(m["x1"], m["x2"])
        for k, src in enumerate(a_sources(name, m)):
            A = m["A_own"] if src == "own" else m["A_affcorr"]
            corrs = np.c_[m["x1"], m["x2"], np.asarray(A).reshape(-1, 4)][keep]
            seconds = float(m["seconds"]) + float(m.get("seconds_shape", 0.0)) * (src == "affcorr")
            jobs.append(
                dict(matcher=name, A_source=src, pair=p, corrs=corrs, first=k == 0, seconds=seconds)
            )
    log(
        f"matches: {len(todo)} (matcher, pair) in {time.time() - t0:.0f} s; matching seconds "
        + ", ".join(f"{k} {v:.0f}" for k, v in per_matcher.items())
    )
    if missing:
        raise SystemExit(
            "--cached: matches not cached for the current shape model or pipeline: "
            + ", ".join(f"{k} {v} of {sum(n == k for n, _ in todo)}" for k, v in missing.items())
            + "; run without --cached to match them"
        )
    MATCHING_SECONDS.update(per_matcher)
    return jobs


MATCHING_SECONDS: dict[str, float] = {}  # per matcher, summed over its pairs (cached or not)


def peer_versions() -> list[str]:
    """The libraries' versions in each estimator venv (the peer worker's list)."""
    out = []
    for group in ("peers", "gcransac"):
        py = peer_run.GROUP_PYTHON[group]
        if not py.exists():
            continue
        code = f"from {peer_run.WORKER} import versions; print(versions())"
        p = subprocess.run(
            [str(py), "-c", code],
            capture_output=True,
            text=True,
            env=peer_run.worker_env(),
        )
        if p.returncode == 0 and p.stdout.strip():
            out.append(f"{group} venv: {p.stdout.strip()}")
    return out


def load_average() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a few pairs per dataset")
    ap.add_argument("--synthetic", type=int, help="synthetic pairs (default: 500, quick: 6)")
    ap.add_argument("--matchers", nargs="*", help="subset of the registry's names")
    ap.add_argument("--out", type=Path, default=suite.RESULTS)
    ap.add_argument("--match-only", action="store_true", help="compute and cache matches only")
    ap.add_argument(
        "--cached",
        action="store_true",
        help="estimate on the cached matches only (no matching; the A of an older shape network "
        "is recomputed)",
    )
    args = ap.parse_args(argv)
    if argv is None:
        suite.use_openblas()  # re-executes this module with OpenBLAS (LightGlue ~15x faster)
    grid = dict(PAIRS["quick" if args.quick else "full"])
    if args.synthetic is not None:
        grid["synthetic"] = args.synthetic
    started = time.time()

    def log(msg):
        print(f"[{time.time() - started:6.0f} s] {msg}", file=sys.stderr, flush=True)

    avail = matchers.available()
    names = [n for n in (args.matchers or matchers.NAMES) if n in avail]
    unavailable = {n: avail[n] for n in names if avail[n]}
    names = [n for n in names if not avail[n]]
    load_before = load_average()
    data = pairs_for(grid)
    log(f"pairs: { {k: len(v) for k, v in data.items()} }, matchers: {names}")
    if args.match_only:
        collect_jobs(names, data, grid, log)
        return 0
    jobs = collect_jobs(names, data, grid, log, cached_only=args.cached)
    notes, versions = [], set()
    with tempfile.TemporaryDirectory() as tmp:
        rows = estimate(jobs, Path(tmp), notes, versions)
    log(f"estimation: {len(rows)} rows")
    # the pairs every matcher has, as datasets of their own (like with like)
    counts, shared_counts = {}, {}
    for ds in COMMON:
        have = defaultdict(set)
        for j in jobs:
            if j["pair"].dataset == ds:
                have[j["matcher"]].add(j["pair"].name)
        shared = set.intersection(*have.values()) if have else set()
        counts[ds] = {k: len(v) for k, v in have.items()}
        shared_counts[ds] = len(shared)
        rows += [
            {**r, "dataset": f"{ds}-common"}
            for r in rows
            if r["dataset"] == ds and r["pair"] in shared
        ]
    meta = dict(
        command=common.command(__spec__.name, argv),
        date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        load=f"{load_before} before, {load_average()} after",
        machine=f"{platform.machine()}, {os.cpu_count()} cores",
        seconds=time.time() - started,
        versions=peer_versions()
        + ["matchers (.venv): " + ", ".join(f"{k} {v}" for k, v in matchers.versions().items())],
        threshold=THRESHOLD,
        grid=grid,
        pair_counts=counts,
        matching_seconds=dict(MATCHING_SECONDS),
        common_pairs=shared_counts,
        cached=args.cached,
        unavailable=unavailable,
        notes=notes,
    )
    write(args.out, rows, meta)
    log(f"done: {args.out}/pose.md")
    return 0


# --- tables and plots ---------------------------------------------------------------------------


def summarize(rows: list[dict]) -> list[dict]:
    groups = defaultdict(list)
    for r in rows:
        groups[(r["dataset"], r["matcher"], r["estimator"], r["A_source"])].append(r)
    out = []
    for (ds, m, est, src), g in groups.items():
        pe = [r["pose_err"] for r in g]
        auc = pose_auc(pe)
        finite = [r for r in g if np.isfinite(r["pose_err"])]
        out.append(
            dict(
                dataset=ds,
                matcher=m,
                estimator=est,
                A_source=src,
                pairs=len(g),
                failures=len(g) - len(finite),
                mean_matches=float(np.mean([r["matches"] for r in g])),
                mean_inliers=float(np.mean([r["inliers"] for r in g])),
                auc5=100 * auc[0],
                auc10=100 * auc[1],
                auc20=100 * auc[2],
                med_rot=float(np.median([r["rot_err"] for r in g])),
                med_t=float(np.median([r["t_err"] for r in g])),
                est_ms=float(np.nanmedian([r["est_ms"] for r in g]))
                if any(np.isfinite(r["est_ms"]) for r in g)
                else float("nan"),
                match_s=float(np.mean([r["match_s"] for r in g])),
            )
        )
    order = {n: i for i, n in enumerate(matchers.NAMES)}
    est_order = {m: i for i, (_, m, _) in enumerate(ESTIMATORS)}
    out.sort(
        key=lambda s: (
            DATASETS.index(s["dataset"]) if s["dataset"] in DATASETS else 99,
            order.get(s["matcher"], 99),
            est_order.get(s["estimator"], 99),
            s["A_source"],
        )
    )
    return out


def fmt(v, digits=1) -> str:
    if isinstance(v, float):
        if np.isnan(v):
            return "–"
        if np.isinf(v):
            return "fail"
        return f"{v:.{digits}f}"
    return str(v)


def estimator_label(s: dict) -> str:
    label = LABELS.get(s["estimator"], s["estimator"])
    if s["A_source"] == "own":
        return label + ", own A"
    if s["A_source"] == "affcorr":
        return label + ", affcorr A"
    return label


def table(summary: list[dict], dataset: str) -> list[str]:
    rows = [s for s in summary if s["dataset"] == dataset]
    if not rows:
        return ["(no results)"]
    lines = [
        "| matcher | estimator | pairs | matches | inliers | AUC@5 | AUC@10 | AUC@20 | "
        "med. rot. ° | med. transl. ° | failures | est. ms |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for s in rows:
        lines.append(
            f"| {matchers.LABELS.get(s['matcher'], s['matcher'])} | {estimator_label(s)} | "
            f"{s['pairs']} | {s['mean_matches']:.0f} | {s['mean_inliers']:.0f} | "
            f"{fmt(s['auc5'])} | {fmt(s['auc10'])} | {fmt(s['auc20'])} | "
            f"{fmt(s['med_rot'], 2)} | {fmt(s['med_t'], 2)} | {s['failures']} | "
            f"{fmt(s['est_ms'])} |"
        )
    return lines


DATASET_TITLES = {
    "synthetic": "Synthetic multi-plane scenes (MegaDepth-like), all pairs of each matcher",
    "synthetic-common": "Synthetic scenes, the pairs every matcher ran on",
    "chessboard": "opencv-doc chessboard set: pairs of left views (board poses)",
    "chessboard-common": "opencv-doc chessboard set: the pairs of left views every matcher ran on",
    "chessboard-stereo": "opencv-doc chessboard set: left/right stereo rig",
    "motorcycle": "scikit-image motorcycle stereo pair (Middlebury 2014)",
}


def plot(rows: list[dict], out: Path) -> str | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    panels = [
        d
        for d in ("synthetic-common", "synthetic", "chessboard")
        if any(r["dataset"] == d for r in rows)
    ]
    if not panels:
        return None
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.5), squeeze=False)
    for ax, ds in zip(axes[0], panels):
        groups = defaultdict(list)
        for r in rows:
            if r["dataset"] == ds and r["estimator"] in (
                "opencv-USAC_MAGSAC",
                "affcorr-AC",
                "gcransac-AC",
            ):
                if (
                    r["estimator"] != "opencv-USAC_MAGSAC"
                    and r["A_source"] == "own"
                    and r["matcher"] != "affcorr"
                ):
                    continue
                groups[(r["matcher"], r["estimator"])].append(r["pose_err"])
        if not ds.endswith("common") and groups:  # matchers on a subset: see the common panel
            most = max(len(v) for v in groups.values())
            groups = {k: v for k, v in groups.items() if len(v) >= 0.95 * most}
        x = np.linspace(0, 20, 201)
        colours = {n: f"C{i}" for i, n in enumerate(matchers.NAMES)}
        for (m, est), errs in sorted(groups.items()):
            e = np.asarray(errs)
            style = {"opencv-USAC_MAGSAC": ":", "gcransac-AC": "--", "affcorr-AC": "-"}[est]
            ax.plot(
                x,
                [np.mean(e <= v) for v in x],
                style,
                color="k" if m == "affcorr" else colours.get(m),
                label=f"{matchers.LABELS.get(m, m)} / {LABELS[est]}",
                lw=2.2 if m == "affcorr" else 1.2,
            )
        ax.set_title(
            DATASET_TITLES[ds].split(":")[0].split(",")[0]
            + (" (common pairs)" if ds == "synthetic-common" else "")
        )
        ax.set_xlabel("pose error max(rot, transl.) [deg]")
        ax.set_ylabel("fraction of pairs")
        ax.grid(alpha=0.3)
        ax.set_ylim(0, 1)
    axes[0][0].legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    path = out / "pose_curves.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def write_rows_csv(path: Path, rows: list[dict]) -> None:
    """One CSV row per estimate, with every key of every row as columns (rows cached before a
    field existed lack it: empty cell), floats at 5 significant digits (far below the errors'
    own noise)."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, restval="")
        w.writeheader()
        w.writerows(
            {k: float(f"{v:.5g}") if isinstance(v, float) else v for k, v in r.items()}
            for r in rows
        )


def write(out: Path, rows: list[dict], meta: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_rows_csv(out / "pose.csv", [r for r in rows if r["dataset"] != "synthetic-common"])
    summary = summarize(rows)
    with open(out / "pose_summary.csv", "w", newline="") as f:
        if summary:
            w = csv.DictWriter(f, fieldnames=list(summary[0].keys()))
            w.writeheader()
            w.writerows(summary)
    png = plot(rows, out)
    lines = [
        "# Experiment 3: relative pose (paper Tables 3, 5, 6)",
        "",
        f"Command: `{meta['command']}`  ",
        f"Date: {meta['date']}; {meta['seconds'] / 60:.1f} min; load average {meta['load']}; "
        f"{meta['machine']}  ",
        "Versions: " + "; ".join(meta["versions"]) + "  ",
        "Matching time (the matchers' own seconds summed over their pairs, single-threaded on "
        "the loaded machine; cached matches keep the time of the run that made them): "
        + ", ".join(f"{k} {v / 60:.1f} min" for k, v in meta["matching_seconds"].items())
        + ".  \n"
        "Pairs with matches, per matcher: "
        + "; ".join(
            f"{ds}: "
            + ", ".join(f"{k} {v}" for k, v in meta["pair_counts"][ds].items())
            + f" ({meta['common_pairs'][ds]} common to all)"
            for ds in COMMON
        )
        + f"; chessboard stereo 13 (slow matchers: 1), motorcycle 1. Full grid: synthetic "
        f"{meta['grid']['synthetic']} (slow matchers {', '.join(sorted(SLOW))}: every "
        f"{meta['grid']['slow_every']}th), chessboard "
        f"{meta['grid']['chessboard'] or 'all 78 + 13'} (slow: every "
        f"{meta['grid']['chess_slow_every']}th)."
        + (" Estimated on the matches cached by `--match-only` runs." if meta["cached"] else ""),
        "",
        f"Every estimator gets the same matches and the same threshold, {meta['threshold']} px "
        "(on its own residual: Sampson distance for PoseLib and affcorr, epipolar-line distance "
        "for OpenCV, in normalised units divided by the mean focal length, and GC-RANSAC), "
        "confidence 0.9999, at most 10000 iterations, one thread. AUC is in percent (the "
        "recall curve of the pose error max(rotation, translation direction) up to 5/10/20°, "
        "failures count as infinite errors); medians in degrees ('fail' when more than half of "
        "the pairs failed); 'est. ms' is the estimator's median wall time per pair; 'inliers' "
        "is the estimator's mean inlier count. ACs: 'own A' is the matcher's own affine shape "
        "(a similarity for SIFT/ASIFT), 'affcorr A' is affcorr's shape network at the same "
        "points.",
        "",
    ]
    lines += [
        "Data (benches/affcorr_bench/eval/pose_data.py): synthetic pairs are rendered "
        "multi-plane scenes "
        "(a back wall, a ground plane, 2-4 slanted facades, textured with held-out real images; "
        "cameras 5-30° apart, different focal lengths, a photometric change; 640x480). In the "
        "chessboard set the camera stands still and the board moves, so the board poses of "
        "left_intrinsics.yml give the motion of the board's points only: those pairs keep the "
        "matches inside the board's outline in both images (one plane, repetitive squares). "
        "The stereo pairs use all matches, with the rig calibrated by OpenCV on the board "
        "corners (pose_calib.py). The motorcycle pair is rectified (R = I).",
        "",
        "'affcorr (2AC, >= 200 samples)' is affcorr's estimator with min_iterations=200 (every "
        "other option at its default), run in this process: it shows what the adaptive stopping "
        "rule costs on these scenes.",
        "",
    ]
    if meta["unavailable"]:
        lines += [
            "Unavailable matchers: "
            + "; ".join(f"{k}: {v}" for k, v in meta["unavailable"].items()),
            "",
        ]
    if png:
        lines += [f"![pose error curves]({png})", ""]
    for ds in DATASETS:
        lines += [f"## {DATASET_TITLES[ds]}", "", *table(summary, ds), ""]
    if meta["notes"]:
        lines += ["## Notes (estimator errors)", "", *[f"- {n}" for n in meta["notes"][:40]], ""]
    (out / "pose.md").write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())

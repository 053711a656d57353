"""affcorr's essential solvers against PoseLib's, timed in one process.

PoseLib ships no sdist on PyPI (wheels only), so there is no C++ harness here: both libraries are
called through their Python bindings, in the same process, on the same samples.

Samples: SAMPLES exact random problems. A random pose (rotation up to 60° about a random axis,
unit baseline in a random direction); general 3D points (no plane) at depth 2-10 in front of
camera 1 and kept only if in front of camera 2 as well. Inputs are normalised coordinates:
affcorr gets (m, 2) arrays [x/z, y/z] (its documented input), PoseLib gets the unit bearing
vectors (m, 3) of the same points (its documented input). All inputs are prepared (contiguous
float64) before timing.

Pairs timed (both return essential matrices only, no decomposition):
  - affcorr.essential_5pt(x1 (5,2), x2)  vs  poselib.essential_matrix_5pt(b1 (5,3), b2)
  - affcorr.essential_8pt(x1 (8,2), x2)  vs  poselib.essential_matrix_8pt(b1 (8,3), b2)
relpose 5pt with cheirality is not timed: affcorr has no Python binding of relative_pose_5pt
(essential_5pt + pose_from_essential in Python would add interpreter time PoseLib does not pay).

Timing: ROUNDS rounds; in each round every timed callable runs over all samples once (one
perf_counter_ns span per callable, ns/call = span / SAMPLES), in the interleaved order
baseline, ours, theirs per pair; the reported figure is the median over rounds. The process is
pinned to one CPU; main() sets RAYON/OMP threads to 1 (unless set) before affcorr and PoseLib
are imported (numpy is imported with the module: OMP_NUM_THREADS=1 on the command line covers it).

Overhead baseline: `_overhead(x1, x2)` = np.ascontiguousarray on both inputs + a trivial C
builtin (operator.is_), i.e. the Python call and argument handling both sides share. Subtracting
it from ns/call gives an ESTIMATE of the kernel time (it still contains the conversion of the
outputs into numpy arrays / Python lists, which neither side can avoid through Python).

Correctness in the same run: a sample succeeds if some returned candidate E satisfies
min(||E/|E| - Et||, ||E/|E| + Et||) < TOL (1e-6) with Et the true E = [t]x R (unit Frobenius
norm); rates at TOL_LOOSE (1e-4), the median and the 99th percentile of that error are reported
too (PoseLib's 5-point solver has a precision tail of ~1e-5 on a few percent of samples).

    OMP_NUM_THREADS=1 PYTHONPATH=benches \
        benches/peers/.venv-peers/bin/python -m affcorr_bench.peers.solver_timing

(affcorr must be importable in .venv-peers: install the abi3 wheel there, see
benches/results/solvers_vs_poselib.md). Writes benches/results/solvers_vs_poselib.csv and
prints the markdown table.
"""

import argparse
import operator
import os
import time
from pathlib import Path

import numpy as np

from .. import common
from ..common import random_rotation, skew

OUT = common.RESULTS
TOL = 1e-6
TOL_LOOSE = 1e-4


def make_sample(rng, m):
    """m exact correspondences of general 3D points in front of both cameras, and the true E."""
    r = random_rotation(rng, np.deg2rad(60))
    t = rng.normal(size=3)
    t /= np.linalg.norm(t)
    pts = []
    while len(pts) < m:
        z = rng.uniform(2, 10)
        p = np.array([rng.uniform(-0.8, 0.8) * z, rng.uniform(-0.8, 0.8) * z, z])
        if (r @ p + t)[2] > 0.1:
            pts.append(p)
    p1 = np.array(pts)
    p2 = p1 @ r.T + t
    e = skew(t) @ r
    e /= np.linalg.norm(e)
    x1 = np.ascontiguousarray(p1[:, :2] / p1[:, 2:])
    x2 = np.ascontiguousarray(p2[:, :2] / p2[:, 2:])
    b1 = np.ascontiguousarray(p1 / np.linalg.norm(p1, axis=1, keepdims=True))
    b2 = np.ascontiguousarray(p2 / np.linalg.norm(p2, axis=1, keepdims=True))
    return x1, x2, b1, b2, e


def e_error(cands, e_true):
    best = np.inf
    for e in cands:
        e = np.asarray(e, dtype=np.float64)
        n = np.linalg.norm(e)
        if not np.isfinite(n) or n == 0:
            continue
        e = e / n
        best = min(best, np.linalg.norm(e - e_true), np.linalg.norm(e + e_true))
    return best


def _overhead(x1, x2):
    return operator.is_(np.ascontiguousarray(x1), np.ascontiguousarray(x2))


def time_span(fn, args):
    t0 = time.perf_counter_ns()
    for a, b in args:
        fn(a, b)
    return (time.perf_counter_ns() - t0) / len(args)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=101)
    ap.add_argument("--chunk", type=int, default=50, help="samples per timed span")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: lowest allowed)")
    ap.add_argument("--csv", type=Path, default=OUT / "solvers_vs_poselib.csv")
    args = ap.parse_args(argv)
    # One thread, before the libraries are imported (their pools start on first use).
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import affcorr
    import poselib

    if hasattr(os, "sched_setaffinity"):
        cpu = args.cpu if args.cpu is not None else min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})

    rng = np.random.default_rng(args.seed)
    data = {m: [make_sample(rng, m) for _ in range(args.samples)] for m in (5, 8)}

    def p8(b1, b2):  # PoseLib's 8pt returns one matrix; wrap for the checker only
        return [poselib.essential_matrix_8pt(b1, b2)]

    pairs = [
        (
            "essential_5pt",
            5,
            affcorr.essential_5pt,
            "essential_matrix_5pt",
            poselib.essential_matrix_5pt,
            poselib.essential_matrix_5pt,
        ),
        (
            "essential_8pt",
            8,
            affcorr.essential_8pt,
            "essential_matrix_8pt",
            poselib.essential_matrix_8pt,
            p8,
        ),
    ]

    # correctness (same process, same samples)
    checks = {}
    for name, m, ours, _, _, theirs_list in pairs:
        err_o = np.array([e_error(ours(x1, x2), e) for x1, x2, _, _, e in data[m]])
        err_t = np.array([e_error(theirs_list(b1, b2), e) for _, _, b1, b2, e in data[m]])
        n_o = np.mean([len(ours(x1, x2)) for x1, x2, _, _, _ in data[m]])
        n_t = np.mean([len(theirs_list(b1, b2)) for _, _, b1, b2, _ in data[m]])
        checks[name] = dict(
            ok_o=np.mean(err_o < TOL),
            ok_t=np.mean(err_t < TOL),
            ok_o_loose=np.mean(err_o < TOL_LOOSE),
            ok_t_loose=np.mean(err_t < TOL_LOOSE),
            p99_o=np.quantile(err_o, 0.99),
            p99_t=np.quantile(err_t, 0.99),
            med_o=np.median(err_o),
            med_t=np.median(err_t),
            n_o=n_o,
            n_t=n_t,
        )

    # timing: interleaved rounds
    ours_args = {m: [(x1, x2) for x1, x2, _, _, _ in data[m]] for m in (5, 8)}
    theirs_args = {m: [(b1, b2) for _, _, b1, b2, _ in data[m]] for m in (5, 8)}
    for m in (5, 8):  # warm-up
        for _, mm, ours, _, theirs, _ in pairs:
            if mm == m:
                time_span(ours, ours_args[m][:100])
                time_span(theirs, theirs_args[m][:100])
    # t[key][round][chunk] = ns/call over that chunk of samples
    t = {k: [] for k in ("ovh5", "ovh8")}
    for name, *_ in pairs:
        t[f"{name}/o"], t[f"{name}/t"] = [], []
    chunks = range(0, args.samples, args.chunk)
    for r in range(args.rounds):
        for name, m, ours, _, theirs, _ in pairs:
            rows_r = {k: [] for k in (f"ovh{m}", f"{name}/o", f"{name}/t")}
            for c0 in chunks:
                oa, ta = ours_args[m][c0 : c0 + args.chunk], theirs_args[m][c0 : c0 + args.chunk]
                rows_r[f"ovh{m}"].append(time_span(_overhead, oa))
                if r % 2 == 0:  # alternate who goes first in each chunk
                    rows_r[f"{name}/o"].append(time_span(ours, oa))
                    rows_r[f"{name}/t"].append(time_span(theirs, ta))
                else:
                    rows_r[f"{name}/t"].append(time_span(theirs, ta))
                    rows_r[f"{name}/o"].append(time_span(ours, oa))
            for k, v in rows_r.items():
                t[k].append(v)
    t = {k: np.array(v) for k, v in t.items()}
    # headline: per chunk the median over rounds (drops rounds hit by preemption on this loaded
    # machine), averaged over the chunks = ns/call over all samples; also the plain median over
    # rounds of the whole-set ns/call, and the minimum per chunk.
    med = {k: float(np.mean(np.median(v, axis=0))) for k, v in t.items()}
    plain = {k: float(np.median(v.mean(axis=1))) for k, v in t.items()}
    low = {k: float(np.mean(np.min(v, axis=0))) for k, v in t.items()}

    rows = []
    for name, m, _, pname, _, _ in pairs:
        c = checks[name]
        o, th, ov = med[f"{name}/o"], med[f"{name}/t"], med[f"ovh{m}"]
        rows.append(
            dict(
                solver=name,
                poselib=pname,
                m=m,
                samples=args.samples,
                rounds=args.rounds,
                ours_ns=round(o),
                poselib_ns=round(th),
                ratio_ours_over_poselib=round(o / th, 3),
                overhead_ns=round(ov),
                ours_est_kernel_ns=round(o - ov),
                poselib_est_kernel_ns=round(th - ov),
                ratio_est_kernel=round((o - ov) / (th - ov), 3),
                ours_success=round(c["ok_o"], 4),
                poselib_success=round(c["ok_t"], 4),
                ours_success_loose=round(c["ok_o_loose"], 4),
                poselib_success_loose=round(c["ok_t_loose"], 4),
                ours_median_err=f"{c['med_o']:.1e}",
                poselib_median_err=f"{c['med_t']:.1e}",
                ours_p99_err=f"{c['p99_o']:.1e}",
                poselib_p99_err=f"{c['p99_t']:.1e}",
                ours_mean_candidates=round(c["n_o"], 2),
                poselib_mean_candidates=round(c["n_t"], 2),
                ours_ns_plain_median=round(plain[f"{name}/o"]),
                poselib_ns_plain_median=round(plain[f"{name}/t"]),
                ours_ns_min=round(low[f"{name}/o"]),
                poselib_ns_min=round(low[f"{name}/t"]),
                chunk=args.chunk,
            )
        )

    common.write_csv(rows, args.csv)

    print(
        f"affcorr {getattr(affcorr, '__version__', '?')} ({affcorr.__file__}), "
        f"poselib {poselib.__version__}, numpy {np.__version__}"
    )
    print(
        f"samples {args.samples}, rounds {args.rounds}, seed {args.seed}, "
        f"success: best candidate within {TOL:g} (loose: {TOL_LOOSE:g}) of the true E"
    )
    print()
    print(
        "| solver (ours / PoseLib) | ours ns/call | PoseLib ns/call | ours/PoseLib "
        "| shared overhead ns | est. kernel ours | est. kernel PoseLib | est. ratio "
        "| success ours | success PoseLib | success (loose) ours / PoseLib "
        "| median err ours / PoseLib | p99 err ours / PoseLib | mean #E ours / PoseLib |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['solver']} / {r['poselib']} | {r['ours_ns']} | {r['poselib_ns']} "
            f"| {r['ratio_ours_over_poselib']:.2f} | {r['overhead_ns']} "
            f"| ~{r['ours_est_kernel_ns']} | ~{r['poselib_est_kernel_ns']} "
            f"| ~{r['ratio_est_kernel']:.2f} | {100 * r['ours_success']:.1f}% "
            f"| {100 * r['poselib_success']:.1f}% "
            f"| {100 * r['ours_success_loose']:.1f}% / {100 * r['poselib_success_loose']:.1f}% "
            f"| {r['ours_median_err']} / {r['poselib_median_err']} "
            f"| {r['ours_p99_err']} / {r['poselib_p99_err']} "
            f"| {r['ours_mean_candidates']} / {r['poselib_mean_candidates']} |"
        )
    print()
    print("ns/call: chunk-median (headline) / plain median over rounds / chunk-min:")
    for k in t:
        print(f"  {k:18s} {med[k]:8.0f} / {plain[k]:8.0f} / {low[k]:8.0f}")


if __name__ == "__main__":
    main()

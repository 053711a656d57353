"""Turn criterion's output for `--bench geom` into the table of benches/results/geom.md.

Usage: .venv/bin/python -m affcorr_bench.geom_table [CRITERION_DIR] [--csv OUT.csv] > table.md

Reads every `<group>/<bench>/new/{benchmark,estimates}.json` under CRITERION_DIR (default
target/criterion) written by benches/benches/geom.rs, and prints a markdown table with the
median time, ACs/s, the bytes each kernel must move per row converted to GB/s, and that as a
fraction of the machine's bandwidth: the best STREAM-like figure of the same run on DRAM-sized
arrays. The same columns from each benchmark's fastest sample are given too: on a machine shared
with other jobs they are the less disturbed estimate.
Standard library only.
"""

import argparse
import csv
import json
from pathlib import Path

# Compulsory bytes per row (reads + writes of f64 data; no write-allocate, as in STREAM).
BYTES_PER_ROW = {
    # in: orientation, scale, residual_shape (5 f64); out: A (4 f64)
    "synthesize_affine": 40 + 32,
    # in: A (4 f64); out: AffineShape (5 f64)
    "decompose_affine": 32 + 40,
    # in: (N, 8); out: (N, 8)
    "normalize_correspondences": 64 + 64,
    # in: x1 (2 f64); out: (N, 8)
    "correspondences_from_homography": 16 + 64,
    # in: (N, 4), shared F; out: SD_P (1 f64)
    "sampson_point": 32 + 8,
    # in: (N, 8), shared F; out: SD_A per row (2 f64)
    "sampson_affine": 64 + 16,
    # in: (N, 8) + one F per row (9 f64); out: 2 f64
    "sampson_affine_per_row_f": 64 + 72 + 16,
    # in: (N, 4); out: PointSampsonGrad (value, d_x1, d_x2, d_F = 14 f64)
    "sampson_point_grad": 32 + 112,
    # in: (N, 8); out: 2 × AffineSampsonGrad (value, d_x1, d_x2, d_A, d_F = 18 f64)
    "sampson_affine_grad": 64 + 288,
    # in: (N, 4); out: value (N), d_corrs (N, 4), d_F (N, 9)
    "sampson_point_grad_columns": 32 + 8 + 32 + 72,
    # in: (N, 8); out: value (N, 2), d_corrs (N, 2, 8), d_F (N, 2, 9)
    "sampson_affine_grad_columns": 64 + 16 + 128 + 144,
}
ORDER = list(BYTES_PER_ROW)


def load(root: Path):
    rows = []
    for bj in sorted(root.glob("**/new/benchmark.json")):
        meta = json.loads(bj.read_text())
        est = json.loads((bj.parent / "estimates.json").read_text())
        smp = json.loads((bj.parent / "sample.json").read_text())
        best_ns = min(t / i for t, i in zip(smp["times"], smp["iters"]))
        rows.append(
            {
                "group": meta["group_id"],
                "function": meta["function_id"],
                "value": meta["value_str"],
                "throughput": meta.get("throughput"),
                "median_ns": est["median"]["point_estimate"],
                "lo_ns": est["median"]["confidence_interval"]["lower_bound"],
                "hi_ns": est["median"]["confidence_interval"]["upper_bound"],
                "best_ns": best_ns,
            }
        )
    return rows


def fmt_time(ns: float) -> str:
    for unit, scale in (("s", 1e9), ("ms", 1e6), ("µs", 1e3)):
        if ns >= scale:
            return f"{ns / scale:.3g} {unit}"
    return f"{ns:.3g} ns"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("criterion_dir", nargs="?", type=Path, default=Path("target/criterion"))
    ap.add_argument("--csv", type=Path, default=None, help="also the table as CSV")
    args = ap.parse_args(argv)
    root, csv_out = args.criterion_dir, args.csv
    rows = load(root)

    # STREAM: bytes moved / time, from the median and from the fastest sample.
    stream = {}
    for r in rows:
        if r["group"] != "stream":
            continue
        op, threads = r["function"].split("/")
        nbytes = r["throughput"]["Bytes"]
        # bytes / ns = GB/s
        stream[(op, threads, r["value"])] = (nbytes / r["median_ns"], nbytes / r["best_ns"])
    dram_mb = max(int(v) for (_, _, v) in stream)
    dram = [g for (_, _, v), g in stream.items() if int(v) == dram_mb]
    bw_median = max(g[0] for g in dram)
    bw_best = max(g[1] for g in dram)

    print("### Measured memory bandwidth (STREAM-like, same run)\n")
    print("| op | threads | footprint (MB) | GB/s (median) | GB/s (fastest sample) |")
    print("|---|---|---|---|---|")
    for (op, t, v), (gm, gb) in sorted(
        stream.items(), key=lambda kv: (-int(kv[0][2]), kv[0][0], kv[0][1])
    ):
        print(f"| {op} | {t[1:]} | {v} | {gm:.2f} | {gb:.2f} |")
    print(
        f"\nReference bandwidth (best over ops and thread counts, DRAM-sized arrays): "
        f"**{bw_median:.2f} GB/s** from medians, **{bw_best:.2f} GB/s** from fastest samples.\n"
    )

    print("### Kernels\n")
    print(
        "| kernel | N | threads | median time [95% CI] | ACs/s | B/row | GB/s | % of BW "
        "| fastest sample | GB/s | % of BW |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    table = []
    for r in rows:
        if r["group"] not in BYTES_PER_ROW:
            continue
        n = int(r["value"])
        bpr = BYTES_PER_ROW[r["group"]]
        table.append(
            {
                "kernel": r["group"],
                "n": n,
                "threads": int(r["function"][1:]),
                "median_ns": r["median_ns"],
                "lo_ns": r["lo_ns"],
                "hi_ns": r["hi_ns"],
                "best_ns": r["best_ns"],
                "acs_per_s": n / (r["median_ns"] * 1e-9),
                "bytes_per_row": bpr,
                "gb_per_s": n * bpr / r["median_ns"],
                "frac_bw": n * bpr / r["median_ns"] / bw_median,
                "gb_per_s_best": n * bpr / r["best_ns"],
                "frac_bw_best": n * bpr / r["best_ns"] / bw_best,
            }
        )
    table.sort(key=lambda x: (ORDER.index(x["kernel"]), x["n"], x["threads"]))
    n_max = max(x["n"] for x in table)
    for x in table:
        ci = f"{fmt_time(x['median_ns'])} [{fmt_time(x['lo_ns'])}, {fmt_time(x['hi_ns'])}]"
        b = "**" if x["n"] == n_max else ""
        print(
            f"| {x['kernel']} | {x['n']:.0e} | {x['threads']} | {ci} | {x['acs_per_s']:.3g} "
            f"| {x['bytes_per_row']} | {x['gb_per_s']:.2f} | {b}{100 * x['frac_bw']:.0f}%{b} "
            f"| {fmt_time(x['best_ns'])} | {x['gb_per_s_best']:.2f} "
            f"| {b}{100 * x['frac_bw_best']:.0f}%{b} |"
        )
    if csv_out:
        with csv_out.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(table[0]))
            w.writeheader()
            w.writerows(table)


if __name__ == "__main__":
    main()

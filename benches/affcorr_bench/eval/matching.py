"""Experiment 1: image matching under the HPatches protocol (paper Table 1, Eq. 16).

    .venv/bin/python -m affcorr_bench.eval.matching [--max-keypoints 1024] [--max-side 512]
        [--images N] [--methods sift,affcorr,...]

Data (data.hpatches_pairs): graffiti 1 -> 3 and HPatches-style sequences of held-out real images
(viewpoint: 5 homographies of growing strength; illumination: 5 photometric changes, H = I).
Every method of the registry (matchers.py) runs on the same pairs.

Metric (D2-Net / PoSFeat protocol): a match is correct at threshold t when the transfer error
||H(x1) - x2|| <= t px; MMA@t is the fraction of a pair's matches that are correct (0 for a pair
without matches), averaged over the pairs of a split; MMAscore (Eq. 16) weighs MMA@t,
t = 1..10, by (2 - 0.1 t). Also the mean number of matches and of matches correct at 3 px per
pair (MMA alone rewards returning few, safe matches) and the median wall time per pair.

Writes benches/results/eval/matching.{md,csv,png}; matches are cached in benches/eval/.cache.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from affcorr._progress import progress
from affcorr.metrics import transfer

from .. import common
from . import data, matchers, suite

THRESHOLDS = np.arange(1, 11)
WEIGHTS = 2.0 - 0.1 * THRESHOLDS
SPLITS = ("overall", "illumination", "viewpoint")


def mma_curve(m: matchers.Matches, H: np.ndarray) -> np.ndarray:
    """MMA@1..10 px of one pair's matches."""
    if len(m) == 0:
        return np.zeros(len(THRESHOLDS))
    err = np.linalg.norm(transfer(H, m.x1) - m.x2, axis=1)
    return (err[:, None] <= THRESHOLDS[None]).mean(0)


def mma_score(curve: np.ndarray) -> float:
    """Eq. 16: sum_t (2 - 0.1 t) MMA@t / sum_t (2 - 0.1 t), t = 1..10."""
    return float((WEIGHTS * curve).sum() / WEIGHTS.sum())


def evaluate(pairs, names, max_keypoints: int) -> list[dict]:
    """One row per pair and method."""
    rows = []
    jobs = [(p, n) for p in pairs for n in names]
    for pair, name in progress(jobs, desc="matching", unit="pair x method"):
        m = suite.matches(name, pair, max_keypoints)
        curve = mma_curve(m, pair.H)
        rows.append(
            dict(
                pair=pair.id,
                kind=pair.kind,
                method=name,
                matches=len(m),
                correct_3px=int(round(curve[2] * len(m))),
                seconds=m.seconds,
                **{f"mma@{t}": float(c) for t, c in zip(THRESHOLDS, curve)},
            )
        )
    return rows


def summarise(rows: list[dict], names: list[str]) -> dict:
    """{(split, method): dict(curve, score, matches, correct, seconds, pairs)}."""
    out = {}
    for split in SPLITS:
        for name in names:
            sel = [r for r in rows if r["method"] == name and split in ("overall", r["kind"])]
            if not sel:
                continue
            curve = np.mean([[r[f"mma@{t}"] for t in THRESHOLDS] for r in sel], axis=0)
            out[split, name] = dict(
                curve=curve,
                score=mma_score(curve),
                matches=float(np.mean([r["matches"] for r in sel])),
                correct=float(np.mean([r["correct_3px"] for r in sel])),
                seconds=float(np.median([r["seconds"] for r in sel])),
                pairs=len(sel),
            )
    return out


def plot(summary: dict, names: list[str], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharey=True)
    for ax, split in zip(axes, SPLITS):
        for name in names:
            s = summary.get((split, name))
            if s is None:
                continue
            style = dict(lw=2.5, color="k") if name == "affcorr" else dict(lw=1.3)
            ax.plot(THRESHOLDS, s["curve"], marker="o", ms=3, label=matchers.LABELS[name], **style)
        ax.set_title(f"{split} ({summary[split, names[0]]['pairs']} pairs)")
        ax.set_xlabel("threshold (px)")
        ax.set_xticks(THRESHOLDS)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("MMA")
    axes[0].set_ylim(0, 1)
    axes[-1].legend(fontsize=8, loc="lower right")
    common.save_figure(fig, path)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--max-keypoints", type=int, default=1024)
    p.add_argument("--max-side", type=int, default=512, help="longer image side (px)")
    p.add_argument("--images", type=int, default=None, help="held-out images per kind")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--methods", default=",".join(matchers.NAMES))
    p.add_argument("--out", default=str(suite.RESULTS / "matching"))
    args = p.parse_args(argv)
    suite.use_openblas()
    t0 = time.time()
    wanted = args.methods.split(",")
    av = matchers.available()
    names = [n for n in wanted if not av.get(n, "unknown method")]
    pairs = data.hpatches_pairs(args.max_side, args.seed, args.images)
    rows = evaluate(pairs, names, args.max_keypoints)
    summary = summarise(rows, names)

    from pathlib import Path

    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))
    plot(summary, names, out.with_suffix(".png"))
    n_kind = {k: sum(p.kind == k for p in pairs) for k in ("viewpoint", "illumination")}
    notes = [
        f"Pairs: {len(pairs)} ({n_kind['viewpoint']} viewpoint incl. graffiti 1-3, "
        f"{n_kind['illumination']} illumination), longer side {args.max_side} px, "
        f"at most {args.max_keypoints} keypoints per image, seed {args.seed}. "
        f"Wall time of the run: {time.time() - t0:.0f} s (cached matches are reused).",
        "MMA@t: fraction of a pair's matches within t px of the ground-truth H, averaged over "
        "pairs. MMAscore = sum_t (2 - 0.1 t) MMA@t / sum_t (2 - 0.1 t), t = 1..10 (paper "
        "Eq. 16). matches / correct: mean per pair (correct: within 3 px). time: median "
        "seconds per pair (detection + matching (+ shape network for affcorr)).",
        "affcorr's matches are XFeat+LighterGlue's (ONNX in Rust); its shape network adds A, "
        "which this experiment does not score (experiment 2 does), and its default affine "
        "Lucas-Kanade refinement of the ACs moves x2 (affcorr.Pipeline(refine_affine=False) "
        "keeps XFeat+LighterGlue's points).",
        *suite.unavailable_note(wanted),
    ]
    cols = ["method", "MMAscore overall", "illumination", "viewpoint"]
    cols += [f"MMA@{t}" for t in (1, 3, 5, 10)] + ["matches", "correct", "time (s)"]
    table = []
    for n in names:
        o = summary["overall", n]
        table.append(
            [
                matchers.LABELS[n],
                o["score"],
                summary.get(("illumination", n), {}).get("score", float("nan")),
                summary.get(("viewpoint", n), {}).get("score", float("nan")),
                *[float(o["curve"][t - 1]) for t in (1, 3, 5, 10)],
                f"{o['matches']:.0f}",
                f"{o['correct']:.0f}",
                f"{o['seconds']:.2f}",
            ]
        )
    per_split = []
    for split in ("illumination", "viewpoint"):
        per_split += ["", f"MMA@1..10 px, {split} pairs:", ""]
        per_split += common.md_table(
            ["method", *[f"{t}" for t in THRESHOLDS]],
            [[matchers.LABELS[n], *summary[split, n]["curve"].tolist()] for n in names],
        )
    lines = suite.header(
        "Experiment 1: image matching, HPatches protocol (paper Table 1, Eq. 16)",
        common.command(__spec__.name),
        notes,
    )
    lines += common.md_table(cols, table) + per_split
    lines += ["", f"![MMA curves]({out.with_suffix('.png').name})"]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())

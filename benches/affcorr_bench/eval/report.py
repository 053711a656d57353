"""Generates docs/evaluation.md from the result files of the evaluation suite's four experiments.

    .venv/bin/python -m affcorr_bench.eval.report [--results DIR] [--out docs/evaluation.md]

Nothing in the page is typed by hand about numbers: every sentence is a template filled from the
CSVs in benches/results/eval/ (and the choice between templates is made by comparing those
numbers); the tables are the experiments' own markdown. An experiment whose files are missing
is reported as "not run yet".
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import time
from pathlib import Path

from .. import common
from . import matchers  # the registry's display names

ROOT = common.ROOT

EXPERIMENTS = [
    ("matching", "1. Image matching, HPatches protocol (paper Table 1)", "eval.matching"),
    ("affine", "2. Affine accuracy (paper Tables 2 and 4)", "eval.affine"),
    ("pose", "3. Relative pose (paper Tables 3, 5 and 6)", "eval.pose"),
    ("extreme", "4. Extreme viewpoint (supplement Table 5)", "eval.extreme"),
]

# --- reading ------------------------------------------------------------------------------------


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def f1(v: float) -> str:
    if math.isnan(v):
        return "–"
    if math.isinf(v):
        return "fail"
    return f"{v:.1f}"


def f2(v: float) -> str:
    if math.isinf(v):
        return "fail"
    return f"{v:.2f}"


def relink(md: str, prefix: str) -> str:
    """Image links of a results page, made relative to docs/."""
    return re.sub(r"!\[([^\]]*)\]\((?!http)([^)]+)\)", lambda m: f"![{m[1]}]({prefix}{m[2]})", md)


def demote(md: str, levels: int = 2) -> str:
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m[1]) + levels) + " ", md, flags=re.M)


# --- experiment 3: relative pose ----------------------------------------------------------------

POINT = ["opencv-USAC_MAGSAC", "poselib", "affcorr-points"]
EST_NAMES = {
    "opencv-USAC_MAGSAC": "OpenCV's USAC_MAGSAC",
    "poselib": "PoseLib",
    "affcorr-points": "affcorr's 5-point RANSAC",
    "gcransac-AC": "GC-RANSAC's 2-AC solver",
    "affcorr-AC": "affcorr's 2-AC RANSAC",
    "affcorr-AC-min200": "affcorr's 2-AC RANSAC with at least 200 samples",
}
MATCHER_NAMES = matchers.LABELS  # the registry's display names
DATASET_NAMES = {
    "synthetic": "the synthetic multi-plane scenes (each matcher on all its pairs)",
    "synthetic-common": "the synthetic scenes, on the pairs every matcher ran on",
    "chessboard": "the chessboard set's pairs of left views (matches on the board only)",
    "chessboard-common": "the chessboard pairs of left views every matcher ran on",
    "chessboard-stereo": "the chessboard set's stereo pairs",
    "motorcycle": "the motorcycle stereo pair",
}


def _label(s: dict) -> str:
    m = MATCHER_NAMES.get(s["matcher"], s["matcher"])
    e = EST_NAMES.get(s["estimator"], s["estimator"])
    src = {"own": " with its own A", "affcorr": " with affcorr's A"}.get(s["A_source"], "")
    return f"{m} + {e}{src}"


def _auc(s: dict) -> str:
    return f"{f1(s['auc5'])}/{f1(s['auc10'])}/{f1(s['auc20'])}"


def _one(g, matcher, estimator, own=False):
    """The summary row of (matcher, estimator); AC rows with affcorr's A unless ``own``."""
    for r in g:
        if r["matcher"] == matcher and r["estimator"] == estimator:
            if r["A_source"] == "-" or (r["A_source"] == "own") == own:
                return r
    return None


def _names(ms) -> str:
    return ", ".join(MATCHER_NAMES.get(m, m) for m in ms)


def pose_sentences(rows: list[dict]) -> list[str]:
    """Plain-words findings of experiment 3, from pose_summary.csv. Comparisons across matchers
    use only the rows on (about) the dataset's full pair count (the ``-common`` datasets put every
    matcher on the same pairs)."""
    for r in rows:
        for k in ("auc5", "auc10", "auc20", "med_rot", "med_t", "est_ms", "pairs", "failures"):
            r[k] = num(r[k])
        r["mean_inliers"] = num(r["mean_inliers"])
    out = []
    for ds, ds_name in DATASET_NAMES.items():
        g_all = [r for r in rows if r["dataset"] == ds]
        if not g_all:
            continue
        pairs = int(max(r["pairs"] for r in g_all))
        g = [r for r in g_all if r["pairs"] >= 0.95 * pairs]  # a run cut short: +-1 pair
        fewer = sorted({r["matcher"] for r in g_all} - {r["matcher"] for r in g})
        matchers_ = sorted(
            {r["matcher"] for r in g},
            key=lambda m: list(MATCHER_NAMES).index(m) if m in MATCHER_NAMES else 99,
        )
        lines = []
        best = max(g, key=lambda r: (r["auc10"], r["auc5"]))
        lines.append(
            f"Best AUC@10: {_label(best)}, AUC@5/10/20 = {_auc(best)} (median rotation error "
            f"{f2(best['med_rot'])}°, translation {f2(best['med_t'])}°)."
        )
        o = _one(g, "affcorr", "affcorr-AC")
        if o:
            gc = _one(g, "affcorr", "gcransac-AC")
            text = (
                f"affcorr end to end (its matches, its ACs, its 2-AC RANSAC): AUC@5/10/20 = "
                f"{_auc(o)}, median errors {f2(o['med_rot'])}° / {f2(o['med_t'])}°, "
                f"{f1(o['est_ms'])} ms per estimation"
            )
            if gc:
                text += (
                    f"; its ACs in GC-RANSAC's AC mode (the paper's best configuration): "
                    f"{_auc(gc)}, {f1(gc['est_ms'])} ms"
                )
            lines.append(text + ".")
            better, worse = [], []
            for m in matchers_:
                if m == "affcorr":
                    continue
                pts = [r for r in g if r["matcher"] == m and r["estimator"] in POINT]
                if pts:
                    b = max(pts, key=lambda r: r["auc10"])
                    d = o["auc10"] - b["auc10"]
                    (better if d > 0 else worse).append(f"{_label(b)} ({f1(b['auc10'])}, {d:+.1f})")
            if better:
                lines.append(
                    "Its AUC@10 is above the best point RANSAC of: " + "; ".join(better) + "."
                )
            if worse:
                lines.append(
                    "Its AUC@10 is not above the best point RANSAC of: " + "; ".join(worse) + "."
                )
        # same matches: affcorr's ACs vs the best point RANSAC, per matcher
        gains = []
        for m in matchers_:
            pts = [r for r in g if r["matcher"] == m and r["estimator"] in POINT]
            ac = _one(g, m, "affcorr-AC")
            if pts and ac:
                gains.append((m, ac["auc10"] - max(r["auc10"] for r in pts)))
        if gains:
            up = [m for m, d in gains if d > 0.5]
            lines.append(
                f"On the same matches, affcorr's 2-AC RANSAC (affcorr's A) is above the best point "
                f"RANSAC in AUC@10 for {len(up)} of {len(gains)} matchers"
                + (f" ({_names(up)})" if up else "")
                + "; differences: "
                + ", ".join(f"{MATCHER_NAMES.get(m, m)} {d:+.1f}" for m, d in gains)
                + "."
            )
        # early stopping: fewer inliers than its own 5-point mode, and the >= 200-sample floor
        early, floor = [], []
        for m in matchers_:
            a, p = _one(g, m, "affcorr-AC"), _one(g, m, "affcorr-points")
            f = _one(g, m, "affcorr-AC-min200")
            if a and p and a["mean_inliers"] < 0.95 * p["mean_inliers"] and a["auc10"] < p["auc10"]:
                early.append(m)
            if a and f and abs(f["auc10"] - a["auc10"]) >= 1.0:
                floor.append(f"{MATCHER_NAMES.get(m, m)} {f1(a['auc10'])} → {f1(f['auc10'])}")
        if early:
            lines.append(
                f"With the matches of {_names(early)}, affcorr's 2-AC RANSAC ends with fewer "
                "inliers than its 5-point RANSAC and a lower AUC@10: its adaptive stopping rule "
                "takes a 2-AC sample of inlier points as all-inlier although their shapes are "
                "noisy, so it stops after a few dozen samples, sometimes at a wrong model."
            )
        if floor:
            lines.append(
                "Drawing at least 200 2-AC samples changes its AUC@10: " + "; ".join(floor) + "."
            )
        # the matchers' own A vs affcorr's A, same points, same estimator
        for m in ("sift", "asift", "hesaff"):
            own, aff = _one(g, m, "affcorr-AC", own=True), _one(g, m, "affcorr-AC")
            if not (own and aff):
                continue
            d = aff["auc10"] - own["auc10"]
            if abs(d) < 0.5:
                verdict = "about the same"
            elif d > 0 and m in ("sift", "asift"):
                verdict = (
                    "better: a similarity (scale and rotation only) ignores the foreshortening "
                    "of slanted surfaces, so 2-AC samples built on it give wrong models"
                )
            elif d > 0:
                verdict = "better: affcorr's shapes give the better 2-AC models here"
            else:
                verdict = "worse: affcorr's shapes do not help these matches here"
            lines.append(
                f"{MATCHER_NAMES[m]}'s matches with affcorr's A instead of their own: AUC@10 "
                f"{f1(aff['auc10'])} vs {f1(own['auc10'])} ({d:+.1f}), {verdict}."
            )
        # GC-RANSAC's AC mode against ours, same ACs
        cmp_ = []
        for m in matchers_:
            for own in (False, True):
                x, y = _one(g, m, "affcorr-AC", own), _one(g, m, "gcransac-AC", own)
                if x and y and x is not y:
                    cmp_.append((x, y))
        if cmp_:
            wins = sum(x["auc10"] > y["auc10"] for x, y in cmp_)
            speed = [y["est_ms"] / x["est_ms"] for x, y in cmp_ if x["est_ms"] > 0]
            text = (
                f"Against GC-RANSAC's AC mode on the same ACs, affcorr's AUC@10 is higher in "
                f"{wins} of {len(cmp_)} cases"
            )
            if speed:
                text += (
                    f"; GC-RANSAC takes {min(speed):.1f}–{max(speed):.1f}× affcorr's median "
                    "time per pair"
                )
            lines.append(text + ".")
        if ds == "chessboard" and best["auc10"] < 50:
            lines.append(
                "Every method does poorly here: the only matches with a known motion are on "
                "the board, one plane (for which the essential matrix is ambiguous) with a "
                "repetitive pattern that lets matches jump between squares."
            )
        fails = [r for r in g if r["failures"] > 0]
        if fails:
            worst = max(fails, key=lambda r: r["failures"])
            lines.append(
                f"Failures (no model, or fewer than 8 matches) in {len(fails)} of {len(g)} rows, "
                f"at most {int(worst['failures'])} of {pairs} pairs ({_label(worst)})."
            )
        if fewer:
            where = (
                "are compared on the common pairs below"
                if ds in ("synthetic", "chessboard")
                else "are left out of these comparisons"
            )
            lines.append(f"{_names(fewer)} ran on fewer pairs (slow on this machine) and {where}.")
        out.append(f"**On {ds_name}** ({pairs} pair{'s' if pairs != 1 else ''}):")
        out.append("")
        out += [f"- {t}" for t in lines]
        out.append("")
    return out


# --- experiments 1, 2, 4 (affcorr_bench.eval.matching, affine, extreme) ------------------------


def _by(rows: list[dict], *keys: str) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def _rank(values: dict[str, float], ours: str, higher_better: bool = True) -> tuple[int, int]:
    v = values[ours]
    better = sum((x > v) if higher_better else (x < v) for x in values.values())
    return 1 + better, len(values)


def matching_sentences(rows: list[dict]) -> list[str]:
    """Experiment 1, from matching.csv (one row per pair and method): MMAscore (Eq. 16) of the
    mean MMA curve per split, affcorr against each peer."""
    import numpy as np

    from .matching import THRESHOLDS, mma_score

    out = []
    for split in ("overall", "illumination", "viewpoint"):
        sel = [r for r in rows if split in ("overall", r["kind"])]
        score = {
            m: mma_score(np.mean([[num(r[f"mma@{t}"]) for t in THRESHOLDS] for r in g], axis=0))
            for (m,), g in _by(sel, "method").items()
        }
        if "affcorr" not in score or len(score) < 2:
            continue
        rank, n = _rank(score, "affcorr")
        o = score["affcorr"]
        above = [m for m, v in score.items() if m != "affcorr" and o > v]
        below = [m for m, v in score.items() if m != "affcorr" and o <= v]
        text = f"{split} pairs: affcorr's MMAscore is {o:.3f}, rank {rank} of {n}"
        if above:
            text += "; above " + ", ".join(
                f"{MATCHER_NAMES.get(m, m)} ({score[m]:.3f})" for m in above
            )
        if below:
            text += "; not above " + ", ".join(
                f"{MATCHER_NAMES.get(m, m)} ({score[m]:.3f})" for m in below
            )
        out.append(text + ".")
    xs = [r for r in rows if r["method"] in ("affcorr", "xfeat-lighterglue")]
    if {r["method"] for r in xs} == {"affcorr", "xfeat-lighterglue"}:
        sc = {
            m: mma_score(np.mean([[num(r[f"mma@{t}"]) for t in THRESHOLDS] for r in g], axis=0))
            for (m,), g in _by(xs, "method").items()
        }
        d = sc["affcorr"] - sc["xfeat-lighterglue"]
        out.append(
            "Why: affcorr's matches are XFeat+LighterGlue's (the same networks, run as ONNX in "
            "Rust), and its default affine Lucas-Kanade refinement of the ACs moves x2 to where "
            "the local affine warp fits the images best, which is what moves its MMA "
            f"({d:+.3f}: MMAscore {sc['affcorr']:.3f} vs upstream {sc['xfeat-lighterglue']:.3f}; "
            "the gain is at the tightest thresholds, MMA@1)."
        )
    return [f"- {t}" for t in out]


def affine_sentences(rows: list[dict]) -> list[str]:
    """Experiment 2, from affine.csv (per split and baseline: errors of the baseline's own A and
    of affcorr's (O,S) and (O,S,A″) shapes at the same matches)."""
    out = []
    for r in rows:
        if r["split"] != "overall":
            continue
        m = r["method"]
        name = MATCHER_NAMES.get(m, m)
        full, os_, own = num(r["fro_mean_full"]), num(r["fro_mean_os"]), num(r["fro_mean_own"])
        cf, cown = num(r["cos_mean_full"]), num(r["cos_mean_own"])
        lk = num(r.get("fro_mean_lk", "nan"))
        refined = (
            ""
            if math.isnan(lk)
            else f" Refined against the images by affine Lucas-Kanade (affcorr.refine_affine): "
            f"mean {lk:.3f}, median {num(r['fro_median_lk']):.3f}, cosine "
            f"{num(r['cos_mean_lk']):.3f}."
        )
        if m == "affcorr":
            out.append(
                f"At affcorr's own matches: mean |A - A_gt|_F {full:.3f} with the residual shape "
                f"A″, {os_:.3f} with orientation and scale only (O,S)"
                + (
                    ": A″ adds the anisotropic part a similarity cannot express."
                    if full < os_
                    else ": A″ does not improve on (O,S) here."
                )
                + refined
            )
            continue
        head = f"At {name}'s matches ({r['pairs']} pairs, {r['n']} matches): "
        if math.isnan(own):
            out.append(
                head + f"{name} has no A of its own; affcorr's shape network at its matches: mean "
                f"Frobenius error {full:.3f}, cosine similarity {cf:.3f}." + refined
            )
            continue
        # affcorr's default output is the refined A; the network alone is reported beside it.
        ours, c_ours = (full, cf) if math.isnan(lk) else (lk, num(r["cos_mean_lk"]))
        label = "affcorr's A" if math.isnan(lk) else "affcorr's A (refined, the default)"
        alone = (
            "" if math.isnan(lk) else f" The shape network alone: mean {full:.3f}, cosine {cf:.3f}."
        )
        if ours < own:
            why = {
                "sift": "SIFT's A is a similarity (scale and orientation of its keypoints), "
                "blind to foreshortening",
                "asift": "ASIFT's reported keypoints are similarities too (OpenCV does not "
                "expose the simulated tilt)",
                "hesaff": "Hessian-Affine's shape is adapted to the local second-moment matrix "
                "and is sensitive to noise and to the region's scale",
            }.get(m, "")
        else:
            why = f"on these pairs {name}'s own A is the more accurate one"
        out.append(
            head + f"{label} is {'closer to' if ours < own else 'not closer to'} the truth "
            f"than {name}'s own (mean Frobenius error {ours:.3f} vs {own:.3f}, cosine "
            f"similarity {c_ours:.3f} vs {cown:.3f})" + (f"; {why}." if why else ".") + alone
        )
    return [f"- {t}" for t in out]


def extreme_sentences(rows: list[dict]) -> list[str]:
    """Experiment 4, from extreme.csv (one row per pair and method label): matched pairs (corner
    error under the success threshold) and correct inliers per pair, per tilt."""
    out, bests = [], []
    ours = [lab for lab in {r["method"] for r in rows} if lab.startswith("affcorr")]
    tilts = sorted({r["tilt"] for r in rows}, key=num)
    for tilt in tilts:
        sel = [r for r in rows if r["tilt"] == tilt]
        matched = {
            m: sum(str(r["matched"]) == "True" for r in g) for (m,), g in _by(sel, "method").items()
        }
        inl = {
            m: sum(num(r["correct_inliers"]) for r in g) / len(g)
            for (m,), g in _by(sel, "method").items()
        }
        pairs = max(len(g) for g in _by(sel, "method").values())
        for o in sorted(ours):
            if o not in matched:
                continue
            rank, n = _rank(matched, o)
            best = max(matched, key=lambda m: (matched[m], inl[m]))
            out.append(
                f"tilt {tilt}°: {o} matches {matched[o]} of {pairs} pairs (rank {rank} of {n}; "
                f"{inl[o]:.0f} correct inliers per pair)"
                + ("" if best == o else f"; most: {best} ({matched[best]}, {inl[best]:.0f})")
                + "."
            )
            bests.append(best)
    if bests and "affcorr" not in bests and max(set(bests), key=bests.count) == "ASIFT":
        out.append(
            "Why: ASIFT matches between simulated tilted views, built for exactly this case; "
            "affcorr's points are XFeat+LighterGlue's, whose descriptors are not tilt-invariant, "
            "and its shapes refine matches the matcher found but cannot add ones it missed."
        )
    return [f"- {t}" for t in out]


SENTENCES = {
    "matching": matching_sentences,
    "affine": affine_sentences,
    "extreme": extreme_sentences,
}


# --- the page -----------------------------------------------------------------------------------


def shown(p: Path) -> str:
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def section(key: str, title: str, module: str, results: Path, link: str) -> list[str]:
    md = results / f"{key}.md"
    lines = [f"## {title}", ""]
    if not md.exists():
        run = f"python -m affcorr_bench.{module}"
        return lines + [f"Not run yet: `{run}` has not written `{shown(md)}`.", ""]
    summary = results / f"{key}_summary.csv"
    table = summary if summary.exists() else results / f"{key}.csv"
    lines.append(f"Source: [`{shown(md)}`]({link}{md.name}).")
    lines.append("")
    if table.exists():
        rows = read_csv(table)
        try:
            found = pose_sentences(rows) if key == "pose" else SENTENCES[key](rows)
        except (KeyError, ValueError, ImportError) as e:  # a changed CSV layout
            found = [f"(findings not derived: {type(e).__name__}: {e})"]
        if found:
            lines += ["### Where affcorr stands", "", *found, ""]
    lines += ["### Tables", "", demote(relink(md.read_text(), link)).strip(), ""]
    return lines


def build(results: Path, out: Path) -> str:
    link = Path("..") / results.relative_to(ROOT) if results.is_relative_to(ROOT) else results
    link = str(link).rstrip("/") + "/"
    lines = [
        "# Evaluation: the paper's experiments on data we can obtain",
        "",
        "Generated by `python -m affcorr_bench.eval.report` on "
        + time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        + " from the result files in `benches/results/eval/`. Every number and every "
        "comparison below is computed from those files; regenerate after re-running an "
        "experiment. Each section's tables carry the command, date, machine load and library "
        "versions of their run.",
        "",
    ]
    for key, title, module in EXPERIMENTS:
        lines += section(key, title, module, results, link)
    text = "\n".join(lines).rstrip() + "\n"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--results", type=Path, default=common.RESULTS / "eval")
    ap.add_argument("--out", type=Path, default=ROOT / "docs/evaluation.md")
    a = ap.parse_args(argv)
    build(a.results.resolve(), a.out)
    print(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

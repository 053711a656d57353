"""What the view cascade's relative budget buys, and what a pair that does not overlap costs.

    .venv/bin/python -m affcorr_bench.views_budget [--unrelated 36] [--zoom-seeds 4]
        [--threads 2] [--out benches/results/views_budget]

The cascade (``views="auto"``) stops at the first view that verifies, so a pair it can solve
costs what its solving view costs; a pair with nothing to find (two images that do not overlap,
the common case in a pair list) runs until ``view_relative_budget`` (in plain passes of work,
counted, not timed) is spent. One run at a budget above the largest tabulated (``RUN_BUDGET``)
on each set gives both sides of the trade-off at every budget, because the budget only decides
where the cascade stops, not what it tries before: each view reports the work spent when it
started (``started``, what the budget was compared with) and what its group's screen spent on
extractions (``screen_extraction``), so a pair solved by a view that started at ``w`` is solved
at any budget above ``w``, and a pair that is never solved costs the work before the cascade's
first check at or above the budget (a screen the budget cuts is skipped, or stopped after its
extractions when those fit: ``cost_at``; tests/test_bench_views_budget.py checks this reading
against runs at smaller budgets).

Sets (planar, exact H; solved: the H within 10 px of the truth over A's pixels seen in B, as
in affcorr_bench.views):

- **rotation**: affcorr_bench.views' rotation family (experiment 1's pairs, B rotated by 0, 30,
  90, 135, 180 deg);
- **zoom**: its zoom family and zoom set (2-6x zooms of A or B into random centres);
- **extreme**: experiment 4's renderings at 50-80 deg of tilt (affcorr_bench.eval.data.
  extreme_pairs: the three images of seed 0 and every held-out image at seed 1);
- **unrelated**: ``--unrelated`` pairs of different images drawn from the training and held-out
  textures (affcorr.train.sources.textures; no two of one family, seeded): nothing to solve.

Writes ``<out>.{md,csv,png}``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from . import common
from . import views as V

BUDGETS = (1, 4, 6, 8, 10, 12, 15, 20, 25, 30)
# The budget of the run that every column is read from (see ``cost_at``).
RUN_BUDGET = 40


def _cases(unrelated: int, zoom_seeds: int):
    """(set, pair id, img1, img2, H or None) of every set."""
    from .eval import data

    for _, what, pid, a, b, H in V.cases(1, ("rotation",)):
        yield "rotation", f"{pid} {what}", a, b, H
    for _, what, pid, a, b, H in V.cases(1, ("zoom", "zoomset"), zoom_seeds):
        yield "zoom", f"{pid} {what}", a, b, H
    for p in data.extreme_pairs() + data.extreme_pairs(seed=1, every_held_out=True):
        yield "extreme", p.id, p.img1, p.img2, p.H
    for a, b, img0, img1 in data.unrelated_pairs(unrelated):
        yield "unrelated", f"{a} | {b}", img0, img1, None


def solved_after(views: list[dict]) -> float:
    """The budget the pair needs: the cascade's work (plain passes) when the view whose ACs
    are the result's started (its ``started``; 0 for the plain pass)."""
    return next((v["started"] for v in views if v["used"]), 0.0)


def cost_at(views: list[dict], budget: float) -> float:
    """The work (plain passes; the views' ``work`` summed, the plain pass's 1 included) of the
    cascade stopped at ``budget``. The cascade checks the budget before each step against the
    work spent (the plain pass's verification included, which is in no view's work); before a
    screened group's screen, against that plus the group's extractions (``screen_extraction``
    of the group's first view), skipping the group when they reach it, then against that plus
    the screens (the first view's ``started``), stopping after the extractions when the screens
    reach it. Exact for budgets up to the run's own less what its last view spent (the last
    view carries the work after it)."""
    if len(views) <= 1:  # no view ran: the plain pass's work (and any screen after it)
        return views[0]["work"] if views else 1.0
    cascade = views[1:]
    # What a view with no screen before it started at beyond the views before it.
    verification = min(v["started"] - w for v, w in zip(cascade, _cumulative(cascade)))
    done = 0.0  # the views' work so far
    for v in cascade:
        before = verification + done
        if before >= budget:
            return 1.0 + done
        if v["started"] >= budget:
            extraction = v["screen_extraction"]
            return 1.0 + done + (extraction if before + extraction < budget else 0.0)
        done += v["work"]
    return 1.0 + done


def _cumulative(views: list[dict]) -> list[float]:
    out, total = [], 0.0
    for v in views:
        out.append(total)
        total += v["work"]
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--unrelated", type=int, default=36, help="pairs that do not overlap")
    p.add_argument("--zoom-seeds", type=int, default=4, help="the zoom set's cases per pair")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(common.RESULTS / "views_budget"))
    args = p.parse_args(argv)

    import affcorr
    from affcorr._progress import progress
    from affcorr.batch import BATCH_VIEW_RELATIVE_BUDGET
    from affcorr.pipeline import PIPELINE_DEFAULTS

    # Above the largest budget tabulated: it runs every view a smaller budget runs, and where
    # it stopped (its last view carries what it spent after it) lies beyond every budget read.
    pipe = affcorr.Pipeline(threads=args.threads, views="auto", view_relative_budget=RUN_BUDGET)
    thr = PIPELINE_DEFAULTS["homography_threshold"]
    cases = list(_cases(args.unrelated, args.zoom_seeds))
    rows = []
    t0 = time.time()
    views_of = []
    for set_name, pid, a, b, H in progress(cases, "views_budget", "pair"):
        t = time.perf_counter()
        res = pipe.match_pair(a, b)
        seconds = time.perf_counter() - t
        views = res.views
        err = float("inf")
        if H is not None and len(res) >= 4:
            try:
                Hest, _ = affcorr.estimate_homography(res.corrs, threshold=thr)
                err = float(V.overlap_error(Hest, H, a, b))
            except RuntimeError:  # no model from these ACs
                pass
        solved = bool(err < V.SUCCESS_PX)
        views_of.append(views)
        row = dict(
            set=set_name,
            pair=pid,
            solved=solved,
            error_px=err,
            seconds=seconds,
            view=next((v["label"] for v in views if v["used"]), ""),
            solved_after=solved_after(views) if solved else float("nan"),
            work=cost_at(views, float("inf")),
        )
        row.update({f"cost_at_{b}": cost_at(views, b) for b in BUDGETS})
        rows.append(row)
    out = Path(args.out)
    common.write_csv(rows, out.with_suffix(".csv"))

    sets = list(dict.fromkeys(r["set"] for r in rows))
    table = []
    for s in sets:
        sel = [r for r in rows if r["set"] == s]
        if s == "unrelated":
            cells = [f"{np.median([r[f'cost_at_{b}'] for r in sel]):.1f}" for b in BUDGETS]
            what = f"unrelated: median work per pair ({len(sel)} pairs)"
        else:
            cells = [str(sum(r["solved"] and r["solved_after"] < b for r in sel)) for b in BUDGETS]
            what = f"{s}: solved of {len(sel)}"
        table.append([what, *cells])
    unrelated = [r for r in rows if r["set"] == "unrelated"]
    plain_s = [r["seconds"] / max(r["work"], 1e-9) for r in unrelated]
    load = common.load_average()
    default = PIPELINE_DEFAULTS["view_relative_budget"]
    lines = [
        "# The view cascade's budget: what it solves, what a pair without overlap costs",
        "",
        f"Command: `{common.command(__spec__.name, argv)}`",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. affcorr "
        f"{affcorr.__version__}; the pipeline's defaults ({PIPELINE_DEFAULTS['matcher']}, "
        f"{PIPELINE_DEFAULTS['max_keypoints']} keypoints), views=auto at budget "
        f"{RUN_BUDGET}, "
        f"{args.threads} threads; homography threshold {thr} px. {len(cases)} pairs in "
        f"{time.time() - t0:.0f} s; load average at the end {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} on 2 cores.",
        "",
        "Each column is a `view_relative_budget`: the cascade's work, in plain passes, after "
        "which it starts nothing new, nor a screen that would reach it. Solved pairs: those "
        "whose solving view started below it (the budget decides where the cascade stops, not "
        f"what it tries first, so one run at {RUN_BUDGET} gives every column). Unrelated "
        "pairs: the work done in all, the plain pass's 1 included, when the cascade stops. "
        f"The pipeline's default is {default:g}, a batch's (`affcorr batch`, "
        f"`affcorr.batch.run`) {BATCH_VIEW_RELATIVE_BUDGET:g}. A plain pass of an unrelated "
        f"pair took {np.median(plain_s):.2f} s here (median of its pairs' time over work).",
        "",
    ]
    lines += common.md_table(["set", *[f"{b:g}" for b in BUDGETS]], table)
    lines += [
        "",
        "Solving views (the pairs the plain pass does not solve): "
        + "; ".join(
            f"{s}: "
            + ", ".join(
                f"{r['view']} after {r['solved_after']:.1f}"
                for r in sorted(
                    (r for r in rows if r["set"] == s and r["solved"] and r["view"] != "plain"),
                    key=lambda r: -r["solved_after"],
                )[:3]
            )
            + " (the latest three)"
            for s in sets
            if s != "unrelated"
        ),
    ]
    common.write_report(out.with_suffix(".md"), lines + [""])
    _plot(rows, views_of, sets, out.with_suffix(".png"), default, BATCH_VIEW_RELATIVE_BUDGET)


def _plot(rows, views_of, sets, path: Path, default: float, batch: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    budgets = np.linspace(1, 30, 117)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.8))
    for s in sets:
        sel = [r for r in rows if r["set"] == s]
        if s == "unrelated":
            continue
        solved = [np.mean([r["solved"] and r["solved_after"] < b for r in sel]) for b in budgets]
        ax.plot(budgets, solved, label=f"{s} ({len(sel)})")
    ax.set(xlabel="view_relative_budget (plain passes)", ylabel="fraction solved", ylim=(0, 1.02))
    unrelated = [v for r, v in zip(rows, views_of) if r["set"] == "unrelated"]
    cost = [np.median([cost_at(v, b) for v in unrelated]) for b in budgets]
    bx.plot(budgets, cost, color="k", label=f"unrelated ({len(unrelated)}), median")
    bx.plot(budgets, budgets, ":", color="grey", label="the budget")
    bx.set(xlabel="view_relative_budget (plain passes)", ylabel="work per pair (plain passes)")
    for a in (ax, bx):
        for x, name in ((default, "pipeline"), (batch, "batch")):
            a.axvline(x, color="grey", lw=0.8, ls="--")
            a.text(x, a.get_ylim()[1], f" {name}", va="top", fontsize=8)
        a.legend(fontsize=8, loc="lower right")
    fig.suptitle("The view cascade's budget: pairs solved, and the cost of a pair without overlap")
    common.save_figure(fig, path)


if __name__ == "__main__":
    main()

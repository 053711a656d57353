"""Pictures of affine correspondences: the two images side by side, matches as lines, and each
AC's affine frame as an ellipse pair (a circle of ``radius`` px around x1 and its image under A
around x2). Needs matplotlib (the ``plot`` extra).

With ``model`` (the inliers and residuals of an estimated H or F), matches are coloured by
the model: inliers green, outliers red, and a panel below shows the residuals' histogram. With
a ground-truth homography, by correctness: green within ``threshold`` px of H, red otherwise;
without either, by ``certainty`` (or one colour).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .metrics import correct_mask


def _gray(img) -> np.ndarray:
    if isinstance(img, (str, Path)):
        from . import read_gray_image

        return read_gray_image(str(img)).astype(np.float64)
    img = np.asarray(img)
    if img.ndim == 3:
        img = img[..., :3].mean(-1)
    img = img.astype(np.float64)
    return img / 255.0 if img.max() > 1.5 else img


def draw_matches(
    image_a,
    image_b,
    corrs,
    out: str | Path | None = None,
    *,
    H=None,
    certainty=None,
    threshold: float = 3.0,
    max_lines: int = 300,
    max_ellipses: int = 80,
    radius: float = 10.0,
    title: str | None = None,
    seed: int = 0,
    model: dict | None = None,
):
    """Draw ``corrs`` (N, 8) (or (N, 4): no ellipses) between two images; returns the figure
    and writes it to exactly ``out`` when given (format from its suffix, PNG without one).

    A random subset of at most ``max_lines`` matches and ``max_ellipses`` ellipse pairs (a
    circle of ``radius`` px around x1, its image under A around x2) is drawn so that dense sets
    stay readable. ``model``: ``{"what": str, "inliers": (N,) bool, "residuals": (N,) px}``
    (``affcorr show --inliers``) colours by the model's inliers, draws the inliers' ellipses
    first and adds the residual histogram; ``H`` then only adds the correct count to the title.
    """
    import matplotlib

    if out is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    corrs = np.asarray(corrs, dtype=np.float64)
    if corrs.ndim != 2 or corrs.shape[1] not in (4, 8):
        raise ValueError(f"corrs must have shape (N, 4) or (N, 8), got {corrs.shape}")
    a, b = _gray(image_a), _gray(image_b)
    h = max(a.shape[0], b.shape[0])
    canvas = np.ones((h, a.shape[1] + b.shape[1]))
    canvas[: a.shape[0], : a.shape[1]] = a
    canvas[: b.shape[0], a.shape[1] :] = b
    dx = a.shape[1]
    height = 12 * h / canvas.shape[1] + 0.6
    if model is None:
        fig, ax = plt.subplots(figsize=(12, height))
        hist_ax = None
    else:
        fig, (ax, hist_ax) = plt.subplots(
            2, 1, figsize=(12, height + 2.4), gridspec_kw={"height_ratios": [height, 2.0]}
        )
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=1)
    ax.set_axis_off()
    rng = np.random.default_rng(seed)
    n = len(corrs)
    order = rng.permutation(n)
    ellipse_order = order
    if model is not None:
        inl = np.asarray(model["inliers"], dtype=bool)
        res = np.asarray(model["residuals"], dtype=np.float64)
        if inl.shape != (n,) or res.shape != (n,):
            raise ValueError(f"model: inliers and residuals must have shape ({n},)")
        colours = np.where(inl[:, None], [[0.1, 0.85, 0.2]], [[0.95, 0.15, 0.1]])
        med = float(np.median(res[inl])) if inl.any() else float("nan")
        label = f"{inl.sum()} / {n} inliers of {model['what']}; median inlier residual {med:.2f} px"
        if H is not None:
            ok = correct_mask(corrs, np.asarray(H, dtype=np.float64), threshold)
            label += f"; {ok.sum()} correct within {threshold:g} px of the ground truth"
        # lines: a random sample of all; ellipse pairs: the inliers' first
        ellipse_order = np.concatenate([order[inl[order]], order[~inl[order]]])
        finite = res[np.isfinite(res)]
        top = max(float(np.percentile(finite, 99)), 1e-3) if len(finite) else 1.0
        bins = np.linspace(0, top, 60)
        hist_ax.hist(
            np.clip(res[inl & np.isfinite(res)], 0, top), bins, color="tab:green", label="inliers"
        )
        hist_ax.hist(
            np.clip(res[~inl & np.isfinite(res)], 0, top),
            bins,
            color="tab:red",
            alpha=0.6,
            label="outliers",
        )
        hist_ax.set_xlabel("residual (px; the last bin holds everything beyond)")
        hist_ax.set_ylabel("ACs")
        hist_ax.legend(fontsize=8)
    elif H is not None:
        ok = correct_mask(corrs, np.asarray(H, dtype=np.float64), threshold)
        colours = np.where(ok[:, None], [[0.1, 0.85, 0.2]], [[0.95, 0.15, 0.1]])
        label = f"{ok.sum()} / {n} correct within {threshold:g} px"
    elif certainty is not None:
        colours = plt.cm.viridis(np.clip(np.asarray(certainty, dtype=np.float64), 0, 1))[:, :3]
        label = f"{n} matches, coloured by certainty"
    else:
        colours = np.tile([[0.1, 0.6, 1.0]], (n, 1))
        label = f"{n} matches"
    for i in order[:max_lines]:
        x1, y1, x2, y2 = corrs[i, :4]
        ax.plot([x1, x2 + dx], [y1, y2], "-", color=colours[i], lw=0.6, alpha=0.7)
    if corrs.shape[1] == 8:
        t = np.linspace(0, 2 * np.pi, 40)
        circle = radius * np.stack([np.cos(t), np.sin(t)])
        for i in ellipse_order[:max_ellipses]:
            A = corrs[i, 4:].reshape(2, 2)
            e = A @ circle
            ax.plot(corrs[i, 0] + circle[0], corrs[i, 1] + circle[1], color=colours[i], lw=1.0)
            ax.plot(corrs[i, 2] + dx + e[0], corrs[i, 3] + e[1], color=colours[i], lw=1.0)
    ax.set_title(f"{title + ': ' if title else ''}{label}", fontsize=10)
    fig.tight_layout()
    if out is not None:
        fmt = Path(out).suffix.lstrip(".").lower() or "png"
        with open(out, "wb") as f:
            fig.savefig(f, format=fmt, dpi=110)
        plt.close(fig)
    return fig

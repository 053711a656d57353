"""Pictures of affine correspondences: the two images side by side, matches as lines, and each
AC's affine frame as an ellipse pair (a circle of ``radius`` px around x1 and its image under A
around x2). Needs matplotlib (the ``plot`` extra).

With a ground-truth homography, matches are coloured by correctness: green within
``threshold`` px of H, red otherwise; without, by ``certainty`` (or one colour).
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
):
    """Draw ``corrs`` (N, 8) (or (N, 4): no ellipses) between two images; returns the figure
    and writes it to ``out`` when given. A random subset of at most ``max_lines`` matches and
    ``max_ellipses`` frames is drawn so that dense sets stay readable."""
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
    fig, ax = plt.subplots(figsize=(12, 12 * h / canvas.shape[1] + 0.6))
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=1)
    ax.set_axis_off()
    rng = np.random.default_rng(seed)
    n = len(corrs)
    if H is not None:
        ok = correct_mask(corrs, np.asarray(H, dtype=np.float64), threshold)
        colours = np.where(ok[:, None], [[0.1, 0.85, 0.2]], [[0.95, 0.15, 0.1]])
        label = f"{ok.sum()} / {n} correct within {threshold:g} px"
    elif certainty is not None:
        colours = plt.cm.viridis(np.clip(np.asarray(certainty, dtype=np.float64), 0, 1))[:, :3]
        label = f"{n} matches, coloured by certainty"
    else:
        colours = np.tile([[0.1, 0.6, 1.0]], (n, 1))
        label = f"{n} matches"
    for i in rng.permutation(n)[:max_lines]:
        x1, y1, x2, y2 = corrs[i, :4]
        ax.plot([x1, x2 + dx], [y1, y2], "-", color=colours[i], lw=0.6, alpha=0.7)
    if corrs.shape[1] == 8:
        t = np.linspace(0, 2 * np.pi, 40)
        circle = radius * np.stack([np.cos(t), np.sin(t)])
        for i in rng.permutation(n)[:max_ellipses]:
            A = corrs[i, 4:].reshape(2, 2)
            e = A @ circle
            ax.plot(corrs[i, 0] + circle[0], corrs[i, 1] + circle[1], color=colours[i], lw=1.0)
            ax.plot(corrs[i, 2] + dx + e[0], corrs[i, 3] + e[1], color=colours[i], lw=1.0)
    ax.set_title(f"{title + ': ' if title else ''}{label}", fontsize=10)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=110)
        plt.close(fig)
    return fig
